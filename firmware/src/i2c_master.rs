//! A bounded I2C master for the STM32F4's I2C peripheral, with bus recovery.
//!
//! stm32f4xx-hal 0.23's I2C busy-waits without a limit on the start
//! condition, the address and every byte; a TMP117 holding SDA low (the MCU
//! reset in the middle of a read) or the F4's busy-flag erratum hangs it
//! for good. This driver runs the same register sequence (RM0090 §27.3.3),
//! but every wait polls against a [`Deadline`]; a timeout ends the
//! transaction with [`I2cError::Timeout`] and recovers the bus: nine SCL
//! clocks with the lines as GPIO (a slave in the middle of a byte
//! releases SDA), a STOP, then a reset of the peripheral. [`BoundedI2c::new`]
//! recovers the bus before first use. The registers are reached through
//! [`I2cRegisters`] (the board: I2C1 and PB6/PB7; the host fault
//! scenarios: an emulated peripheral and bus).

use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation, SevenBitAddress};

use crate::clock::{Clock, Deadline, delay_us};

/// SR1: start condition generated.
pub const SR1_SB: u16 = 1 << 0;
/// SR1: address sent and acknowledged.
pub const SR1_ADDR: u16 = 1 << 1;
/// SR1: byte transfer finished.
pub const SR1_BTF: u16 = 1 << 2;
/// SR1: receive register not empty.
pub const SR1_RXNE: u16 = 1 << 6;
/// SR1: transmit register empty.
pub const SR1_TXE: u16 = 1 << 7;
/// SR1: bus error (misplaced START/STOP).
pub const SR1_BERR: u16 = 1 << 8;
/// SR1: arbitration lost.
pub const SR1_ARLO: u16 = 1 << 9;
/// SR1: acknowledge failure (NACK).
pub const SR1_AF: u16 = 1 << 10;
/// SR1: overrun.
pub const SR1_OVR: u16 = 1 << 11;
/// CR1: peripheral enable.
pub const CR1_PE: u16 = 1 << 0;
/// CR1: generate START.
pub const CR1_START: u16 = 1 << 8;
/// CR1: generate STOP.
pub const CR1_STOP: u16 = 1 << 9;
/// CR1: acknowledge received bytes.
pub const CR1_ACK: u16 = 1 << 10;
/// CR1: ACK applies to the next byte (the one in the shift register), for 2-byte reads.
pub const CR1_POS: u16 = 1 << 11;

/// Longest a whole transaction may take, µs: a TMP117 register read
/// (five bytes) takes about 130 µs at 400 kHz.
pub const TRANSACTION_TIMEOUT_US: u32 = 1000;
/// Half an SCL period of the recovery clocks, µs (50 kHz: slow enough for any slave).
pub const RECOVERY_HALF_PERIOD_US: u32 = 10;

/// The I2C peripheral's registers and its two lines.
pub trait I2cRegisters {
    /// SR1.
    fn sr1(&mut self) -> u16;
    /// SR2 (reading it after SR1 clears ADDR).
    fn sr2(&mut self) -> u16;
    /// CR1.
    fn cr1(&mut self) -> u16;
    /// Writes CR1.
    fn set_cr1(&mut self, value: u16);
    /// Clears the SR1 flags in `bits` (they are cleared by writing 0).
    fn clear_sr1(&mut self, bits: u16);
    /// Writes DR.
    fn write_dr(&mut self, byte: u8);
    /// Reads DR.
    fn read_dr(&mut self) -> u8;
    /// Resets the peripheral (RCC), sets its clock and timing again and enables it.
    fn reset(&mut self);
    /// Hands the lines to GPIO open-drain (`true`, for recovery) or back to the peripheral.
    fn lines_as_gpio(&mut self, gpio: bool);
    /// Drives SCL (GPIO mode): high releases it.
    fn set_scl(&mut self, high: bool);
    /// Drives SDA (GPIO mode): high releases it.
    fn set_sda(&mut self, high: bool);
    /// Whether SDA reads high.
    fn sda_is_high(&mut self) -> bool;
}

