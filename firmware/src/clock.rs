//! Time for bounded waits: a free-running tick counter and deadlines on it.
//!
//! Every wait on a peripheral in this crate polls against a [`Deadline`]
//! (the board: TIM2 at the timer clock; the host fault scenarios: a
//! simulated clock), so no wait can outlast its limit.

/// A free-running, wrapping tick counter.
pub trait Clock {
    /// The counter now, ticks (wraps; only differences of less than half the range are meaningful).
    fn now_ticks(&mut self) -> u32;
    /// Ticks per microsecond (≥ 1).
    fn ticks_per_us(&self) -> u32;
}

impl<C: Clock> Clock for &mut C {
    fn now_ticks(&mut self) -> u32 {
        C::now_ticks(self)
    }
    fn ticks_per_us(&self) -> u32 {
        C::ticks_per_us(self)
    }
}

/// A point in time a wait must not pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Deadline {
    start_ticks: u32,
    limit_ticks: u32,
}

impl Deadline {
    /// The deadline `limit_us` µs from now.
    pub fn after_us<C: Clock>(clock: &mut C, limit_us: u32) -> Self {
        Deadline {
            start_ticks: clock.now_ticks(),
            limit_ticks: limit_us.saturating_mul(clock.ticks_per_us().max(1)),
        }
    }

    /// Whether the deadline has passed.
    pub fn expired<C: Clock>(&self, clock: &mut C) -> bool {
        clock.now_ticks().wrapping_sub(self.start_ticks) >= self.limit_ticks
    }
}

/// Busy-waits `us` µs on `clock` (bounded by construction).
#[inline(never)]
pub fn delay_us<C: Clock>(clock: &mut C, us: u32) {
    let deadline = Deadline::after_us(clock, us);
    while !deadline.expired(clock) {}
}

/// The unit tests' clock: one tick per read, wrapping like TIM2.
#[cfg(test)]
#[derive(Debug)]
pub(crate) struct CountingClock {
    /// The counter now.
    pub ticks: u32,
    /// Ticks per µs.
    pub ticks_per_us: u32,
}

#[cfg(test)]
impl Clock for CountingClock {
    fn now_ticks(&mut self) -> u32 {
        self.ticks = self.ticks.wrapping_add(1);
        self.ticks
    }
    fn ticks_per_us(&self) -> u32 {
        self.ticks_per_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_deadline_expires_after_its_limit_even_across_the_counter_wrap() {
        let mut clock = CountingClock {
            ticks: u32::MAX - 5,
            ticks_per_us: 2,
        };
        let deadline = Deadline::after_us(&mut clock, 10);
        let mut polls = 0;
        while !deadline.expired(&mut clock) {
            polls += 1;
        }
        assert_eq!(polls, 19, "20 ticks = 10 µs at 2 ticks/µs, one tick per read");
    }
}
