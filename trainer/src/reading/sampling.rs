//! The sample rate of a recorded run, checked: a `# sample_rate_hz` value
//! must be a plausible rate and agree with the time column, and the rate
//! must not change within the run (recorded-run format: "constant apart from
//! small jitter"). A run that breaks these would be compensated as a string
//! of one-sample segments, all warming up; it is refused instead, with the
//! lines concerned and what was expected.

use crate::reading::limits::{MAX_SAMPLE_RATE_HZ, MIN_SAMPLE_RATE_HZ};

/// Consecutive time steps off the nominal period (over twice it, or under
/// half) that mark a change of sample rate rather than a gap or jitter.
pub const CHANGE_STEPS: usize = 10;

/// A number with four significant digits, for messages (`0.01`, `1e-6`).
pub fn sig(x: f64) -> String {
    match format!("{x:.3e}").parse::<f64>() {
        Ok(r) => format!("{r}"),
        Err(_) => format!("{x}"),
    }
}

/// The rate a `# sample_rate_hz` value states, Hz: `Ok(None)` for a value
/// that is not a number (`50 (assumed)`: ignored, as the shared period rule
/// and the firmware replay ignore it), an error for a number that is not a
/// plausible rate (not finite, not positive, outside [`MIN_SAMPLE_RATE_HZ`]
/// … [`MAX_SAMPLE_RATE_HZ`]).
pub fn metadata_rate_hz(value: &str) -> Result<Option<f64>, String> {
    let refused = |why: &str| {
        Err(format!(
            "# sample_rate_hz: {:?} {why}; it must be the gyro sample rate in Hz, {MIN_SAMPLE_RATE_HZ} … {MAX_SAMPLE_RATE_HZ}",
            crate::text::escape_controls(value)
        ))
    };
    match value.parse::<f64>() {
        Err(_) => Ok(None),
        Ok(hz) if !hz.is_finite() => refused("is not finite"),
        Ok(hz) if hz <= 0.0 => refused("is not positive"),
        Ok(hz) if !(MIN_SAMPLE_RATE_HZ..=MAX_SAMPLE_RATE_HZ).contains(&hz) => refused("is out of range"),
        Ok(hz) => Ok(Some(hz)),
    }
}

/// True when a time step of `step_s` is off a nominal period of `period_s`:
/// over twice it (a gap, by the format's rule) or under half of it.
fn is_off(step_s: f64, period_s: f64) -> bool {
    step_s > 2.0 * period_s || step_s < 0.5 * period_s
}

/// Refuses metadata whose period disagrees with the time column: the
/// median of the first steps (`median_step_s`, of rows `first_line` …
/// `last_line`) more than twice the stated period or under half of it.
pub fn check_agreement(
    rate_hz: f64,
    median_step_s: f64,
    steps: usize,
    (first_line, last_line): (usize, usize),
) -> Result<(), String> {
    let period_s = 1.0 / rate_hz;
    if steps == 0 || !is_off(median_step_s, period_s) {
        return Ok(());
    }
    Err(format!(
        "# sample_rate_hz: {rate_hz} states a sample period of {} s, but the time column steps by {} s ({} Hz; the median of the {steps} steps of lines {first_line}–{last_line}); correct or remove the metadata line",
        sig(period_s),
        sig(median_step_s),
        sig(1.0 / median_step_s)
    ))
}

/// Longest sample period a run may have without a `# sample_rate_hz` line
/// stating it, s: a gyro logged slower than once every 5 s is far more
/// likely a time column in milliseconds (a gyro sampled at 200 Hz or slower).
pub const MAX_UNSTATED_PERIOD_S: f64 = 5.0;

