//! The board's timer arithmetic, host-tested: TIM2's rate in the units the
//! drivers and the pacer take, the SysTick reload, the SPI device's delay,
//! and elapsed ticks and cycles on wrapping 32-bit counters (TIM2, the DWT
//! cycle counter). Pure functions of their arguments; the board
//! (`firmware::board`, on the MCU) calls them with its clock tree.

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::{Clock, Deadline};
    use crate::pacing::Pacer;

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

    /// TIM2 as the clock of a deadline: one tick per read, from just below the wrap.
    struct Tim2(u32);

    impl Clock for Tim2 {
        fn now_ticks(&mut self) -> u32 {
            self.0 = self.0.wrapping_add(1);
            self.0
        }
        fn ticks_per_us(&self) -> u32 {
            ticks_per_us(84_000_000)
        }
    }

    #[test]
    fn a_deadline_at_the_board_rate_holds_across_the_wrap() {
        let mut clock = Tim2(u32::MAX - 10);
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
