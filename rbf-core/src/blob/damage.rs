//! Test support: damaging a good blob the ways storage and radio links do,
//! shared by the tests of every blob layout (single model, per-axis models,
//! shared basis) so each checks the same defects the same way.

use super::{CRC_LEN, CRC32};

/// Rewrites the trailing CRC-32 over the damaged bytes, so a defect reaches
/// the decoder's structural checks instead of failing the checksum.
pub(crate) fn reseal(blob: &mut [u8]) {
    let n = blob.len() - CRC_LEN;
    let crc = CRC32.checksum(&blob[..n]);
    blob[n..].copy_from_slice(&crc.to_le_bytes());
}

/// Asserts that `decode` refuses every single-bit flip of `good` (the CRC
/// alone guarantees it; this checks the CRC is really consulted).
pub(crate) fn assert_every_bit_flip_refused<T, E>(good: &[u8], mut decode: impl FnMut(&[u8]) -> Result<T, E>) {
    for byte in 0..good.len() {
        for bit in 0..8 {
            let mut v = good.to_vec();
            v[byte] ^= 1 << bit;
            assert!(decode(&v).is_err(), "flip of bit {bit} in byte {byte} accepted");
        }
    }
}

/// Feeds `decode` `rounds` copies of `good` with `edits` random bytes
/// overwritten and the CRC resealed, whole and cut at a random length: each
/// may be refused or decoded, none may panic. A cheap deterministic sweep
/// (xorshift32 from `seed`); the fuzz targets cover this properly.
pub(crate) fn garbage_never_panics<T, E>(
    good: &[u8],
    seed: u32,
    rounds: usize,
    edits: usize,
    mut decode: impl FnMut(&[u8]) -> Result<T, E>,
) {
    let mut state = seed;
    for _ in 0..rounds {
        let mut v = good.to_vec();
        for _ in 0..edits {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            let i = state as usize % v.len();
            v[i] = (state >> 24) as u8;
        }
        reseal(&mut v);
        let _ = decode(&v);
        let _ = decode(&v[..state as usize % v.len()]);
    }
}
