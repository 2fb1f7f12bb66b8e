//! From data-ready timestamps to sample steps: which edges are samples,
//! how many were missed, and what to do when data-ready falls silent.
//!
//! The board's EXTI0 handler stamps each data-ready edge with TIM2 and
//! queues the stamp; the main loop hands every stamp queued since its last
//! pass to [`Pacer::take`], which yields at most one [`Tick`] per pass:
//! - an edge less than half a period after the last accepted one is a
//!   glitch: dropped and counted ([`PacerCounters::glitches`]);
//! - of several queued edges (the loop was stalled) only the newest is a
//!   step; the edge number still advances by the whole periods between
//!   accepted edges, so the edges passed over count as missed samples in
//!   the loop ([`crate::compensation::LoopStats::samples_missed`], flag 32)
//!   and the front end is read once, for its newest sample;
//! - when data-ready stays silent for [`SILENT_PERIODS`] periods (a front
//!   end not yet booted, or a line stuck high after an MCU-only reset) a
//!   step is synthesised at the nominal period: its front-end read fails
//!   or is stale and is flagged, the frame still goes out, and reading
//!   SAMPLE acknowledges a stuck data-ready line.

use crate::watchdog::Watchdog;

/// Periods of silence on data-ready after which steps are synthesised.
pub const SILENT_PERIODS: u32 = 2;

/// One sample step: the data-ready edge number and the time since the previous step, s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tick {
    /// Edge number (whole nominal periods since the first step).
    pub seq: u32,
    /// Time since the previous step, s.
    pub dt_s: f32,
    /// The step was synthesised for a silent data-ready line, not stamped by an edge.
    pub synthetic: bool,
}

/// What the pacer dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PacerCounters {
    /// Edges rejected as glitches (closer than half a period to the last).
    pub glitches: u32,
    /// Edges passed over for a newer sample: queued behind a newer edge, or
    /// a period or more before the step (lost to a full queue).
    pub backlog: u32,
    /// Steps synthesised while data-ready was silent.
    pub synthetic: u32,
}

/// Edge numbering and step pacing over timer stamps.
#[derive(Clone, Debug)]
pub struct Pacer {
    ticks_per_s: f32,
    period_ticks: u32,
    /// Edge number and stamp of the last step; before the first, the start time.
    last: Option<(u32, u32)>,
    start_ticks: u32,
    counters: PacerCounters,
    /// dt from whole periods between edges, not from the stamps ([`Pacer::timed_by_edge_count`]).
    edge_counted_dt: bool,
}

impl Pacer {
    /// A pacer for a timer of `ticks_per_s` and samples every `period_ticks`, started at `now_ticks`.
    pub fn new(ticks_per_s: u32, period_ticks: u32, now_ticks: u32) -> Self {
        Pacer {
            ticks_per_s: ticks_per_s as f32,
            period_ticks: period_ticks.max(2),
            last: None,
            start_ticks: now_ticks,
            counters: PacerCounters::default(),
            edge_counted_dt: false,
        }
    }

    /// The same pacer with every dt taken as whole periods between edges
    /// times the nominal period rather than from the stamps: the front
    /// end's crystal paces the samples, so when the timer runs from an
    /// inaccurate clock (the HSI, ±1 % or worse) its error stays out of dt.
    pub fn timed_by_edge_count(self) -> Self {
        Pacer {
            edge_counted_dt: true,
            ..self
        }
    }

    /// The counters so far.
    pub fn counters(&self) -> PacerCounters {
        self.counters
    }

    fn nominal_dt_s(&self) -> f32 {
        self.period_ticks as f32 / self.ticks_per_s
    }

