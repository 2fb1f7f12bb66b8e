//! # trainer: the host side of IFOG temperature-drift compensation
//!
//! Reads recorded chamber runs, fits a bias model, writes the model blob, and
//! compensates/evaluates runs with exactly the `rbf-core` code the firmware
//! runs. The `trainer` binary is a thin clap front end over these modules.
//!
//! Data flow of a fit: [`run`] (CSV) → [`dataset`] (rbf-core features,
//! 1-s block means, targets) → [`fit`] (OLS centre selection, ridge weights,
//! validation) → [`blobfile`] (postcard + CRC) → [`evaluate`] (streaming
//! compensation + [`metrics`]).

#![forbid(unsafe_code)]

pub mod allan;
pub mod axes;
pub mod blobfile;
pub mod chunked;
pub mod dataset;
pub mod decimal;
pub mod describe;
pub mod device;
pub mod diagnose;
pub mod evaluate;
pub mod fit;
pub mod fit_axes;
pub mod frames;
pub mod gradients;
pub mod input;
pub mod limits;
pub mod metrics;
pub mod output;
pub mod parallel;
pub mod plan;
pub mod plausible;
pub mod plotting;

pub mod refusals;
pub mod report;
pub mod run;
pub mod sampling;
pub mod simulate;
pub mod summary;
pub mod text;
