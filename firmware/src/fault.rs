//! What the board remembers across a reset: the cause of the last fault, and
//! the boot report frame that tells the host about it.
//!
//! The fault handlers (panic, HardFault; `firmware::board` and the board
//! binary) write a [`FaultRecord`] into four words of RAM that the runtime
//! never initialises (`.uninit`), then reset. At boot the record is read
//! and cleared; a valid one (magic and check word) or a watchdog reset flag
//! makes the board send a boot report frame before its first output frame,
//! and flag that frame ([`rbf_core::Flags::FAULT_RESET`]).
//!
//! The boot report's layout on the wire is [`gyro_wire::boot`]'s.

use gyro_wire::boot::BootReport;
/// Why the firmware stopped: the record's reason, the boot report's second byte.
pub use gyro_wire::boot::FaultReason;

/// Words the record occupies in RAM.
pub const RECORD_WORDS: usize = 4;
/// Marks a written record (a cold start leaves random RAM, which the check word rejects).
const MAGIC: u32 = 0xFA17_5AFE;

/// A fault as the handler recorded it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FaultRecord {
    /// What happened.
    pub reason: FaultReason,
    /// Program counter of the faulting instruction (HardFault) or the
    /// panic handler's return address (panic).
    pub pc: u32,
    /// Link register at the fault.
    pub lr: u32,
}

impl FaultRecord {
    /// The words the handler stores: magic, reason, PC, LR xor-folded into a check word.
    pub fn to_words(self) -> [u32; RECORD_WORDS] {
        let reason = self.reason as u32;
        [MAGIC ^ reason, self.pc, self.lr, check(reason, self.pc, self.lr)]
    }

    /// The record in `words`, if one was written whole (random RAM after a
    /// power-on fails the check).
    pub fn from_words(words: [u32; RECORD_WORDS]) -> Option<Self> {
        let [tagged, pc, lr, check_word] = words;
        let reason = match tagged ^ MAGIC {
            1 => FaultReason::Panic,
            2 => FaultReason::HardFault,
            _ => return None,
        };
        (check(reason as u32, pc, lr) == check_word).then_some(FaultRecord { reason, pc, lr })
    }
}

fn check(reason: u32, pc: u32, lr: u32) -> u32 {
    (MAGIC.rotate_left(7) ^ reason ^ pc.rotate_left(13) ^ lr.rotate_left(23)).wrapping_add(0x9E37_79B9)
}

/// The cause of this boot from the record found in RAM and whether the
/// watchdog's reset flag was set; `None` for an ordinary start.
pub fn boot_cause(record: Option<FaultRecord>, watchdog_reset: bool) -> Option<FaultRecord> {
    match record {
        Some(r) => Some(r),
        None if watchdog_reset => Some(FaultRecord {
            reason: FaultReason::Watchdog,
            pc: 0,
            lr: 0,
        }),
        None => None,
    }
}

/// Bytes of the exception frame the core stacks on a fault (R0–R3, R12, LR, PC, xPSR).
pub const EXCEPTION_FRAME_LEN: u32 = 32;

/// The record of a HardFault whose handler found the main stack pointer at
/// `faulting_sp`, the stack being `stack_bottom..stack_top`: PC and LR from
/// the exception frame (words 6 and 5, read with `read_word`) when the
/// frame lies inside the stack; otherwise the stack overflowed (the core
/// could not stack the frame), and the record says so with PC 0 and the
/// faulting SP in place of the LR, without reading the bad address. The
/// board's handler runs this on a fresh stack (`firmware::board`).
pub fn hard_fault_record(
    faulting_sp: u32,
    stack_bottom: u32,
    stack_top: u32,
    read_word: impl Fn(u32) -> u32,
) -> FaultRecord {
    let frame_inside = faulting_sp >= stack_bottom
        && faulting_sp.is_multiple_of(4)
        && faulting_sp
            .checked_add(EXCEPTION_FRAME_LEN)
            .is_some_and(|end| end <= stack_top);
    let (pc, lr) = if frame_inside {
        (read_word(faulting_sp + 24), read_word(faulting_sp + 20))
    } else {
        (0, faulting_sp)
    };
    FaultRecord {
        reason: FaultReason::HardFault,
        pc,
        lr,
    }
}

