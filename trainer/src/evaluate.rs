//! Compensation of whole runs and their before/after accuracy.

use std::io::Write;
use std::path::Path;

use anyhow::Context;
use rbf_core::record;
use rbf_core::{CompensatedSample, Compensator, CompensatorConfig, Flags, Model};
use serde::Serialize;

use crate::allan::{self, AllanDeviation};
use crate::metrics::{cluster_std, improvement_pct, msd};
use crate::output::write_atomically;
use crate::run::{Run, RunReader, gyro_sample, probe_nominal_period_s};

/// How many samples carried each flag.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct FlagCounts {
    /// Flag 1: input clamped to the training range.
    pub input_clamped: usize,
    /// Flag 2: temperature sensor fault, last good value held.
    pub temp_sensor_fault: usize,
    /// Flag 4: no valid model, output uncompensated.
    pub no_valid_model: usize,
    /// Flag 8: features warming up.
    pub warming_up: usize,
    /// Flag 16: rate sample invalid.
    pub rate_invalid: usize,
}

impl FlagCounts {
    fn add(&mut self, flags: Flags) {
        let count = |bit: Flags| usize::from(flags.contains(bit));
        self.input_clamped += count(Flags::INPUT_CLAMPED);
        self.temp_sensor_fault += count(Flags::TEMP_SENSOR_FAULT);
        self.no_valid_model += count(Flags::NO_VALID_MODEL);
        self.warming_up += count(Flags::WARMING_UP);
        self.rate_invalid += count(Flags::RATE_INVALID);
    }
}

/// Before/after accuracy of one run.
#[derive(Clone, Debug, Serialize)]
pub struct RunEvaluation {
    /// The run file.
    pub run: String,
    /// Number of samples (= output rows).
    pub samples: usize,
    /// What the rate was compared with: `ref_dph` or `run mean`.
    pub reference: &'static str,
    /// MSD of the raw rate (IFOG Eq. 24, 1-s means), °²/h².
    pub msd_before_dph2: f64,
    /// MSD of the compensated rate, °²/h².
    pub msd_after_dph2: f64,
    /// MSD improvement, %.
    pub msd_improvement_pct: f64,
    /// Bias STD of 100-s cluster means, raw, °/h.
    pub cluster_std_before_dph: f64,
    /// Bias STD of 100-s cluster means, compensated, °/h.
    pub cluster_std_after_dph: f64,
    /// Cluster-STD improvement, %.
    pub cluster_std_improvement_pct: f64,
    /// Samples per flag.
    pub flagged: FlagCounts,
    /// Overlapping Allan deviation of rate − reference, raw.
    pub allan_before: AllanDeviation,
    /// Overlapping Allan deviation of rate − reference, compensated.
    pub allan_after: AllanDeviation,
}

/// Compensates every sample of `run` (one output per input, always).
pub fn compensate_run(model: Option<&Model>, run: &Run) -> Vec<CompensatedSample> {
    let config = run.compensator_config();
    let mut compensator = Compensator::new();
    run.samples().map(|s| compensator.process(model, &config, &s)).collect()
}

/// Before/after accuracy of `model` on `run`.
pub fn evaluate_run(model: &Model, run: &Run) -> RunEvaluation {
    evaluate_output(run, &compensate_run(Some(model), run))
}

/// Before/after accuracy of `run` given its compensated output `out` (one per sample).
pub fn evaluate_output(run: &Run, out: &[CompensatedSample]) -> RunEvaluation {
    let reference = run.reference_dph();
    let about_mean = run.ref_dph.is_none();
    let before: Vec<f64> = (0..run.len()).map(|i| run.rate_dph[i] - reference.at(i)).collect();
    let after: Vec<f64> = (0..run.len())
        .map(|i| out[i].rate_comp_dph as f64 - reference.at(i))
        .collect();
    let mut flagged = FlagCounts::default();
    out.iter().for_each(|o| flagged.add(o.flags));
    let period = run.nominal_period_s;
    let (msd_before, msd_after) = (
        msd(&run.time_s, &before, period, about_mean),
        msd(&run.time_s, &after, period, about_mean),
    );
    let (std_before, std_after) = (
        cluster_std(&run.time_s, &before, period),
        cluster_std(&run.time_s, &after, period),
    );
    RunEvaluation {
        run: run.path.display().to_string(),
        samples: run.len(),
        reference: if about_mean { "run mean" } else { "ref_dph" },
        msd_before_dph2: msd_before,
        msd_after_dph2: msd_after,
        msd_improvement_pct: improvement_pct(msd_before, msd_after),
        cluster_std_before_dph: std_before,
        cluster_std_after_dph: std_after,
        cluster_std_improvement_pct: improvement_pct(std_before, std_after),
        flagged,
        allan_before: allan::analyse(&before, period),
        allan_after: allan::analyse(&after, period),
    }
}