/// Why a transaction failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum I2cError {
    /// A wait ran out of time; the bus has been recovered since.
    Timeout,
    /// The slave did not acknowledge.
    Nack(NoAcknowledgeSource),
    /// Another master (or noise) won the bus.
    ArbitrationLoss,
    /// An overrun or an empty read.
    Overrun,
}

impl embedded_hal::i2c::Error for I2cError {
    fn kind(&self) -> ErrorKind {
        match self {
            I2cError::Timeout => ErrorKind::Other,
            I2cError::Nack(source) => ErrorKind::NoAcknowledge(*source),
            I2cError::ArbitrationLoss => ErrorKind::ArbitrationLoss,
            I2cError::Overrun => ErrorKind::Overrun,
        }
    }
}

/// What the master has been through (for the health report).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct I2cCounters {
    /// Transactions that ran out of time.
    pub timeouts: u32,
    /// Bus recoveries (nine clocks, STOP, peripheral reset), the one at init included.
    pub recoveries: u32,
    /// Transactions the slave did not acknowledge.
    pub nacks: u32,
}

/// The bounded master over registers `R`, timed by `C`.
#[derive(Debug)]
pub struct BoundedI2c<R, C> {
    regs: R,
    clock: C,
    counters: I2cCounters,
}

impl<R: I2cRegisters, C: Clock> BoundedI2c<R, C> {
    /// The master; recovers the bus first (a slave may hold SDA from
    /// before the reset) and resets the peripheral.
    pub fn new(regs: R, clock: C) -> Self {
        let mut master = BoundedI2c {
            regs,
            clock,
            counters: I2cCounters::default(),
        };
        master.recover();
        master
    }

    /// The counters so far.
    pub fn counters(&self) -> I2cCounters {
        self.counters
    }

    /// Gives the registers and clock back.
    pub fn destroy(self) -> (R, C) {
        (self.regs, self.clock)
    }

    /// Nine SCL clocks (fewer once SDA is released), a STOP, a peripheral reset.
    pub fn recover(&mut self) {
        let half = RECOVERY_HALF_PERIOD_US;
        // Output latches high before the pins become outputs: no glitch on the lines.
        self.regs.set_sda(true);
        self.regs.set_scl(true);
        self.regs.lines_as_gpio(true);
        delay_us(&mut self.clock, half);
        for _ in 0..9 {
            if self.regs.sda_is_high() {
                break;
            }
            self.regs.set_scl(false);
            delay_us(&mut self.clock, half);
            self.regs.set_scl(true);
            delay_us(&mut self.clock, half);
        }
        // STOP: SDA rises while SCL is high.
        self.regs.set_scl(false);
        delay_us(&mut self.clock, half);
        self.regs.set_sda(false);
        delay_us(&mut self.clock, half);
        self.regs.set_scl(true);
        delay_us(&mut self.clock, half);
        self.regs.set_sda(true);
        delay_us(&mut self.clock, half);
        self.regs.lines_as_gpio(false);
        self.regs.reset();
        self.counters.recoveries = self.counters.recoveries.wrapping_add(1);
    }

    /// Polls SR1 until `flag` is set, an error flag is or the deadline passes.
    fn wait_sr1(&mut self, flag: u16, deadline: &Deadline, nack: NoAcknowledgeSource) -> Result<(), I2cError> {
        loop {
            let sr1 = self.regs.sr1();
            if sr1 & SR1_AF != 0 {
                self.regs.clear_sr1(SR1_AF);
                return Err(I2cError::Nack(nack));
            }
            if sr1 & SR1_ARLO != 0 {
                self.regs.clear_sr1(SR1_ARLO);
                return Err(I2cError::ArbitrationLoss);
            }
            if sr1 & SR1_OVR != 0 {
                self.regs.clear_sr1(SR1_OVR);
                return Err(I2cError::Overrun);
            }
            // The errata: BERR may be flagged wrongly; cleared and ignored.
            if sr1 & SR1_BERR != 0 {
                self.regs.clear_sr1(SR1_BERR);
            }
            if sr1 & flag != 0 {
                return Ok(());
            }
            if deadline.expired(&mut self.clock) {
                return Err(I2cError::Timeout);
            }
        }
    }

