//! `trainer blocks`: the training data a fit sees, as CSV.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use rbf_core::FeatureSet;
use trainer::blobfile::read_model;
use trainer::dataset::{Blocks, RunFiles, RunSet};
use trainer::output::{self, Output, Transaction};
use trainer::reading::limits::{MAX_BLOCKS_WRITTEN, check_block_s};
use trainer::{reading::input, text};

use super::common::{ForceArg, input_names, print_and_commit};
use super::values::FeaturesArg;

/// Write the training data a fit sees: block means of the features and the bias target.
///
/// The features are rbf-core's (the firmware's own computation), averaged with
/// the target rate_dph − ref_dph (or minus the run mean) over blocks; warm-up
/// and sensor-fault samples are left out. For comparing other learners on
/// exactly the same data (bench/accuracy).
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer blocks --model model.bin chamber.csv --block-s 10 -o blocks.csv")]
pub struct Args {
    /// Runs to read (- reads standard input).
    ///
    /// Blocks are written in order, with a run column.
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    runs: Vec<PathBuf>,
    /// Block length, s.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0, help_heading = "Data")]
    block_s: f64,
    /// Input set (without --model).
    ///
    /// multiscale (default here; the first-order set), multiscale-second-order (also
    /// for multiscale-validated, which chooses between the two) or paper (T, ΔT, T×ΔT).
    /// lag-bank, the fit's default, is identified from the runs by the fit: give a
    /// fitted lag bank's inputs with --model MODEL.bin.
    #[arg(long, value_enum, default_value_t = FeaturesArg::Multiscale, hide_possible_values = true,
          help_heading = "Model")]
    features: FeaturesArg,
    /// Fastest ΔT filter time constant, s (without --model).
    #[arg(
        long = "dt-window-s",
        alias = "rate-window-s",
        value_name = "SECONDS",
        default_value_t = 60.0,
        help_heading = "Model"
    )]
    dt_window_s: f32,
    /// Coil lag of the second-order set's lagged form, minutes.
    ///
    /// Input 0 becomes the mean coil temperature estimate T − L·ΔT₃ for a coil lag L
    /// (what `trainer fit` reports as `MultiScaleLagged`).
    #[arg(long, value_name = "MINUTES", help_heading = "Model")]
    coil_lag_min: Option<u16>,
    /// The inputs of a fitted model instead of --features.
    ///
    /// Every setting as the blob holds it (set, all ΔT windows, coil lag): how
    /// bench/accuracy gives the Python peers the features the default fit chose.
    #[arg(long, value_name = "MODEL.bin", conflicts_with_all = ["features", "dt_window_s", "coil_lag_min"],
          help_heading = "Model")]
    model: Option<PathBuf>,
    /// CSV to write.
    #[arg(short, long, value_name = "BLOCKS.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Runs `trainer blocks`.
pub fn run(a: Args) -> anyhow::Result<()> {
    check_block_s(a.block_s)?;
    anyhow::ensure!(
        a.dt_window_s.is_finite() && (0.0..=86_400.0).contains(&a.dt_window_s),
        "--dt-window-s must be 0 … 86400 s"
    );
    let inputs: Vec<&Path> = a.runs.iter().map(|p| p.as_path()).chain(a.model.as_deref()).collect();
    input::check_stdin_once(inputs.iter().copied())?;
    let target = output::check_target(&a.output, &inputs, a.force.existing())?;
    let features = match &a.model {
        Some(model) => *read_model(model)?.0.features(),
        None => {
            anyhow::ensure!(
                a.features != FeaturesArg::LagBank,
                "--features lag-bank: a lag bank's filters, coil lags and gain are identified by `trainer fit`; \
                 pass the fitted model with --model MODEL.bin for its inputs"
            );
            let inputs = match a.features {
                // The validated choice's second candidate, which `--coil-lag-min` lags.
                FeaturesArg::MultiscaleValidated => Some(trainer::fit::RbfInputs::MultiscaleSecondOrder),
                features => features.rbf_inputs(),
            };
            let inputs = inputs.ok_or_else(|| {
                anyhow::anyhow!(
                    "--features response-bank: the response bank's weights are identified by `trainer fit`; pass the \
                     fitted model with --model MODEL.bin for its inputs"
                )
            })?;
            let set = match (inputs.feature_set(), a.coil_lag_min) {
                (set, None) => set,
                (FeatureSet::MultiScaleSecondOrder, Some(coil_lag_min)) => {
                    FeatureSet::MultiScaleLagged { coil_lag_min }
                }
                (_, Some(_)) => anyhow::bail!("--coil-lag-min needs --features multiscale-second-order"),
            };
            trainer::fit::rbf::feature_config(set, a.dt_window_s, 1.0)
        }
    };
    // Streamed: one pass per run, every block as asked; memory bounded by
    // MAX_BLOCKS_WRITTEN blocks per run (past it the builder merges them in
    // pairs, which is refused here: the blocks would not be those asked for).
    let blocks = RunFiles::new(&a.runs)
        .with_max_blocks_per_run(MAX_BLOCKS_WRITTEN)
        .block_means(&features, a.block_s)?;
    anyhow::ensure!(
        blocks.doublings == 0,
        "a run holds more than {MAX_BLOCKS_WRITTEN} blocks of {} s; at most {MAX_BLOCKS_WRITTEN} per run are written (the limit): use --block-s {} or longer",
        a.block_s,
        blocks.length_s(a.block_s)
    );
    let mut out = Output::open(target)?;
    write_csv(&mut out, features.set, &blocks).with_context(|| format!("{}: write failed", text::path(&a.output)))?;
    let printed = format!("wrote {} ({} blocks)\n", text::path(&a.output), blocks.len());
    print_and_commit(printed.as_bytes(), false, Transaction::of(out))
}

/// The blocks CSV: a `# features` comment naming the inputs, then
/// `run,x0,…,target_dph` rows.
pub fn write_csv(out: &mut impl Write, set: FeatureSet, blocks: &Blocks) -> std::io::Result<()> {
    let names: Vec<String> = (0..set.dims()).map(|i| format!("x{i}")).collect();
    writeln!(out, "# features: {}", input_names(set).join(", "))?;
    writeln!(out, "run,{},target_dph", names.join(","))?;
    for i in 0..blocks.len() {
        let x: Vec<String> = (0..set.dims()).map(|k| blocks.feature(i, k).to_string()).collect();
        writeln!(out, "{},{},{}", blocks.run[i], x.join(","), blocks.y[i])?;
    }
    Ok(())
}
