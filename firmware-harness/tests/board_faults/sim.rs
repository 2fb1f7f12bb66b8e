//! Simulated peripherals for the board-fault scenarios: a clock, the
//! watchdog at a chosen LSI frequency, the STM32F4 I2C peripheral with a
//! TMP117 on its bus, the flash controller, and the IFOG front end with
//! its data-ready line. Each can be told to misbehave.

use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::rc::Rc;

use embedded_hal::spi::{self, Operation, SpiDevice};
use firmware::clock::Clock;
use firmware::flash_ctl::{self, FlashRegisters};
use firmware::frontend;
use firmware::i2c_master::{self, I2cRegisters};
use firmware::watchdog::{IwdgSetting, Watchdog, running_setting};

/// Simulated time, µs; every read of the counter takes a microsecond (the
/// CPU polling), so every bounded wait ends.
#[derive(Clone, Debug, Default)]
pub struct SimClock(Rc<Cell<u64>>);

impl SimClock {
    /// Now, µs.
    pub fn now_us(&self) -> u64 {
        self.0.get()
    }
    /// Lets `us` pass.
    pub fn advance_us(&self, us: u64) {
        self.0.set(self.0.get() + us);
    }
    /// Jumps to `us` (never back).
    pub fn set_us(&self, us: u64) {
        self.0.set(self.0.get().max(us));
    }
}

impl Clock for SimClock {
    fn now_ticks(&mut self) -> u32 {
        self.advance_us(1);
        self.now_us() as u32
    }
    fn ticks_per_us(&self) -> u32 {
        1
    }
}

/// The independent watchdog counting an LSI of `lsi_hz`.
#[derive(Clone, Debug)]
pub struct SimWatchdog(Rc<RefCell<WatchdogState>>);

/// What the simulated watchdog saw.
#[derive(Debug)]
pub struct WatchdogState {
    clock: SimClock,
    lsi_hz: u32,
    /// The period in force.
    pub setting: IwdgSetting,
    last_feed_us: u64,
    /// When the chip would have been reset, if ever.
    pub expired_at_us: Option<u64>,
    /// Longest time between two feeds, µs.
    pub longest_gap_us: u64,
}

impl SimWatchdog {
    /// A watchdog started with the running period.
    pub fn new(clock: &SimClock, lsi_hz: u32) -> Self {
        SimWatchdog(Rc::new(RefCell::new(WatchdogState {
            clock: clock.clone(),
            lsi_hz,
            setting: running_setting(),
            last_feed_us: clock.now_us(),
            expired_at_us: None,
            longest_gap_us: 0,
        })))
    }

    /// Checks for expiry up to now; the state.
    pub fn check(&self) -> std::cell::Ref<'_, WatchdogState> {
        {
            let mut s = self.0.borrow_mut();
            let now = s.clock.now_us();
            let gap = now - s.last_feed_us;
            s.longest_gap_us = s.longest_gap_us.max(gap);
            let period = s.setting.period_us_at(s.lsi_hz);
            if gap > period && s.expired_at_us.is_none() {
                s.expired_at_us = Some(s.last_feed_us + period);
            }
        }
        self.0.borrow()
    }
}

impl Watchdog for SimWatchdog {
    fn feed(&mut self) {
        drop(self.check());
        let mut s = self.0.borrow_mut();
        s.last_feed_us = s.clock.now_us();
    }
    fn set_period(&mut self, setting: IwdgSetting) -> bool {
        self.feed();
        self.0.borrow_mut().setting = setting;
        true
    }
}

/// The STM32F4 I2C peripheral with a TMP117 at 0x48 on its bus.
#[derive(Debug)]
pub struct I2cSim {
    clock: SimClock,
    /// SCL clocks the TMP117 still needs before it releases SDA (0: released).
    pub sda_stuck_clocks: u32,
    /// The peripheral's BUSY flag is stuck (the F4 erratum): no START until a reset.
    pub busy_stuck: bool,
    /// The TMP117 does not acknowledge its address in this window, µs.
    pub nack_window_us: (u64, u64),
    /// The TMP117's reading, raw.
    pub temp_raw: i16,
    /// From when the TMP117 converts (before: its result register reads −256 °C), µs.
    pub converting_from_us: u64,
    /// Peripheral resets seen.
    pub resets: u32,
    /// STOP conditions generated with the lines as GPIO.
    pub gpio_stops: u32,
    cr1: u16,
    sr1: u16,
    gpio: bool,
    scl_high: bool,
    sda_high: bool,
    phase: Phase,
    pointer: u8,
    written: Vec<u8>,
    reply: [u8; 2],
    read_index: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Idle,
    Address,
    Writing,
    Reading,
}

