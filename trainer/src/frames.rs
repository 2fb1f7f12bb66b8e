//! `trainer decode`: firmware output frames (postcard + COBS, each ended by
//! 0x00) from a UART capture into CSV, streaming: memory holds one frame,
//! whatever the capture's length.

use std::io::{BufRead, BufReader, Read, Write};

use rbf_core::frame::{self, MAX_FRAME_LEN};

use crate::limits::{MAX_FRAME_SEARCH_BYTES, bytes};

/// The CSV header `decode` writes.
pub const CSV_HEADER: &str = "seq,rate_dph,bias_dph,rate_comp_dph,temp_c,flags";

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
/// [`CSV_HEADER`]). A damaged frame is skipped and counted (a capture that
/// starts mid-frame loses only that first partial frame); a capture without
/// one valid frame in its first [`MAX_FRAME_SEARCH_BYTES`] is refused as
/// not a capture, so an endless source ends quickly, and so is a capture
/// that holds damaged frames only (an empty one decodes to no rows).
pub fn decode_capture(capture: impl Read, out: &mut impl Write) -> anyhow::Result<Decoded> {
    let mut source = BufReader::with_capacity(1 << 16, capture);
    let mut decoded = Decoded::default();
    let mut chunk = Vec::with_capacity(MAX_FRAME_LEN + 1);
    let mut offset = 0u64;
    writeln!(out, "{CSV_HEADER}")?;
    loop {
        if decoded.frames == 0 && offset > MAX_FRAME_SEARCH_BYTES {
            anyhow::bail!(
                "no valid frame in its first {}: not a capture of firmware output frames",
                bytes(MAX_FRAME_SEARCH_BYTES)
            );
        }
        chunk.clear();
        let read = (&mut source).take(MAX_FRAME_LEN as u64 + 1).read_until(0, &mut chunk)?;
        if read == 0 {
            break;
        }
        let start = offset;
        offset += read as u64;
        let ended = chunk.last() == Some(&0);
        if ended {
            chunk.pop();
        } else if chunk.len() > MAX_FRAME_LEN {
            // Longer than any frame: skip to the next delimiter.
            offset += skip_to_delimiter(&mut source)?;
        }
        if chunk.is_empty() {
            continue;
        }
        let frame = (chunk.len() <= MAX_FRAME_LEN)
            .then(|| frame::decode(&mut chunk).ok())
            .flatten();
        match frame {
            Some(f) => {
                writeln!(
                    out,
                    "{},{},{},{},{},{}",
                    f.seq, f.rate_dph, f.bias_dph, f.rate_comp_dph, f.temp_c, f.flags
                )?;
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
    fn endless_zeros_or_noise_are_refused_after_the_search_limit() {
        for byte in [0u8, 0x55] {
            let endless = std::io::repeat(byte);
            let mut out = Vec::new();
            let err = decode_capture(endless, &mut out).unwrap_err().to_string();
            assert!(err.contains("no valid frame in its first 1 MiB"), "{err}");
        }
    }
}
