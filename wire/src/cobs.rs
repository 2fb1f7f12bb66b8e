//! COBS (consistent overhead byte stuffing), the framing of every message
//! in both directions: the payload without a 0x00, then one 0x00 that ends
//! it, so a receiver resynchronises at the next zero after any byte loss.
//! A payload of `n` bytes takes at most `n + n / 254 + 2` bytes on the wire
//! ([`max_encoded_len`]).
//!
//! Why not the `cobs` crate (0.3, the one postcard's COBS flavour uses): its
//! frames are ours byte for byte, but `try_encode` reports a length past the
//! end of a buffer one byte too small (it skips the last code byte it has
//! no room for and still counts it) and encodes an empty source as nothing,
//! and its decoder takes the bytes before a 0x00 inside a frame as the
//! frame (`cobs_crate_frames_are_ours_but_its_edges_are_not`). Here a
//! short buffer is `None` and a damaged frame is refused, and neither
//! function can panic, so both link in the panic-free firmware image.

/// Bytes a COBS frame of a `payload_len`-byte payload takes at most,
/// its 0x00 delimiter included.
pub const fn max_encoded_len(payload_len: usize) -> usize {
    payload_len + payload_len / 254 + 2
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

/// Decodes a COBS frame (without its 0x00 delimiter) in place; returns the
/// decoded length, or `None` if the frame is malformed (a zero inside, a
/// block running past the end). Never panics: every access is checked (the
/// `cobs` crate's decoder indexes its buffer), so it links in the
/// panic-free firmware image. The decoded bytes never overtake the encoded
/// ones: writing in place is safe.
pub fn cobs_decode_in_place(frame: &mut [u8]) -> Option<usize> {
    let (mut read, mut write) = (0usize, 0usize);
    let end = frame.len();
    while let Some(&code) = frame.get(read) {
        if code == 0 {
            return None;
        }
        read += 1;
        for _ in 1..code {
            let byte = *frame.get(read)?;
            if byte == 0 {
                return None;
            }
            *frame.get_mut(write)? = byte;
            read += 1;
            write += 1;
        }
        if code != 0xFF && read < end {
            *frame.get_mut(write)? = 0;
            write += 1;
        }
    }
    Some(write)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Why this crate keeps its own COBS (module docs): the crate's bytes
    /// are ours, its edges are not what a panic-free receiver needs.
    #[test]
    fn cobs_crate_frames_are_ours_but_its_edges_are_not() {
        for src in [&[0x11, 0, 0x22, 0x33][..], &[0u8; 3], &[7u8; 300], &[0, 1, 2, 0]] {
            let mut ours = [0u8; 400];
            let n = cobs_encode(src, &mut ours).unwrap();
            let mut theirs = [0u8; 400];
            let m = cobs::try_encode(src, &mut theirs).unwrap();
            assert_eq!(ours[..n - 1], theirs[..m], "the same frame, ours with its 0x00");
        }
        // A buffer one byte short: the crate says it wrote 2 bytes into 1.
        assert_eq!(cobs::try_encode(&[0], &mut [0u8; 1]).ok(), Some(2));
        assert_eq!(cobs_encode(&[0], &mut [0u8; 2]), None);
        // An empty source: nothing from the crate, a frame from ours.
        assert_eq!(cobs::try_encode(&[], &mut [0u8; 4]).ok(), Some(0));
        assert_eq!(cobs_encode(&[], &mut [0u8; 4]), Some(2));
        // A 0x00 inside a frame: the crate decodes what lies before it.
        assert_eq!(cobs::decode_in_place(&mut [2, 7, 0, 9, 9]).ok(), Some(1));
        assert_eq!(cobs_decode_in_place(&mut [2, 7, 0, 9, 9]), None);
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

    #[test]
    fn cobs_decoding_inverts_the_encoder_within_its_bound_and_refuses_what_is_not_cobs() {
        // Payloads with zeros in every position and runs past 254 bytes.
        let mut state = 0x1234_5678u32;
        for len in (0..600).step_by(7) {
            let payload: std::vec::Vec<u8> = (0..len)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    if state.is_multiple_of(5) { 0 } else { state as u8 }
                })
                .collect();
            let mut out = std::vec![0u8; max_encoded_len(len)];
            let n = cobs_encode(&payload, &mut out).unwrap();
            let frame = &mut out[..n - 1];
            let decoded = cobs_decode_in_place(frame).unwrap();
            assert_eq!(&frame[..decoded], &payload[..], "length {len}");
        }
        // The bound is reached: 254 non-zero bytes need a second code byte.
        assert_eq!(cobs_encode(&[7u8; 254], &mut [0u8; 300]), Some(max_encoded_len(254)));
        assert_eq!(cobs_decode_in_place(&mut [3, 1, 0, 2]), None, "a zero inside");
        assert_eq!(cobs_decode_in_place(&mut [5, 1, 2]), None, "a block past the end");
        assert_eq!(cobs_decode_in_place(&mut []), Some(0));
    }
}