/// Byte time at 400 kHz, µs.
const I2C_BYTE_US: u64 = 23;

impl I2cSim {
    /// A healthy bus with the TMP117 reading `temp_raw` from the start.
    pub fn new(clock: &SimClock, temp_raw: i16) -> Self {
        I2cSim {
            clock: clock.clone(),
            sda_stuck_clocks: 0,
            busy_stuck: false,
            nack_window_us: (0, 0),
            temp_raw,
            converting_from_us: 0,
            resets: 0,
            gpio_stops: 0,
            cr1: 0,
            sr1: 0,
            gpio: false,
            scl_high: true,
            sda_high: true,
            phase: Phase::Idle,
            pointer: 0,
            written: Vec::new(),
            reply: [0; 2],
            read_index: 0,
        }
    }

    fn acks(&self) -> bool {
        let now = self.clock.now_us();
        !(self.nack_window_us.0..self.nack_window_us.1).contains(&now)
    }

    fn register(&self, pointer: u8) -> u16 {
        match pointer {
            0x0F => 0x0117,
            0x00 if self.clock.now_us() >= self.converting_from_us => self.temp_raw as u16,
            0x00 => 0x8000,
            0x01 => 0x0220,
            _ => 0,
        }
    }
}

/// The I2C registers as the driver sees them.
#[derive(Clone, Debug)]
pub struct FakeI2c(pub Rc<RefCell<I2cSim>>);

impl I2cRegisters for FakeI2c {
    fn sr1(&mut self) -> u16 {
        let s = self.0.borrow();
        s.clock.advance_us(1);
        s.sr1
    }
    fn sr2(&mut self) -> u16 {
        let mut s = self.0.borrow_mut();
        s.clock.advance_us(1);
        if s.sr1 & i2c_master::SR1_ADDR != 0 {
            s.sr1 &= !i2c_master::SR1_ADDR;
            if s.phase == Phase::Reading {
                // Both bytes of a register arrive: the first in DR, the
                // second held in the shift register (BTF), SCL stretched.
                s.reply = s.register(s.pointer).to_be_bytes();
                s.read_index = 0;
                s.clock.advance_us(2 * I2C_BYTE_US);
                s.sr1 |= i2c_master::SR1_RXNE | i2c_master::SR1_BTF;
            } else {
                s.sr1 |= i2c_master::SR1_TXE;
            }
        }
        let busy = s.phase != Phase::Idle || s.sda_stuck_clocks > 0 || s.busy_stuck;
        u16::from(s.phase != Phase::Idle) | (u16::from(busy) << 1)
    }
    fn cr1(&mut self) -> u16 {
        self.0.borrow().cr1
    }
    fn set_cr1(&mut self, value: u16) {
        let mut s = self.0.borrow_mut();
        s.clock.advance_us(1);
        s.cr1 = value & !(i2c_master::CR1_START | i2c_master::CR1_STOP);
        if value & i2c_master::CR1_STOP != 0 {
            if s.phase == Phase::Writing && s.pointer == 0x01 && s.written.len() == 3 {
                // CONFIGURATION written: continuous conversion; the first result after 15.5 ms.
                s.converting_from_us = s.converting_from_us.max(s.clock.now_us() + 15_500);
            }
            // A STOP during a read comes after the byte in reception, which still arrives.
            if s.phase != Phase::Reading {
                s.sr1 &= !(i2c_master::SR1_TXE | i2c_master::SR1_BTF | i2c_master::SR1_RXNE);
            }
            s.phase = Phase::Idle;
        } else if value & i2c_master::CR1_START != 0 {
            if s.sda_stuck_clocks > 0 || s.busy_stuck {
                // The bus looks busy: the START waits, SB never rises.
                s.cr1 |= i2c_master::CR1_START;
                return;
            }
            s.phase = Phase::Address;
            s.sr1 |= i2c_master::SR1_SB;
        }
    }
    fn clear_sr1(&mut self, bits: u16) {
        self.0.borrow_mut().sr1 &= !bits;
    }
    fn write_dr(&mut self, byte: u8) {
        let mut s = self.0.borrow_mut();
        s.clock.advance_us(I2C_BYTE_US);
        match s.phase {
            Phase::Address => {
                s.sr1 &= !i2c_master::SR1_SB;
                if byte >> 1 == 0x48 && s.acks() {
                    s.sr1 |= i2c_master::SR1_ADDR;
                    if byte & 1 == 1 {
                        s.phase = Phase::Reading;
                    } else {
                        s.phase = Phase::Writing;
                        s.written.clear();
                    }
                } else {
                    s.sr1 |= i2c_master::SR1_AF;
                    s.phase = Phase::Idle;
                }
            }
            Phase::Writing => {
                if s.written.is_empty() {
                    s.pointer = byte;
                }
                s.written.push(byte);
                s.sr1 |= i2c_master::SR1_TXE | i2c_master::SR1_BTF;
            }
            _ => {}
        }
    }
    fn read_dr(&mut self) -> u8 {
        let mut s = self.0.borrow_mut();
        let byte = s.reply.get(s.read_index).copied().unwrap_or(0xFF);
        s.read_index += 1;
        s.sr1 &= !i2c_master::SR1_BTF;
        if s.read_index >= s.reply.len() {
            s.sr1 &= !i2c_master::SR1_RXNE;
        }
        s.clock.advance_us(I2C_BYTE_US);
        byte
    }
    fn reset(&mut self) {
        let mut s = self.0.borrow_mut();
        s.cr1 = i2c_master::CR1_PE;
        s.sr1 = 0;
        s.phase = Phase::Idle;
        s.busy_stuck = false;
        s.resets += 1;
    }
    fn lines_as_gpio(&mut self, gpio: bool) {
        self.0.borrow_mut().gpio = gpio;
    }
    fn set_scl(&mut self, high: bool) {
        let mut s = self.0.borrow_mut();
        if s.gpio && s.scl_high && !high && s.sda_stuck_clocks > 0 {
            s.sda_stuck_clocks -= 1;
        }
        s.scl_high = high;
    }
    fn set_sda(&mut self, high: bool) {
        let mut s = self.0.borrow_mut();
        if s.gpio && s.scl_high && high && !s.sda_high {
            s.gpio_stops += 1;
        }
        s.sda_high = high;
    }
    fn sda_is_high(&mut self) -> bool {
        let s = self.0.borrow();
        s.sda_high && s.sda_stuck_clocks == 0
    }
}