    /// Waits for a STOP in progress to finish.
    fn wait_stop_done(&mut self, deadline: &Deadline) -> Result<(), I2cError> {
        while self.regs.cr1() & CR1_STOP != 0 {
            if deadline.expired(&mut self.clock) {
                return Err(I2cError::Timeout);
            }
        }
        Ok(())
    }

    /// START (or repeated START) and the address byte; ADDR cleared.
    fn address(&mut self, address_byte: u8, ack: bool, deadline: &Deadline) -> Result<(), I2cError> {
        let cr1 = self.regs.cr1() & !(CR1_STOP | CR1_ACK);
        self.regs.set_cr1(cr1 | CR1_START | if ack { CR1_ACK } else { 0 });
        self.wait_sr1(SR1_SB, deadline, NoAcknowledgeSource::Unknown)?;
        self.regs.write_dr(address_byte);
        self.wait_sr1(SR1_ADDR, deadline, NoAcknowledgeSource::Address)
    }

    fn stop(&mut self) {
        let cr1 = self.regs.cr1();
        self.regs.set_cr1((cr1 & !CR1_START) | CR1_STOP);
    }

    /// A 1-byte read (RM0090 §27.3.3, "case of a single byte"): NACK set
    /// before ADDR is cleared, STOP right after, then the byte.
    fn read_one(&mut self, address: u8, read: &mut [u8], deadline: &Deadline) -> Result<(), I2cError> {
        self.address((address << 1) | 1, false, deadline)?;
        let _ = self.regs.sr2();
        self.stop();
        self.wait_sr1(SR1_RXNE, deadline, NoAcknowledgeSource::Data)?;
        if let Some(byte) = read.first_mut() {
            *byte = self.regs.read_dr();
        }
        Ok(())
    }

    /// A 2-byte read (RM0090 §27.3.3, "case of two bytes"): POS and ACK
    /// set before ADDR is cleared, ACK cleared after it (so the second
    /// byte is NACKed whatever delays the CPU), BTF awaited (both bytes
    /// in), STOP, then DR read twice. POS is cleared once the STOP is done
    /// ([`Self::clear_pos`]: clearing it earlier would rewrite CR1 while
    /// the STOP is pending).
    fn read_two(&mut self, address: u8, read: &mut [u8], deadline: &Deadline) -> Result<(), I2cError> {
        let cr1 = self.regs.cr1();
        self.regs.set_cr1(cr1 | CR1_POS);
        self.address((address << 1) | 1, true, deadline)?;
        let _ = self.regs.sr2();
        let cr1 = self.regs.cr1();
        self.regs.set_cr1(cr1 & !(CR1_ACK | CR1_START));
        self.wait_sr1(SR1_BTF, deadline, NoAcknowledgeSource::Data)?;
        self.stop();
        for byte in read.iter_mut() {
            *byte = self.regs.read_dr();
        }
        Ok(())
    }

    /// A read of three bytes or more (RM0090 §27.3.3): bytes on RXNE until
    /// three are left; then BTF (N−2 in DR, N−1 in the shift register),
    /// NACK, byte N−2; BTF again, STOP, bytes N−1 and N.
    fn read_many(&mut self, address: u8, read: &mut [u8], deadline: &Deadline) -> Result<(), I2cError> {
        self.address((address << 1) | 1, true, deadline)?;
        let _ = self.regs.sr2();
        let (head, last_three) = read.split_at_mut(read.len().saturating_sub(3));
        for byte in head.iter_mut() {
            self.wait_sr1(SR1_RXNE, deadline, NoAcknowledgeSource::Data)?;
            *byte = self.regs.read_dr();
        }
        let [n2, n1, n] = last_three else {
            return Err(I2cError::Overrun);
        };
        self.wait_sr1(SR1_BTF, deadline, NoAcknowledgeSource::Data)?;
        let cr1 = self.regs.cr1();
        self.regs.set_cr1(cr1 & !(CR1_ACK | CR1_START));
        *n2 = self.regs.read_dr();
        self.wait_sr1(SR1_BTF, deadline, NoAcknowledgeSource::Data)?;
        self.stop();
        *n1 = self.regs.read_dr();
        *n = self.regs.read_dr();
        Ok(())
    }

