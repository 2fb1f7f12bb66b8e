//! The register writes of the board's setup and drivers (`hw`), each over
//! the peripheral's PAC register block it is given: on the MCU the
//! peripheral itself, in the host tests a zeroed block in host memory (a
//! svd2rust `RegisterBlock` is `repr(C)` cells, so it is a valid simulated
//! peripheral), which then holds the words the board writes (RM0090's
//! fields, checked below).

#[cfg(not(target_os = "none"))]
use stm32f4::stm32f405 as pac;
#[cfg(target_os = "none")]
use stm32f4xx_hal::pac;

use super::timing::{self, ClockTree};
use crate::watchdog::IwdgSetting;

/// Register polls a setup wait may take before it gives up (before the
/// clock tree and TIM2 run there is no timer: a count of polls bounds it).
pub const SETUP_POLLS: u32 = 200_000;

/// Polls `done` at most [`SETUP_POLLS`] times; whether it came true.
pub fn poll(mut done: impl FnMut() -> bool) -> bool {
    (0..SETUP_POLLS).any(|_| done())
}

/// Sets a USART's baud rate for `tree`'s APB2 (16× oversampling,
/// [`timing::usart_brr`]), the UART disabled while BRR changes.
pub fn write_usart_baud(usart: &pac::usart1::RegisterBlock, tree: &ClockTree, baud: u32) {
    let (mantissa, fraction) = timing::usart_brr_fields(timing::usart_brr(tree.pclk2_hz, baud));
    usart.cr1().modify(|_, w| w.ue().clear_bit().over8().clear_bit());
    usart
        .brr()
        .write(|w| w.div_mantissa().set(mantissa).div_fraction().set(fraction));
    usart.cr1().modify(|_, w| w.ue().set_bit());
}

/// Sets an SPI's clock divider for `tree`'s APB2: at most `max_hz`
/// (rounded down to a power of two, [`crate::frontend::spi_divider`]),
/// the SPI disabled while BR changes.
pub fn write_spi_divider(spi: &pac::spi1::RegisterBlock, tree: &ClockTree, max_hz: u32) {
    let code = timing::spi_baud_code(crate::frontend::spi_divider(tree.pclk2_hz, max_hz));
    spi.cr1().modify(|_, w| w.spe().clear_bit());
    spi.cr1().modify(|_, w| w.br().set(code).spe().set_bit());
}

/// Sets a freshly reset I2C peripheral up for fast mode at an APB1 clock
/// of `pclk1_mhz` MHz (clamped to 2 … 42): FREQ, TRISE for 300 ns, CCR for
/// at most 400 kHz with duty 2:1 (RM0090 §27.6), then PE.
pub fn write_i2c_fast_mode(i2c: &pac::i2c1::RegisterBlock, pclk1_mhz: u16) {
    let mhz = pclk1_mhz.clamp(2, 42);
    let ccr = timing::i2c_fast_mode_ccr(u32::from(mhz) * 1_000_000);
    // SAFETY: FREQ 2 … 42 (MHz).
    i2c.cr2().write(|w| unsafe { w.freq().bits(mhz as u8) });
    i2c.trise().write(|w| w.trise().set(timing::i2c_fast_mode_trise(mhz)));
    // SAFETY: CCR 1 … 0xFFF (`i2c_fast_mode_ccr` clamps it).
    i2c.ccr()
        .write(|w| unsafe { w.f_s().fast().duty().duty2_1().ccr().bits(ccr) });
    i2c.cr1().write(|w| w.pe().set_bit());
}

/// Feeds the independent watchdog (its reload key).
pub fn feed_iwdg(iwdg: &pac::iwdg::RegisterBlock) {
    iwdg.kr().write(|w| w.key().feed());
}

/// Sets the watchdog's period to `setting` (RM0090 §21.3: PR and RLR take
/// new values only while SR shows no update in progress; the unlock key
/// first), then feeds it; false if an update stayed in progress (the
/// period then is the old one).
pub fn write_iwdg_period(iwdg: &pac::iwdg::RegisterBlock, setting: IwdgSetting) -> bool {
    let idle = || {
        let sr = iwdg.sr().read();
        sr.pvu().bit_is_clear() && sr.rvu().bit_is_clear()
    };
    if !poll(idle) {
        feed_iwdg(iwdg);
        return false;
    }
    iwdg.kr().write(|w| w.key().unlock());
    iwdg.pr().write(|w| w.pr().set(setting.prescaler_code & 0b111));
    iwdg.rlr().write(|w| w.rl().set(setting.reload & 0xFFF));
    let taken = poll(idle);
    feed_iwdg(iwdg);
    taken
}

/// Flash wait states for 168 MHz at 2.7–3.6 V (RM0090 §3.5.1, table 10).
pub const WAIT_STATES_168_MHZ: u8 = 5;

