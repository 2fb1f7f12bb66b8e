//! `trainer decode`: firmware output frames (postcard + COBS, each ended by
//! 0x00) from a UART capture into CSV, streaming: memory holds one frame,
//! whatever the capture's length. A single-axis firmware's frames give one
//! row per frame with [`CSV_HEADER`]; a three-axis firmware's
//! ([`frame::AxesFrame`]) one row per frame with each axis's columns.

use std::io::{BufRead, BufReader, Read, Write};

use gyro_wire::frame::{self, AxesFrame, FrameFormat, MAX_AXES_FRAME_LEN, MAX_FRAME_LEN, OutputFrame};
use rbf_core::axis::AxisSet;

use crate::reading::limits::{MAX_FRAME_SEARCH_BYTES, bytes};

/// The CSV header `decode` writes.
pub const CSV_HEADER: &str = "seq,rate_dph,bias_dph,rate_comp_dph,temp_c,flags";

/// Which firmware's frames a capture holds (set by its first valid frame).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// [`OutputFrame`]s.
    Single,
    /// [`AxesFrame`]s with these axes.
    Axes(AxisSet),
}

/// One decoded output frame of either kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Frame {
    /// A single-axis firmware's frame.
    Single(OutputFrame),
    /// A three-axis firmware's frame.
    Axes(AxesFrame),
}

impl Frame {
    /// Decodes `chunk` (COBS bytes without the 0x00, decoded in place) as
    /// the frame its length allows, of either format; `None` when it is no
    /// output frame (a format-2 frame whose CRC does not match included).
    pub fn decode(chunk: &mut [u8]) -> Option<(Frame, FrameFormat)> {
        if chunk.len() <= MAX_FRAME_LEN {
            frame::decode_with_format(chunk)
                .ok()
                .map(|(f, format)| (Frame::Single(f), format))
        } else if chunk.len() <= MAX_AXES_FRAME_LEN {
            frame::decode_axes_with_format(chunk)
                .ok()
                .map(|(f, format)| (Frame::Axes(f), format))
        } else {
            None
        }
    }

    /// Which firmware sends frames like this one.
    pub fn kind(&self) -> Kind {
        match self {
            Frame::Single(_) => Kind::Single,
            Frame::Axes(f) => Kind::Axes(f.axes_present()),
        }
    }

    /// The frame's sequence number.
    pub fn seq(&self) -> u32 {
        match self {
            Frame::Single(f) => f.seq,
            Frame::Axes(f) => f.seq,
        }
    }
}

/// Most a format-1 frame's sequence number may lie past the one before it
/// for the two to confirm each other ([`FrameSync`]).
const CONFIRM_WITHIN: u32 = 16;

/// Which frames of a stream are the unit's. The stream's kind and format
/// are those of its first CRC-checked frame (format 2), or of a format-1
/// frame that the next frame confirms (same kind and format, its sequence
/// number 1 … 16 on): format 1 carries no check, so the
/// tail of a cut frame, or a damaged format-2 frame, can pass for one.
/// After that a frame of another kind or format is refused.
#[derive(Debug, Default)]
pub struct FrameSync {
    locked: Option<(Kind, FrameFormat)>,
    candidate: Option<Frame>,
}

/// What [`FrameSync::push`] made of a frame.
#[derive(Debug, Default)]
pub struct Synced {
    /// The stream's frames to take, in order (a confirmed candidate first).
    pub frames: Vec<Frame>,
    /// Frames refused: of another kind or format than the stream's, or a
    /// candidate the next frame did not confirm.
    pub refused: u64,
}

impl FrameSync {
    /// The stream's kind, once known.
    pub fn kind(&self) -> Option<Kind> {
        self.locked.map(|(k, _)| k)
    }

    /// The stream's format, once known.
    pub fn format(&self) -> Option<FrameFormat> {
        self.locked.map(|(_, f)| f)
    }

    /// Takes the next decoded frame of the stream.
    pub fn push(&mut self, frame: Frame, format: FrameFormat) -> Synced {
        let mut synced = Synced::default();
        match self.locked {
            Some(stream) if stream == (frame.kind(), format) => synced.frames.push(frame),
            Some(_) => synced.refused += 1,
            None if format.is_checked() => {
                synced.refused += u64::from(self.candidate.take().is_some());
                self.locked = Some((frame.kind(), format));
                synced.frames.push(frame);
            }
            None => match self.candidate.replace(frame) {
                Some(c)
                    if c.kind() == frame.kind()
                        && (1..=CONFIRM_WITHIN).contains(&frame.seq().wrapping_sub(c.seq())) =>
                {
                    self.candidate = None;
                    self.locked = Some((frame.kind(), format));
                    synced.frames.extend([c, frame]);
                }
                Some(_) => synced.refused += 1,
                None => {}
            },
        }
        synced
    }