    /// One transaction: `write` (if any), then `read` (if any) after a repeated START, then STOP.
    fn transfer(&mut self, address: u8, write: &[u8], read: &mut [u8]) -> Result<(), I2cError> {
        let deadline = Deadline::after_us(&mut self.clock, TRANSACTION_TIMEOUT_US);
        self.wait_stop_done(&deadline)?;
        self.clear_pos();
        self.regs.clear_sr1(0xFFFF);
        if !write.is_empty() || read.is_empty() {
            self.address(address << 1, false, &deadline)?;
            let _ = self.regs.sr2();
            for &byte in write {
                self.wait_sr1(SR1_TXE, &deadline, NoAcknowledgeSource::Data)?;
                self.regs.write_dr(byte);
            }
            self.wait_sr1(SR1_BTF, &deadline, NoAcknowledgeSource::Data)?;
        }
        match read.len() {
            0 => self.stop(),
            1 => self.read_one(address, read, &deadline)?,
            2 => self.read_two(address, read, &deadline)?,
            _ => self.read_many(address, read, &deadline)?,
        }
        self.wait_stop_done(&deadline)?;
        self.clear_pos();
        Ok(())
    }

    /// Clears POS (a 2-byte read's) with no STOP pending; also at the start
    /// of every transaction, after one that ended in an error.
    fn clear_pos(&mut self) {
        let cr1 = self.regs.cr1();
        if cr1 & CR1_POS != 0 {
            self.regs.set_cr1(cr1 & !(CR1_POS | CR1_START | CR1_STOP));
        }
    }
}

impl<R: I2cRegisters, C: Clock> ErrorType for BoundedI2c<R, C> {
    type Error = I2cError;
}

