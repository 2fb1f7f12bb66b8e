//! Firmware output frames: one per gyro sample, postcard-encoded and
//! COBS-framed (0x00 ends every frame), so a receiver resynchronises after
//! any byte loss at the next zero.
//!
//! Format 2 (this firmware's): a tag byte that names the kind and version
//! ([`OUTPUT_FRAME_TAG`], [`AXES_FRAME_TAG`]), the postcard fields, then the
//! CRC-32 (ISO-HDLC, the model blob's, little-endian) of every byte before
//! it; a frame whose CRC does not match is [`FrameError::BadCrc`]. Format 1
//! (older firmware: no check; the single-axis frame without a tag, the
//! three-axis one tagged [`AXES_FRAME_TAG_V1`]) is still decoded, and
//! [`FrameFormat`] says which one a frame came in.
//!
//! Frame kinds share the wire with the other messages, told apart by
//! payload length (the crate docs; docs/firmware.md, "Output frames"):
//! command replies 2, boot report 11, bench report 17, single-axis frames
//! 18 … 22 (format 1) and [`OUTPUT_FRAME_PAYLOAD_MIN`] …
//! [`OUTPUT_FRAME_PAYLOAD_MAX`] (format 2), three-axis frames
//! [`AXES_FRAME_PAYLOAD_MIN`] … [`AXES_FRAME_PAYLOAD_MAX`] (either format,
//! and the tag), the health report 116.

use serde::{Deserialize, Serialize};

use rbf_core::axis::AxisSet;
use rbf_core::blob::CRC32;
use rbf_core::flags::Flags;

use crate::cobs::{cobs_decode_in_place, cobs_encode};

/// Largest encoded single-axis frame including the 0x00 delimiter, bytes.
pub const MAX_FRAME_LEN: usize = 32;

/// Bytes of the CRC-32 that ends a format-2 payload.
pub const FRAME_CRC_LEN: usize = 4;

/// First payload byte of a single-axis [`OutputFrame`] of format 2.
pub const OUTPUT_FRAME_TAG: u8 = 0xB2;
/// Payload bytes of an [`OutputFrame`]'s fields: a 1- to 5-byte sequence
/// number, four f32 and the flags byte (format 1 is exactly these).
const OUTPUT_FIELDS_MIN: usize = 1 + 16 + 1;
const OUTPUT_FIELDS_MAX: usize = 5 + 16 + 1;
/// Shortest format-2 single-axis payload (tag, fields, CRC), bytes.
pub const OUTPUT_FRAME_PAYLOAD_MIN: usize = 1 + OUTPUT_FIELDS_MIN + FRAME_CRC_LEN;
/// Longest format-2 single-axis payload, bytes.
pub const OUTPUT_FRAME_PAYLOAD_MAX: usize = 1 + OUTPUT_FIELDS_MAX + FRAME_CRC_LEN;

/// How a decoded frame came: which format, and so whether it was checked.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameFormat {
    /// Format 1 (older firmware): no check; any bytes of the right length
    /// decode, so a damaged frame can pass for one.
    V1,
    /// Format 2: its CRC-32 matched.
    V2,
}

impl FrameFormat {
    /// Whether the frame's bytes were checked (its CRC matched).
    pub const fn is_checked(self) -> bool {
        matches!(self, FrameFormat::V2)
    }
}

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

/// First payload byte of a format-2 [`AxesFrame`].
pub const AXES_FRAME_TAG: u8 = 0xA4;
/// First payload byte of a format-1 [`AxesFrame`] (no CRC).
pub const AXES_FRAME_TAG_V1: u8 = 0xA3;
/// Shortest payload of an [`AxesFrame`] (format 1: tag, 1-byte sequence
/// number, mask, three axes), bytes.
pub const AXES_FRAME_PAYLOAD_MIN: usize = 3 + 3 * AXIS_OUTPUT_LEN;
/// Longest payload of an [`AxesFrame`] (format 2: a 5-byte sequence
/// number and the CRC), bytes.
pub const AXES_FRAME_PAYLOAD_MAX: usize = 7 + 3 * AXIS_OUTPUT_LEN + FRAME_CRC_LEN;
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
    /// [`AXES_FRAME_TAG`] (or [`AXES_FRAME_TAG_V1`] as decoded from format
    /// 1): tells this frame from an [`OutputFrame`] and versions its layout.
    /// [`encode_axes`] writes [`AXES_FRAME_TAG`] whatever it holds.
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

