//! `trainer compensate`: apply a model to a run exactly as the firmware does.

use std::io::Write;
use std::path::PathBuf;

use trainer::evaluate::compensate_command;
use trainer::text;

use super::common::{AllowUncompensated, ForceArg, stdout};
use super::model_arg::ModelArg;

/// Compensate a run with a model, exactly as the firmware does.
///
/// Writes the input lines unchanged followed by bias_dph [°/h], rate_comp_dph
/// [°/h] and flags (1 clamped · 2 temperature-sensor fault · 4 no valid model ·
/// 8 warming up · 16 rate invalid); one output row per input row. Rows with
/// temp_fault = 1 are treated as a sensor that does not answer.
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
    let c = compensate_command(
        &a.model.path,
        &a.run,
        &a.output,
        a.force.existing(),
        a.uncompensated.allow_uncompensated,
    )?;
    writeln!(
        stdout(),
        "wrote {} ({} rows; flagged: {})",
        text::path(&a.output),
        c.rows,
        serde_json::to_string(&c.flagged)?
    )?;
    Ok(())
}
