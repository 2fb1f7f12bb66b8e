//! Why a run gave nothing usable, in the user's terms: when no sample could
//! be compensated or trained on, the message names the cause found in the
//! rows (temperatures outside the sensor's range, with a units hint; a
//! sensor fault on every row; a gap at every step; a rate that never
//! varies) instead of only the flag counts. A run that was usable but has
//! gaps gets a notice naming them ([`RunDiagnosis::gap_notice`]).

use std::path::{Path, PathBuf};

use rbf_core::CompensatorConfig;
use rbf_core::axis::Axis;
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::record::{self as record, Columns, Row, column};
use rbf_core::thermometer::ThermometerSet;

use crate::reading::plausible::Plausibility;
use crate::reading::run::RunReader;
use crate::reading::run::rows::RunError;
use crate::reading::sampling::sig;
use crate::text;

/// Least and greatest of a column's values and how many there were.
#[derive(Clone, Copy, Debug)]
struct Spread {
    min: f64,
    max: f64,
    count: usize,
    /// Readings outside the compensator's plausible temperature range.
    implausible: usize,
    first_implausible_line: usize,
}

impl Spread {
    const EMPTY: Spread = Spread {
        min: f64::INFINITY,
        max: f64::NEG_INFINITY,
        count: 0,
        implausible: 0,
        first_implausible_line: 0,
    };

    fn push(&mut self, v: f64) {
        self.min = self.min.min(v);
        self.max = self.max.max(v);
        self.count += 1;
    }
}

/// The gaps in a run's time column: time steps over twice the nominal
/// period, after each of which the compensator's features restart (flag 8
/// on the rows that follow while they warm up). Four numbers, whatever the
/// run's length; `trainer eval --json` gives them per run as `gaps`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Gaps {
    /// Number of gaps.
    pub count: usize,
    /// The longest gap's time step (from the row before it to the row after it), s; 0 without gaps.
    pub longest_s: f64,
    /// The file line (1-based) of the row right after the longest gap.
    pub longest_line: Option<usize>,
    /// The file line (1-based) of the row right after the first gap.
    pub first_line: Option<usize>,
}

impl Gaps {
    /// Takes a gap of `step_s` seconds before the row at `line`; of gaps
    /// equally long, the first is the longest.
    fn push(&mut self, line: usize, step_s: f64) {
        self.count += 1;
        self.first_line.get_or_insert(line);
        if self.longest_line.is_none() || step_s > self.longest_s {
            self.longest_s = step_s;
            self.longest_line = Some(line);
        }
    }
}

/// A run spanning less than this, s, is named as too short when nothing of
/// it was usable (ten minutes: the least a fit takes).
const SHORT_SPAN_S: f64 = 600.0;

/// Facts gathered row by row for [`RunDiagnosis::causes`]; a few numbers per
/// column, whatever the run's length.
#[derive(Clone, Debug)]
pub struct RunDiagnosis {
    path: PathBuf,
    nominal_period_s: f64,
    plausible_c: (f64, f64),
    rows: usize,
    first_time_s: Option<f64>,
    prev_time_s: Option<f64>,
    gaps: Gaps,
    temp_fault_rows: usize,
    temps: [Spread; THERMOMETERS],
    target_dph: Spread,
    /// The header's names of the rate, reference and thermometer columns
    /// read (a multi-axis run's axis: `rate_y_dph`, `ref_y_dph`, `temp_y_c`).
    rate_name: String,
    ref_name: String,
    temp_names: [String; THERMOMETERS],
    plausibility: Plausibility,
}

impl RunDiagnosis {
    /// Nothing seen yet of the run at `path`, sampled every `nominal_period_s`.
    pub fn new(path: &Path, nominal_period_s: f64) -> Self {
        let config = CompensatorConfig::for_nominal_period_s(nominal_period_s);
        RunDiagnosis {
            path: path.to_owned(),
            nominal_period_s,
            plausible_c: (
                f64::from(config.min_plausible_temp_c),
                f64::from(config.max_plausible_temp_c),
            ),
            rows: 0,
            first_time_s: None,
            prev_time_s: None,
            gaps: Gaps::default(),
            temp_fault_rows: 0,
            temps: [Spread::EMPTY; THERMOMETERS],
            target_dph: Spread::EMPTY,
            rate_name: column::RATE_DPH.to_owned(),
            ref_name: column::REF_DPH.to_owned(),
            temp_names: column::THERMOMETERS.map(str::to_owned),
            plausibility: Plausibility::new(column::TEMP_C),
        }
    }