/// Why bytes are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameError {
    /// The COBS layer or the postcard payload is malformed, or its length
    /// or tag is no frame's.
    Malformed,
    /// A format-2 frame whose CRC-32 does not match its bytes.
    BadCrc,
    /// The output buffer is too small.
    BufferTooSmall,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Malformed => "malformed frame",
            FrameError::BadCrc => "frame CRC mismatch",
            FrameError::BufferTooSmall => "buffer too small for the frame",
        })
    }
}

#[cfg(feature = "std")]
impl std::error::Error for FrameError {}

/// Serialises `value` into `raw`, appends the CRC-32 of those bytes and
/// COBS-frames the lot into `out`; returns the bytes used. Never panics:
/// postcard serialises into a plain slice (errors, no panics) and every
/// other access is checked.
fn encode_checked<T: Serialize>(value: &T, raw: &mut [u8], out: &mut [u8]) -> Result<usize, FrameError> {
    let n = postcard::to_slice(value, raw)
        .map_err(|_| FrameError::BufferTooSmall)?
        .len();
    let crc = CRC32.checksum(raw.get(..n).ok_or(FrameError::BufferTooSmall)?);
    let slot = raw
        .get_mut(n..)
        .and_then(|rest| rest.first_chunk_mut::<FRAME_CRC_LEN>())
        .ok_or(FrameError::BufferTooSmall)?;
    *slot = crc.to_le_bytes();
    let payload = raw.get(..n + FRAME_CRC_LEN).ok_or(FrameError::BufferTooSmall)?;
    cobs_encode(payload, out).ok_or(FrameError::BufferTooSmall)
}

/// The fields of a format-2 `payload` (tag first): without the CRC when it
/// matches.
fn checked_fields(payload: &[u8]) -> Result<&[u8], FrameError> {
    let (body, crc) = payload
        .split_last_chunk::<FRAME_CRC_LEN>()
        .ok_or(FrameError::Malformed)?;
    if CRC32.checksum(body) != u32::from_le_bytes(*crc) {
        return Err(FrameError::BadCrc);
    }
    Ok(body)
}

/// `bytes` as a `T`, every byte used.
fn exactly<'a, T: Deserialize<'a>>(bytes: &'a [u8]) -> Result<T, FrameError> {
    match postcard::take_from_bytes(bytes) {
        Ok((value, [])) => Ok(value),
        _ => Err(FrameError::Malformed),
    }
}

/// Decodes `bytes`' COBS layer (with or without its 0x00) in place; the payload.
fn payload(bytes: &mut [u8]) -> Result<&[u8], FrameError> {
    let len = bytes.len() - usize::from(bytes.last() == Some(&0));
    let bytes = bytes.get_mut(..len).ok_or(FrameError::Malformed)?;
    let n = cobs_decode_in_place(bytes).ok_or(FrameError::Malformed)?;
    bytes.get(..n).ok_or(FrameError::Malformed)
}

/// Encodes `frame` in format 2 (the tag, its fields, the CRC) COBS-framed,
/// 0x00-terminated, into `out`; returns the bytes used.
///
/// This runs once per gyro sample in the firmware, so it must not be able to
/// panic (checked at link time, firmware/src/bin/panic_free_check.rs):
/// postcard serialises into a plain slice (returns errors, never panics) and
/// [`crate::cobs::cobs_encode`] frames it; postcard's own COBS flavour indexes with
/// assertions the optimiser cannot remove. The bytes are the same
/// (`frames_round_trip_bit_for_bit_and_our_cobs_is_postcards`).
pub fn encode(frame: &OutputFrame, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; OUTPUT_FRAME_PAYLOAD_MAX];
    encode_checked(&(OUTPUT_FRAME_TAG, frame), &mut raw, out)
}

/// Decodes one single-axis frame of either format from its COBS bytes
/// (with or without the 0x00), in place.
pub fn decode(bytes: &mut [u8]) -> Result<OutputFrame, FrameError> {
    decode_with_format(bytes).map(|(frame, _)| frame)
}

