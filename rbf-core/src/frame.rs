//! Firmware output frames: one per gyro sample, postcard-encoded and
//! COBS-framed (0x00 ends every frame), so a receiver resynchronises after
//! any byte loss at the next zero.
//!
//! Two frame kinds share the wire, told apart by their decoded length:
//! a single-axis firmware sends [`OutputFrame`]s (18 … 22 payload bytes),
//! a multi-axis one [`AxesFrame`]s ([`AXES_FRAME_PAYLOAD_MIN`] …
//! [`AXES_FRAME_PAYLOAD_MAX`] bytes, led by [`AXES_FRAME_TAG`]); command
//! replies have 2 (docs/firmware.md, "Output frames").

use serde::{Deserialize, Serialize};

use crate::axis::AxisSet;
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

/// First payload byte of an [`AxesFrame`] (its frame format version).
pub const AXES_FRAME_TAG: u8 = 0xA3;
/// Shortest payload of an [`AxesFrame`] (tag, 1-byte sequence number,
/// mask, three axes), bytes.
pub const AXES_FRAME_PAYLOAD_MIN: usize = 3 + 3 * AXIS_OUTPUT_LEN;
/// Longest payload of an [`AxesFrame`] (a 5-byte sequence number), bytes.
pub const AXES_FRAME_PAYLOAD_MAX: usize = 7 + 3 * AXIS_OUTPUT_LEN;
/// Largest encoded [`AxesFrame`] including COBS overhead and the 0x00 delimiter, bytes.
pub const MAX_AXES_FRAME_LEN: usize = AXES_FRAME_PAYLOAD_MAX + 2;
/// Payload bytes of one [`AxisOutput`]: four f32 and the flags byte.
const AXIS_OUTPUT_LEN: usize = 17;

/// One axis's part of an [`AxesFrame`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisOutput {
    /// Raw gyro rate of the axis, °/h.
    pub rate_dph: f32,
    /// Bias estimate subtracted, °/h.
    pub bias_dph: f32,
    /// Compensated rate, °/h.
    pub rate_comp_dph: f32,
    /// The axis's loop temperature used, °C (NaN if none).
    pub temp_c: f32,
    /// The axis's status bits ([`Flags`]).
    pub flags: u8,
}

impl AxisOutput {
    /// The axis's flags.
    pub fn flags(&self) -> Flags {
        Flags(self.flags)
    }
}

/// What a multi-axis firmware emits for every sample: every axis of the
/// IMU in one frame, x, y, z (axes not in `axis_mask` are all zero).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AxesFrame {
    /// [`AXES_FRAME_TAG`]: tells this frame from an [`OutputFrame`] and
    /// versions its layout.
    pub tag: u8,
    /// Sample counter since boot (wraps at 2³²); a gap reveals lost frames.
    pub seq: u32,
    /// Axes present: bit 0 = x, bit 1 = y, bit 2 = z.
    pub axis_mask: u8,
    /// Per axis, x first.
    pub axes: [AxisOutput; 3],
}

impl AxesFrame {
    /// The axes present ([`AxesFrame::axis_mask`] as a set).
    pub const fn axes_present(&self) -> AxisSet {
        AxisSet::from_bits(self.axis_mask)
    }
}

/// Encodes `frame` COBS-framed, 0x00-terminated, into `out`; returns the
/// bytes used. Never panics, as [`encode`].
pub fn encode_axes(frame: &AxesFrame, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; AXES_FRAME_PAYLOAD_MAX];
    let raw = postcard::to_slice(frame, &mut raw).map_err(|_| FrameError::BufferTooSmall)?;
    cobs_encode(raw, out).ok_or(FrameError::BufferTooSmall)
}

/// Decodes one multi-axis frame from its COBS bytes (with or without the
/// 0x00), in place; a frame without [`AXES_FRAME_TAG`] is malformed.
pub fn decode_axes(bytes: &mut [u8]) -> Result<AxesFrame, FrameError> {
    let frame: AxesFrame = postcard::from_bytes_cobs(bytes).map_err(|_| FrameError::Malformed)?;
    if frame.tag != AXES_FRAME_TAG {
        return Err(FrameError::Malformed);
    }
    Ok(frame)
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
///
/// This runs once per gyro sample in the firmware, so it must not be able to
/// panic (checked at link time, firmware/src/bin/panic_free_check.rs):
/// postcard serialises into a plain slice (returns errors, never panics) and
/// [`cobs_encode`] frames it; postcard's own COBS flavour indexes with
/// assertions the optimiser cannot remove. The bytes are the same
/// (`frames_match_postcards_cobs_encoding`); decoding uses postcard.
pub fn encode(frame: &OutputFrame, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_FRAME_LEN];
    let raw = postcard::to_slice(frame, &mut raw).map_err(|_| FrameError::BufferTooSmall)?;
    cobs_encode(raw, out).ok_or(FrameError::BufferTooSmall)
}

