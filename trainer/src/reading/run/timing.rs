//! The checks on a run's time column: every row later than the one before,
//! the nominal period settled on the first rows (against any stated
//! `# sample_rate_hz`), and every later step watched for a change of rate
//! ([`crate::reading::sampling`]).

use std::collections::VecDeque;

use rbf_core::record::{self, PeriodEstimator};

use super::rows::RawRow;
use crate::reading::sampling::{self, PeriodSource, PeriodWatch};

/// What the time column has shown so far: the last time and, once the
/// period is settled, the watch on the steps.
#[derive(Debug, Default)]
pub(super) struct TimeCheck {
    last_time_s: Option<f64>,
    watch: Option<PeriodWatch>,
}

/// A time-column defect: the line it is reported at and the message.
pub(super) type TimeDefect = (usize, String);

impl TimeCheck {
    /// The time of the last row that passed, s.
    pub(super) fn last_time_s(&self) -> Option<f64> {
        self.last_time_s
    }

    /// Checks the row of `line` at `time_s` (the time column is field
    /// `time_field`, 0-based): later than the one before and, once the
    /// period is settled, at the same rate.
    pub(super) fn step(&mut self, time_s: f64, line: usize, time_field: usize) -> Result<(), TimeDefect> {
        if let Some(last) = self.last_time_s {
            if time_s <= last {
                return Err((
                    line,
                    format!(
                        "column time_s (field {}): {time_s} does not increase (previous row {last})",
                        time_field + 1
                    ),
                ));
            }
            if let Some(watch) = &mut self.watch {
                watch.push(time_s - last, line)?;
            }
        }
        self.last_time_s = Some(time_s);
        Ok(())
    }

    /// Settles the nominal period on the rows read ahead (`estimator`:
    /// primed with the run's metadata), checks every stated rate (line, Hz)
    /// against them, and watches every later step; the nominal period, s.
    /// With `counted_time_base` (a sample counter: long steps are missed
    /// samples) the stated rate is the unit's whatever was lost at the start,
    /// and every long step is a gap, never a change of rate.
    pub(super) fn settle(
        &mut self,
        ahead: &VecDeque<RawRow>,
        metadata_rates: &[(usize, f64)],
        counted_time_base: bool,
        mut estimator: PeriodEstimator,
    ) -> Result<f64, TimeDefect> {
        let mut steps: Vec<f64> = Vec::with_capacity(ahead.len());
        let mut prev: Option<f64> = None;
        for raw in ahead {
            if !estimator.is_complete() {
                estimator.push_time(raw.row.time_s);
            }
            if let Some(p) = prev {
                steps.push(raw.row.time_s - p);
            }
            prev = Some(raw.row.time_s);
        }
        let nominal_period_s = estimator.period_s();
        let count = steps.len();
        let median = record::nominal_period_s(None, &mut steps);
        let lines = (ahead.front().map_or(0, |r| r.line), ahead.back().map_or(0, |r| r.line));
        for &(line, hz) in metadata_rates.iter().filter(|_| !counted_time_base) {
            sampling::check_agreement(hz, median, count, lines).map_err(|m| (line, m))?;
        }
        if metadata_rates.is_empty() {
            sampling::check_unstated_period(median, count, lines).map_err(|m| (lines.0, m))?;
        }
        let source = if metadata_rates.is_empty() {
            PeriodSource::Median
        } else {
            PeriodSource::Metadata
        };
        let mut watch = PeriodWatch::new(nominal_period_s, source);
        if counted_time_base {
            watch = watch.counted();
        }
        let mut prev: Option<f64> = None;
        for raw in ahead {
            if let Some(p) = prev {
                watch.push(raw.row.time_s - p, raw.line)?;
            }
            prev = Some(raw.row.time_s);
        }
        self.watch = Some(watch);
        Ok(nominal_period_s)
    }
}
