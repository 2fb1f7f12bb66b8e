//! Firmware output frames: one per gyro sample, postcard-encoded and
//! COBS-framed (0x00 ends every frame), so a receiver resynchronises after
//! any byte loss at the next zero.

use serde::{Deserialize, Serialize};

use crate::flags::Flags;

/// Largest encoded frame including the 0x00 delimiter, bytes.
pub const MAX_FRAME_LEN: usize = 32;

/// What the firmware emits for every gyro sample.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputFrame {
    /// Sample counter since boot (wraps at 2³²); a gap reveals lost frames.
    pub seq: u32,
    /// Raw gyro rate, °/h.
    pub rate_dph: f32,
    /// Bias estimate subtracted, °/h.
    pub bias_dph: f32,
    /// Compensated rate, °/h.
    pub rate_comp_dph: f32,
    /// Loop temperature used, °C (NaN if none).
    pub temp_c: f32,
    /// Status bits ([`Flags`]).
    pub flags: u8,
}

impl OutputFrame {
    /// The frame's flags.
    pub fn flags(&self) -> Flags {
        Flags(self.flags)
    }
}

/// Why bytes are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameError {
    /// The COBS layer or the postcard payload is malformed.
    Malformed,
    /// The output buffer is too small.
    BufferTooSmall,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Malformed => "malformed frame",
            FrameError::BufferTooSmall => "buffer too small for the frame",
        })
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Encodes `frame` COBS-framed, 0x00-terminated, into `out`; returns the bytes used.
pub fn encode(frame: &OutputFrame, out: &mut [u8]) -> Result<usize, FrameError> {
    postcard::to_slice_cobs(frame, out)
        .map(|b| b.len())
        .map_err(|_| FrameError::BufferTooSmall)
}

/// Decodes one frame from its COBS bytes (with or without the 0x00), in place.
pub fn decode(bytes: &mut [u8]) -> Result<OutputFrame, FrameError> {
    postcard::from_bytes_cobs(bytes).map_err(|_| FrameError::Malformed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_end_in_the_only_zero() {
        let frame = OutputFrame {
            seq: 0x0102_0304,
            rate_dph: 10.5,
            bias_dph: 0.25,
            rate_comp_dph: 10.25,
            temp_c: f32::NAN,
            flags: 2 | 8,
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode(&frame, &mut buf).unwrap();
        assert_eq!(buf[n - 1], 0);
        assert!(!buf[..n - 1].contains(&0), "COBS: 0x00 only as the delimiter");
        let back = decode(&mut buf[..n]).unwrap();
        assert_eq!(back.seq, frame.seq);
        assert_eq!(back.rate_comp_dph.to_bits(), frame.rate_comp_dph.to_bits());
        assert!(back.temp_c.is_nan());
        assert_eq!(back.flags(), Flags::TEMP_SENSOR_FAULT | Flags::WARMING_UP);
        let mut garbage = [1u8, 2, 3, 0];
        assert_eq!(decode(&mut garbage), Err(FrameError::Malformed));
    }
}