/// Start of the simulated model slots (sector 10).
pub const SLOTS_START: u32 = 0x000C_0000;

/// The flash controller and sectors 10 and 11.
#[derive(Debug)]
pub struct FlashSim {
    clock: SimClock,
    mem: Vec<u8>,
    sr: u32,
    cr: u32,
    locked: bool,
    key_step: u8,
    /// How long a sector erase stalls the CPU, µs.
    pub erase_us: u64,
    /// Programs of a word that fail (PGSERR), from the next one on.
    pub failing_programs: u32,
    /// Erases started, each with the PSIZE it used.
    pub erases: Vec<u32>,
    /// Words programmed, and with which PSIZE the last was.
    pub words: u32,
    /// Cache flushes after the last erase.
    pub flushes_since_erase: u32,
}

impl FlashSim {
    /// Erased slots, a controller locked after reset.
    pub fn new(clock: &SimClock, erase_us: u64) -> Self {
        FlashSim {
            clock: clock.clone(),
            mem: vec![0xFF; 0x4_0000],
            sr: 0,
            cr: 0,
            locked: true,
            key_step: 0,
            erase_us,
            failing_programs: 0,
            erases: Vec::new(),
            words: 0,
            flushes_since_erase: 0,
        }
    }

    /// Whether the controller is locked.
    pub fn locked(&self) -> bool {
        self.locked
    }

    /// SR now (error flags left behind).
    pub fn status(&self) -> u32 {
        self.sr
    }
}