/// Five wait states with the prefetch and both caches on, before the
/// switch to 168 MHz; whether the latency took (read back).
pub fn write_flash_wait_states(flash: &pac::flash::RegisterBlock) -> bool {
    flash.acr().modify(|_, w| {
        w.latency()
            .set(WAIT_STATES_168_MHZ)
            .prften()
            .set_bit()
            .icen()
            .set_bit()
            .dcen()
            .set_bit()
    });
    flash.acr().read().latency().bits() == WAIT_STATES_168_MHZ
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::watchdog::{install_setting, running_setting};

    /// The 32-bit word at byte `offset` of a simulated peripheral (for the
    /// write-only registers, which the PAC gives no read for).
    fn word<T>(block: &T, offset: usize) -> u32 {
        assert!(offset + 4 <= core::mem::size_of::<T>());
        // SAFETY: an aligned word inside the block (registers are words).
        unsafe { core::ptr::from_ref(block).cast::<u32>().add(offset / 4).read_volatile() }
    }

    /// A peripheral in host memory, every register 0.
    fn zeroed<T>() -> Box<T> {
        // SAFETY: a PAC register block is `repr(C)` cells of integers, for
        // which all-zero bits are a valid value.
        Box::new(unsafe { core::mem::zeroed() })
    }

    #[test]
    fn usart1_brr_is_rm0090s_for_921_600_bd_on_every_tree_and_the_uart_ends_enabled() {
        for (tree, brr) in [(timing::pll_tree(true), 0x5B), (timing::HSI_TREE, 0x11)] {
            let usart = zeroed::<pac::usart1::RegisterBlock>();
            write_usart_baud(&usart, &tree, 921_600);
            // 84 MHz: USARTDIV 5.6875 (mantissa 5, fraction 11); 16 MHz: 17.36 → 17.
            assert_eq!(usart.brr().read().bits(), brr, "{tree:?}");
            let cr1 = usart.cr1().read();
            assert!(cr1.ue().bit_is_set() && cr1.over8().bit_is_clear());
        }
    }

    #[test]
    fn spi1_runs_at_5_25_mhz_on_the_pll_and_8_mhz_on_the_hsi_never_over_10() {
        for (tree, br) in [(timing::pll_tree(true), 3), (timing::HSI_TREE, 0)] {
            let spi = zeroed::<pac::spi1::RegisterBlock>();
            write_spi_divider(&spi, &tree, 10_000_000);
            let cr1 = spi.cr1().read();
            assert_eq!(cr1.br().bits(), br, "{tree:?}");
            assert!(cr1.spe().bit_is_set());
            assert!(tree.pclk2_hz >> (br + 1) <= 10_000_000);
        }
    }

    #[test]
    fn i2c1_fast_mode_registers_are_rm0090s_at_42_and_16_mhz() {
        // (MHz, CCR, TRISE): SCL = PCLK1 / (3 CCR) ≤ 400 kHz; TRISE = 300 ns / t_PCLK1 + 1.
        for (mhz, ccr, trise) in [(42u16, 35u16, 13u8), (16, 14, 5)] {
            let i2c = zeroed::<pac::i2c1::RegisterBlock>();
            write_i2c_fast_mode(&i2c, mhz);
            assert_eq!(i2c.cr2().read().freq().bits(), mhz as u8);
            assert_eq!(i2c.trise().read().trise().bits(), trise);
            let r = i2c.ccr().read();
            assert!(r.f_s().is_fast() && r.duty().is_duty2_1(), "fast mode, duty 2:1");
            assert_eq!(r.ccr().bits(), ccr);
            assert!(u32::from(mhz) * 1_000_000 / (3 * u32::from(ccr)) <= 400_000);
            assert!(i2c.cr1().read().pe().bit_is_set());
        }
    }

    #[test]
    fn the_watchdog_takes_its_period_after_the_unlock_key_and_is_fed_last() {
        for setting in [running_setting(), install_setting()] {
            let iwdg = zeroed::<pac::iwdg::RegisterBlock>();
            assert!(write_iwdg_period(&iwdg, setting));
            assert_eq!(iwdg.pr().read().pr().bits(), setting.prescaler_code);
            assert_eq!(iwdg.rlr().read().rl().bits(), setting.reload);
            assert_eq!(word(&*iwdg, 0x00), 0xAAAA, "the feed key last (KR)");
        }
    }

    #[test]
    fn a_watchdog_update_stuck_in_progress_is_reported_and_the_dog_still_fed() {
        let mut iwdg = zeroed::<pac::iwdg::RegisterBlock>();
        // SAFETY: PVU (SR bit 0, offset 0x0C) set by hand, as the hardware
        // would while a prescaler update is in progress; SR is read-only to software.
        unsafe { core::ptr::from_mut(&mut *iwdg).cast::<u32>().add(3).write_volatile(1) };
        assert!(!write_iwdg_period(&iwdg, install_setting()));
        assert_eq!(iwdg.pr().read().pr().bits(), 0, "PR written while busy");
        assert_eq!(word(&*iwdg, 0x00), 0xAAAA, "fed all the same (KR)");
    }

    #[test]
    fn flash_runs_five_wait_states_with_prefetch_and_caches_for_168_mhz() {
        let flash = zeroed::<pac::flash::RegisterBlock>();
        assert!(write_flash_wait_states(&flash));
        // LATENCY 5, PRFTEN (bit 8), ICEN (9), DCEN (10).
        assert_eq!(flash.acr().read().bits(), 0x705);
    }
}