    /// At the stream's end: a candidate never confirmed (refused).
    pub fn finish(&mut self) -> u64 {
        u64::from(self.candidate.take().is_some())
    }
}

/// The CSV header of frames of `kind`: [`CSV_HEADER`], or `seq` and each
/// axis's columns.
pub fn header(kind: Kind) -> String {
    header_with(kind, "")
}

/// The columns of frames of `kind` in a recorded run (`trainer device
/// record`): [`header`]'s, with the unit's bias, compensated rate and flags
/// named `unit_bias_dph`, `unit_rate_comp_dph`, `unit_flags` (per axis
/// `unit_bias_x_dph` …), so that `trainer compensate` adds its own beside them.
pub fn recording_header(kind: Kind) -> String {
    header_with(kind, "unit_")
}

/// The header with `unit` before the names of the unit's outputs.
fn header_with(kind: Kind, unit: &str) -> String {
    match kind {
        Kind::Single => format!("seq,rate_dph,{unit}bias_dph,{unit}rate_comp_dph,temp_c,{unit}flags"),
        Kind::Axes(axes) => std::iter::once("seq".to_owned())
            .chain(axes.iter().flat_map(|a| {
                let n = a.name();
                [
                    format!("rate_{n}_dph"),
                    format!("{unit}bias_{n}_dph"),
                    format!("{unit}rate_comp_{n}_dph"),
                    format!("temp_{n}_c"),
                    format!("{unit}flags_{n}"),
                ]
            }))
            .collect::<Vec<_>>()
            .join(","),
    }
}

/// Writes `frame` as a CSV row of [`header`]'s columns.
pub fn write_row(out: &mut impl Write, frame: &Frame) -> std::io::Result<()> {
    match frame {
        Frame::Single(f) => writeln!(
            out,
            "{},{},{},{},{},{}",
            f.seq, f.rate_dph, f.bias_dph, f.rate_comp_dph, f.temp_c, f.flags
        ),
        Frame::Axes(f) => {
            write!(out, "{}", f.seq)?;
            for a in f.axes_present().iter() {
                let o = &f.axes[a.index()];
                write!(
                    out,
                    ",{},{},{},{},{}",
                    o.rate_dph, o.bias_dph, o.rate_comp_dph, o.temp_c, o.flags
                )?;
            }
            writeln!(out)
        }
    }
}

/// Byte offsets of damaged frames kept for the report.
const DAMAGED_SHOWN: usize = 10;

/// What a capture held.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Decoded {
    /// Frames decoded and written.
    pub frames: usize,
    /// Damaged frames skipped.
    pub damaged: usize,
    /// Byte offsets of the first damaged frames.
    pub damaged_at: Vec<u64>,
}

/// Decodes the frames of `capture` into CSV rows on `out` (header
/// [`CSV_HEADER`], or each axis's columns for a three-axis firmware's
/// frames). A damaged frame (a format-2 frame whose CRC does not match, a
/// frame of another kind or format than the capture's, see [`FrameSync`])
/// is skipped and counted (a capture that starts mid-frame loses only that
/// first partial frame). A capture without one valid frame is refused: an
/// empty one (no kind to name the columns by), one of damaged frames only,
/// or one without a valid frame in its first [`MAX_FRAME_SEARCH_BYTES`], so
/// an endless source ends quickly.
pub fn decode_capture(capture: impl Read, out: &mut impl Write) -> anyhow::Result<Decoded> {
    let mut source = BufReader::with_capacity(1 << 16, capture);
    let mut decoded = Decoded::default();
    let mut chunk = Vec::with_capacity(MAX_AXES_FRAME_LEN + 1);
    let mut offset = 0u64;
    let mut sync = FrameSync::default();
    let damaged = |decoded: &mut Decoded, at: u64, n: u64| {
        for _ in 0..n {
            decoded.damaged += 1;
            if decoded.damaged_at.len() < DAMAGED_SHOWN {
                decoded.damaged_at.push(at);
            }
        }
    };
    loop {
        if decoded.frames == 0 && offset > MAX_FRAME_SEARCH_BYTES {
            anyhow::bail!(
                "no valid frame in its first {}: not a capture of firmware output frames",
                bytes(MAX_FRAME_SEARCH_BYTES)
            );
        }
        chunk.clear();
        let read = (&mut source)
            .take(MAX_AXES_FRAME_LEN as u64 + 1)
            .read_until(0, &mut chunk)?;
        if read == 0 {
            break;
        }
        let start = offset;
        offset += read as u64;
        let ended = chunk.last() == Some(&0);
        if ended {
            chunk.pop();
        } else if chunk.len() > MAX_AXES_FRAME_LEN {
            // Longer than any frame: skip to the next delimiter.
            offset += skip_to_delimiter(&mut source)?;
        }
        if chunk.is_empty() {
            continue;
        }
        let Some((frame, format)) = Frame::decode(&mut chunk) else {
            damaged(&mut decoded, start, 1);
            continue;
        };
        let synced = sync.push(frame, format);
        damaged(&mut decoded, start, synced.refused);
        for f in &synced.frames {
            if decoded.frames == 0 {
                writeln!(out, "{}", header(f.kind()))?;
            }
            write_row(out, f)?;
            decoded.frames += 1;
        }
    }
    let unconfirmed = sync.finish();
    damaged(&mut decoded, offset, unconfirmed);
    if decoded.frames == 0 {
        anyhow::ensure!(
            decoded.damaged > 0,
            "empty: not one byte of a frame, so no output (was the capture taken from the unit's port, at its baud rate?)"
        );
        anyhow::bail!(
            "{} damaged frame(s) and not one valid frame: not a capture of firmware output frames",
            decoded.damaged
        );
    }
    Ok(decoded)
}

