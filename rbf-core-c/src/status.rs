//! The status codes the C functions return and their meaning in words
//! (`rbf_status_message`): 0 is success, every failure a negative code of
//! its own, one per check the Rust decoder makes and one per argument check.

use core::ffi::CStr;

use rbf_core::ModelError;
use rbf_core::blob::DecodeError;

/// Success.
pub const RBF_OK: i32 = 0;
/// A pointer argument is NULL.
pub const RBF_ERR_NULL_POINTER: i32 = -1;
/// The state buffer is shorter than the state size constant of its kind.
pub const RBF_ERR_STATE_TOO_SMALL: i32 = -2;
/// The state buffer is not aligned to the state alignment constant of its kind.
pub const RBF_ERR_STATE_MISALIGNED: i32 = -3;
/// The state buffer was not set up by its kind's load function (or was overwritten).
pub const RBF_ERR_STATE_NOT_LOADED: i32 = -4;
/// The sample rate is not a finite number above 0 Hz.
pub const RBF_ERR_SAMPLE_RATE: i32 = -5;
/// The blob is shorter than its header or the length its header states.
pub const RBF_ERR_BLOB_TRUNCATED: i32 = -10;
/// The blob does not start with `IFOG`: not a model blob (or erased flash).
pub const RBF_ERR_BLOB_BAD_MAGIC: i32 = -11;
/// The blob's format version is one this library cannot read.
pub const RBF_ERR_BLOB_UNSUPPORTED_VERSION: i32 = -12;
/// The blob names a model kind this library does not know.
pub const RBF_ERR_BLOB_UNKNOWN_KIND: i32 = -13;
/// The blob's CRC-32 does not match its bytes: the blob is corrupt.
pub const RBF_ERR_BLOB_CRC_MISMATCH: i32 = -14;
/// The blob's model has more centres or inputs than the state can hold.
pub const RBF_ERR_BLOB_OVER_CAPACITY: i32 = -15;
/// The blob's payload does not parse, or disagrees with its header.
pub const RBF_ERR_BLOB_MALFORMED: i32 = -16;
/// A multi-axis blob given to the single-axis `rbf_gyro_load`: use `rbf_imu_load`.
pub const RBF_ERR_BLOB_MULTI_AXIS: i32 = -17;
/// A multi-axis blob's axis mask names no axis, or one beyond z.
pub const RBF_ERR_BLOB_BAD_AXIS_MASK: i32 = -18;
/// A blob of another multi-axis layout than its header announces.
pub const RBF_ERR_BLOB_LAYOUT: i32 = -19;
/// The model's parameter arrays disagree with its shape.
pub const RBF_ERR_MODEL_SHAPE_MISMATCH: i32 = -20;
/// A model parameter is NaN or infinite.
pub const RBF_ERR_MODEL_NON_FINITE: i32 = -21;
/// A model parameter is out of its valid range (a width ≤ 0, a range with min > max, ...).
pub const RBF_ERR_MODEL_INVALID_PARAMETER: i32 = -22;
/// The model's output could exceed ±1e6 °/h within its input ranges.
pub const RBF_ERR_MODEL_OUTPUT_UNBOUNDED: i32 = -23;
/// The blob is refused for a reason newer than this list.
pub const RBF_ERR_BLOB_OTHER: i32 = -29;

