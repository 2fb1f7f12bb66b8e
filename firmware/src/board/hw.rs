//! The board's register-level pieces behind the library's small traits:
//! TIM2 as the [`Clock`] of every bounded wait, the IWDG as the
//! [`Watchdog`], I2C1 on PB6/PB7 as [`I2cRegisters`], the flash controller
//! as [`FlashRegisters`], and the bounded HSE start. Fields are written by
//! the PAC's field writers, in `registers` where a write can be checked
//! on the host (over a zeroed register block); the I2C and flash registers pass whole words to
//! the drivers, which name their bits (`i2c_master`, `flash_ctl`). What runs
//! on these is library code (`cargo xtask board-faults` runs it against
//! simulations).
#![allow(unsafe_code)]

use core::sync::atomic::AtomicU32;
use core::sync::atomic::Ordering;

use super::registers::{self, poll};
use crate::clock::Clock;
use crate::flash_ctl::FlashRegisters;
use crate::i2c_master::I2cRegisters;
use crate::model_store::SlotLayout;
use crate::watchdog::{IwdgSetting, Watchdog};
use stm32f4xx_hal::pac;

/// I2C1 bus recoveries (each ends in a peripheral reset): the one at boot,
/// then one after every transaction that ran out of time.
pub static I2C_RECOVERIES: AtomicU32 = AtomicU32::new(0);

/// TIM2, free-running over 32 bits at the timer clock.
#[derive(Clone, Copy, Debug)]
pub struct Tim2Clock {
    /// Timer ticks per µs.
    pub ticks_per_us: u32,
}

impl Tim2Clock {
    /// TIM2's counter now.
    pub fn now() -> u32 {
        // SAFETY: a read of TIM2's free-running counter, which only the
        // board's setup writes (before anything reads it).
        unsafe { (*pac::TIM2::ptr()).cnt().read().bits() }
    }
}

impl Clock for Tim2Clock {
    fn now_ticks(&mut self) -> u32 {
        Tim2Clock::now()
    }
    fn ticks_per_us(&self) -> u32 {
        self.ticks_per_us
    }
}

/// The independent watchdog (RM0090 §21): the key register's start,
/// unlock (PR, RLR) and feed keys, by the PAC's names.
#[derive(Clone, Copy, Debug)]
pub struct Iwdg;

impl Iwdg {
    /// Starts the watchdog at `setting`, frozen while a debugger halts the
    /// core; false if the period did not take (it then runs at its reset
    /// period, the longest).
    pub fn start(setting: IwdgSetting) -> bool {
        // SAFETY: DBG_IWDG_STOP only affects debug halts.
        unsafe {
            (*pac::DBGMCU::ptr())
                .apb1_fz()
                .modify(|_, w| w.dbg_iwdg_stop().set_bit())
        };
        // SAFETY: the start key.
        unsafe { (*pac::IWDG::ptr()).kr().write(|w| w.key().start()) };
        Iwdg.set_period(setting)
    }
}

impl Watchdog for Iwdg {
    fn feed(&mut self) {
        // SAFETY: the reload key.
        registers::feed_iwdg(unsafe { &*pac::IWDG::ptr() });
    }

    #[inline(never)]
    fn set_period(&mut self, setting: IwdgSetting) -> bool {
        // SAFETY: IWDG accesses as RM0090 §21.3 describes (`registers`).
        registers::write_iwdg_period(unsafe { &*pac::IWDG::ptr() }, setting)
    }
}

pub use super::timing::{ClockTree, HSI_TREE};

