//! The board's timer arithmetic, host-tested: TIM2's rate in the units the
//! drivers and the pacer take, the SysTick reload, the SPI device's delay,
//! and elapsed ticks and cycles on wrapping 32-bit counters (TIM2, the DWT
//! cycle counter), the clock trees the setup can end in and the dividers
//! for them (I2C1's CCR, USART1's BRR). Pure functions of their arguments; the board
//! (`firmware::board`, on the MCU) calls them with its clock tree.

/// The frequencies the board runs at, Hz.
#[derive(Clone, Copy, Debug)]
pub struct ClockTree {
    /// Core (SYSCLK = HCLK).
    pub sysclk_hz: u32,
    /// APB1 (I2C1).
    pub pclk1_hz: u32,
    /// APB2 (SPI1, USART1).
    pub pclk2_hz: u32,
    /// APB1 timers (TIM2).
    pub timclk1_hz: u32,
    /// The PLL runs from the crystal (false: from the HSI, a dead crystal).
    pub on_crystal: bool,
}

/// After reset the chip runs on the 16 MHz HSI, every bus undivided.
pub const HSI_TREE: ClockTree = ClockTree {
    sysclk_hz: 16_000_000,
    pclk1_hz: 16_000_000,
    pclk2_hz: 16_000_000,
    timclk1_hz: 16_000_000,
    on_crystal: false,
};

/// The tree the clock setup ends in when the PLL runs (168 MHz core,
/// APB1 ÷4: 42 MHz, timers 84 MHz, APB2 ÷2: 84 MHz), from the crystal or,
/// when it did not start, from the HSI.
pub const fn pll_tree(on_crystal: bool) -> ClockTree {
    ClockTree {
        sysclk_hz: 168_000_000,
        pclk1_hz: 42_000_000,
        pclk2_hz: 84_000_000,
        timclk1_hz: 84_000_000,
        on_crystal,
    }
}

/// Every tree the clock setup can leave the board in: the PLL from the
/// crystal or from the HSI, or the HSI alone (the PLL did not lock, or the
/// switch to it did not take and the prescalers were set back to ÷1).
pub const BOARD_TREES: [ClockTree; 3] = [pll_tree(true), pll_tree(false), HSI_TREE];

/// The pacer of the board's samples on TIM2 at `timer_hz`, samples every
/// `period_ticks`, started at `now_ticks`: on the HSI (`tree` not on the
/// crystal) dt comes from the edge count ([`Pacer::timed_by_edge_count`]),
/// so the HSI's error (±1 % or more) stays out of every frame.
pub fn sample_pacer(tree: &ClockTree, timer_hz: u32, period_ticks: u32, now_ticks: u32) -> Pacer {
    let pacer = Pacer::new(timer_hz, period_ticks, now_ticks);
    if tree.on_crystal {
        pacer
    } else {
        pacer.timed_by_edge_count()
    }
}

/// Fastest SCL of I2C fast mode, Hz.
pub const I2C_FAST_MODE_MAX_HZ: u32 = 400_000;

/// CCR of the I2C peripheral in fast mode with duty 2:1 (RM0090 §27.6.8:
/// SCL = PCLK1 / (3 · CCR)) for an APB1 clock of `pclk1_hz`: rounded up,
/// so that SCL never exceeds 400 kHz; 1 … 0xFFF.
pub const fn i2c_fast_mode_ccr(pclk1_hz: u32) -> u16 {
    let ccr = pclk1_hz.div_ceil(3 * I2C_FAST_MODE_MAX_HZ);
    if ccr < 1 {
        1
    } else if ccr > 0xFFF {
        0xFFF
    } else {
        ccr as u16
    }
}

/// USART BRR at 16× oversampling (RM0090 §30.3.4: mantissa · 16 +
/// fraction = PCLK / baud) for `pclk_hz` and `baud`, rounded to nearest;
/// at least 16 (a mantissa of 0 is not allowed).
pub const fn usart_brr(pclk_hz: u32, baud: u32) -> u16 {
    let baud = if baud == 0 { 1 } else { baud };
    let brr = pclk_hz.saturating_add(baud / 2) / baud;
    if brr < 16 {
        16
    } else if brr > 0xFFFF {
        0xFFFF
    } else {
        brr as u16
    }
}

/// I2C TRISE in fast mode (RM0090 §27.6.9: the 300-ns maximum rise time in
/// PCLK1 periods, plus 1) for an APB1 clock of `pclk1_mhz` MHz (2 … 42).
pub const fn i2c_fast_mode_trise(pclk1_mhz: u16) -> u8 {
    let mhz = if pclk1_mhz < 2 {
        2
    } else if pclk1_mhz > 42 {
        42
    } else {
        pclk1_mhz
    };
    (mhz * 300 / 1000 + 1) as u8
}

/// USART BRR split into its DIV_Mantissa (bits 4–15) and DIV_Fraction
/// (bits 0–3) fields, as the PAC's field writers take them.
pub const fn usart_brr_fields(brr: u16) -> (u16, u8) {
    (brr >> 4, (brr & 0xF) as u8)
}

