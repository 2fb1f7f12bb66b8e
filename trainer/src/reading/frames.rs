//! `trainer decode`: firmware output frames (postcard + COBS, each ended by
//! 0x00) from a UART capture into CSV, streaming: memory holds one frame,
//! whatever the capture's length. A single-axis firmware's frames give one
//! row per frame with [`CSV_HEADER`]; a three-axis firmware's
//! ([`frame::AxesFrame`]) one row per frame with each axis's columns.

use std::io::{BufRead, BufReader, Read, Write};

use rbf_core::axis::AxisSet;
use rbf_core::frame::{self, AxesFrame, MAX_AXES_FRAME_LEN, MAX_FRAME_LEN, OutputFrame};

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
    /// the frame its length allows; `None` when it is no output frame.
    pub fn decode(chunk: &mut [u8]) -> Option<Frame> {
        if chunk.len() <= MAX_FRAME_LEN {
            frame::decode(chunk).ok().map(Frame::Single)
        } else if chunk.len() <= MAX_AXES_FRAME_LEN {
            frame::decode_axes(chunk).ok().map(Frame::Axes)
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
}

/// The CSV header of frames of `kind`: [`CSV_HEADER`], or `seq` and each
/// axis's columns.
pub fn header(kind: Kind) -> String {
    match kind {
        Kind::Single => CSV_HEADER.to_owned(),
        Kind::Axes(axes) => std::iter::once("seq".to_owned())
            .chain(axes.iter().flat_map(|a| {
                let n = a.name();
                [
                    format!("rate_{n}_dph"),
                    format!("bias_{n}_dph"),
                    format!("rate_comp_{n}_dph"),
                    format!("temp_{n}_c"),
                    format!("flags_{n}"),
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
/// [`CSV_HEADER`], or each axis's columns for a three-axis firmware's frames). A damaged frame is skipped and counted (a capture that
/// starts mid-frame loses only that first partial frame); a capture without
/// one valid frame in its first [`MAX_FRAME_SEARCH_BYTES`] is refused as
/// not a capture, so an endless source ends quickly, and so is a capture
/// that holds damaged frames only (an empty one decodes to no rows).
pub fn decode_capture(capture: impl Read, out: &mut impl Write) -> anyhow::Result<Decoded> {
    let mut source = BufReader::with_capacity(1 << 16, capture);
    let mut decoded = Decoded::default();
    let mut chunk = Vec::with_capacity(MAX_AXES_FRAME_LEN + 1);
    let mut offset = 0u64;
    let mut kind: Option<Kind> = None;
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
        // The first valid frame says which firmware sent the capture; a
        // frame of another kind (or other axes) after it is damage.
        let frame = Frame::decode(&mut chunk).filter(|f| kind.is_none_or(|k| k == f.kind()));
        match frame {
            Some(f) => {
                if kind.is_none() {
                    kind = Some(f.kind());
                    writeln!(out, "{}", header(f.kind()))?;
                }
                write_row(out, &f)?;
                decoded.frames += 1;
            }
            None => {
                decoded.damaged += 1;
                if decoded.damaged_at.len() < DAMAGED_SHOWN {
                    decoded.damaged_at.push(start);
                }
            }
        }
    }
    if decoded.frames == 0 && decoded.damaged > 0 {
        anyhow::bail!(
            "{} damaged frame(s) and not one valid frame: not a capture of firmware output frames",
            decoded.damaged
        );
    }
    if kind.is_none() {
        writeln!(out, "{CSV_HEADER}")?;
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
    fn a_capture_of_damaged_frames_only_is_refused_an_empty_one_is_not() {
        let mut out = Vec::new();
        let err = decode_capture(&b"\x03abc\x00\x05\x00"[..], &mut out).unwrap_err();
        assert!(
            err.to_string().contains("2 damaged frame(s) and not one valid frame"),
            "{err}"
        );
        let mut out = Vec::new();
        assert_eq!(decode_capture(&b""[..], &mut out).unwrap(), Decoded::default());
        assert_eq!(String::from_utf8(out).unwrap(), format!("{CSV_HEADER}\n"));
    }

    #[test]
    fn a_three_axis_firmware_s_frames_give_each_axis_s_columns_and_other_frames_count_as_damage() {
        use rbf_core::frame::{AXES_FRAME_TAG, AxisOutput, MAX_AXES_FRAME_LEN};
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
