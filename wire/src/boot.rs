//! Unit → host: the boot report, sent after a fault or watchdog reset before
//! the first output frame.
//!
//! `COBS([BOOT_REPORT_TAG, reason, pc u32, lr u32, reset flags]) 0x00`,
//! [`BOOT_REPORT_LEN`] payload bytes, little-endian: told from an output
//! frame (at least 18) and a reply (2) by its length. What the board keeps
//! across the reset to fill it is the firmware's (`firmware::fault`).

use crate::cobs::cobs_encode;

/// First payload byte of a boot report frame.
pub const BOOT_REPORT_TAG: u8 = 0xFB;
/// Payload bytes of a boot report frame.
pub const BOOT_REPORT_LEN: usize = 11;

byte_enum! {
    /// Why the firmware stopped (the boot report's second byte).
    pub enum FaultReason {
        /// No fault recorded (a power-on or a reset by the debugger).
        None = 0,
        /// A Rust panic (a bug: the panic-free check says none is reachable after init).
        Panic = 1,
        /// A HardFault (bus, memory or usage fault escalated): PC and LR of the faulting code.
        HardFault = 2,
        /// No record, but the independent watchdog reset the chip (a hang, or a
        /// lockup such as a stack overflow fault with no stack left to report it).
        Watchdog = 3,
    }
}

/// What the boot report carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootReport {
    /// Why the firmware stopped.
    pub reason: FaultReason,
    /// Program counter of the fault (0 when unknown).
    pub pc: u32,
    /// Link register at the fault (the faulting SP after a stack overflow).
    pub lr: u32,
    /// The raw reset flags (RCC_CSR bits 24–31 on the STM32F4).
    pub reset_flags: u8,
}

impl BootReport {
    /// The payload bytes (module docs).
    pub fn to_bytes(&self) -> [u8; BOOT_REPORT_LEN] {
        let [p0, p1, p2, p3] = self.pc.to_le_bytes();
        let [l0, l1, l2, l3] = self.lr.to_le_bytes();
        [
            BOOT_REPORT_TAG,
            self.reason as u8,
            p0,
            p1,
            p2,
            p3,
            l0,
            l1,
            l2,
            l3,
            self.reset_flags,
        ]
    }

    /// The report in a decoded `payload`; `None` for anything else.
    pub fn from_bytes(payload: &[u8]) -> Option<BootReport> {
        let [tag, reason, p0, p1, p2, p3, l0, l1, l2, l3, reset_flags] =
            *<&[u8; BOOT_REPORT_LEN]>::try_from(payload).ok()?;
        if tag != BOOT_REPORT_TAG {
            return None;
        }
        Some(BootReport {
            reason: FaultReason::from_u8(reason)?,
            pc: u32::from_le_bytes([p0, p1, p2, p3]),
            lr: u32::from_le_bytes([l0, l1, l2, l3]),
            reset_flags,
        })
    }

    /// The COBS-framed report into `out`; the bytes used.
    pub fn encode(&self, out: &mut [u8]) -> Option<usize> {
        cobs_encode(&self.to_bytes(), out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cobs::cobs_decode_in_place;

    #[test]
    fn the_boot_report_is_tagged_little_endian_and_eleven_bytes() {
        let report = BootReport {
            reason: FaultReason::Panic,
            pc: 0x0800_4321,
            lr: 0x0800_1111,
            reset_flags: 0x24,
        };
        let mut out = [0u8; 16];
        let n = report.encode(&mut out).unwrap();
        let len = cobs_decode_in_place(&mut out[..n - 1]).unwrap();
        assert_eq!(len, BOOT_REPORT_LEN);
        assert_eq!(&out[..len], &[0xFB, 1, 0x21, 0x43, 0, 8, 0x11, 0x11, 0, 8, 0x24]);
        assert_eq!(BootReport::from_bytes(&out[..len]), Some(report));
        assert_eq!(BootReport::from_bytes(&out[..len - 1]), None, "one byte short");
        let mut unknown = report.to_bytes();
        unknown[1] = 4;
        assert_eq!(BootReport::from_bytes(&unknown), None, "a reason no firmware sends");
    }
}
