//! # firmware: IFOG temperature-drift compensation on the gyro's MCU
//!
//! `no_std`, no allocation. This library holds everything but the board
//! wiring, so it builds and is tested on the host; the board binaries only
//! connect peripherals to it.
//!
//! Status: skeleton. The model region is validated at boot with the same
//! `rbf-core` decoder the trainer uses; the embedded-hal compensation loop,
//! drivers and output framing arrive with the firmware issue.
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]

use rbf_core::Model;
use rbf_core::blob::{self, DecodeError};

/// Length of one model flash slot (`MODEL_A`/`MODEL_B` in memory.x), bytes.
pub const MODEL_SLOT_LEN: usize = 128 * 1024;

/// Validates the model blob at the start of a flash slot.
///
/// An erased slot (0xFF) or a corrupt blob yields the reason; the caller then
/// runs uncompensated with flag 4 on every frame rather than halting.
pub fn load_model(slot: &[u8]) -> Result<Model, DecodeError> {
    blob::decode(slot).map(|d| d.model)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erased_flash_is_refused_with_a_reason_not_a_panic() {
        let erased = [0xFFu8; 256];
        assert_eq!(load_model(&erased), Err(DecodeError::BadMagic));
    }
}