impl<R: I2cRegisters, C: Clock> I2c<SevenBitAddress> for BoundedI2c<R, C> {
    /// Supports what the drivers here send: a write, a read, or a write then
    /// a read; other sequences run operation by operation.
    fn transaction(&mut self, address: u8, operations: &mut [Operation<'_>]) -> Result<(), I2cError> {
        let result = match operations {
            [Operation::Write(w), Operation::Read(r)] => self.transfer(address, w, r),
            [Operation::Write(w)] => self.transfer(address, w, &mut []),
            [Operation::Read(r)] if !r.is_empty() => self.transfer(address, &[], r),
            ops => {
                let mut result = Ok(());
                for op in ops.iter_mut() {
                    result = match op {
                        Operation::Write(w) => self.transfer(address, w, &mut []),
                        Operation::Read(r) if !r.is_empty() => self.transfer(address, &[], r),
                        Operation::Read(_) => Err(I2cError::Overrun),
                    };
                    if result.is_err() {
                        break;
                    }
                }
                result
            }
        };
        match result {
            Err(I2cError::Timeout) => {
                self.counters.timeouts = self.counters.timeouts.wrapping_add(1);
                self.recover();
            }
            Err(I2cError::Nack(_) | I2cError::ArbitrationLoss | I2cError::Overrun) => {
                if matches!(result, Err(I2cError::Nack(_))) {
                    self.counters.nacks = self.counters.nacks.wrapping_add(1);
                }
                // End the transaction on the bus; a STOP that never completes
                // shows up as a timeout of the next transaction.
                self.stop();
            }
            Ok(()) => {}
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The I2C peripheral reading two bytes from a slave, to RM0090's
    /// rules: a byte takes 3 register accesses; with POS clear the ACK bit
    /// answers the byte being received when it ends, with POS set the next
    /// one; a second byte that finds DR full waits in the shift register
    /// (BTF) with SCL held. The CPU is held up (an interrupt) for
    /// `stall_after_first_read` accesses as it reads the first byte.
    #[derive(Default)]
    struct TwoByteRead {
        t: u32,
        cr1: u16,
        started: bool,
        addressed: bool,
        addr_cleared_at: Option<u32>,
        byte1_in: bool,
        byte2_in: bool,
        dr_reads: usize,
        stall_after_first_read: u32,
        /// Whether the master acknowledged the second byte (then the slave sends a third).
        byte2_acked: Option<bool>,
    }

    impl TwoByteRead {
        fn update(&mut self) {
            let Some(t0) = self.addr_cleared_at else { return };
            let ack = self.cr1 & CR1_ACK != 0;
            let pos = self.cr1 & CR1_POS != 0;
            if !self.byte1_in && self.t >= t0 + 3 {
                self.byte1_in = true;
                if pos {
                    self.byte2_acked = Some(ack);
                }
            }
            if self.byte1_in && !self.byte2_in && self.t >= t0 + 6 {
                self.byte2_in = true;
                if self.byte2_acked.is_none() {
                    self.byte2_acked = Some(ack);
                }
            }
        }
    }

    impl I2cRegisters for TwoByteRead {
        fn sr1(&mut self) -> u16 {
            self.t += 1;
            self.update();
            let mut sr1 = 0;
            if self.started && !self.addressed {
                sr1 |= SR1_SB;
            }
            if self.addressed && self.addr_cleared_at.is_none() {
                sr1 |= SR1_ADDR;
            }
            if self.byte1_in && self.dr_reads < 2 {
                sr1 |= SR1_RXNE;
            }
            if self.byte2_in && self.dr_reads == 0 {
                sr1 |= SR1_BTF;
            }
            sr1
        }
        fn sr2(&mut self) -> u16 {
            self.t += 1;
            if self.addressed && self.addr_cleared_at.is_none() {
                self.addr_cleared_at = Some(self.t);
            }
            0
        }
        fn cr1(&mut self) -> u16 {
            self.cr1
        }
        fn set_cr1(&mut self, value: u16) {
            self.t += 1;
            self.update();
            if value & CR1_START != 0 {
                self.started = true;
            }
            self.cr1 = value & !(CR1_START | CR1_STOP);
        }
        fn clear_sr1(&mut self, _bits: u16) {}
        fn write_dr(&mut self, _byte: u8) {
            self.t += 1;
            if self.started {
                self.addressed = true;
            }
        }
        fn read_dr(&mut self) -> u8 {
            if self.dr_reads == 0 {
                self.t += self.stall_after_first_read;
            }
            self.t += 1;
            self.update();
            self.dr_reads += 1;
            [0x12, 0x34].get(self.dr_reads - 1).copied().unwrap_or(0xFF)
        }
        fn reset(&mut self) {
            self.cr1 = CR1_PE;
        }
        fn lines_as_gpio(&mut self, _gpio: bool) {}
        fn set_scl(&mut self, _high: bool) {}
        fn set_sda(&mut self, _high: bool) {}
        fn sda_is_high(&mut self) -> bool {
            true
        }
    }

    #[test]
    fn a_two_byte_read_nacks_the_second_byte_even_when_an_interrupt_delays_the_cpu() {
        for stall in [0, 50] {
            let regs = TwoByteRead {
                stall_after_first_read: stall,
                ..TwoByteRead::default()
            };
            let mut master = BoundedI2c::new(
                regs,
                crate::clock::CountingClock {
                    ticks: 0,
                    ticks_per_us: 1,
                },
            );
            let mut bytes = [0u8; 2];
            master.read(0x48, &mut bytes).unwrap();
            assert_eq!(bytes, [0x12, 0x34]);
            let (regs, _) = master.destroy();
            assert_eq!(
                regs.byte2_acked,
                Some(false),
                "stall {stall}: the last byte is NACKed (RM0090's POS sequence), or the slave sends on"
            );
            assert_eq!(regs.cr1 & CR1_POS, 0, "POS is cleared again for the next transaction");
        }
    }
}