/// [`decode`], and the format the frame came in.
pub fn decode_with_format(bytes: &mut [u8]) -> Result<(OutputFrame, FrameFormat), FrameError> {
    let payload = payload(bytes)?;
    match (payload.len(), payload.first()) {
        (OUTPUT_FRAME_PAYLOAD_MIN..=OUTPUT_FRAME_PAYLOAD_MAX, Some(&OUTPUT_FRAME_TAG)) => {
            let (_, frame): (u8, OutputFrame) = exactly(checked_fields(payload)?)?;
            Ok((frame, FrameFormat::V2))
        }
        (OUTPUT_FIELDS_MIN..=OUTPUT_FIELDS_MAX, _) => Ok((exactly(payload)?, FrameFormat::V1)),
        _ => Err(FrameError::Malformed),
    }
}

/// Encodes `frame` in format 2 (tag [`AXES_FRAME_TAG`], its fields, the
/// CRC) COBS-framed, 0x00-terminated, into `out`; returns the bytes used.
/// Never panics, as [`encode`].
pub fn encode_axes(frame: &AxesFrame, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; AXES_FRAME_PAYLOAD_MAX];
    let frame = AxesFrame {
        tag: AXES_FRAME_TAG,
        ..*frame
    };
    encode_checked(&frame, &mut raw, out)
}

/// Decodes one multi-axis frame of either format from its COBS bytes (with
/// or without the 0x00), in place; a frame without either tag is malformed.
pub fn decode_axes(bytes: &mut [u8]) -> Result<AxesFrame, FrameError> {
    decode_axes_with_format(bytes).map(|(frame, _)| frame)
}

