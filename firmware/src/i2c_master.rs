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

    /// One transaction: `write` (if any), then `read` (if any) after a repeated START, then STOP.
    fn transfer(&mut self, address: u8, write: &[u8], read: &mut [u8]) -> Result<(), I2cError> {
        let deadline = Deadline::after_us(&mut self.clock, TRANSACTION_TIMEOUT_US);
        self.wait_stop_done(&deadline)?;
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
        if let Some((last, head)) = read.split_last_mut() {
            self.address((address << 1) | 1, !head.is_empty(), &deadline)?;
            let _ = self.regs.sr2();
            for byte in head.iter_mut() {
                self.wait_sr1(SR1_RXNE, &deadline, NoAcknowledgeSource::Data)?;
                *byte = self.regs.read_dr();
            }
            // NACK and STOP after the last byte.
            let cr1 = self.regs.cr1() & !CR1_ACK;
            self.regs.set_cr1(cr1);
            self.stop();
            self.wait_sr1(SR1_RXNE, &deadline, NoAcknowledgeSource::Data)?;
            *last = self.regs.read_dr();
        } else {
            self.stop();
        }
        self.wait_stop_done(&deadline)
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
