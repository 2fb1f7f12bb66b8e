//! `trainer correlate`: which temperatures and gradients explain the bias.

use std::path::{Path, PathBuf};

use clap::builder::RangedU64ValueParser;
use trainer::dataset::gradients::{Selection, candidate_name, correlations, row_block_means, select};
use trainer::output::Existing;
use trainer::reading::input;
use trainer::reading::limits::MAX_BLOCK_SAMPLES;

use super::common::{JsonArg, PAPER_THRESHOLD, SelectArgs, describe_selection, print_json_and_commit, rule_name};
use trainer::output::Transaction;

/// Which temperatures and gradients explain the bias: the RLG paper's input selection.
///
/// Reads the thermometers temp_a … temp_h of multi-point runs (`trainer simulate --multi`
/// writes them), averages every --block-samples rows (the paper: 100), and prints the Pearson
/// correlation with the bias (rate_dph − ref_dph) of each temperature (diagonal) and each
/// gradient T_i − T_j (row i, column j), like the paper's Table 3, marking the inputs selected
/// by --select-threshold (|r| ≥ 0.9 by default) or --select-top N. (`trainer fit --method
/// svr-pso` prints the same table, then by default chooses its thermometers by validation.)
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer correlate multi.csv --select-top 4 --json correlations.json")]
pub struct Args {
    /// Multi-point runs (the same thermometers in each; - reads standard input).
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    runs: Vec<PathBuf>,
    /// Rows averaged per block (the paper's smoothing).
    #[arg(long, value_name = "N", default_value_t = 100, help_heading = "Data",
          value_parser = RangedU64ValueParser::<usize>::new().range(1..=MAX_BLOCK_SAMPLES))]
    block_samples: usize,
    #[command(flatten)]
    select: SelectArgs,
    #[command(flatten)]
    json: JsonArg,
    /// Replace the JSON file if it exists.
    #[arg(long, help_heading = "Output")]
    force: bool,
}

/// Runs `trainer correlate`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let inputs: Vec<&Path> = a.runs.iter().map(|p| p.as_path()).collect();
    input::check_stdin_once(inputs.iter().copied())?;
    let json_out = a.json.sink(&inputs, Existing::from_force(a.force))?;
    let selection = a.select.selection()?.unwrap_or(Selection::Threshold(PAPER_THRESHOLD));
    let blocks = row_block_means(&a.runs, a.block_samples)?;
    anyhow::ensure!(
        blocks.bias.len() >= 3,
        "only {} blocks of {} rows: too few to correlate",
        blocks.bias.len(),
        a.block_samples
    );
    let table = correlations(&blocks);
    let selected = select(&table, selection);
    let names: Vec<String> = selected.iter().map(|&c| candidate_name(&table, c)).collect();
    let json_on_stdout = json_out.is_stdout();
    let mut transaction = Transaction::new();
    let json = json_out.write(
        &serde_json::json!({ "table": table, "selected": selected, "selected_names": names }),
        &mut transaction,
    )?;
    let text = describe_selection(&table, &selected, &rule_name(selection));
    print_json_and_commit(text.as_bytes(), json_on_stdout, json, transaction)
}
