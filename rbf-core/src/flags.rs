//! Per-sample status bits, as written in the `flags` column of compensated runs
//! and in firmware output frames.

use serde::{Deserialize, Serialize};

/// Status bits of one compensated sample. Bits combine; 0 means all is well.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Flags(pub u8);

impl Flags {
    /// No condition to report.
    pub const NONE: Flags = Flags(0);
    /// At least one model input lay outside the training range and was clamped to it.
    pub const INPUT_CLAMPED: Flags = Flags(1);
    /// The temperature sensor failed or read implausibly; the last good value is held.
    pub const TEMP_SENSOR_FAULT: Flags = Flags(2);
    /// No valid model (absent, corrupt, or no usable temperature): output is uncompensated.
    pub const NO_VALID_MODEL: Flags = Flags(4);
    /// Features are still settling after a start or a gap (ΔT filter warm-up).
    pub const WARMING_UP: Flags = Flags(8);
    /// The gyro rate sample itself was NaN or over range; passed through unchanged.
    pub const RATE_INVALID: Flags = Flags(16);
    /// Firmware only: data-ready edges passed unprocessed before this sample
    /// (its sequence number jumped by that many; a model install stalls the CPU).
    pub const SAMPLES_MISSED: Flags = Flags(32);
    /// Firmware only: output frames were dropped before this one (the UART
    /// transmit queue was full; the sequence numbers show how many).
    pub const OUTPUT_DROPPED: Flags = Flags(64);
    /// Firmware only: the first frame after a reset by the fault handler or
    /// the watchdog (the boot report frame before it gives the cause).
    pub const FAULT_RESET: Flags = Flags(128);

    /// True when every bit of `other` is set in `self`.
    pub const fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }

    /// Sets the bits of `other`.
    pub fn insert(&mut self, other: Flags) {
        self.0 |= other.0;
    }

    /// The raw bit pattern.
    pub const fn bits(self) -> u8 {
        self.0
    }
}

impl core::ops::BitOr for Flags {
    type Output = Flags;
    fn bitor(self, rhs: Flags) -> Flags {
        Flags(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for Flags {
    fn bitor_assign(&mut self, rhs: Flags) {
        self.0 |= rhs.0;
    }
}
