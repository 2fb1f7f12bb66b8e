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

#[cfg(feature = "full")]
pub mod acceptance;
#[cfg(feature = "full")]
pub mod blobfile;
#[cfg(feature = "full")]
pub mod calibration;
#[cfg(feature = "full")]
pub mod dataset;
#[cfg(feature = "full")]
pub mod describe;
#[cfg(feature = "full")]
pub mod device;
#[cfg(feature = "full")]
pub mod evaluation;
#[cfg(feature = "full")]
pub mod fit;
#[cfg(feature = "full")]
pub mod metrics;
#[cfg(feature = "full")]
pub mod output;
#[cfg(feature = "full")]
pub mod parallel;
#[cfg(feature = "full")]
pub mod plan;
#[cfg(feature = "full")]
pub mod plotting;
#[cfg(feature = "full")]
pub mod provenance;
pub mod reading;
#[cfg(feature = "full")]
pub mod records;
#[cfg(feature = "full")]
pub mod refusals;
#[cfg(feature = "full")]
pub mod report;
#[cfg(feature = "full")]
pub mod simulate;
pub mod text;
