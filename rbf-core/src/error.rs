//! Why a set of model parameters is not a usable model: the error every
//! model body ([`crate::rbf`], [`crate::poly`]) and [`crate::model`] return.

#[cfg(doc)]
use crate::{MAX_CENTERS, MAX_INPUTS};

/// Largest |bias| a model may be able to produce anywhere in its input box,
/// °/h (about 280 °/s: no gyro's thermal bias comes near). A model whose
/// worst case exceeds it is refused, which also proves that evaluation can
/// never overflow to ±∞ or NaN.
pub const MAX_ABS_BIAS_DPH: f64 = 1.0e6;

/// Why a set of model parameters is not a usable model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ModelError {
    /// More centres or inputs than the firmware capacity ([`MAX_CENTERS`], [`MAX_INPUTS`]).
    ShapeOverCapacity,
    /// Parameter arrays disagree in length with the model's shape.
    ShapeMismatch,
    /// A parameter is NaN or infinite.
    NonFiniteParameter,
    /// A parameter is finite but meaningless (width ≤ 0, range min > max, ...).
    InvalidParameter,
    /// Somewhere in its input box the model's output could exceed
    /// ±[`MAX_ABS_BIAS_DPH`] (or overflow).
    OutputUnbounded,
}

impl core::fmt::Display for ModelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ModelError::ShapeOverCapacity => "model shape exceeds the firmware capacity",
            ModelError::ShapeMismatch => "parameter arrays disagree with the model shape",
            ModelError::NonFiniteParameter => "a model parameter is NaN or infinite",
            ModelError::InvalidParameter => "a model parameter is out of its valid range",
            ModelError::OutputUnbounded => "the model's output can exceed ±1e6 °/h within its input ranges",
        })
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ModelError {}