/// Reads up to and including the next 0x00 without keeping the bytes, at
/// most [`MAX_FRAME_SEARCH_BYTES`] at a time; returns how many.
fn skip_to_delimiter(source: &mut impl BufRead) -> std::io::Result<u64> {
    let mut skipped = 0u64;
    while skipped <= MAX_FRAME_SEARCH_BYTES {
        let buf = source.fill_buf()?;
        if buf.is_empty() {
            return Ok(skipped);
        }
        match memchr::memchr(0, buf) {
            Some(i) => {
                source.consume(i + 1);
                return Ok(skipped + i as u64 + 1);
            }
            None => {
                let n = buf.len();
                source.consume(n);
                skipped += n as u64;
            }
        }
    }
    Ok(skipped)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_capture_of_damaged_frames_only_is_refused_and_so_is_an_empty_one() {
        let mut out = Vec::new();
        let err = decode_capture(&b"\x03abc\x00\x05\x00"[..], &mut out).unwrap_err();
        assert!(
            err.to_string().contains("2 damaged frame(s) and not one valid frame"),
            "{err}"
        );
        for empty in [&b""[..], b"\0\0\0"] {
            let mut out = Vec::new();
            let err = decode_capture(empty, &mut out).unwrap_err().to_string();
            assert!(err.starts_with("empty: not one byte of a frame"), "{err}");
            assert!(out.is_empty(), "no header without a frame to name its columns");
        }
    }

    #[test]
    fn a_three_axis_firmware_s_frames_give_each_axis_s_columns_and_other_frames_count_as_damage() {
        use gyro_wire::frame::{AXES_FRAME_TAG, AxisOutput, MAX_AXES_FRAME_LEN};
        let axis = |v: f32, flags: u8| AxisOutput {
            rate_dph: v,
            bias_dph: v / 2.0,
            rate_comp_dph: v / 2.0,
            temp_c: 25.5,
            flags,
        };
        let mut capture = Vec::new();
        let mut buf = [0u8; MAX_AXES_FRAME_LEN];
        for seq in [7u32, 8] {
            let f = AxesFrame {
                tag: AXES_FRAME_TAG,
                seq,
                axis_mask: 0b101,
                axes: [axis(1.0, 0), AxisOutput::default(), axis(3.0, 2)],
            };
            let n = frame::encode_axes(&f, &mut buf).unwrap();
            capture.extend_from_slice(&buf[..n]);
            if seq == 7 {
                // A single-axis frame in a three-axis capture is not its frame.
                let single = OutputFrame {
                    seq: 1,
                    rate_dph: 1.0,
                    bias_dph: 0.0,
                    rate_comp_dph: 1.0,
                    temp_c: 20.0,
                    flags: 0,
                };
                let n = frame::encode(&single, &mut buf).unwrap();
                capture.extend_from_slice(&buf[..n]);
            }
        }
        let mut out = Vec::new();
        let decoded = decode_capture(&capture[..], &mut out).unwrap();
        assert_eq!((decoded.frames, decoded.damaged), (2, 1));
        assert_eq!(
            String::from_utf8(out).unwrap(),
            "seq,rate_x_dph,bias_x_dph,rate_comp_x_dph,temp_x_c,flags_x,rate_z_dph,bias_z_dph,rate_comp_z_dph,temp_z_c,flags_z\n\
             7,1,0.5,0.5,25.5,0,3,1.5,1.5,25.5,2\n\
             8,1,0.5,0.5,25.5,0,3,1.5,1.5,25.5,2\n"
        );
    }

    #[test]
    fn endless_zeros_or_noise_are_refused_after_the_search_limit() {
        for byte in [0u8, 0x55] {
            let endless = std::io::repeat(byte);
            let mut out = Vec::new();
            let err = decode_capture(endless, &mut out).unwrap_err().to_string();
            assert!(err.contains("no valid frame in its first 1 MiB"), "{err}");
        }
    }
}