/// Sets the clock tree up with every wait bounded (RM0090 §6.3; the
/// stm32f4xx-hal's `freeze` waits without a limit and asserts): the 8 MHz
/// crystal if it starts, else the HSI, into the PLL (VCO input 1 MHz,
/// ×336, ÷2: 168 MHz; ÷7: 48 MHz), five flash wait states with the
/// prefetch and caches on, APB1 ÷4 (42 MHz, timers 84 MHz), APB2 ÷2
/// (84 MHz). A PLL that does not lock leaves the chip on the HSI
/// ([`HSI_TREE`]).
pub fn setup_clocks() -> ClockTree {
    // SAFETY: RCC and FLASH's ACR, configured once from `main` before any
    // peripheral runs; values as RM0090 §6.3 and §3.5.1 define them.
    let rcc = unsafe { &*pac::RCC::ptr() };
    let flash = unsafe { &*pac::FLASH::ptr() };
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    let on_crystal = poll(|| rcc.cr().read().hserdy().bit_is_set());
    if !on_crystal {
        rcc.cr().modify(|_, w| w.hseon().clear_bit());
    }
    // VCO input 1 MHz: the 8 MHz crystal ÷8 or the 16 MHz HSI ÷16.
    let pllm = if on_crystal { 8 } else { 16 };
    // SAFETY: PLLM 8 or 16 (2 … 63), PLLN 336 (50 … 432), PLLQ 7 (2 … 15).
    rcc.pllcfgr().modify(|_, w| unsafe {
        let w = w.pllm().bits(pllm).plln().bits(336).pllp().div2().pllq().bits(7);
        if on_crystal { w.pllsrc().hse() } else { w.pllsrc().hsi() }
    });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    if !poll(|| rcc.cr().read().pllrdy().bit_is_set()) {
        rcc.cr().modify(|_, w| w.pllon().clear_bit());
        return HSI_TREE;
    }
    // Five wait states for 168 MHz at 2.7–3.6 V, before the switch.
    if !registers::write_flash_wait_states(flash) {
        return HSI_TREE;
    }
    rcc.cfgr()
        .modify(|_, w| w.hpre().div1().ppre1().div4().ppre2().div2().sw().pll());
    if !poll(|| rcc.cfgr().read().sws().is_pll()) {
        // Still on the HSI: the prescalers back to ÷1 and SW to the HSI, so
        // that the tree is the one the dividers are known for (APB2 at
        // 4 MHz would leave the UART 3.5 % slow).
        rcc.cfgr()
            .modify(|_, w| w.hpre().div1().ppre1().div1().ppre2().div1().sw().hsi());
        return HSI_TREE;
    }
    super::timing::pll_tree(on_crystal)
}

/// Sets SPI1's clock divider for `tree` (the HAL computed one for the
/// reset clocks it believes in): at most the front end's `max_hz`.
pub fn set_spi1_divider(tree: &ClockTree, max_hz: u32) {
    // SAFETY: SPI1's CR1, disabled while BR changes (`registers`).
    registers::write_spi_divider(unsafe { &*pac::SPI1::ptr() }, tree, max_hz);
}

/// Sets USART1's baud rate for `tree` (16× oversampling, [`super::timing::usart_brr`]).
pub fn set_usart1_baud(tree: &ClockTree, baud: u32) {
    // SAFETY: USART1's CR1 and BRR, the UART disabled while BRR changes (`registers`).
    registers::write_usart_baud(unsafe { &*pac::USART1::ptr() }, tree, baud);
}

/// Enables USART1's transmit-empty interrupt (TXEIE) from the main loop:
/// a read-modify-write of CR1 the USART1 handler cannot interleave with
/// (interrupts masked for its three instructions).
pub fn usart1_listen_tx() {
    // SAFETY: CR1's TXEIE alone changes; the handler only ever clears it.
    let usart = unsafe { &*pac::USART1::ptr() };
    cortex_m::interrupt::free(|_| usart.cr1().modify(|_, w| w.txeie().set_bit()));
}

/// I2C1 (RM0090 §27) with SCL on PB6 and SDA on PB7 (AF4, open drain).
#[derive(Debug)]
pub struct I2c1Regs {
    /// APB1 clock, MHz (2 … 42).
    pub pclk1_mhz: u16,
}

impl I2c1Regs {
    fn i2c() -> &'static pac::i2c1::RegisterBlock {
        // SAFETY: I2C1 is owned by this driver alone (the HAL's I2C is not built).
        unsafe { &*pac::I2C1::ptr() }
    }
    fn gpiob() -> &'static pac::gpioa::RegisterBlock {
        // SAFETY: only PB6/PB7's bits are touched, with read-modify-writes
        // from the main loop (no handler touches GPIOB's mode registers).
        unsafe { &*pac::GPIOB::ptr().cast::<pac::gpioa::RegisterBlock>() }
    }
}

