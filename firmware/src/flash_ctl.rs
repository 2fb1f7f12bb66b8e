//! The STM32F405's flash controller, bounded and watchdog-aware: the model
//! slots' erase and program (RM0090 §3.6).
//!
//! stm32f4xx-hal 0.23 erases with ×8 parallelism, waits on BSY without a
//! limit, never clears the error flags (one error fails every later
//! operation until reset), leaves SER/SNB set and the data cache stale.
//! This driver: clears the error flags before and checks them after every
//! operation; erases and programs with ×32 parallelism (a 3.3 V supply);
//! bounds every BSY wait; switches the watchdog to
//! [`crate::watchdog::install_setting`] around the erase (the CPU stalls
//! for the erase, feeds included) and back; resets the data and
//! instruction caches after it (stale lines of the erased sector); and
//! locks the controller again after each operation. The registers are
//! reached through [`FlashRegisters`] (the board: FLASH; the host fault
//! scenarios: an emulated controller).

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

use crate::clock::{Clock, Deadline};
use crate::model_store::MappedFlash;
use crate::watchdog::{LSI_FASTEST_HZ, SECTOR_ERASE_WORST_MS, Watchdog, install_setting, running_setting};

/// SR: end of operation.
pub const SR_EOP: u32 = 1 << 0;
/// SR: operation error.
pub const SR_OPERR: u32 = 1 << 1;
/// SR: write protection error.
pub const SR_WRPERR: u32 = 1 << 4;
/// SR: programming alignment error.
pub const SR_PGAERR: u32 = 1 << 5;
/// SR: programming parallelism error.
pub const SR_PGPERR: u32 = 1 << 6;
/// SR: programming sequence error.
pub const SR_PGSERR: u32 = 1 << 7;
/// SR: an operation is in progress.
pub const SR_BSY: u32 = 1 << 16;
/// SR: every error flag.
pub const SR_ERRORS: u32 = SR_OPERR | SR_WRPERR | SR_PGAERR | SR_PGPERR | SR_PGSERR;
/// CR: program.
pub const CR_PG: u32 = 1 << 0;
/// CR: sector erase.
pub const CR_SER: u32 = 1 << 1;
/// CR: sector number shift.
pub const CR_SNB_SHIFT: u32 = 3;
/// CR: ×32 parallelism (PSIZE = 0b10).
pub const CR_PSIZE_X32: u32 = 0b10 << 8;
/// CR: start the erase.
pub const CR_STRT: u32 = 1 << 16;
/// CR: locked.
pub const CR_LOCK: u32 = 1 << 31;
/// The two unlock keys, in order.
pub const KEYS: [u32; 2] = [0x4567_0123, 0xCDEF_89AB];

/// Longest a 128 KiB sector erase may take before it counts as failed, µs:
/// the datasheet's worst case at ×8 ([`SECTOR_ERASE_WORST_MS`]; at the ×32
/// used here it is 2 s).
pub const ERASE_TIMEOUT_US: u32 = SECTOR_ERASE_WORST_MS * 1000;
/// Longest one word program may take before it counts as failed, µs (100 µs worst case).
pub const PROGRAM_TIMEOUT_US: u32 = 1000;
/// Longest a previous operation may keep the controller busy, µs (none
/// should: every operation here waits for its end; a controller still busy
/// is stuck).
pub const IDLE_TIMEOUT_US: u32 = 100_000;

/// Every wait of one erase ends before the install watchdog fires (it is
/// fed before each sector; at the fastest LSI): a stuck controller is an
/// error the unit reports, not a watchdog reset in the middle of an install.
const _: () =
    assert!((IDLE_TIMEOUT_US as u64 + ERASE_TIMEOUT_US as u64) < install_setting().period_us_at(LSI_FASTEST_HZ));

/// The flash controller's registers and the memory-mapped flash.
pub trait FlashRegisters {
    /// SR.
    fn sr(&mut self) -> u32;
    /// Clears the SR flags in `bits` (they are cleared by writing 1).
    fn clear_sr(&mut self, bits: u32);
    /// CR.
    fn cr(&mut self) -> u32;
    /// Writes CR.
    fn set_cr(&mut self, value: u32);
    /// Writes KEYR.
    fn write_key(&mut self, key: u32);
    /// Writes one 32-bit word at `offset` from the start of flash; false,
    /// and nothing written, when `offset` lies outside the words it may
    /// program (the board: the model slots).
    fn write_word(&mut self, offset: u32, word: u32) -> bool;
    /// Resets the data and instruction caches (off, reset, on).
    fn flush_caches(&mut self);
    /// The `len` bytes at `offset` from the start of flash, memory-mapped.
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]>;
}

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// The controller stayed locked after the keys.
    Locked,
    /// The controller stayed busy past the operation's time limit.
    Timeout,
    /// The controller reported these SR error flags.
    Controller(u32),
    /// The range is not in a sector, or not word-aligned.
    OutOfBounds,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The sector holding `offset` from the start of a 1 MiB STM32F405 flash