/// COBS-encodes `src` into `out` followed by the 0x00 delimiter; returns the
/// bytes used, or `None` if `out` is too small. Never panics: every access is
/// checked and fails as `None`.
pub fn cobs_encode(src: &[u8], out: &mut [u8]) -> Option<usize> {
    // `code_at` holds the code byte of the current block: 1 + its non-zero bytes.
    let mut code_at = 0;
    let mut code = 1u8;
    let mut next = 1;
    for &byte in src {
        if byte != 0 {
            *out.get_mut(next)? = byte;
            next += 1;
            code += 1;
        }
        if byte == 0 || code == 0xFF {
            *out.get_mut(code_at)? = code;
            code_at = next;
            next += 1;
            code = 1;
        }
    }
    *out.get_mut(code_at)? = code;
    *out.get_mut(next)? = 0;
    Some(next + 1)
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

    #[test]
    fn frames_match_postcards_cobs_encoding() {
        let mut state = 0x9E37_79B9u32;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        for i in 0..10_000u32 {
            // Many zero bytes (small values, zero floats) and arbitrary patterns.
            let word = |r: u32| if i % 3 == 0 { r & 0x0000_FF00 } else { r };
            let frame = OutputFrame {
                seq: word(next()) >> (i % 32),
                rate_dph: f32::from_bits(word(next())),
                bias_dph: f32::from_bits(word(next())),
                rate_comp_dph: if i % 5 == 0 { 0.0 } else { f32::from_bits(next()) },
                temp_c: f32::from_bits(word(next())),
                flags: (next() & 0x1F) as u8,
            };
            let mut ours = [0u8; MAX_FRAME_LEN];
            let n = encode(&frame, &mut ours).unwrap();
            let mut theirs = [0u8; MAX_FRAME_LEN];
            let reference = postcard::to_slice_cobs(&frame, &mut theirs).unwrap();
            assert_eq!(&ours[..n], reference, "frame {frame:?}");
        }
    }

    #[test]
    fn axes_frames_round_trip_within_their_bounds_and_never_pass_for_single_axis_frames() {
        let axis = |i: u8| AxisOutput {
            rate_dph: f32::from(i) * 1.5,
            bias_dph: -0.25,
            rate_comp_dph: f32::MAX,
            temp_c: if i == 1 { f32::NAN } else { 25.0 },
            flags: i,
        };
        for seq in [0u32, 127, 128, u32::MAX] {
            let frame = AxesFrame {
                tag: AXES_FRAME_TAG,
                seq,
                axis_mask: 0b111,
                axes: [axis(0), axis(1), axis(2)],
            };
            let mut buf = [0u8; MAX_AXES_FRAME_LEN];
            let n = encode_axes(&frame, &mut buf).unwrap();
            assert_eq!(buf[n - 1], 0);
            assert!(!buf[..n - 1].contains(&0));
            let mut raw = [0u8; 64];
            let payload = postcard::to_slice(&frame, &mut raw).unwrap().len();
            assert!((AXES_FRAME_PAYLOAD_MIN..=AXES_FRAME_PAYLOAD_MAX).contains(&payload));
            let back = decode_axes(&mut buf[..n]).unwrap();
            assert_eq!((back.seq, back.axis_mask), (seq, 0b111));
            assert!(back.axes[1].temp_c.is_nan());
            assert_eq!(back.axes[2].flags(), Flags(2));
        }
        let single = OutputFrame {
            seq: 7,
            rate_dph: 1.0,
            bias_dph: 2.0,
            rate_comp_dph: -1.0,
            temp_c: 20.0,
            flags: 0,
        };
        // A single-axis frame is too short to pass for one, whatever its sequence number.
        for seq in [7u32, 0xA3, 0xA3A3_A3A3] {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = encode(&OutputFrame { seq, ..single }, &mut buf).unwrap();
            assert_eq!(decode_axes(&mut buf[..n]), Err(FrameError::Malformed));
        }
        // A wrong tag is refused.
        let mut frame_bytes = [0u8; MAX_AXES_FRAME_LEN];
        let wrong = AxesFrame {
            tag: 0x01,
            seq: 1,
            axis_mask: 1,
            axes: [AxisOutput::default(); 3],
        };
        let n = encode_axes(&wrong, &mut frame_bytes).unwrap();
        assert_eq!(decode_axes(&mut frame_bytes[..n]), Err(FrameError::Malformed));
    }

    #[test]
    fn cobs_encoding_refuses_small_buffers_and_handles_long_runs() {
        assert_eq!(cobs_encode(&[1, 2, 3], &mut [0u8; 4]), None);
        let mut out = [0u8; 5];
        assert_eq!(cobs_encode(&[1, 2, 3], &mut out), Some(5));
        assert_eq!(out, [4, 1, 2, 3, 0]);
        assert_eq!(cobs_encode(&[0, 0], &mut out), Some(4));
        assert_eq!(&out[..4], [1, 1, 1, 0]);
        // 254 non-zero bytes fill a block: a new code byte follows.
        let src = [7u8; 300];
        let mut out = [0u8; 310];
        let n = cobs_encode(&src, &mut out).unwrap();
        assert_eq!((out[0], out[255], n), (0xFF, 47, 303));
        assert!(!out[..n - 1].contains(&0));
    }
}