/// Writes a before/after table, one line per (role, evaluation).
pub fn print_table(out: &mut impl Write, rows: &[(&str, &RunEvaluation)]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<10} {:<28} {:>11} {:>11} {:>7}  {:>11} {:>11} {:>7}",
        "role", "run", "MSD before", "MSD after", "gain", "STD100 bef", "STD100 aft", "gain"
    )?;
    writeln!(
        out,
        "{:<10} {:<28} {:>11} {:>11} {:>7}  {:>11} {:>11} {:>7}",
        "", "", "[°²/h²]", "[°²/h²]", "[%]", "[°/h]", "[°/h]", "[%]"
    )?;
    for (role, e) in rows {
        writeln!(
            out,
            "{:<10} {:<28} {:>11.4e} {:>11.4e} {:>7.1}  {:>11.4e} {:>11.4e} {:>7.1}",
            role,
            table_name(&e.run),
            e.msd_before_dph2,
            e.msd_after_dph2,
            e.msd_improvement_pct,
            e.cluster_std_before_dph,
            e.cluster_std_after_dph,
            e.cluster_std_improvement_pct
        )?;
    }
    Ok(())
}

/// Writes the Allan read-offs (ARW, bias instability), one line per (role, evaluation).
pub fn print_allan_table(out: &mut impl Write, rows: &[(&str, &RunEvaluation)]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<10} {:<28} {:>11} {:>11}  {:>11} {:>11} {:>9}",
        "role", "run", "ARW before", "ARW after", "BI before", "BI after", "BI at τ"
    )?;
    writeln!(
        out,
        "{:<10} {:<28} {:>11} {:>11}  {:>11} {:>11} {:>9}",
        "", "", "[°/√h]", "[°/√h]", "[°/h]", "[°/h]", "[s]"
    )?;
    for (role, e) in rows {
        writeln!(
            out,
            "{:<10} {:<28} {:>11.3e} {:>11.3e}  {:>11.3e} {:>11.3e} {:>9.0}",
            role,
            table_name(&e.run),
            e.allan_before.arw_deg_per_sqrt_h,
            e.allan_after.arw_deg_per_sqrt_h,
            e.allan_before.bias_instability_dph,
            e.allan_after.bias_instability_dph,
            e.allan_after.floor_tau_s
        )?;
    }
    Ok(())
}

/// A run's file name, shortened from the left to fit the table's column.
fn table_name(run: &str) -> String {
    let name = Path::new(run)
        .file_name()
        .map_or(run.to_owned(), |n| n.to_string_lossy().into_owned());
    truncate(&name, 28)
}

fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        format!(
            "…{}",
            s.chars()
                .rev()
                .take(max - 1)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect::<String>()
        )
    }
}

/// Streams `input` through the compensator into `output` (recorded-run format
/// with `bias_dph`, `rate_comp_dph`, `flags` appended); returns the flag counts.
///
/// Input lines are passed through as read; one output row per input row.
pub fn compensate_file(model: Option<&Model>, input: &Path, output: &Path) -> anyhow::Result<(usize, FlagCounts)> {
    let period_s = probe_nominal_period_s(input)?;
    let mut reader = RunReader::open(input)?;
    reader.require_temp()?;
    let config = CompensatorConfig::for_nominal_period_s(period_s);
    let mut compensator = Compensator::new();
    let (mut rows, mut flagged) = (0usize, FlagCounts::default());
    write_atomically(output, |out| {
        let io = |e: std::io::Error| anyhow::Error::new(e).context(format!("{}: write failed", output.display()));
        for line in reader.preamble() {
            writeln!(out, "{line}").map_err(io)?;
        }
        writeln!(out, "{}{}", reader.header_line(), record::COMPENSATED_COLUMNS).map_err(io)?;
        let mut prev_time_s = None;
        while let Some(raw) = reader.next_row()? {
            let sample = gyro_sample(prev_time_s, raw.row.time_s, raw.row.rate_dph, raw.temp_c());
            prev_time_s = Some(raw.row.time_s);
            let o = compensator.process(model, &config, &sample);
            writeln!(
                out,
                "{},{},{},{}",
                raw.text,
                o.bias_dph,
                o.rate_comp_dph,
                o.flags.bits()
            )
            .map_err(io)?;
            flagged.add(o.flags);
            rows += 1;
        }
        Ok(())
    })
    .with_context(|| format!("compensating {}", input.display()))?;
    Ok((rows, flagged))
}
