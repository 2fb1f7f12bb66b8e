//! `trainer compensate`: apply a model to a run exactly as the firmware does.

use std::path::PathBuf;

use trainer::evaluation::axes::{self, compensate_command};
use trainer::text;

use super::common::{AllowUncompensated, ForceArg, print_and_commit, print_notes};
use super::model_arg::ModelArg;
use trainer::output::Transaction;

/// Compensate a run with a model, exactly as the firmware does.
///
/// Writes `# model: FILE` and `# model_blob_crc32: 0x…` first (the model
/// that compensated the run, named as `trainer device status` names a unit's
/// running model), then the input's metadata lines, header and data rows unchanged (`#`
/// lines between data rows are not part of the format and are dropped, as the
/// firmware replay drops them), each row followed by bias_dph [°/h], rate_comp_dph
/// [°/h] and flags (1 clamped · 2 temperature-sensor fault · 4 no valid model ·
/// 8 warming up · 16 rate invalid); one output row per input row. Rows with
/// temp_fault = 1 are treated as a sensor that does not answer. A multi-axis
/// run (rate_x_dph …) with a multi-axis model gets bias_<axis>_dph,
/// rate_comp_<axis>_dph and flags_<axis> per axis.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer compensate --model model.bin field.csv -o field-compensated.csv")]
pub struct Args {
    #[command(flatten)]
    model: ModelArg,
    /// Run to compensate (- reads standard input).
    #[arg(value_name = "RUN.csv", help_heading = "Data")]
    run: PathBuf,
    /// Compensated run to write.
    #[arg(short, long, value_name = "OUT.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Runs `trainer compensate`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let (c, out) = compensate_command(
        &a.model.path,
        &a.run,
        &a.output,
        a.force.existing(),
        a.uncompensated.acceptance(),
    )?;
    print_notes(axes::gap_notice(&c).as_slice());
    let rows = c.first().map_or(0, |(_, c)| c.rows);
    let flagged = match c.as_slice() {
        [(None, single)] => single.flagged.summary(),
        _ => c
            .iter()
            .map(|(axis, c)| format!("{} {}", axis.map_or("", |a| a.name()), c.flagged.summary()))
            .collect::<Vec<_>>()
            .join("; "),
    };
    let axes: Vec<_> = c.iter().filter_map(|(a, _)| *a).collect();
    let what = if axes.is_empty() {
        String::new()
    } else {
        format!(", axes {}", axes::names(&axes))
    };
    let printed = format!(
        "wrote {} ({rows} rows{what}; flagged: {flagged})\n",
        text::path(&a.output)
    );
    print_and_commit(printed.as_bytes(), false, Transaction::of(out))
}