    /// A step for an edge a period or more before `now_ticks` (its stamp
    /// waited in a queue that then overflowed, or data-ready stayed high
    /// with no further edge) would read a newer sample than its edge's:
    /// the step is moved to the newest whole period before now, the edges
    /// between counted as missed by the loop.
    fn catch_up(&mut self, tick: Tick, now_ticks: u32) -> Tick {
        let Some((seq, stamp)) = self.last else {
            return tick;
        };
        let behind = now_ticks.wrapping_sub(stamp);
        if behind >= u32::MAX / 2 || behind < self.period_ticks {
            return tick;
        }
        let periods = behind / self.period_ticks.max(1);
        self.last = Some((
            seq.wrapping_add(periods),
            stamp.wrapping_add(periods.wrapping_mul(self.period_ticks)),
        ));
        self.counters.backlog = self.counters.backlog.wrapping_add(periods);
        Tick {
            seq: seq.wrapping_add(periods),
            dt_s: tick.dt_s + (periods.wrapping_mul(self.period_ticks)) as f32 / self.ticks_per_s,
            synthetic: false,
        }
    }

    /// Takes the stamps queued since the last call, oldest first, and the
    /// time now; the step to run, if any (see the module docs).
    pub fn take(&mut self, stamps: impl IntoIterator<Item = u32>, now_ticks: u32) -> Option<Tick> {
        let mut newest: Option<Tick> = None;
        for stamp in stamps {
            let tick = match self.last {
                None => Tick {
                    seq: 0,
                    dt_s: self.nominal_dt_s(),
                    synthetic: false,
                },
                Some((seq, last)) => {
                    let ticks = stamp.wrapping_sub(last);
                    if ticks < self.period_ticks / 2 {
                        self.counters.glitches = self.counters.glitches.wrapping_add(1);
                        continue;
                    }
                    // Whole periods since the last accepted edge: ≥ 1 here.
                    let periods = ticks.saturating_add(self.period_ticks / 2) / self.period_ticks.max(1);
                    let dt_s = if self.edge_counted_dt {
                        periods as f32 * self.nominal_dt_s()
                    } else {
                        ticks as f32 / self.ticks_per_s
                    };
                    Tick {
                        seq: seq.wrapping_add(periods),
                        dt_s,
                        synthetic: false,
                    }
                }
            };
            if newest.is_some() {
                self.counters.backlog = self.counters.backlog.wrapping_add(1);
            }
            // dt of a step over several edges spans them all.
            let dt_s = newest.map_or(tick.dt_s, |n| n.dt_s + tick.dt_s);
            newest = Some(Tick { dt_s, ..tick });
            self.last = Some((tick.seq, stamp));
        }
        if let Some(tick) = newest {
            return Some(self.catch_up(tick, now_ticks));
        }
        // Silence: a step at the nominal period after the last one.
        let (seq, since) = match self.last {
            None => (0, self.start_ticks),
            Some((seq, last)) => (seq.wrapping_add(1), last),
        };
        let silent_ticks = now_ticks.wrapping_sub(since);
        if silent_ticks < self.period_ticks.saturating_mul(SILENT_PERIODS) {
            return None;
        }
        // Long silences (a stall) jump to now: the periods between are missed samples.
        let periods = (silent_ticks / self.period_ticks.max(1)).saturating_sub(1).max(1);
        let (seq, stamp) = match self.last {
            None => (0, now_ticks),
            Some(_) => (
                seq.wrapping_add(periods - 1),
                since.wrapping_add(periods.wrapping_mul(self.period_ticks)),
            ),
        };
        self.last = Some((seq, stamp));
        self.counters.synthetic = self.counters.synthetic.wrapping_add(1);
        Some(Tick {
            seq,
            dt_s: periods as f32 * self.nominal_dt_s(),
            synthetic: true,
        })
    }
}