impl FlashRegisters for FlashSim {
    fn sr(&mut self) -> u32 {
        self.clock.advance_us(1);
        self.sr
    }
    fn clear_sr(&mut self, bits: u32) {
        self.sr &= !bits;
    }
    fn cr(&mut self) -> u32 {
        self.cr | if self.locked { flash_ctl::CR_LOCK } else { 0 }
    }
    fn set_cr(&mut self, value: u32) {
        if self.locked {
            return;
        }
        if value & flash_ctl::CR_LOCK != 0 {
            self.locked = true;
            self.key_step = 0;
            self.cr = 0;
            return;
        }
        self.cr = value;
        if value & flash_ctl::CR_STRT != 0 && value & flash_ctl::CR_SER != 0 {
            let sector = (value >> flash_ctl::CR_SNB_SHIFT) & 0xF;
            self.erases.push(value & (0b11 << 8));
            if let Some(start) = [10u32, 11].iter().position(|&s| s == sector) {
                let from = start * 0x2_0000;
                self.mem[from..from + 0x2_0000].fill(0xFF);
            }
            // The CPU stalls for the whole erase, interrupts and feeds included.
            self.clock.advance_us(self.erase_us);
            self.flushes_since_erase = 0;
            self.sr |= flash_ctl::SR_EOP;
            self.cr &= !flash_ctl::CR_STRT;
        }
    }
    fn write_key(&mut self, key: u32) {
        match (self.key_step, key) {
            (0, k) if k == flash_ctl::KEYS[0] => self.key_step = 1,
            (1, k) if k == flash_ctl::KEYS[1] => {
                self.locked = false;
                self.key_step = 0;
            }
            // A wrong key locks the controller until reset.
            _ => self.key_step = 2,
        }
    }
    fn write_word(&mut self, offset: u32, word: u32) -> bool {
        self.clock.advance_us(16);
        if self.locked || self.cr & flash_ctl::CR_PG == 0 {
            self.sr |= flash_ctl::SR_PGSERR;
            return true;
        }
        if self.cr & (0b11 << 8) != flash_ctl::CR_PSIZE_X32 {
            self.sr |= flash_ctl::SR_PGPERR;
            return true;
        }
        if self.failing_programs > 0 {
            self.failing_programs -= 1;
            self.sr |= flash_ctl::SR_PGSERR;
            return true;
        }
        let Some(at) = offset.checked_sub(SLOTS_START).map(|a| a as usize) else {
            return false;
        };
        if let Some(cells) = self.mem.get_mut(at..at + 4) {
            for (cell, byte) in cells.iter_mut().zip(word.to_le_bytes()) {
                *cell &= byte;
            }
            self.words += 1;
            true
        } else {
            false
        }
    }
    fn flush_caches(&mut self) {
        self.flushes_since_erase += 1;
    }
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
        let at = offset.checked_sub(SLOTS_START)? as usize;
        self.mem.get(at..at.checked_add(len)?)
    }
}

/// The IFOG front end: a sample every `period_us` from `boot_at_us` on,
/// data-ready raised on each and lowered by a SAMPLE read.
#[derive(Debug)]
pub struct FrontEndSim {
    clock: SimClock,
    /// When the electronics answer and sample, µs.
    pub boot_at_us: u64,
    /// Sample period, µs.
    pub period_us: u64,
    /// The scale factor it reports, °/h per unit.
    pub scale_dph: f32,
    /// Until then SCALE_FACTOR reads 0 (calibration not loaded) while the rest answers, µs.
    pub scale_from_us: u64,
    /// The rate word of sample `n` is `n as f32`.
    pub counter: u8,
    /// Samples taken so far.
    pub samples: u64,
    /// The data-ready level.
    pub level_high: bool,
    /// Data-ready pulses on every sample whether SAMPLE was read or not
    /// (false: the line stays high until SAMPLE is read, docs/frontend.md).
    pub pulsed: bool,
    /// A glitch edge this long after each real edge, µs (0: none).
    pub glitch_after_us: u64,
    next_sample_us: u64,
    pending_glitch_us: Option<u64>,
    /// Data-ready stamps queued for the loop (TIM2 at 1 tick/µs), at most 15 (the board's spsc queue).
    pub stamps: VecDeque<u32>,
    /// Stamps lost to a full queue.
    pub stamp_overruns: u32,
    /// SAMPLE reads.
    pub sample_reads: u32,
}

impl FrontEndSim {
    /// A front end sampling at 1 kHz from `boot_at_us`.
    pub fn new(clock: &SimClock, boot_at_us: u64) -> Self {
        FrontEndSim {
            clock: clock.clone(),
            boot_at_us,
            period_us: 1000,
            scale_dph: 2.0,
            scale_from_us: 0,
            counter: 0,
            samples: 0,
            level_high: false,
            pulsed: false,
            glitch_after_us: 0,
            next_sample_us: boot_at_us + 1000,
            pending_glitch_us: None,
            stamps: VecDeque::new(),
            stamp_overruns: 0,
            sample_reads: 0,
        }
    }

    fn stamp(&mut self, at_us: u64) {
        if self.stamps.len() >= 15 {
            self.stamp_overruns += 1;
        } else {
            self.stamps.push_back(at_us as u32);
        }
    }

