//! # firmware: IFOG temperature-drift compensation on the gyro's MCU
//!
//! `no_std`, no allocation. Everything but the board wiring lives here, so it
//! builds and is tested on the host:
//! - [`tmp117`]: loop-thermometer driver (I2C); [`frontend`]: rate front end (SPI, docs/frontend.md);
//! - [`sensors`]: the traits the loop needs from them, per axis;
//! - [`compensation`]: the per-sample loop for any number of axes (rbf-core compensation, one
//!   output frame per sample: a single gyro's frame, or one frame with every axis of an IMU);
//! - [`uart`]: the transmit queue an interrupt drains (frames whole or dropped and counted);
//!   [`interrupts`]: what the board's UART and data-ready interrupt handlers do;
//! - [`model_store`]: two flash slots with power-safe model updates; [`update`]: the UART command that delivers one;
//!   [`commands`]: the loop's command path (installs, replies, the board's reports);
//! - [`fault`]: the fault record kept across a reset and the boot report frame; [`health`]: the health report's
//!   reset cause and board flags;
//! - the board's peripherals, bounded and host-tested (`cargo xtask board-faults`): [`clock`] (deadlines),
//!   [`i2c_master`] (I2C with timeouts and bus recovery), [`flash_ctl`] (the flash controller),
//!   [`watchdog`] (IWDG periods), [`pacing`] (data-ready stamps to sample steps);
//! - the board loop's pass as host code: [`samples`] (a paced, timed step) and [`commands`],
//!   which the board's run loop ([`board::run_loop`]) runs;
//! - [`bench`](mod@bench): the board's `bench` command (DWT cycle counts of its sample steps);
//! - [`load_model`]: boot-time validation of the model flash slot.
//!
//! - [`board`]: the board's timer arithmetic and run loop ([`board::run_loop`], host-tested
//!   and run by the fault campaign) and, on the MCU, its setup, handlers and register glue;
//!   one small binary per board image in `src/bin/` wires its sensors to it.
//!
//! What goes on the wire (output frames, COBS, commands and replies, the boot, bench and
//! health reports) is the crate `gyro-wire`'s, which the host decodes with.
//!
//! The test harnesses (emulated devices and flash, the recorded-run replayer, fault
//! injection, semihosting files) and the QEMU images built on them are the crate
//! `firmware-harness` (`firmware-harness/`), so that neither the board image nor an
//! application of this library ever sees them.
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]

pub mod bench;
pub mod clock;
pub mod commands;
pub mod compensation;
pub mod fault;
pub mod flash_ctl;
pub mod frontend;
pub mod health;
pub mod i2c_master;
pub mod interrupts;
pub mod model_store;
pub mod pacing;
pub mod samples;
pub mod sensors;
pub mod tmp117;
pub mod uart;
pub mod update;
pub mod watchdog;

pub mod board;

use rbf_core::Model;
use rbf_core::blob::{self, DecodeError};

/// Centres each axis's model may have on the three-axis board (the
/// image `stm32f405-axes`): the capacity `K` of its
/// [`rbf_core::blob::axes::AxisModels`], chosen so that three models, the
/// update buffer and the stack stay within the board's 16 KiB of RAM
/// (docs/firmware.md, "Three axes"). A blob with a larger axis is refused
/// with [`DecodeError::ShapeOverCapacity`] (an update: reply status
/// `Refused`, the running models stay; at boot: uncompensated, flag 4).
pub const AXIS_CENTERS: usize = rbf_core::MAX_AXIS_CENTERS;

/// Centres the shared basis may have on the shared-basis three-axis board
/// (image `stm32f405-axes-shared`): the capacity `K` of its
/// [`rbf_core::shared_basis::SharedAxisModels`]. One basis with a weight per
/// axis takes about a third of three models' RAM, so this image holds
/// twice the per-axis board's centres within the same 16 KiB
/// (docs/firmware.md, "Three axes"). A blob with a larger basis is refused
/// with [`DecodeError::ShapeOverCapacity`], as on the per-axis board.
pub const SHARED_AXIS_CENTERS: usize = rbf_core::MAX_SHARED_AXIS_CENTERS;

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