/// SPI CR1's BR code for a clock `divider` (a power of two, 2 … 256:
/// f_PCLK / 2^(BR+1), RM0090 §28.5.1).
pub const fn spi_baud_code(divider: u32) -> u8 {
    (divider.trailing_zeros().saturating_sub(1) & 0b111) as u8
}

/// Ticks per µs of a timer at `timer_hz` (≥ 1: the [`crate::clock::Clock`] contract).
#[inline]
pub const fn ticks_per_us(timer_hz: u32) -> u32 {
    let ticks = timer_hz / 1_000_000;
    if ticks == 0 { 1 } else { ticks }
}

/// Timer ticks per sample at `sample_rate_hz` (the pacer's nominal period).
#[inline]
pub fn sample_period_ticks(timer_hz: u32, sample_rate_hz: f32) -> u32 {
    (timer_hz as f32 / sample_rate_hz) as u32
}

/// SysTick's reload for a wake-up every millisecond at `core_hz` (24 bits at most).
#[inline]
pub const fn systick_reload_1ms(core_hz: u32) -> u32 {
    let reload = (core_hz / 1000).saturating_sub(1);
    if reload > 0x00FF_FFFF { 0x00FF_FFFF } else { reload }
}

/// Core cycles to busy-wait for `ns` ns at `core_hz`: rounded up to whole
/// µs, 32-bit arithmetic (a 64-bit division would link the soft division
/// routine into the image), saturating rather than wrapping.
#[inline]
pub const fn delay_cycles(ns: u32, core_hz: u32) -> u32 {
    (ns / 1000 + 1).saturating_mul(core_hz / 1_000_000)
}

/// Ticks from `start` to `now` on a free-running 32-bit counter that may
/// have wrapped in between (once at most: meaningful below 2^32 ticks).
#[inline]
pub const fn elapsed(start: u32, now: u32) -> u32 {
    now.wrapping_sub(start)
}