    /// Names the columns in messages as `other` does ([`RunDiagnosis::named_by`]).
    pub fn named_like(mut self, other: &RunDiagnosis) -> Self {
        self.rate_name.clone_from(&other.rate_name);
        self.ref_name.clone_from(&other.ref_name);
        self.temp_names.clone_from(&other.temp_names);
        self.plausibility.set_temp_name(&self.temp_names[LOOP_THERMOMETER]);
        self.plausibility.set_rate_names(&self.rate_name, &self.ref_name);
        self
    }

    /// Names the columns in messages as the header `header_line` does for
    /// `columns` (the columns of one axis of a multi-axis run, say).
    pub fn named_by(mut self, header_line: &str, columns: &Columns) -> Self {
        let names: Vec<&str> = header_line.split(',').map(record::trim_field).collect();
        let name = |i: usize| names.get(i).map(|n| text::escape_controls(n).into_owned());
        if let Some(n) = name(columns.rate_dph) {
            self.rate_name = n;
        }
        if let Some(n) = columns.ref_dph.and_then(name) {
            self.ref_name = n;
        }
        for (slot, index) in self.temp_names.iter_mut().zip(columns.temps) {
            if let Some(n) = index.and_then(name) {
                *slot = n;
            }
        }
        self.plausibility.set_temp_name(&self.temp_names[LOOP_THERMOMETER]);
        self.plausibility.set_rate_names(&self.rate_name, &self.ref_name);
        self
    }

    /// Takes the row at `line`.
    pub fn push(&mut self, line: usize, row: &Row) {
        self.rows += 1;
        if let Some(prev) = self.prev_time_s
            && row.time_s - prev > 2.0 * self.nominal_period_s
        {
            self.gaps.push(line, row.time_s - prev);
        }
        self.prev_time_s = Some(row.time_s);
        self.first_time_s.get_or_insert(row.time_s);
        self.temp_fault_rows += usize::from(row.temp_fault);
        let (lo, hi) = self.plausible_c;
        for (spread, t) in self.temps.iter_mut().zip(row.temps_c) {
            if let Some(t) = t {
                spread.push(t);
                if !(lo..=hi).contains(&t) {
                    if spread.implausible == 0 {
                        spread.first_implausible_line = line;
                    }
                    spread.implausible += 1;
                }
            }
        }
        self.target_dph.push(row.rate_dph - row.ref_dph.unwrap_or(0.0));
        self.plausibility.push(line, row.time_s, row.temps_c[LOOP_THERMOMETER]);
        self.plausibility.push_rate(row.rate_dph, row.ref_dph);
    }

    /// What is implausible about the run as a gyro recording ([`Plausibility::findings`]).
    pub fn implausible(&self) -> Vec<String> {
        self.plausibility.findings(&self.path)
    }

    /// True when the bias target (`rate_dph − ref_dph`) is the same on every
    /// row (within [`crate::fit::MIN_TARGET_SPREAD_DPH`]).
    pub fn target_is_constant(&self) -> bool {
        self.target_dph.count > 0 && self.target_dph.max - self.target_dph.min < crate::fit::MIN_TARGET_SPREAD_DPH
    }

    /// The message for a target that never varies.
    pub fn constant_target(&self) -> String {
        format!(
            "{rate} − {} is {} °/h on every one of its {} rows: no gyro signal to compensate or fit (is {rate} the gyro output?)",
            self.ref_name,
            sig(self.target_dph.min),
            self.rows,
            rate = self.rate_name
        )
    }

    /// The gaps seen in the run's time column so far.
    pub fn gaps(&self) -> Gaps {
        self.gaps
    }