/// Refuses a time column whose median step (`median_step_s`, of rows
/// `first_line` … `last_line`) is longer than [`MAX_UNSTATED_PERIOD_S`]
/// when no metadata states that rate: the usual cause is time in
/// milliseconds.
pub fn check_unstated_period(
    median_step_s: f64,
    steps: usize,
    (first_line, last_line): (usize, usize),
) -> Result<(), String> {
    if steps == 0 || median_step_s <= MAX_UNSTATED_PERIOD_S {
        return Ok(());
    }
    Err(format!(
        "column time_s steps by {} s (the median of the {steps} steps of lines {first_line}–{last_line}), one sample every {} s, slower than a gyro is logged without saying so: is time_s in milliseconds? Give it in seconds, or state so slow a rate with a `# sample_rate_hz` line",
        sig(median_step_s),
        sig(median_step_s)
    ))
}

/// The metadata key of a run's time base.
pub const TIME_BASE_KEY: &str = "time_base";

/// The [`TIME_BASE_KEY`] value of a run whose `time_s` counts the unit's
/// samples (`trainer device record`: the frames' sequence numbers at the
/// unit's rate). Its rate cannot change, so a long step there is samples
/// missed (frames lost on the line, frames the reader would refuse, a
/// reset): a gap, never a change of rate, however many come in a row.
pub const COUNTED_TIME_BASE: &str = "sample counter";

/// The metadata line a run with a counted time base carries: what the
/// recorder writes and the reader recognises ([`is_counted_time_base`]),
/// so the two agree by construction.
pub fn counted_time_base_line() -> String {
    format!("# {TIME_BASE_KEY}: {COUNTED_TIME_BASE}")
}

/// Whether the metadata `key: value` states a counted time base.
pub fn is_counted_time_base(key: &str, value: &str) -> bool {
    key == TIME_BASE_KEY && value == COUNTED_TIME_BASE
}

/// Where the nominal period came from, for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PeriodSource {
    /// `# sample_rate_hz`.
    Metadata,
    /// The median of the first time steps.
    Median,
}

/// Watches a run's time steps for a change of sample rate:
/// [`CHANGE_STEPS`] consecutive steps off the nominal period, all longer or
/// all shorter.
#[derive(Clone, Debug)]
pub struct PeriodWatch {
    period_s: f64,
    source: PeriodSource,
    /// Line of the first step of the current streak, its length, the sum of
    /// its steps, and whether they are long ones.
    streak: Option<(usize, usize, f64, bool)>,
    /// The time base counts samples ([`COUNTED_TIME_BASE`]): long steps are gaps.
    counted: bool,
}

impl PeriodWatch {
    /// A watch for a nominal period of `period_s`.
    pub fn new(period_s: f64, source: PeriodSource) -> Self {
        PeriodWatch {
            period_s,
            source,
            streak: None,
            counted: false,
        }
    }

    /// The watch of a run whose time base counts samples
    /// ([`COUNTED_TIME_BASE`]): a step over twice the period is samples
    /// missed, never part of a change of rate; a step under half of it
    /// (which no counter makes) still is.
    pub fn counted(self) -> Self {
        PeriodWatch { counted: true, ..self }
    }

