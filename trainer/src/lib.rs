//! # trainer: the host side of IFOG temperature-drift compensation
//!
//! Reads recorded chamber runs, fits a bias model, writes the model blob, and
//! compensates/evaluates runs with exactly the `rbf-core` code the firmware
//! runs. The `trainer` binary is a thin clap front end over these modules.
//!
//! Data flow of a fit, one folder a layer: [`reading`] (the run CSV, parsed
//! on every core and checked: [`reading::run`]) → [`dataset`] (rbf-core
//! features, 1-s block means, targets) → [`fit`] (OLS centre selection,
//! ridge weights, validation; [`fit::axes`]: every axis of a multi-axis run
//! and the joint model) → [`blobfile`] (postcard + CRC) → [`evaluation`]
//! (streaming compensation + [`metrics`]) → [`report`] (plots and written
//! summary; [`describe`]: a model in words). Beside them: [`plan`] designs
//! the chamber run, [`simulate`] synthesises runs, [`device`] talks to the
//! unit, [`output`] writes every file through a transaction, [`refusals`]
//! names the flag that accepts a refusal; [`acceptance`] judges a unit against a spec,
//! [`provenance`] says where a blob came from, [`calibration`] makes a unit's summary
//! rows and [`records`] keeps each calibration in SQLite or PostgreSQL. Shared helpers sit below the
//! features that use them: [`parallel`], [`plotting`], [`text`].

#![forbid(unsafe_code)]

pub mod acceptance;
pub mod blobfile;
pub mod calibration;
pub mod dataset;
pub mod describe;
pub mod device;
pub mod evaluation;
pub mod fit;
pub mod metrics;
pub mod output;
pub mod parallel;
pub mod plan;
pub mod plotting;
pub mod provenance;
pub mod reading;
pub mod records;
pub mod refusals;
pub mod report;
pub mod simulate;
pub mod text;