/// Every code with its meaning, the words `rbf_status_message` returns.
const MESSAGES: [(i32, &CStr); 21] = [
    (RBF_OK, c"ok"),
    (RBF_ERR_NULL_POINTER, c"a pointer argument is NULL"),
    (
        RBF_ERR_STATE_TOO_SMALL,
        c"the state buffer is shorter than RBF_GYRO_STATE_SIZE / RBF_IMU_STATE_SIZE",
    ),
    (
        RBF_ERR_STATE_MISALIGNED,
        c"the state buffer is not aligned to RBF_GYRO_STATE_ALIGN / RBF_IMU_STATE_ALIGN",
    ),
    (
        RBF_ERR_STATE_NOT_LOADED,
        c"the state was not set up by rbf_gyro_load / rbf_imu_load (or was overwritten)",
    ),
    (
        RBF_ERR_SAMPLE_RATE,
        c"the sample rate is not a finite number above 0 Hz",
    ),
    (
        RBF_ERR_BLOB_TRUNCATED,
        c"truncated blob: shorter than its header or than the length its header states",
    ),
    (
        RBF_ERR_BLOB_BAD_MAGIC,
        c"bad magic: not an IFOG model blob (or erased flash)",
    ),
    (
        RBF_ERR_BLOB_UNSUPPORTED_VERSION,
        c"unsupported blob format version (this library reads 2 and 3)",
    ),
    (RBF_ERR_BLOB_UNKNOWN_KIND, c"unknown model kind code"),
    (RBF_ERR_BLOB_CRC_MISMATCH, c"CRC-32 mismatch: the blob is corrupt"),
    (
        RBF_ERR_BLOB_OVER_CAPACITY,
        c"the model has more centres or inputs than this state holds",
    ),
    (
        RBF_ERR_BLOB_MALFORMED,
        c"malformed payload: it does not parse or disagrees with the header",
    ),
    (
        RBF_ERR_BLOB_MULTI_AXIS,
        c"a multi-axis blob where a single-axis model is expected: load it with rbf_imu_load",
    ),
    (
        RBF_ERR_BLOB_BAD_AXIS_MASK,
        c"the blob's axis mask names no axis or one beyond z",
    ),
    (
        RBF_ERR_BLOB_LAYOUT,
        c"the multi-axis blob's layout is not the one its header announces",
    ),
    (
        RBF_ERR_MODEL_SHAPE_MISMATCH,
        c"invalid model: parameter arrays disagree with the model shape",
    ),
    (
        RBF_ERR_MODEL_NON_FINITE,
        c"invalid model: a parameter is NaN or infinite",
    ),
    (
        RBF_ERR_MODEL_INVALID_PARAMETER,
        c"invalid model: a parameter is out of its valid range",
    ),
    (
        RBF_ERR_MODEL_OUTPUT_UNBOUNDED,
        c"invalid model: its output can exceed 1e6 deg/h within its input ranges",
    ),
    (
        RBF_ERR_BLOB_OTHER,
        c"the blob is refused (a reason newer than this library's list)",
    ),
];

/// The words for `code`: a NUL-terminated string that lives as long as the program.
pub fn message(code: i32) -> &'static CStr {
    MESSAGES
        .iter()
        .find(|(c, _)| *c == code)
        .map_or(c"unknown status code", |(_, m)| *m)
}

/// The code of a decoder's refusal.
pub fn from_decode(e: DecodeError) -> i32 {
    match e {
        DecodeError::Truncated { .. } => RBF_ERR_BLOB_TRUNCATED,
        DecodeError::BadMagic => RBF_ERR_BLOB_BAD_MAGIC,
        DecodeError::UnsupportedVersion(_) => RBF_ERR_BLOB_UNSUPPORTED_VERSION,
        DecodeError::UnknownKind(_) => RBF_ERR_BLOB_UNKNOWN_KIND,
        DecodeError::CrcMismatch { .. } => RBF_ERR_BLOB_CRC_MISMATCH,
        DecodeError::ShapeOverCapacity { .. } => RBF_ERR_BLOB_OVER_CAPACITY,
        DecodeError::Malformed => RBF_ERR_BLOB_MALFORMED,
        DecodeError::Model(m) => from_model(m),
        DecodeError::MultiAxis => RBF_ERR_BLOB_MULTI_AXIS,
        DecodeError::BadAxisMask(_) => RBF_ERR_BLOB_BAD_AXIS_MASK,
        DecodeError::SharedBasis | DecodeError::NotSharedBasis => RBF_ERR_BLOB_LAYOUT,
        _ => RBF_ERR_BLOB_OTHER,
    }
}

/// The code of a model the decoder parsed but found unusable.
fn from_model(e: ModelError) -> i32 {
    match e {
        ModelError::ShapeOverCapacity => RBF_ERR_BLOB_OVER_CAPACITY,
        ModelError::ShapeMismatch => RBF_ERR_MODEL_SHAPE_MISMATCH,
        ModelError::NonFiniteParameter => RBF_ERR_MODEL_NON_FINITE,
        ModelError::InvalidParameter => RBF_ERR_MODEL_INVALID_PARAMETER,
        ModelError::OutputUnbounded => RBF_ERR_MODEL_OUTPUT_UNBOUNDED,
        _ => RBF_ERR_BLOB_OTHER,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_has_its_own_words_and_an_unknown_code_says_so() {
        let codes: Vec<i32> = MESSAGES.iter().map(|(c, _)| *c).collect();
        for (i, &c) in codes.iter().enumerate() {
            assert!(!codes[i + 1..].contains(&c), "code {c} listed twice");
            assert_ne!(message(c), c"unknown status code", "code {c}");
        }
        let words: std::collections::BTreeSet<&CStr> = codes.iter().map(|&c| message(c)).collect();
        assert_eq!(words.len(), codes.len(), "two codes share their words");
        assert_eq!(message(12345), c"unknown status code");
        assert_eq!(
            message(from_decode(DecodeError::CrcMismatch { stored: 1, computed: 2 })),
            c"CRC-32 mismatch: the blob is corrupt"
        );
    }
}