/// (sectors 0–3: 16 KiB, 4: 64 KiB, 5–11: 128 KiB) and the sector's start.
pub fn sector_of(offset: u32) -> Option<(u8, u32)> {
    match offset {
        0..0x1_0000 => Some(((offset / 0x4000) as u8, offset / 0x4000 * 0x4000)),
        0x1_0000..0x2_0000 => Some((4, 0x1_0000)),
        0x2_0000..0x10_0000 => Some(((offset / 0x2_0000 + 4) as u8, offset / 0x2_0000 * 0x2_0000)),
        _ => None,
    }
}

/// The flash behind its controller: a [`NorFlash`] for the model store.
#[derive(Debug)]
pub struct ControllerFlash<R, C, W> {
    regs: R,
    clock: C,
    watchdog: W,
    errors: u32,
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> ControllerFlash<R, C, W> {
    /// The flash; the controller is left locked.
    pub fn new(regs: R, clock: C, watchdog: W) -> Self {
        let mut flash = ControllerFlash {
            regs,
            clock,
            watchdog,
            errors: 0,
        };
        flash.lock();
        flash
    }

    /// Operations that failed so far.
    pub fn errors(&self) -> u32 {
        self.errors
    }

    /// The registers (host scenarios inspect the emulation).
    pub fn registers(&self) -> &R {
        &self.regs
    }

    fn lock(&mut self) {
        self.regs.set_cr(CR_LOCK);
    }

    fn wait_idle(&mut self, limit_us: u32) -> Result<(), FlashError> {
        let deadline = Deadline::after_us(&mut self.clock, limit_us);
        while self.regs.sr() & SR_BSY != 0 {
            if deadline.expired(&mut self.clock) {
                return Err(FlashError::Timeout);
            }
        }
        Ok(())
    }

    /// Waits for an idle controller, clears the flags of earlier operations, unlocks.
    fn begin(&mut self) -> Result<(), FlashError> {
        self.wait_idle(IDLE_TIMEOUT_US)?;
        self.regs.clear_sr(SR_ERRORS | SR_EOP);
        if self.regs.cr() & CR_LOCK != 0 {
            for key in KEYS {
                self.regs.write_key(key);
            }
        }
        if self.regs.cr() & CR_LOCK != 0 {
            return Err(FlashError::Locked);
        }
        Ok(())
    }

    /// The error flags the operation left, as a result.
    fn check(&mut self) -> Result<(), FlashError> {
        let errors = self.regs.sr() & SR_ERRORS;
        if errors != 0 {
            self.regs.clear_sr(errors);
            return Err(FlashError::Controller(errors));
        }
        Ok(())
    }

    /// Counts a failure, locks the controller, passes the result on.
    fn end(&mut self, result: Result<(), FlashError>) -> Result<(), FlashError> {
        self.lock();
        if result.is_err() {
            self.errors = self.errors.wrapping_add(1);
        }
        result
    }

    #[inline(never)]
    fn erase_sector(&mut self, sector: u8) -> Result<(), FlashError> {
        self.begin()?;
        let cr = CR_PSIZE_X32 | CR_SER | (u32::from(sector) << CR_SNB_SHIFT);
        self.regs.set_cr(cr);
        self.regs.set_cr(cr | CR_STRT);
        let waited = self.wait_idle(ERASE_TIMEOUT_US);
        // Lines of the erased sector may sit in the data cache.
        self.regs.flush_caches();
        waited?;
        self.check()
    }

    #[inline(never)]
    fn program(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.begin()?;
        self.regs.set_cr(CR_PSIZE_X32 | CR_PG);
        let mut at = offset;
        for word in bytes.chunks_exact(4) {
            let value = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
            if !self.regs.write_word(at, value) {
                self.regs.set_cr(CR_PSIZE_X32);
                return Err(FlashError::OutOfBounds);
            }
            self.wait_idle(PROGRAM_TIMEOUT_US)?;
            self.check()?;
            at = at.wrapping_add(4);
        }
        self.regs.set_cr(CR_PSIZE_X32);
        self.regs.flush_caches();
        Ok(())
    }
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> ErrorType for ControllerFlash<R, C, W> {
    type Error = FlashError;
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> ReadNorFlash for ControllerFlash<R, C, W> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let src = self.regs.mapped(offset, bytes.len()).ok_or(FlashError::OutOfBounds)?;
        bytes.copy_from_slice(src);
        Ok(())
    }

    fn capacity(&self) -> usize {
        0x10_0000
    }
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> NorFlash for ControllerFlash<R, C, W> {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = 128 * 1024;

    /// Erases the sectors `from..to` covers (whole 128 KiB sectors): the
    /// watchdog runs at its install period meanwhile.
    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let mut at = from;
        let mut result = Ok(());
        let _ = self.watchdog.set_period(install_setting());
        while at < to {
            let Some((sector, start)) = sector_of(at).filter(|&(_, start)| start == at) else {
                result = Err(FlashError::OutOfBounds);
                break;
            };
            self.watchdog.feed();
            result = self.erase_sector(sector);
            self.watchdog.feed();
            if result.is_err() {
                break;
            }
            let next = sector_of(start).map_or(to, |_| match sector {
                0..=3 => start + 0x4000,
                4 => start + 0x1_0000,
                _ => start + 0x2_0000,
            });
            at = next;
        }
        let _ = self.watchdog.set_period(running_setting());
        self.end(result)
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let result = if !offset.is_multiple_of(4) || !bytes.len().is_multiple_of(4) {
            Err(FlashError::OutOfBounds)
        } else {
            self.program(offset, bytes)
        };
        self.end(result)
    }
}

impl<R: FlashRegisters, C: Clock, W: Watchdog> MappedFlash for ControllerFlash<R, C, W> {
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
        self.regs.mapped(offset, len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sector_erase_and_its_idle_wait_end_before_the_install_watchdog_fires() {
        let watchdog_us = install_setting().period_us_at(LSI_FASTEST_HZ);
        let longest_us = u64::from(IDLE_TIMEOUT_US) + u64::from(ERASE_TIMEOUT_US);
        assert!(
            longest_us < watchdog_us,
            "{longest_us} µs of waits, watchdog {watchdog_us} µs"
        );
        let x32_worst_us = 2_000_000;
        assert!(ERASE_TIMEOUT_US >= x32_worst_us, "the ×32 worst case still fits");
    }

    /// A controller that programs whatever lands inside `slots`.
    struct SlotRegs {
        slots: crate::model_store::SlotLayout,
        written: u32,
    }

    impl FlashRegisters for SlotRegs {
        fn sr(&mut self) -> u32 {
            0
        }
        fn clear_sr(&mut self, _bits: u32) {}
        fn cr(&mut self) -> u32 {
            0
        }
        fn set_cr(&mut self, _value: u32) {}
        fn write_key(&mut self, _key: u32) {}
        fn write_word(&mut self, offset: u32, _word: u32) -> bool {
            let inside = self.slots.holds_word(offset);
            self.written += u32::from(inside);
            inside
        }
        fn flush_caches(&mut self) {}
        fn mapped(&self, _offset: u32, _len: usize) -> Option<&[u8]> {
            None
        }
    }

    struct NoWatchdog;

    impl Watchdog for NoWatchdog {
        fn feed(&mut self) {}
        fn set_period(&mut self, _setting: crate::watchdog::IwdgSetting) -> bool {
            true
        }
    }

    #[test]
    fn a_write_outside_the_model_slots_is_refused_not_skipped() {
        let slots = crate::model_store::SlotLayout {
            offsets: [0x000C_0000, 0x000E_0000],
            len: 0x2_0000,
        };
        let regs = SlotRegs { slots, written: 0 };
        let mut flash = ControllerFlash::new(
            regs,
            crate::clock::CountingClock {
                ticks: 0,
                ticks_per_us: 1,
            },
            NoWatchdog,
        );
        assert_eq!(flash.write(0x000C_0000, &[1, 2, 3, 4]), Ok(()));
        assert_eq!(
            flash.write(0x0000_8000, &[1, 2, 3, 4]),
            Err(FlashError::OutOfBounds),
            "the program image's sector 2"
        );
        assert_eq!(
            flash.write(0x000F_FFFC, &[1, 2, 3, 4, 5, 6, 7, 8]),
            Err(FlashError::OutOfBounds),
            "a write that runs past slot B's end, the end of flash"
        );
        assert_eq!(flash.errors(), 2);
        assert_eq!(flash.registers().written, 2, "the first word, and slot B's last word");
    }

    #[test]
    fn the_model_slots_are_sectors_10_and_11() {
        assert_eq!(sector_of(0x000C_0000), Some((10, 0x000C_0000)));
        assert_eq!(sector_of(0x000E_0000), Some((11, 0x000E_0000)));
        assert_eq!(sector_of(0x000E_0010), Some((11, 0x000E_0000)));
        assert_eq!(sector_of(0x0000_4000), Some((1, 0x4000)));
        assert_eq!(sector_of(0x0001_0000), Some((4, 0x1_0000)));
        assert_eq!(sector_of(0x0010_0000), None);
    }
}