/// Encodes the boot report for `cause` and the raw reset flags
/// (RCC_CSR bits 24..31 on the STM32F4) into `out`; the bytes used.
pub fn encode_boot_report(cause: FaultRecord, reset_flags: u8, out: &mut [u8]) -> Option<usize> {
    BootReport {
        reason: cause.reason,
        pc: cause.pc,
        lr: cause.lr,
        reset_flags,
    }
    .encode(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_survives_as_words_and_random_ram_is_no_record() {
        let r = FaultRecord {
            reason: FaultReason::HardFault,
            pc: 0x0800_1234,
            lr: 0xFFFF_FFF9,
        };
        assert_eq!(FaultRecord::from_words(r.to_words()), Some(r));
        let mut torn = r.to_words();
        torn[1] ^= 4;
        assert_eq!(FaultRecord::from_words(torn), None, "a changed PC fails the check");
        assert_eq!(FaultRecord::from_words([0; 4]), None);
        assert_eq!(FaultRecord::from_words([0xDEAD_BEEF, 1, 2, 3]), None);
    }

    #[test]
    fn a_hard_fault_on_an_overflowed_stack_is_recorded_without_reading_the_frame() {
        let (bottom, top) = (0x2000_0000, 0x2000_4000);
        let memory = |addr: u32| {
            assert!((bottom..top).contains(&addr), "read outside the stack at {addr:#x}");
            addr ^ 0x5555_0000
        };
        let inside = hard_fault_record(0x2000_1000, bottom, top, memory);
        assert_eq!(inside.reason, FaultReason::HardFault);
        assert_eq!(
            (inside.pc, inside.lr),
            (0x2000_1018 ^ 0x5555_0000, 0x2000_1014 ^ 0x5555_0000)
        );
        // flip-link: an overflow runs below the start of RAM.
        let overflow = hard_fault_record(0x1FFF_FFE0, bottom, top, memory);
        assert_eq!(
            (overflow.reason, overflow.pc, overflow.lr),
            (FaultReason::HardFault, 0, 0x1FFF_FFE0)
        );
        let at_top = hard_fault_record(top - 16, bottom, top, memory);
        assert_eq!(at_top.pc, 0, "a frame that would end above the stack is not read");
        let wrapped = hard_fault_record(u32::MAX - 3, bottom, top, memory);
        assert_eq!(wrapped.lr, u32::MAX - 3);
        assert_eq!(
            FaultRecord::from_words(overflow.to_words()),
            Some(overflow),
            "and it survives the reset"
        );
    }

    #[test]
    fn the_boot_report_names_the_cause_and_is_told_apart_by_its_length() {
        assert_eq!(boot_cause(None, false), None);
        let dog = boot_cause(None, true).unwrap();
        assert_eq!(dog.reason, FaultReason::Watchdog);
        let panic = FaultRecord {
            reason: FaultReason::Panic,
            pc: 0x0800_4321,
            lr: 0x0800_1111,
        };
        assert_eq!(
            boot_cause(Some(panic), true),
            Some(panic),
            "the record says more than the flag"
        );
        let mut out = [0u8; 16];
        let n = encode_boot_report(panic, 0x24, &mut out).unwrap();
        let mut frame = out[..n].to_vec();
        let len = gyro_wire::cobs::cobs_decode_in_place(&mut frame[..n - 1]).unwrap();
        assert_eq!(
            BootReport::from_bytes(&frame[..len]),
            Some(BootReport {
                reason: FaultReason::Panic,
                pc: 0x0800_4321,
                lr: 0x0800_1111,
                reset_flags: 0x24
            })
        );
    }
}