    /// Runs the front end up to now: new samples, edges, glitches.
    pub fn advance(&mut self) {
        let now = self.clock.now_us();
        loop {
            let glitch = self.pending_glitch_us.filter(|&g| g <= now);
            let sample = (self.next_sample_us <= now).then_some(self.next_sample_us);
            match (glitch, sample) {
                (Some(g), s) if s.is_none_or(|s| g < s) => {
                    self.pending_glitch_us = None;
                    self.stamp(g);
                }
                (_, Some(t)) => {
                    self.next_sample_us += self.period_us;
                    self.samples += 1;
                    self.counter = self.counter.wrapping_add(1);
                    if !self.level_high || self.pulsed {
                        self.level_high = true;
                        self.stamp(t);
                        if self.glitch_after_us > 0 {
                            self.pending_glitch_us = Some(t + self.glitch_after_us);
                        }
                    }
                }
                _ => break,
            }
        }
    }

    /// When the next edge may come, µs.
    pub fn next_event_us(&self) -> u64 {
        self.pending_glitch_us.unwrap_or(u64::MAX).min(self.next_sample_us)
    }

    /// The rate (front-end units) of sample `counter`.
    pub fn rate_word(counter: u8) -> f32 {
        f32::from(counter)
    }
}

/// The front end as the SPI device the driver reads.
#[derive(Clone, Debug)]
pub struct FakeSpi(pub Rc<RefCell<FrontEndSim>>);

impl spi::ErrorType for FakeSpi {
    type Error = spi::ErrorKind;
}

impl SpiDevice for FakeSpi {
    fn transaction(&mut self, operations: &mut [Operation<'_, u8>]) -> Result<(), spi::ErrorKind> {
        let mut s = self.0.borrow_mut();
        s.clock.advance_us(10);
        let [Operation::Write([command]), Operation::Read(buf)] = operations else {
            return Err(spi::ErrorKind::Other);
        };
        if s.clock.now_us() < s.boot_at_us {
            // Unpowered electronics: MISO floats to its pull-up.
            buf.fill(0xFF);
            return Ok(());
        }
        let mut reply = [0u8; frontend::SAMPLE_LEN];
        match *command & !frontend::READ {
            frontend::REG_WHO_AM_I => reply[..2].copy_from_slice(&frontend::WHO_AM_I.to_be_bytes()),
            frontend::REG_SCALE_FACTOR => {
                let scale = if s.clock.now_us() < s.scale_from_us {
                    0.0
                } else {
                    s.scale_dph
                };
                reply[..4].copy_from_slice(&scale.to_bits().to_be_bytes());
            }
            frontend::REG_SAMPLE => {
                let counter = s.counter;
                reply =
                    frontend::encode_counted_sample(frontend::STATUS_VALID, counter, FrontEndSim::rate_word(counter));
                s.level_high = false;
                s.sample_reads += 1;
            }
            _ => return Err(spi::ErrorKind::Other),
        }
        for (d, r) in buf.iter_mut().zip(reply) {
            *d = r;
        }
        Ok(())
    }
}

/// USART1's receiver as the board's interrupt logic reads it
/// (`firmware::interrupts::serve_uart`): the bytes that arrived on the
/// line, one per read, and a framing error for every `error_every`-th.
#[derive(Debug, Default)]
pub struct UartRxSim {
    /// Bytes on the line, oldest first.
    pub line: VecDeque<u8>,
    /// Every this many bytes arrive with a framing error (0: never).
    pub error_every: u32,
    received: u32,
}

impl UartRxSim {
    /// A receiver whose every `error_every`-th byte has a framing error.
    pub fn with_errors_every(error_every: u32) -> UartRxSim {
        UartRxSim {
            error_every,
            ..UartRxSim::default()
        }
    }
}

impl embedded_hal_nb::serial::ErrorType for UartRxSim {
    type Error = embedded_hal_nb::serial::ErrorKind;
}

impl embedded_hal_nb::serial::Read<u8> for UartRxSim {
    fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
        let byte = self.line.pop_front().ok_or(embedded_hal_nb::nb::Error::WouldBlock)?;
        self.received += 1;
        if self.error_every != 0 && self.received.is_multiple_of(self.error_every) {
            return Err(embedded_hal_nb::nb::Error::Other(
                embedded_hal_nb::serial::ErrorKind::FrameFormat,
            ));
        }
        Ok(byte)
    }
}

/// USART1's transmitter: takes every byte (the wire is faster than the
/// loop's frames), keeps what went out.
#[derive(Debug, Default)]
pub struct UartTxSim {
    /// Bytes sent, in order.
    pub sent: Vec<u8>,
}

impl embedded_hal_nb::serial::ErrorType for UartTxSim {
    type Error = embedded_hal_nb::serial::ErrorKind;
}

impl embedded_hal_nb::serial::Write<u8> for UartTxSim {
    fn write(&mut self, byte: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        self.sent.push(byte);
        Ok(())
    }
    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
}