    /// The notice of a run with gaps in its time column: how many, the
    /// longest and the first, each by the file line of the row after it;
    /// `None` for a run without gaps. A run of gaps only is rather a
    /// cause of nothing usable ([`RunDiagnosis::causes`]).
    pub fn gap_notice(&self) -> Option<String> {
        let gaps = &self.gaps;
        let first = gaps.first_line?;
        let longest = gaps.longest_line.unwrap_or(first);
        let name = text::path(&self.path);
        let period = sig(self.nominal_period_s);
        let length = sig(gaps.longest_s);
        Some(if gaps.count == 1 {
            format!(
                "{name}: 1 gap in {TIME} (a time step over twice the nominal period of {period} s): {length} s before line {first}; \
                 the features restart after it, and the rows that follow warm up (flag 8)",
                TIME = column::TIME_S
            )
        } else {
            format!(
                "{name}: {} gaps in {TIME} (time steps over twice the nominal period of {period} s), the longest {length} s \
                 before line {longest}, the first before line {first}; the features restart after each, and the rows \
                 that follow warm up (flag 8)",
                gaps.count,
                TIME = column::TIME_S
            )
        })
    }

    /// What in this run keeps samples from being compensated or trained on,
    /// for `thermometers`; empty when the rows show nothing wrong.
    pub fn causes(&self, thermometers: ThermometerSet) -> Vec<String> {
        let name = text::path(&self.path);
        let mut causes = Vec::new();
        let (lo, hi) = self.plausible_c;
        for (i, spread) in self.temps.iter().enumerate() {
            if !thermometers.contains(i) || spread.implausible == 0 || 2 * spread.implausible < spread.count {
                continue;
            }
            let hint = if spread.min >= 200.0 && spread.max <= 500.0 {
                "; kelvin? temperatures are °C (subtract 273.15)"
            } else if spread.max > 500.0 {
                "; not a temperature in °C"
            } else {
                ""
            };
            causes.push(format!(
                "{name}: {}: {} of {} readings lie outside {lo} … {hi} °C, the range a loop thermometer can read (first at line {}; read {} … {} °C){hint}; such readings count as sensor faults",
                self.temp_names[i],
                spread.implausible,
                spread.count,
                spread.first_implausible_line,
                sig(spread.min),
                sig(spread.max),
            ));
        }
        if self.rows > 0 && self.temp_fault_rows == self.rows {
            causes.push(format!(
                "{name}: temp_fault is 1 on every row: the temperature sensor never answers"
            ));
        }
        if self.rows > 1 && 2 * self.gaps.count >= self.rows - 1 {
            causes.push(format!(
                "{name}: {} of {} time steps are gaps (over twice the nominal period of {} s); each gap restarts the features",
                self.gaps.count,
                self.rows - 1,
                sig(self.nominal_period_s)
            ));
        }
        if self.target_is_constant() {
            causes.push(format!("{name}: {}", self.constant_target()));
        }
        let span_s = self
            .prev_time_s
            .zip(self.first_time_s)
            .map_or(0.0, |(last, first)| last - first);
        // The explanation of last resort: a run too short for anything else to show.
        if causes.is_empty() && self.rows > 1 && span_s < SHORT_SPAN_S {
            causes.push(format!(
                "{name}: its {} rows span only {} s ({} Hz), too short for the features to warm up: is time_s in seconds (not hours or minutes)?",
                self.rows,
                sig(span_s),
                sig(1.0 / self.nominal_period_s)
            ));
        }
        causes
    }
}

/// Reads the run at `path` once and diagnoses it ([`RunDiagnosis`]).
pub fn diagnose_file(path: &Path) -> Result<RunDiagnosis, RunError> {
    let mut reader = RunReader::open(path)?;
    let mut diagnosis = RunDiagnosis::new(path, reader.nominal_period_s());
    while let Some((line, row)) = reader.next_parsed()? {
        diagnosis.push(line, &row);
    }
    Ok(diagnosis)
}

/// `error` with the causes found in the runs at `paths` (for
/// `thermometers`) appended, when there are any: for a fit refused for lack of
/// usable data. Runs that cannot be read add nothing (their error was
/// reported first).
pub fn with_causes(error: anyhow::Error, paths: &[PathBuf], thermometers: ThermometerSet) -> anyhow::Error {
    let causes: Vec<String> = paths
        .iter()
        .filter_map(|p| diagnose_file(p).ok())
        .flat_map(|d| d.causes(thermometers))
        .collect();
    if causes.is_empty() {
        error
    } else {
        let error = error.to_string();
        let stop = if error.ends_with('.') { "" } else { "." };
        anyhow::anyhow!("{error}{stop} Why: {}", causes.join("; "))
    }
}