    /// Takes the step `step_s` that ends at line `line`; on a change of rate,
    /// the line where it starts and the message.
    pub fn push(&mut self, step_s: f64, line: usize) -> Result<(), (usize, String)> {
        if !is_off(step_s, self.period_s) {
            self.streak = None;
            return Ok(());
        }
        let longer = step_s > self.period_s;
        if longer && self.counted {
            self.streak = None;
            return Ok(());
        }
        let (start, count, sum, _) = match self.streak {
            Some((start, count, sum, was_longer)) if was_longer == longer => (start, count + 1, sum + step_s, longer),
            _ => (line, 1, step_s, longer),
        };
        self.streak = Some((start, count, sum, longer));
        if count < CHANGE_STEPS {
            return Ok(());
        }
        let mean_s = sum / count as f64;
        let from = match self.source {
            PeriodSource::Metadata => "# sample_rate_hz".to_owned(),
            PeriodSource::Median => format!(
                "the median of its first {} steps",
                rbf_core::record::PERIOD_ESTIMATE_STEPS
            ),
        };
        Err((
            start,
            format!(
                "the sample rate changes here: the {count} time steps from this line on are {} s each ({} Hz), the run's nominal period is {} s ({} Hz, {from}); a run keeps one sample rate, so split the file where it changes",
                sig(mean_s),
                sig(1.0 / mean_s),
                sig(self.period_s),
                sig(1.0 / self.period_s)
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metadata_rates_must_be_plausible_numbers() {
        assert_eq!(metadata_rate_hz("10"), Ok(Some(10.0)));
        assert_eq!(metadata_rate_hz("50 (assumed)"), Ok(None), "not a number: no statement");
        for (value, why) in [
            ("0", "is not positive"),
            ("-5", "is not positive"),
            ("1e-9", "is out of range"),
            ("1e7", "is out of range"),
            ("inf", "is not finite"),
            ("NaN", "is not finite"),
        ] {
            let err = metadata_rate_hz(value).unwrap_err();
            assert!(err.contains(why) && err.contains("0.001 … 1000000"), "{value}: {err}");
        }
    }

    #[test]
    fn metadata_must_agree_with_the_time_column_within_a_factor_two() {
        assert!(check_agreement(1.0, 1.0, 1000, (3, 1003)).is_ok());
        assert!(
            check_agreement(2.0, 1.0, 1000, (3, 1003)).is_ok(),
            "a factor 2 is no gap yet"
        );
        let err = check_agreement(1e6, 1.0, 1000, (3, 1003)).unwrap_err();
        assert!(
            err.contains("states a sample period of 0.000001 s, but the time column steps by 1 s")
                && err.contains("lines 3–1003"),
            "{err}"
        );
        assert!(check_agreement(0.1, 1.0, 1000, (3, 1003)).is_err());
    }

    #[test]
    fn a_counted_time_base_takes_any_run_of_missed_samples_as_gaps() {
        let mut counted = PeriodWatch::new(0.001, PeriodSource::Metadata).counted();
        let mut plain = PeriodWatch::new(0.001, PeriodSource::Metadata);
        // Two frames of three lost for 50 frames: a counter's gaps, else a change to 333 Hz.
        let plain_err = (0..50).find_map(|k| plain.push(0.003, 100 + k).err());
        assert_eq!(plain_err.map(|(line, _)| line), Some(100));
        for k in 0..50 {
            assert!(counted.push(0.003, 100 + k).is_ok(), "step {k}");
        }
        // A counter never steps short: ten in a row are still refused.
        let short = (0..10).find_map(|k| counted.push(0.0001, 200 + k).err());
        assert_eq!(short.map(|(line, _)| line), Some(200));
        assert!(counted_time_base_line().ends_with(&format!("{TIME_BASE_KEY}: {COUNTED_TIME_BASE}")));
    }

    #[test]
    fn a_change_of_rate_is_found_where_it_starts_and_gaps_or_jitter_are_not_one() {
        let mut watch = PeriodWatch::new(0.01, PeriodSource::Median);
        // Jitter and a single gap.
        for (line, step) in [(3, 0.011), (4, 0.009), (5, 5.0), (6, 0.01), (7, 0.0051)] {
            watch.push(step, line).unwrap();
        }
        // Nine long steps, a normal one, then the rate drops to 1 Hz for good.
        for line in 8..17 {
            watch.push(1.0, line).unwrap();
        }
        watch.push(0.01, 17).unwrap();
        let mut err = None;
        for line in 18..40 {
            if let Err(e) = watch.push(1.0, line) {
                err = Some(e);
                break;
            }
        }
        let (line, message) = err.expect("the change is found");
        assert_eq!(line, 18);
        assert!(
            message.contains("are 1 s each (1 Hz), the run's nominal period is 0.01 s (100 Hz"),
            "{message}"
        );
        let mut faster = PeriodWatch::new(1.0, PeriodSource::Metadata);
        let found = (1..=CHANGE_STEPS).map(|l| faster.push(0.01, l)).find(|r| r.is_err());
        assert!(found.is_some(), "a faster rate is a change too");
    }
}
