//! `trainer eval`: before/after accuracy of a model on runs.

use std::io::Write;
use std::path::PathBuf;

use trainer::blobfile::read_model_file;
use trainer::evaluation::axes::evaluate_files;
use trainer::evaluation::evaluate::RunEvaluation;
use trainer::evaluation::table::{print_allan_table, print_settled_table, print_table};

use super::common::{AllowUncompensated, ForceArg, JsonArg, print_json_and_commit, print_notes};
use super::model_arg::ModelArg;
use trainer::output::Transaction;

/// Before/after accuracy of a model on runs.
///
/// Per run: MSD (IFOG paper Eq. 24) of 1-s means against ref_dph (or about the
/// mean), and the bias STD of 100-s cluster means (RLG paper), before and after
/// compensation, with the improvement in %; then the overlapping Allan
/// deviation (IEEE Std 952) before and after, with angle random walk [°/√h] and
/// bias instability [°/h] read off it (--json has the whole curves); then the
/// settled bias of every plateau where the loop held a temperature for 30 min
/// (a soak test), before and after, and its spread across the plateaus
/// (--json: `settled_spread_dph`, `settled_spread_before_dph`, `plateaus`).
/// A plateau the model reads outside its training range (the `outside`
/// column: share of its window with inputs clamped) is its extrapolation;
/// where there is one, the spread inside the range follows
/// (`settled_spread_in_range_dph`). A multi-axis run gets a row per axis,
/// with its axis's model, in one pass.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer eval --model model.bin check.csv field.csv --json eval.json")]
pub struct Args {
    #[command(flatten)]
    model: ModelArg,
    /// Runs to evaluate (- reads standard input).
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    runs: Vec<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Runs `trainer eval`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let model_path = a.model.path.as_path();
    let inputs = a.model.with_evaluated_runs(&a.runs)?;
    let json_out = a.json.sink(&inputs, a.force.existing())?;
    let (model, _) = read_model_file(model_path)?;
    let (evals, notices) = evaluate_files(&model, model_path, &a.runs, a.uncompensated.acceptance())?;
    print_notes(&notices);
    let json_on_stdout = json_out.is_stdout();
    let mut transaction = Transaction::new();
    let json = json_out.write(&serde_json::to_value(&evals)?, &mut transaction)?;
    let mut text = Vec::new();
    write_tables(&mut text, &evals)?;
    print_json_and_commit(&text, json_on_stdout, json, transaction)
}

/// The accuracy and Allan tables `trainer eval` prints.
pub fn write_tables(out: &mut impl Write, evals: &[RunEvaluation]) -> anyhow::Result<()> {
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|e| ("eval", e)).collect();
    print_table(out, &rows)?;
    writeln!(out, "\nOverlapping Allan deviation (IEEE Std 952) of rate − reference:")?;
    print_allan_table(out, &rows)?;
    writeln!(
        out,
        "\nSettled bias of soak plateaus (mean of rate − reference over the plateau's settled window):"
    )?;
    print_settled_table(out, &rows)?;
    Ok(())
}