/// One pass of the board's sample service: drains the queued stamps
/// (`next_stamp` until `None`), runs `step` for the tick the pacer makes
/// of them (or of the silence until `now_ticks`) and feeds the watchdog
/// after it. True when a step ran. The watchdog is fed by steps alone, so
/// a loop that stops stepping resets the chip.
pub fn serve_samples<W: Watchdog>(
    pacer: &mut Pacer,
    next_stamp: impl FnMut() -> Option<u32>,
    now_ticks: u32,
    watchdog: &mut W,
    step: impl FnOnce(Tick),
) -> bool {
    match pacer.take(core::iter::from_fn(next_stamp), now_ticks) {
        Some(tick) => {
            step(tick);
            watchdog.feed();
            true
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1 kHz samples on a 1 MHz timer.
    fn pacer() -> Pacer {
        Pacer::new(1_000_000, 1000, 0)
    }

    #[test]
    fn edges_number_by_whole_periods_and_a_glitch_is_dropped() {
        let mut p = pacer();
        assert_eq!(p.take([100], 100).map(|t| t.seq), Some(0));
        assert_eq!(p.take([1100], 1100).map(|t| t.seq), Some(1));
        assert_eq!(p.take([1400], 1400), None, "0.3 periods after the last: a glitch");
        assert_eq!(p.counters().glitches, 1);
        let t = p.take([2110], 2110).unwrap();
        assert_eq!((t.seq, t.synthetic), (2, false));
        assert!((t.dt_s - 1.01e-3).abs() < 1e-6);
    }

    #[test]
    fn timed_by_edge_count_a_timer_off_by_1_5_percent_leaves_dt_at_the_nominal_period() {
        // The timer believes in 1 MHz but runs 1.5 % fast (an HSI at its
        // limit): the front end's edges come every 1015 of its ticks.
        let mut by_stamps = pacer();
        let mut by_edges = pacer().timed_by_edge_count();
        for p in [&mut by_stamps, &mut by_edges] {
            p.take([0], 0);
        }
        let stamped = by_stamps.take([1015], 1015).unwrap();
        let counted = by_edges.take([1015], 1015).unwrap();
        assert!((stamped.dt_s - 1.015e-3).abs() < 1e-7, "stamps carry the timer's error");
        assert_eq!(counted.seq, 1);
        assert_eq!(counted.dt_s.to_bits(), 1e-3f32.to_bits(), "one nominal period, exactly");
        let skipped = by_edges.take([3045], 3045).unwrap();
        assert_eq!(skipped.seq, 3);
        assert!((skipped.dt_s - 2e-3).abs() < 1e-9, "two periods: two nominal periods");
    }

    #[test]
    fn a_backlog_gives_one_step_for_the_newest_edge_the_others_missed() {
        let mut p = pacer();
        p.take([0], 0);
        let t = p.take((1..=15).map(|i| i * 1000), 15_400).unwrap();
        assert_eq!(t.seq, 15, "edges 1..14 are missed samples, counted by the gap");
        assert!((t.dt_s - 0.015).abs() < 1e-6);
        assert_eq!(p.counters().backlog, 14);
    }

    #[test]
    fn an_edge_stamped_long_before_the_step_is_moved_to_the_sample_read_now() {
        // The queue kept edges 1..15; edges up to 200 were lost to it, or a
        // level-triggered line gave none: SAMPLE holds sample 200 now.
        let mut p = pacer();
        p.take([0], 0);
        let t = p.take((1..=15).map(|i| i * 1000), 200_300).unwrap();
        assert_eq!(t.seq, 200);
        assert!((t.dt_s - 0.2).abs() < 1e-6);
        assert_eq!(p.counters().backlog, 14 + 185);
        assert_eq!(p.take([201_000], 201_000).map(|t| t.seq), Some(201));
    }

    #[test]
    fn silence_synthesises_steps_at_the_nominal_period_and_edges_take_over_again() {
        let mut p = pacer();
        assert_eq!(p.take([], 1500), None);
        let first = p.take([], 2000).unwrap();
        assert_eq!((first.seq, first.synthetic), (0, true));
        assert_eq!(p.take([], 3000), None, "one period after: not silent yet");
        assert_eq!(p.take([], 4000).map(|t| t.seq), Some(1));
        // The synthetic step 1 stands for 3000: an edge at 5300 is two periods later.
        let edge = p.take([5300], 5300).unwrap();
        assert_eq!((edge.seq, edge.synthetic), (3, false));
        assert_eq!(p.counters().synthetic, 2);
    }
}