/// [`decode_axes`], and the format the frame came in.
pub fn decode_axes_with_format(bytes: &mut [u8]) -> Result<(AxesFrame, FrameFormat), FrameError> {
    let payload = payload(bytes)?;
    if !(AXES_FRAME_PAYLOAD_MIN..=AXES_FRAME_PAYLOAD_MAX).contains(&payload.len()) {
        return Err(FrameError::Malformed);
    }
    match payload.first() {
        Some(&AXES_FRAME_TAG) => Ok((exactly(checked_fields(payload)?)?, FrameFormat::V2)),
        Some(&AXES_FRAME_TAG_V1) => Ok((exactly(payload)?, FrameFormat::V1)),
        _ => Err(FrameError::Malformed),
    }
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
    fn frames_round_trip_bit_for_bit_and_our_cobs_is_postcards() {
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
            let (back, format) = decode_with_format(&mut ours[..n]).unwrap();
            assert_eq!(format, FrameFormat::V2);
            let bits = |f: &OutputFrame| {
                (
                    f.seq,
                    [f.rate_dph, f.bias_dph, f.rate_comp_dph, f.temp_c].map(f32::to_bits),
                    f.flags,
                )
            };
            assert_eq!(bits(&back), bits(&frame));
            // The COBS layer is postcard's, byte for byte.
            let mut raw = [0u8; MAX_FRAME_LEN];
            let raw = postcard::to_slice(&frame, &mut raw).unwrap();
            let n = cobs_encode(raw, &mut ours).unwrap();
            let mut theirs = [0u8; MAX_FRAME_LEN];
            let reference = postcard::to_slice_cobs(&frame, &mut theirs).unwrap();
            assert_eq!(&ours[..n], reference, "frame {frame:?}");
        }
    }

    #[test]
    fn format_2_frames_are_tagged_and_checked_and_every_bit_flip_is_refused() {
        let frame = OutputFrame {
            seq: 1100,
            rate_dph: 10.5,
            bias_dph: 0.25,
            rate_comp_dph: 10.25,
            temp_c: 25.0,
            flags: 0,
        };
        for seq in [0u32, 1100, u32::MAX] {
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = encode(&OutputFrame { seq, ..frame }, &mut buf).unwrap();
            let mut payload = buf;
            let len = cobs_decode_in_place(&mut payload[..n - 1]).unwrap();
            assert!(
                (OUTPUT_FRAME_PAYLOAD_MIN..=OUTPUT_FRAME_PAYLOAD_MAX).contains(&len),
                "{len}"
            );
            assert_eq!(payload[0], OUTPUT_FRAME_TAG);
        }
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode(&frame, &mut buf).unwrap();
        for bit in 0..(n - 1) * 8 {
            let mut damaged = buf;
            damaged[bit / 8] ^= 1 << (bit % 8);
            if damaged[bit / 8] == 0 {
                continue; // a 0x00 ends the frame early: the receiver sees two fragments
            }
            let result = decode_with_format(&mut damaged[..n - 1]);
            assert!(
                matches!(result, Err(FrameError::BadCrc | FrameError::Malformed)),
                "bit {bit}: {result:?}"
            );
        }
        // One bit of the sequence number on the payload, CRC left as it was.
        let mut raw = [0u8; MAX_FRAME_LEN];
        let len = postcard::to_slice(&(OUTPUT_FRAME_TAG, frame), &mut raw).unwrap().len();
        let crc = CRC32.checksum(&raw[..len]).to_le_bytes();
        raw[len..len + 4].copy_from_slice(&crc);
        raw[2] ^= 0x08;
        let mut wire = [0u8; MAX_FRAME_LEN + 2];
        let n = cobs_encode(&raw[..len + 4], &mut wire).unwrap();
        assert_eq!(decode(&mut wire[..n]), Err(FrameError::BadCrc));
    }

    #[test]
    fn format_1_captures_still_decode_and_say_so() {
        let frame = OutputFrame {
            seq: 77,
            rate_dph: -3.5,
            bias_dph: 0.5,
            rate_comp_dph: -4.0,
            temp_c: 21.25,
            flags: 8,
        };
        // Format 1 was postcard's COBS of the bare fields.
        let mut old = [0u8; MAX_FRAME_LEN];
        let n = postcard::to_slice_cobs(&frame, &mut old).unwrap().len();
        assert_eq!(decode_with_format(&mut old[..n]), Ok((frame, FrameFormat::V1)));
        let axes = AxesFrame {
            tag: AXES_FRAME_TAG_V1,
            seq: 9,
            axis_mask: 0b111,
            axes: [AxisOutput {
                rate_dph: 1.0,
                bias_dph: 0.5,
                rate_comp_dph: 0.5,
                temp_c: 20.0,
                flags: 1,
            }; 3],
        };
        let mut old = [0u8; MAX_AXES_FRAME_LEN];
        let n = postcard::to_slice_cobs(&axes, &mut old).unwrap().len();
        assert_eq!(decode_axes_with_format(&mut old[..n]), Ok((axes, FrameFormat::V1)));
        // Format 1 with a trailing byte is no frame.
        let mut raw = [0u8; MAX_FRAME_LEN];
        let len = postcard::to_slice(&frame, &mut raw).unwrap().len();
        let mut wire = [0u8; MAX_FRAME_LEN + 2];
        let n = cobs_encode(&raw[..len + 1], &mut wire).unwrap();
        assert_eq!(decode(&mut wire[..n]), Err(FrameError::Malformed));
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
        // A wrong tag is refused, with a matching CRC or without one.
        let wrong = AxesFrame {
            tag: 0x01,
            seq: 1,
            axis_mask: 1,
            axes: [AxisOutput::default(); 3],
        };
        let mut raw = [0u8; AXES_FRAME_PAYLOAD_MAX];
        let len = postcard::to_slice(&wrong, &mut raw).unwrap().len();
        let mut frame_bytes = [0u8; MAX_AXES_FRAME_LEN];
        let n = cobs_encode(&raw[..len], &mut frame_bytes).unwrap();
        assert_eq!(decode_axes(&mut frame_bytes[..n]), Err(FrameError::Malformed));
        let crc = CRC32.checksum(&raw[..len]).to_le_bytes();
        raw[len..len + 4].copy_from_slice(&crc);
        let n = cobs_encode(&raw[..len + 4], &mut frame_bytes).unwrap();
        assert_eq!(decode_axes(&mut frame_bytes[..n]), Err(FrameError::Malformed));
        // encode_axes writes the current tag, and every bit flip is refused.
        let n = encode_axes(&wrong, &mut frame_bytes).unwrap();
        assert_eq!(
            decode_axes_with_format(&mut { frame_bytes }[..n]).unwrap().1,
            FrameFormat::V2
        );
        for bit in 0..(n - 1) * 8 {
            let mut damaged = frame_bytes;
            damaged[bit / 8] ^= 1 << (bit % 8);
            if damaged[bit / 8] != 0 {
                assert!(decode_axes(&mut damaged[..n - 1]).is_err(), "bit {bit}");
            }
        }
    }
}