impl I2cRegisters for I2c1Regs {
    fn sr1(&mut self) -> u16 {
        Self::i2c().sr1().read().bits()
    }
    fn sr2(&mut self) -> u16 {
        Self::i2c().sr2().read().bits()
    }
    fn cr1(&mut self) -> u16 {
        Self::i2c().cr1().read().bits()
    }
    fn set_cr1(&mut self, value: u16) {
        // SAFETY: CR1's bits as RM0090 §27.6.1 defines them.
        Self::i2c().cr1().write(|w| unsafe { w.bits(value) });
    }
    fn clear_sr1(&mut self, bits: u16) {
        // SAFETY: SR1's flags clear on a written 0 (rc_w0); ones leave the others.
        Self::i2c().sr1().write(|w| unsafe { w.bits(!bits) });
    }
    fn write_dr(&mut self, byte: u8) {
        // SAFETY: a data byte.
        Self::i2c().dr().write(|w| unsafe { w.bits(u16::from(byte)) });
    }
    fn read_dr(&mut self) -> u8 {
        Self::i2c().dr().read().bits() as u8
    }
    #[inline(never)]
    fn reset(&mut self) {
        // SAFETY: RCC's I2C1 reset bit, pulsed; then I2C1's own registers.
        let rcc = unsafe { &*pac::RCC::ptr() };
        rcc.apb1rstr().modify(|_, w| w.i2c1rst().set_bit());
        rcc.apb1rstr().modify(|_, w| w.i2c1rst().clear_bit());
        // Fast mode, at most 400 kHz, duty 2:1, rise time 300 ns.
        registers::write_i2c_fast_mode(Self::i2c(), self.pclk1_mhz);
        I2C_RECOVERIES.fetch_add(1, Ordering::Relaxed);
    }
    fn lines_as_gpio(&mut self, gpio: bool) {
        // PB6 and PB7 as outputs (open drain, as OTYPER already says) or
        // back to their alternate function.
        Self::gpiob().moder().modify(|_, w| {
            if gpio {
                w.moder6().output().moder7().output()
            } else {
                w.moder6().alternate().moder7().alternate()
            }
        });
    }
    fn set_scl(&mut self, high: bool) {
        // BSRR sets or resets PB6 alone.
        Self::gpiob()
            .bsrr()
            .write(|w| if high { w.bs6().set_bit() } else { w.br6().set_bit() });
    }
    fn set_sda(&mut self, high: bool) {
        // BSRR sets or resets PB7 alone.
        Self::gpiob()
            .bsrr()
            .write(|w| if high { w.bs7().set_bit() } else { w.br7().set_bit() });
    }
    fn sda_is_high(&mut self) -> bool {
        Self::gpiob().idr().read().idr7().bit_is_set()
    }
}

/// The flash controller (RM0090 §3.9) and the model slots, memory-mapped.
#[derive(Debug)]
pub struct FlashRegs;

impl FlashRegs {
    fn flash() -> &'static pac::flash::RegisterBlock {
        // SAFETY: the flash controller is owned by this driver alone.
        unsafe { &*pac::FLASH::ptr() }
    }
}

/// Where flash is mapped (RM0090 §2.3: main memory at 0x0800_0000).
const FLASH_BASE: u32 = 0x0800_0000;

/// MODEL_A and MODEL_B (memory.x) as offsets from the start of flash:
/// sectors 10 and 11, the only words [`FlashRegs`] programs or maps.
pub const MODEL_SLOTS: SlotLayout = SlotLayout {
    offsets: [0x000C_0000, 0x000E_0000],
    len: crate::MODEL_SLOT_LEN as u32,
};

impl FlashRegisters for FlashRegs {
    fn sr(&mut self) -> u32 {
        Self::flash().sr().read().bits()
    }
    fn clear_sr(&mut self, bits: u32) {
        // SAFETY: SR's flags clear on a written 1 (rc_w1).
        Self::flash().sr().write(|w| unsafe { w.bits(bits) });
    }
    fn cr(&mut self) -> u32 {
        Self::flash().cr().read().bits()
    }
    fn set_cr(&mut self, value: u32) {
        // SAFETY: CR's bits as RM0090 §3.9.7 defines them.
        Self::flash().cr().write(|w| unsafe { w.bits(value) });
    }
    fn write_key(&mut self, key: u32) {
        // SAFETY: KEYR takes the unlock keys.
        Self::flash().keyr().write(|w| unsafe { w.bits(key) });
    }
    fn write_word(&mut self, offset: u32, word: u32) -> bool {
        // Only words inside the model slots are ever programmed.
        if !MODEL_SLOTS.holds_word(offset) {
            return false;
        }
        let address = FLASH_BASE + offset;
        // SAFETY: an aligned word inside a model slot, with PG set (the
        // driver's sequence); the controller flags anything else.
        unsafe { core::ptr::write_volatile(address as *mut u32, word) };
        true
    }
    fn flush_caches(&mut self) {
        // RM0090 §3.5.2: caches off, reset, on again.
        let acr = Self::flash().acr();
        acr.modify(|_, w| w.dcen().clear_bit().icen().clear_bit());
        acr.modify(|_, w| w.dcrst().set_bit().icrst().set_bit());
        acr.modify(|_, w| w.dcrst().clear_bit().icrst().clear_bit());
        acr.modify(|_, w| w.dcen().set_bit().icen().set_bit());
    }
    fn mapped(&self, offset: u32, len: usize) -> Option<&[u8]> {
        // Only the model slots are read (the linker's MODEL_A and MODEL_B).
        let slots = [crate::board::model_slot_a(), crate::board::model_slot_b()];
        MODEL_SLOTS.offsets.iter().zip(slots).find_map(|(start, slot)| {
            let from = offset.checked_sub(*start)? as usize;
            slot.get(from..from.checked_add(len)?)
        })
    }
}
