//! `trainer report`: plots and a written summary of a model on runs.

use std::io::Write;
use std::path::PathBuf;

use trainer::blobfile::read_model_file;
use trainer::text;

use super::common::{AllowUncompensated, ForceArg, stdout};
use super::model_arg::ModelArg;

/// Plots and a written summary of a model on runs, for people who would rather look.
///
/// Writes into DIR, as SVG and PNG: per run the raw and compensated rate − reference
/// (10-s means) with the loop temperature, the bias (10-s means) against the loop
/// temperature with the model overlaid and the residual, and the overlapping Allan
/// deviation before and after on log-log axes; the model's bias over T and a steady
/// ramp ΔT. Plus report.json (every figure of `trainer eval --json`) and report.md.
/// A multi-axis model on multi-axis runs: the same per axis, in DIR/axis-x, DIR/axis-y, DIR/axis-z.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer report --model model.bin check.csv -o report/")]
pub struct Args {
    #[command(flatten)]
    model: ModelArg,
    /// Runs to report on (- reads standard input).
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    runs: Vec<PathBuf>,
    /// Directory to write into (created if missing).
    #[arg(short, long, value_name = "DIR", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Runs `trainer report`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let (file, _) = read_model_file(&a.model.path)?;
    let axes = file.axes();
    if axes.is_empty() {
        let model = file.model(None).ok_or_else(|| anyhow::anyhow!("the model file holds no model"))?;
        let files = trainer::report::write_report(
            model,
            &a.model.path,
            &a.runs,
            &a.output,
            a.force.existing(),
            a.uncompensated.allow_uncompensated,
        )?;
        writeln!(stdout(), "wrote {} files into {}", files.len(), text::path(&a.output))?;
        return Ok(());
    }
    // A multi-axis model: a whole report per axis, in DIR/axis-<axis>.
    for axis in axes {
        // A shared-basis file: the axis's model is the basis with its layer
        // (within the table exponential's error of the shared step).
        let owned = match &file {
            trainer::blobfile::ModelFile::Shared(shared) => Some(
                shared
                    .axis_model(axis)
                    .ok_or_else(|| anyhow::anyhow!("axis {} has no layer", axis.name()))?
                    .map_err(|e| anyhow::anyhow!("axis {}: {e}", axis.name()))?,
            ),
            _ => None,
        };
        let model = owned
            .as_ref()
            .or_else(|| file.model(Some(axis)))
            .ok_or_else(|| anyhow::anyhow!("axis {} has no model", axis.name()))?;
        let dir = a.output.join(format!("axis-{}", axis.name()));
        let files = trainer::report::write_axis_report(
            model,
            &a.model.path,
            &a.runs,
            &dir,
            a.force.existing(),
            a.uncompensated.allow_uncompensated,
            Some(axis),
        )
        .map_err(|e| e.context(format!("axis {}", axis.name())))?;
        writeln!(stdout(), "wrote {} files into {}", files.len(), text::path(&dir))?;
    }
    Ok(())
}
