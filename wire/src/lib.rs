//! # gyro-wire: what a compensated IFOG and its host say over the UART
//!
//! `no_std`, no allocation, no panics on any input: the firmware encodes
//! with these functions on the Cortex-M4F, and the host (`trainer device`,
//! the test harnesses, a C firmware through its library) decodes with the
//! same ones, so both ends read every byte the same way. What the board
//! keeps and collects to fill a message (flash slots, counters, the fault
//! record) stays in the firmware.
//!
//! Every message, in both directions, is `COBS(payload) 0x00` ([`cobs`]).
//! From the unit the messages share one line and are told apart by payload
//! length and first byte (docs/firmware.md, "Output and commands on USART1"):
//!
//! | payload bytes | first byte | message |
//! |---|---|---|
//! | [`REPLY_LEN`] (2) | the command | reply to a command ([`command`]) |
//! | [`BOOT_REPORT_LEN`] (11) | 0xFB | boot report after a fault or watchdog reset ([`boot`]) |
//! | [`BENCH_REPORT_LEN`] (17) | 0x02 | bench report ([`mod@bench`]) |
//! | 18 … 22 (format 1), 23 … 27 (format 2) | 0xB2 (format 2) | single-axis output frame ([`frame`]) |
//! | 54 … 62 | 0xA3, 0xA4 | three-axis output frame ([`frame`]) |
//! | [`HEALTH_REPORT_LEN`] (116) | 0xFC | health report ([`health`]) |
//!
//! To the unit: a command ([`command`]), at most [`MAX_COMMAND_FRAME_LEN`]
//! bytes on the wire.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]

/// A message byte's meanings: a `#[repr(u8)]` enum whose variants are the
/// byte's values, and its decoder `from_u8` (`None` for a byte no variant
/// has, e.g. a newer unit's), written once for every such byte.
macro_rules! byte_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident {
            $($(#[$variant_meta:meta])* $variant:ident = $value:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[repr(u8)]
        pub enum $name {
            $($(#[$variant_meta])* $variant = $value,)+
        }

        impl $name {
            /// The value with wire byte `value`; `None` for any other byte.
            pub const fn from_u8(value: u8) -> Option<$name> {
                match value {
                    $($value => Some($name::$variant),)+
                    _ => None,
                }
            }
        }
    };
}

pub mod bench;
pub mod boot;
pub mod cobs;
pub mod command;
pub mod frame;
pub mod health;

pub use bench::BENCH_REPORT_LEN;
pub use boot::BOOT_REPORT_LEN;
pub use command::{MAX_COMMAND_FRAME_LEN, REPLY_LEN};
pub use health::HEALTH_REPORT_LEN;

#[cfg(test)]
mod tests {
    use super::*;

    /// The table in the crate docs: no two messages from the unit share a
    /// payload length, so a receiver tells them apart by length first.
    #[test]
    fn every_message_from_the_unit_has_a_length_of_its_own() {
        let single = frame::OUTPUT_FRAME_PAYLOAD_MIN - 5..=frame::OUTPUT_FRAME_PAYLOAD_MAX;
        let axes = frame::AXES_FRAME_PAYLOAD_MIN..=frame::AXES_FRAME_PAYLOAD_MAX;
        assert_eq!((single.start(), single.end()), (&18, &27));
        assert_eq!((axes.start(), axes.end()), (&54, &62));
        for fixed in [REPLY_LEN, BOOT_REPORT_LEN, BENCH_REPORT_LEN, HEALTH_REPORT_LEN] {
            assert!(!single.contains(&fixed) && !axes.contains(&fixed), "{fixed}");
        }
        assert_eq!(
            [REPLY_LEN, BOOT_REPORT_LEN, BENCH_REPORT_LEN, HEALTH_REPORT_LEN],
            [2, 11, 17, 116]
        );
    }
}