use crate::pacing::Pacer;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::{CountingClock, Deadline};

    #[test]
    fn on_every_clock_tree_i2c_stays_at_or_below_400_khz_and_the_uart_within_2_5_percent() {
        for tree in BOARD_TREES {
            let ccr = u32::from(i2c_fast_mode_ccr(tree.pclk1_hz));
            let scl_hz = tree.pclk1_hz / (3 * ccr);
            assert!(
                (300_000..=I2C_FAST_MODE_MAX_HZ).contains(&scl_hz),
                "SCL {scl_hz} Hz on APB1 {} Hz",
                tree.pclk1_hz
            );
            let brr = u32::from(usart_brr(tree.pclk2_hz, 921_600));
            let baud = tree.pclk2_hz as f64 / brr as f64;
            let error = (baud / 921_600.0 - 1.0).abs();
            assert!(error < 0.025, "{baud} Bd on APB2 {} Hz: {error}", tree.pclk2_hz);
        }
        // The HSI tree at 16 MHz: 13.3 rounds up to 14 (381 kHz), not down to 13 (410 kHz).
        assert_eq!(i2c_fast_mode_ccr(16_000_000), 14);
        assert_eq!(i2c_fast_mode_ccr(42_000_000), 35, "exactly 400 kHz");
        assert_eq!(usart_brr(8_000_000, 921_600), 16, "never a mantissa of 0");
    }

    #[test]
    fn on_the_hsi_the_pacer_takes_dt_from_the_edges_and_on_the_crystal_from_the_stamps() {
        let period = sample_period_ticks(16_000_000, 1000.0);
        // TIM2 on an HSI running 1 % fast: the front end's edges come every 16,160 ticks.
        let mut hsi = sample_pacer(&HSI_TREE, 16_000_000, period, 0);
        hsi.take([0], 0);
        let tick = hsi.take([16_160], 16_160).unwrap();
        assert_eq!(
            tick.dt_s.to_bits(),
            1e-3f32.to_bits(),
            "the front end's period, not the HSI's"
        );
        let mut crystal = sample_pacer(&pll_tree(true), 16_000_000, period, 0);
        crystal.take([0], 0);
        let tick = crystal.take([16_160], 16_160).unwrap();
        assert!(
            (tick.dt_s - 1.01e-3).abs() < 1e-7,
            "on the crystal the stamps are the time"
        );
    }

    #[test]
    fn the_register_fields_hw_writes_are_rm0090s() {
        // TRISE: 300 ns at 42 MHz is 12.6 periods (13), at the HSI's 16 MHz 4.8 (5).
        assert_eq!(i2c_fast_mode_trise(42), 13);
        assert_eq!(i2c_fast_mode_trise(16), 5);
        assert_eq!(i2c_fast_mode_trise(0), 1, "clamped to the 2-MHz minimum");
        // BRR: RM0090's table for 84 MHz at 921.6 kBd and 16× oversampling:
        // USARTDIV 5.6875, mantissa 5, fraction 11; on the HSI, 17.36: 17, 6 (rounded).
        assert_eq!(usart_brr_fields(usart_brr(84_000_000, 921_600)), (5, 11));
        assert_eq!(usart_brr_fields(usart_brr(16_000_000, 921_600)), (1, 1));
        // SPI: ÷2 … ÷256 are BR 0 … 7; the board's 84 MHz APB2 and the
        // front end's 10 MHz give ÷16 (BR 3, 5.25 MHz), the HSI ÷2 (8 MHz).
        assert_eq!(
            [2, 4, 8, 16, 32, 64, 128, 256].map(spi_baud_code),
            [0, 1, 2, 3, 4, 5, 6, 7]
        );
        let pll = pll_tree(true);
        assert_eq!(spi_baud_code(crate::frontend::spi_divider(pll.pclk2_hz, 10_000_000)), 3);
        assert_eq!(
            spi_baud_code(crate::frontend::spi_divider(HSI_TREE.pclk2_hz, 10_000_000)),
            0
        );
    }

    #[test]
    fn elapsed_ticks_are_right_across_the_wrap_at_u32_max() {
        assert_eq!(elapsed(u32::MAX, 0), 1);
        assert_eq!(elapsed(u32::MAX - 5, 10), 16);
        assert_eq!(elapsed(10, 10), 0);
        assert_eq!(elapsed(0, u32::MAX), u32::MAX);
        // A DWT count of 1,000 cycles that straddles the wrap.
        assert_eq!(elapsed(u32::MAX - 399, 600), 1000);
    }

    #[test]
    fn the_board_clock_rates_convert_as_the_drivers_expect() {
        // TIM2 at 84 MHz (the crystal), 16 MHz (HSI) and QEMU's 1 GHz.
        assert_eq!(ticks_per_us(84_000_000), 84);
        assert_eq!(ticks_per_us(16_000_000), 16);
        assert_eq!(ticks_per_us(1_000_000_000), 1000);
        assert_eq!(ticks_per_us(999_999), 1, "never 0");
        assert_eq!(sample_period_ticks(84_000_000, 1000.0), 84_000);
        assert_eq!(sample_period_ticks(16_000_000, 1000.0), 16_000);
        assert_eq!(sample_period_ticks(1_000_000_000, 1000.0), 1_000_000);
        assert_eq!(systick_reload_1ms(168_000_000), 167_999);
        assert_eq!(systick_reload_1ms(16_000_000), 15_999);
        assert_eq!(
            systick_reload_1ms(u32::MAX),
            4_294_966,
            "any u32 clock fits SysTick's 24 bits"
        );
        assert_eq!(systick_reload_1ms(0), 0);
        assert_eq!(delay_cycles(0, 168_000_000), 168);
        assert_eq!(delay_cycles(1500, 168_000_000), 336);
        assert_eq!(delay_cycles(u32::MAX, 168_000_000), 721_554_624, "4.3 s in 32 bits");
        assert_eq!(delay_cycles(u32::MAX, u32::MAX), u32::MAX, "saturates, never wraps");
    }

    #[test]
    fn a_deadline_at_the_board_rate_holds_across_the_wrap() {
        // TIM2 as the clock of a deadline: one tick per read, from just below the wrap.
        let mut clock = CountingClock {
            ticks: u32::MAX - 10,
            ticks_per_us: ticks_per_us(84_000_000),
        };
        let deadline = Deadline::after_us(&mut clock, 2);
        let mut polls = 0u32;
        while !deadline.expired(&mut clock) {
            polls += 1;
        }
        assert_eq!(polls, 167, "168 ticks = 2 µs at 84 ticks/µs, one tick per read");
    }

    #[test]
    fn data_ready_stamps_across_the_wrap_step_by_whole_periods() {
        let period = sample_period_ticks(84_000_000, 1000.0);
        let start = u32::MAX - 2 * period - 7;
        let mut pacer = Pacer::new(84_000_000, period, start);
        let mut stamp = start;
        let first = pacer.take([stamp], stamp).map(|t| t.seq);
        assert_eq!(first, Some(0));
        for seq in 1..=5u32 {
            stamp = stamp.wrapping_add(period);
            let tick = pacer.take([stamp], stamp).expect("an edge a period later is a step");
            assert_eq!(tick.seq, seq);
            assert!((tick.dt_s - 1e-3).abs() < 1e-7, "dt {} at seq {seq}", tick.dt_s);
        }
        assert!(stamp < start, "the stamps wrapped at u32::MAX");
        // Two periods lost across the wrap: the gap numbers the step.
        stamp = stamp.wrapping_add(3 * period);
        assert_eq!(pacer.take([stamp], stamp).map(|t| t.seq), Some(8));
        assert_eq!(pacer.counters().glitches, 0);
    }

    #[test]
    fn silence_across_the_wrap_synthesises_a_step() {
        let period = sample_period_ticks(84_000_000, 1000.0);
        let stamp = u32::MAX - period / 2;
        let mut pacer = Pacer::new(84_000_000, period, stamp);
        assert_eq!(pacer.take([stamp], stamp).map(|t| t.seq), Some(0));
        // Nothing for a while after the wrap: a synthesised step follows.
        let tick = (1..20u32)
            .find_map(|n| pacer.take([], stamp.wrapping_add(n * period)))
            .expect("a silent line still steps");
        assert!(tick.synthetic);
        assert!(tick.seq >= 1);
    }
}
