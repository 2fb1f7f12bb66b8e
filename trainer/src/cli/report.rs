//! `trainer report`: plots and a written summary of a model on runs.

use std::io::Write;
use std::path::{Path, PathBuf};

use trainer::blobfile::read_model_file;
use trainer::output::{StagedDir, Transaction};
use trainer::text;

use super::common::{AllowUncompensated, ForceArg, print_and_commit, print_notes};
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
    /// Directory to write (replaced as a whole; see --help).
    ///
    /// Written beside DIR and renamed into place when complete: DIR holds the whole old
    /// report or the whole new one. An existing DIR that is not empty is replaced only
    /// with --force, and only when it holds nothing but a report's files.
    #[arg(short, long, value_name = "DIR", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Runs `trainer report`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let model_path = a.model.path.as_path();
    let inputs = a.model.with_evaluated_runs(&a.runs)?;
    let (_, target) = trainer::report::check_report_targets(&a.runs, &a.output, &inputs, &[], a.force.existing())?;
    let (file, _) = read_model_file(model_path)?;
    // Written into a hidden directory beside DIR, which replaces DIR as a whole at the end.
    let staged = StagedDir::create(target)?;
    let allow = a.uncompensated.acceptance();
    // Which runs trained the model is not known here.
    let runs = trainer::report::ReportRuns {
        paths: &a.runs,
        trained_on: None,
    };
    let mut printed = Vec::new();
    // The runs' gap notices: every axis reads the one time column, so the first axis's.
    let mut notices = Vec::new();
    let axes = file.axes();
    if axes.is_empty() {
        let model = file
            .model(None)
            .ok_or_else(|| anyhow::anyhow!("the model file holds no model"))?;
        let (files, _, gaps) =
            trainer::report::write_report(model, model_path, runs, &staged, Path::new(""), allow, None)?;
        notices = gaps;
        writeln!(printed, "wrote {files} files into {}", text::path(&a.output))?;
    }
    // A multi-axis model: a whole report per axis, in DIR/axis-<axis>.
    let mut summary = Vec::new();
    for axis in axes.iter().copied() {
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
        let sub = PathBuf::from(format!("axis-{}", axis.name()));
        let (files, evaluations, gaps) =
            trainer::report::write_report(model, model_path, runs, &staged, &sub, allow, Some(axis))
                .map_err(|e| e.context(format!("axis {}", axis.name())))?;
        if summary.is_empty() {
            notices = gaps;
        }
        writeln!(printed, "wrote {files} files into {}", text::path(&a.output.join(&sub)))?;
        summary.push((axis, evaluations));
    }
    if !summary.is_empty() {
        let md = trainer::report::axes_summary_markdown(model_path, &summary);
        staged.write(Path::new("report.md"), md.as_bytes())?;
        writeln!(printed, "wrote {}", text::path(&a.output.join("report.md")))?;
    }
    print_notes(&notices);
    let mut transaction = Transaction::new();
    transaction.add_dir(staged);
    print_and_commit(&printed, false, transaction)
}
