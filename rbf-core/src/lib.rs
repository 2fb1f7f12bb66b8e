//! # rbf-core: the computation every gyro sample goes through
//!
//! `no_std`, no allocation, no panics on any input. The host `trainer` and the
//! `firmware` both call these functions, so a model evaluates to the same bits
//! on the calibration PC and on the gyro's Cortex-M4F.
//!
//! - [`features`]: streaming fiber-loop temperature features (T, ΔT, T×ΔT), ΔT in °C/min;
//!   [`lag_bank`]: the thermal lag bank (mean coil temperature and coil rates);
//!   [`response_bank`]: the thermal response bank (a static quartic and three free rate responses).
//! - [`filter`]: the first-order derivative filter every ΔT is read through.
//! - [`rbf`]: a fixed-capacity Gaussian RBF network with input normalisation and clamping.
//! - [`poly`]: the cubic-in-T baseline (the PX4 / ArduPilot form).
//! - [`error`]: why parameters are not a usable model ([`ModelError`]).
//! - [`model`]: a deployable model (either kind + feature configuration + ranges).
//! - [`compensator`]: the per-sample loop state (sensor-fault hold, gaps, flags).
//! - [`blob`]: the model blob format (header, postcard payload, CRC-32) and its decoder.
//! - [`shared_basis`]: shared-basis multi-axis models (one basis, an output layer per axis).
//! - [`stored_model`]: a model of any kind decoded in place from its blob ([`stored_model::StoredModel`]).
//! - [`record`]: row parsing of recorded runs; [`sensor`]: TMP117 conversions;
//!   [`axis`]: the axes of a multi-axis IMU ([`axis::Axis`], [`axis::MAX_AXES`]);
//!   [`thermometer`]: the thermometers a run provides and a model reads ([`thermometer::ThermometerSet`]).
//!
//! Sizes live in types ([`MAX_CENTERS`], [`MAX_INPUTS`]); values are runtime data.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

pub mod axis;
pub mod blob;
pub mod compensator;
pub mod error;
pub mod fastmath;
pub mod features;
pub mod filter;
pub mod flags;
pub mod lag_bank;
pub mod model;
pub mod poly;
pub mod rbf;
pub mod record;
pub mod response_bank;
pub mod sensor;
pub mod shared_basis;
pub mod stored_model;
pub mod thermometer;

/// Most Gaussian centres a deployable model may hold (firmware RAM is sized for it).
pub const MAX_CENTERS: usize = 64;
/// Most Gaussian centres each axis's model of a multi-axis blob may hold:
/// the capacity of the three-axis board's decoded models, sized so that
/// three models, the update buffer and the stack fit its 16 KiB of RAM
/// (docs/firmware.md, "Three axes"). `trainer fit` keeps multi-axis models
/// within it; the board refuses a blob with a larger axis.
pub const MAX_AXIS_CENTERS: usize = 16;
/// Most Gaussian centres the shared basis of a shared-basis multi-axis blob
/// may hold on the three-axis boards and in the C library's IMU state: one
/// basis with a weight per axis takes about a third of three models' RAM,
/// so it holds twice [`MAX_AXIS_CENTERS`] in the same room.
pub const MAX_SHARED_AXIS_CENTERS: usize = 2 * MAX_AXIS_CENTERS;
/// Most model inputs (features) a deployable model may use.
pub const MAX_INPUTS: usize = 12;
/// Most inputs the Gaussians of a network may see (the rest enter linearly).
pub const MAX_KERNEL_INPUTS: usize = 8;

pub use compensator::{CompensatedSample, Compensator, CompensatorConfig, GyroSample};
pub use features::{FeatureConfig, FeatureExtractor, FeatureSet, FeatureVector};
pub use flags::Flags;
pub use model::{Model, ModelError, ModelInfo};
