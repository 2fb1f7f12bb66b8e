//! The `bench` command: cycle counts of the board's own sample steps.
//!
//! Host → gyro: `COBS([CMD_BENCH]) 0x00`. The board then times its next
//! [`BENCH_STEPS`] sample steps (front-end read, thermometer reads when due,
//! the compensation, framing and queueing the output frame) with the
//! Cortex-M DWT cycle counter and answers with the bench report
//! ([`gyro_wire::bench`]: steps, min, mean, max, CPU cycles at the core
//! clock), so a user with a board
//! measures real cycles: flash wait states, bus transfers and interrupts
//! included, which QEMU's instruction counts (`cargo xtask bench-fw`) leave
//! out. The debug image (`board-debug`) logs the same figures over RTT.

use gyro_wire::bench::BenchReport;
use gyro_wire::cobs::cobs_encode;

/// Sample steps one bench command (`gyro_wire::command::CMD_BENCH`) times (one second at 1 kHz).
pub const BENCH_STEPS: u32 = 1000;

/// Cycle counts of timed steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CycleStats {
    /// Steps timed.
    pub steps: u32,
    /// Fewest cycles of a step.
    pub min: u32,
    /// Most cycles of a step.
    pub max: u32,
    /// Cycles of all steps.
    pub total: u64,
}

impl CycleStats {
    /// Adds one step that took `cycles`.
    pub fn record(&mut self, cycles: u32) {
        self.min = if self.steps == 0 { cycles } else { self.min.min(cycles) };
        self.max = self.max.max(cycles);
        self.total = self.total.saturating_add(u64::from(cycles));
        self.steps = self.steps.saturating_add(1);
    }

    /// Mean cycles per step, rounded down (0 before any; u32::MAX past it).
    pub fn mean(&self) -> u32 {
        let steps = self.steps;
        if steps == 0 {
            return 0;
        }
        let (high, low) = ((self.total >> 32) as u32, self.total as u32);
        if high >= steps {
            return u32::MAX;
        }
        // A u64 `/` would link the 64-bit division routine into the board
        // image for this one report.
        if steps <= 0xFFFF {
            // Exact, by schoolbook division in 16-bit digits: each partial
            // dividend fits 32 bits because its remainder is below `steps`.
            let upper = (high << 16) | (low >> 16);
            let lower = ((upper % steps) << 16) | (low & 0xFFFF);
            ((upper / steps) << 16) | (lower / steps)
        } else {
            // Counts no bench reaches: the f32 quotient, rounded down.
            (self.total as f32 / steps as f32) as u32
        }
    }

    /// Encodes the report frame into `out`; the bytes used.
    pub fn encode_report(&self, out: &mut [u8]) -> Option<usize> {
        let report = BenchReport {
            steps: self.steps,
            min: self.min,
            mean: self.mean(),
            max: self.max,
        };
        // Framed here, not by `BenchReport::encode`: compiled inside gyro-wire,
        // that unrolls the COBS loop over the 17 bytes (584 B more flash).
        cobs_encode(&report.to_bytes(), out)
    }
}

/// A bench in progress: which steps to time and what they took.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Bench {
    stats: CycleStats,
    running: bool,
}

impl Bench {
    /// Starts timing (again, from zero).
    pub fn start(&mut self) {
        *self = Bench {
            stats: CycleStats::default(),
            running: true,
        };
    }

    /// Whether steps are being timed.
    pub fn running(&self) -> bool {
        self.running
    }

    /// Adds a timed step; the statistics once [`BENCH_STEPS`] are in (the bench then stops).
    pub fn record(&mut self, cycles: u32) -> Option<CycleStats> {
        if !self.running {
            return None;
        }
        self.stats.record(cycles);
        if self.stats.steps < BENCH_STEPS {
            return None;
        }
        self.running = false;
        Some(self.stats)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_wire::cobs::cobs_decode_in_place;

    #[test]
    fn a_bench_times_its_steps_then_reports_min_mean_max_once() {
        let mut bench = Bench::default();
        assert_eq!(bench.record(5), None, "nothing is timed before the command");
        bench.start();
        let mut report = None;
        for i in 0..BENCH_STEPS {
            report = bench.record(1000 + i % 3);
        }
        let stats = report.expect("a report after BENCH_STEPS steps");
        assert_eq!(
            (stats.steps, stats.min, stats.max, stats.mean()),
            (BENCH_STEPS, 1000, 1002, 1000)
        );
        assert!(!bench.running() && bench.record(1).is_none(), "one report per command");
        let mut out = [0u8; 32];
        let n = stats.encode_report(&mut out).unwrap();
        let frame = &mut out[..n - 1];
        let len = cobs_decode_in_place(frame).unwrap();
        let sent = BenchReport::from_bytes(&frame[..len]).unwrap();
        assert_eq!(
            [sent.steps, sent.min, sent.mean, sent.max],
            [BENCH_STEPS, 1000, 1000, 1002]
        );
    }

    #[test]
    fn the_mean_is_the_total_divided_by_the_steps_rounded_down_or_saturated() {
        let mean = |total: u64, steps: u32| {
            CycleStats {
                steps,
                min: 0,
                max: 0,
                total,
            }
            .mean()
        };
        // Exact against u64 division wherever the quotient fits 32 bits.
        for &(total, steps) in &[
            (0u64, 1u32),
            (2_000_999, 1000),
            (u64::from(u32::MAX), 1),
            ((1u64 << 32) * 999 + 123_456_789, 1000),
            ((1u64 << 32) * 65_534 + u64::from(u32::MAX), 65_535),
            (0xFFFE_FFFF_FFFF, 0xFFFF),
        ] {
            assert_eq!(
                u64::from(mean(total, steps)),
                total / u64::from(steps),
                "{total} / {steps}"
            );
        }
        assert_eq!(mean(5, 0), 0, "no steps");
        assert_eq!(mean(1u64 << 32, 1), u32::MAX, "saturated");
        assert_eq!(mean(3_000_000_000, 100_000), 30_000, "large step counts, through f32");
    }
}
