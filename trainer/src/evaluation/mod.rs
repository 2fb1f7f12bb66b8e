//! A model on runs: compensation of whole runs and their before/after
//! accuracy ([`evaluate`]), the compensated CSV ([`compensate`]), the accuracy
//! tables ([`table`]), every axis of multi-axis runs and models
//! ([`axes`]), the Allan deviation ([`allan`]), why a run gave nothing usable
//! ([`diagnose`]), and the compensated output's number format ([`decimal`]).

pub mod allan;
pub mod axes;
pub mod compensate;
pub mod decimal;
pub mod diagnose;
pub mod evaluate;
pub mod table;