/// What [`run_findings`] found in a fit's runs.
#[derive(Clone, Debug, Default)]
pub struct RunFindings {
    /// What is implausible about the runs as gyro recordings ([`RunDiagnosis::implausible`]).
    pub implausible: Vec<String>,
    /// The notices of runs with gaps ([`RunDiagnosis::gap_notice`]), one per run.
    pub gap_notices: Vec<String>,
}

/// What is implausible about each run of `paths` as a gyro recording
/// ([`RunDiagnosis::implausible`]) and which have gaps
/// ([`RunDiagnosis::gap_notice`]), each read through once: the checks
/// `eval` and `compensate` make as they go, for the runs a fit reads in
/// blocks. `axis`: the axis of multi-axis runs to read (`None`: single-axis
/// runs); its findings name it.
pub fn run_findings(paths: &[PathBuf], axis: Option<Axis>) -> Result<RunFindings, RunError> {
    let mut found = RunFindings::default();
    for path in paths {
        let mut reader = RunReader::open(path)?;
        if let Some(axis) = axis {
            reader.select_axis(axis)?;
        }
        let mut diagnosis =
            RunDiagnosis::new(path, reader.nominal_period_s()).named_by(reader.header().line(), reader.columns());
        while let Some((line, row)) = reader.next_parsed()? {
            diagnosis.push(line, &row);
        }
        let on_axis = |finding: String| match axis {
            Some(axis) => format!("axis {}: {finding}", axis.name()),
            None => finding,
        };
        found
            .implausible
            .extend(diagnosis.implausible().into_iter().map(on_axis));
        found.gap_notices.extend(diagnosis.gap_notice());
    }
    Ok(found)
}

/// For each run at `paths` that spans less than `min_span_s` seconds, a
/// sentence naming it (`role`: how the command uses it, e.g. "--validate"),
/// its span and its rows: a run too short to validate is named, rather than
/// the training runs blamed. Runs that cannot be read add nothing.
pub fn short_runs(paths: &[PathBuf], role: &str, min_span_s: f64) -> Vec<String> {
    let mut found = Vec::new();
    for path in paths {
        let Ok(mut reader) = RunReader::open(path) else {
            continue;
        };
        let (mut first, mut last, mut rows) = (None, 0.0, 0usize);
        while let Ok(Some((_, row))) = reader.next_parsed() {
            first.get_or_insert(row.time_s);
            last = row.time_s;
            rows += 1;
        }
        let span_s = first.map_or(0.0, |f| last - f);
        if span_s < min_span_s {
            found.push(format!(
                "{}: the {role} run spans only {} s ({rows} rows); a run needs at least {min_span_s} s",
                text::path(path),
                sig(span_s)
            ));
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(time_s: f64, rate_dph: f64, temp_c: f64) -> Row {
        let mut temps_c = [None; THERMOMETERS];
        temps_c[rbf_core::features::LOOP_THERMOMETER] = Some(temp_c);
        Row {
            time_s,
            rate_dph,
            temps_c,
            ref_dph: None,
            temp_fault: false,
        }
    }

    fn diagnose(rows: impl Iterator<Item = Row>) -> Vec<String> {
        let mut d = RunDiagnosis::new(Path::new("run.csv"), 1.0);
        for (i, r) in rows.enumerate() {
            d.push(i + 3, &r);
        }
        d.causes(ThermometerSet::ALL)
    }

    #[test]
    fn kelvin_and_absurd_temperatures_are_named_with_a_units_hint() {
        let kelvin = diagnose((0..100).map(|i| row(i as f64, 0.1 * i as f64, 293.15 + 0.1 * i as f64)));
        assert_eq!(kelvin.len(), 1, "{kelvin:?}");
        assert!(
            kelvin[0].contains("temp_c: 100 of 100 readings lie outside -60 … 160 °C")
                && kelvin[0].contains("first at line 3")
                && kelvin[0].contains("kelvin?"),
            "{}",
            kelvin[0]
        );
        let hot = diagnose((0..10).map(|i| row(i as f64, i as f64, 10_000.0)));
        assert!(hot[0].contains("not a temperature in °C"), "{hot:?}");
        let cold = diagnose((0..10).map(|i| row(i as f64, i as f64, -273.15)));
        assert!(cold[0].contains("read -273.1 … -273.1 °C"), "{cold:?}");
        let fine = diagnose((0..700).map(|i| row(i as f64, i as f64, 25.0)));
        assert!(fine.is_empty(), "{fine:?}");
    }

    #[test]
    fn a_run_too_short_to_warm_up_is_named_when_nothing_else_explains_it() {
        // A 1-Hz run with time_s in hours: 700 rows in 0.19 s.
        let mut d = RunDiagnosis::new(Path::new("run.csv"), 1.0 / 3600.0);
        for i in 0..700 {
            d.push(i + 3, &row(i as f64 / 3600.0, i as f64, 25.0));
        }
        let causes = d.causes(ThermometerSet::ALL);
        assert_eq!(causes.len(), 1, "{causes:?}");
        assert!(
            causes[0].contains("run.csv: its 700 rows span only 0.1942 s (3600 Hz)")
                && causes[0].contains("is time_s in seconds"),
            "{causes:?}"
        );
    }

    #[test]
    fn a_rate_that_never_varies_and_gaps_at_every_step_are_named() {
        let flat = diagnose((0..10).map(|i| row(i as f64, 0.0, 25.0)));
        assert!(
            flat[0].contains("rate_dph − ref_dph is 0 °/h on every one of its 10 rows"),
            "{flat:?}"
        );
        let gaps = diagnose((0..10).map(|i| row(10.0 * i as f64, i as f64, 25.0)));
        assert!(gaps[0].contains("9 of 9 time steps are gaps"), "{gaps:?}");
    }

    #[test]
    fn gaps_are_counted_and_the_first_and_longest_named_by_line() {
        // 1 Hz, rows at lines 3 …: a 4.1-s step before the row at line 103
        // (time 104), a 601-s step before line 203 (time 804), a step of
        // 1.9 s (jitter, no gap) before line 53.
        let times = (0..300).map(|i| match i {
            0..50 => i as f64,
            50..100 => i as f64 + 0.9,
            100..200 => i as f64 + 4.0,
            _ => i as f64 + 604.0,
        });
        let mut d = RunDiagnosis::new(Path::new("run.csv"), 1.0);
        for (i, t) in times.enumerate() {
            d.push(i + 3, &row(t, i as f64, 25.0));
        }
        assert_eq!(
            d.gaps(),
            Gaps {
                count: 2,
                longest_s: 601.0,
                longest_line: Some(203),
                first_line: Some(103),
            }
        );
        assert_eq!(
            d.gap_notice().as_deref(),
            Some(
                "run.csv: 2 gaps in time_s (time steps over twice the nominal period of 1 s), the longest 601 s before \
                 line 203, the first before line 103; the features restart after each, and the rows that follow warm \
                 up (flag 8)"
            )
        );
        assert!(
            d.causes(ThermometerSet::ALL).is_empty(),
            "{:?}",
            d.causes(ThermometerSet::ALL)
        );

        let mut one = RunDiagnosis::new(Path::new("run.csv"), 0.01);
        for (i, t) in [0.0, 0.01, 0.02, 0.5, 0.51].into_iter().enumerate() {
            one.push(i + 2, &row(t, i as f64, 25.0));
        }
        assert_eq!(one.gaps().count, 1);
        assert_eq!(
            one.gap_notice().as_deref(),
            Some(
                "run.csv: 1 gap in time_s (a time step over twice the nominal period of 0.01 s): 0.48 s before line 5; \
                 the features restart after it, and the rows that follow warm up (flag 8)"
            )
        );
    }

    #[test]
    fn a_run_without_gaps_has_no_gap_notice() {
        let mut d = RunDiagnosis::new(Path::new("run.csv"), 1.0);
        for i in 0..700 {
            d.push(i + 3, &row(i as f64 + 0.4 * (i % 2) as f64, i as f64, 25.0));
        }
        assert_eq!(d.gaps(), Gaps::default());
        assert_eq!(d.gap_notice(), None);
        assert_eq!(RunDiagnosis::new(Path::new("run.csv"), 1.0).gap_notice(), None);
    }
}
