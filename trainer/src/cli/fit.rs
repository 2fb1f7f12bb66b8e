//! `trainer fit`: fit a bias model to recorded runs and write the model blob.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::builder::RangedU64ValueParser;
use rbf_core::features::Probe;
use rbf_core::thermometer::ThermometerSet;
use trainer::blobfile::encode_model;
use trainer::dataset::{RunFiles, RunSet};
use trainer::evaluation::evaluate::{RunEvaluation, RunModels, evaluate_blocks, evaluate_reader, only_axis};
use trainer::evaluation::table::print_table;
use trainer::fit::coverage::InUse;
use trainer::fit::{self, FitOptions};
use trainer::output::{self, Output, StagedDir, Transaction};
use trainer::reading::limits::MAX_FOLDS;
use trainer::reading::plausible;
use trainer::reading::run::RunReader;
use trainer::text;
use trainer::{evaluation::diagnose, reading::input};

use super::common::{ForceArg, JsonArg, JsonSink, SelectArgs, print_and_commit};
use super::values::{FeaturesArg, MethodArg};

mod axes;
pub(super) mod json;
mod summary;

use self::json::{outcome_json, runs_json};
use self::summary::{FitHow, training_loop_range_c, write_summary};

/// Fit a bias model to recorded chamber runs and write the model blob.
///
/// The model's inputs are computed per sample by rbf-core, as the firmware
/// does, then averaged over blocks together with the bias target
/// `rate_dph − ref_dph` (or minus the run mean without ref_dph). The default
/// is the thermal lag bank: the mean coil temperature T̂ and the loop
/// temperature's rates through 4–5 derivative filters, its filters, coil lags
/// and Shupe gain identified from the runs and chosen on held-out thermal
/// events (or whole runs, or the --validate runs); a cubic in T̂ and the rates,
/// linear, with ridge weights. The other RBF forms (--features paper: T, ΔT,
/// T×ΔT; multiscale) choose Gaussian centres by orthogonal least squares, with
/// the ΔT window, width, ridge strength and number of centres chosen on the
/// --validate runs or by contiguous 5-fold validation. Prints the model as it
/// is, a before/after accuracy table and what the training covered, then
/// writes the blob.
///
/// Runs with rate_x_dph, rate_y_dph, rate_z_dph (all runs the same axes):
/// every axis is fitted as above on its own rate, thermometer and reference,
/// and one multi-axis blob holds the axis models; the table has a row per run
/// and axis.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer fit chamber.csv --validate check.csv -o model.bin --report fit-report")]
pub struct Args {
    /// Training runs (recorded-run CSV with temp_c).
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    runs: Vec<PathBuf>,
    /// Runs that choose the hyper-parameters (repeatable).
    ///
    /// Used only to choose hyper-parameters and report generalisation.
    #[arg(long, value_name = "RUN.csv", help_heading = "Data")]
    validate: Vec<PathBuf>,
    /// Runs only reported, never used to choose.
    ///
    /// Reported in the accuracy table and never used to choose anything: an honest
    /// test of generalisation.
    #[arg(long, value_name = "RUN.csv", help_heading = "Data")]
    holdout: Vec<PathBuf>,
    /// Multi-axis runs: a model per axis, never one shared basis.
    ///
    /// For the per-axis three-axis firmware image, stm32f405-axes;
    /// stm32f405-axes-shared takes the joint model's blob.
    #[arg(long, help_heading = "Model")]
    no_joint: bool,
    /// Multi-axis runs on one thermometer: one shared basis, whatever it costs.
    ///
    /// Writes the joint model even where an axis loses more than 0.5 points
    /// (100-s cluster STD) with it against its own fit; the firmware then
    /// evaluates one basis for every axis (image stm32f405-axes-shared).
    #[arg(long, help_heading = "Model", conflicts_with = "no_joint")]
    joint: bool,
    /// Averaging block for training, s; a run past 32768 blocks has them
    /// merged in pairs into blocks twice as long, as often as it takes
    /// (docs/methods.md, "Large runs").
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0, help_heading = "Data")]
    block_s: f64,
    /// Model form (see --help).
    ///
    /// rbf = Gaussian RBF network (inputs: --features); rbf2 = RBF on (T, ΔT), the IFOG
    /// paper's model before its modification; poly3 = cubic in T (PX4/ArduPilot form);
    /// svr-pso = ε-SVR with σ, C, ε tuned by particle swarm on 3 contiguous folds (the RLG
    /// paper's method), deployed as an RBF network with one width (support vectors reduced by
    /// OLS to --centers, else --max-centers, when there are more); its inputs: on runs with
    /// thermometers temp_a … temp_h, the subset of thermometers that validates best on the
    /// same folds (every subset scored by a fast Gaussian + linear ridge network; the gradients
    /// between the chosen ones are in the model's linear span), or the temperatures and
    /// gradients the RLG paper's correlation rule selects (--select-threshold 0.9,
    /// --select-top N), or named ones (--inputs); else (T, ΔT, T×ΔT) (ΔT window: the middle of
    /// --dt-window-s).
    #[arg(long, value_enum, default_value_t = MethodArg::Rbf, hide_possible_values = true, help_heading = "Model")]
    method: MethodArg,
    /// Inputs of --method rbf (see --help).
    ///
    /// Default: the thermal lag bank, or the response bank below where the lag bank's residual
    /// on the training runs is above 1/0.6 × the response bank's (a coil unlike the one it
    /// encodes; `fit` prints both). lag-bank = the thermal lag bank alone: the mean coil temperature
    /// T̂ = T + Σ a_k·ΔT_k and the loop temperature's rates ΔT_k through 4–5 derivative
    /// filters from 15 s to 2 h, times a Shupe gain linear in T̂; a cubic in T̂ and the rates
    /// linear; filter set, coil lags a_k and gain identified from the runs and chosen by how
    /// well they predict held-out thermal events (or whole runs, or --validate runs); past the
    /// covered range of T̂ the cubic continues along its tangent, or itself for one band where
    /// an edge test on the outer 30 % of the range trusts it; Gaussians over T̂ only with
    /// --centers K (they bend the curve near the range's ends and extrapolate worse). It
    /// holds on temperature histories unlike the chamber's (cold starts, ambient steps, fast
    /// swings). multiscale = T, ΔT over three time scales (τ, 16τ, 256τ), T×ΔT₁, T×ΔT₂,
    /// T×ΔT₃ and T²×ΔT₂, Gaussians over T and the ΔT terms linear (the mean coil temperature
    /// lags the sensor in proportion to the rate: first-order terms of that lag);
    /// multiscale-second-order = the same with the second-order term ΔT₃² in place
    /// of T×ΔT₁; multiscale-validated = both fitted from one pass over the data, the
    /// second-order set also in its lagged forms (Gaussians over the mean coil temperature
    /// estimate T − L·ΔT₃, coil lag L of 10, 20, 40 or 80 min, at the second-order set's
    /// window and width) and, when that family already validates better than the first-order
    /// set, all of them again with the slowest window 1.25× longer (320τ: it should follow the
    /// coil's slowest radial mode), the best of these kept only when its validation RMS is
    /// below 0.9 × the first-order one (a term fitted at one ramp rate must earn its
    /// extrapolation); paper = (T, ΔT, T×ΔT) with Gaussians over all, the IFOG paper's network;
    /// response-bank = the thermal response bank alone: 12 derivative filters from 10 s to 11 h
    /// on T, (T − T₀)² and (T − T₀)³, a static cubic in T − T₀ (T₀ the middle of the covered
    /// range, tangent beyond it), five free mixtures of the filters' rates (R₀, (T − T₀)·R₁,
    /// (T − T₀)²·R₂ and the filtered square and cube), fitted by one ridge regression on 10-s
    /// block means whose penalty grows with each filter's time constant, so that responses of
    /// hours a chamber run barely excites stay small (docs/methods.md).
    #[arg(long, value_enum, hide_possible_values = true, help_heading = "Model")]
    features: Option<FeaturesArg>,
    /// Use exactly K Gaussian centres (1–64; 1–16 per axis on multi-axis runs).
    ///
    /// Fewer if OLS finds fewer independent ones; without it K ≤ --max-centers is chosen
    /// on validation, except for the lag bank, which has none unless asked.
    #[arg(long, value_name = "K", value_parser = centres_parser(), help_heading = "Model")]
    centers: Option<usize>,
    /// Most centres tried (1–64; at most 16 per axis on multi-axis runs).
    ///
    /// The firmware's evaluation cost grows with K; the three-axis firmware holds 16
    /// centres per axis.
    #[arg(long, value_name = "K", default_value_t = 32, value_parser = centres_parser(), help_heading = "Search")]
    max_centers: usize,
    /// ΔT filter time constants to choose from, s.
    ///
    /// Comma-separated; for multiscale the fastest of three, the others 16 and 256 times
    /// it; 0 = one-sample difference (IFOG Eq. 22). Default: choose among 15, 60 and 240 s.
    #[arg(
        long = "dt-window-s",
        alias = "rate-window-s",
        value_name = "SECONDS",
        value_delimiter = ',',
        help_heading = "Search"
    )]
    dt_window_s: Vec<f32>,
    /// Folds per run without --validate (2–20).
    ///
    /// Validation splits each training run into N contiguous folds when no --validate
    /// runs are given.
    #[arg(long, value_name = "N", default_value_t = 5, help_heading = "Search",
          value_parser = RangedU64ValueParser::<usize>::new().range(2..=MAX_FOLDS))]
    folds: usize,
    /// Gyro serial number stored in the blob (≤ 32 bytes).
    #[arg(long, help_heading = "Model")]
    serial: Option<String>,
    #[command(flatten)]
    select: SelectArgs,
    /// svr-pso: these inputs, not a selection.
    ///
    /// Comma-separated temperatures and gradients, e.g. `temp_d,temp_c-temp_d,temp_a-temp_b`
    /// (at most 8).
    #[arg(long, value_name = "LIST", value_delimiter = ',', value_parser = parse_probe,
          help_heading = "Multi-point")]
    inputs: Option<Vec<Probe>>,
    /// Model blob to write.
    ///
    /// postcard + CRC-32; flash it into the firmware's model region.
    #[arg(short, long, value_name = "MODEL.bin", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    json: JsonArg,
    #[command(flatten)]
    force: ForceArg,
    /// Also write plots, table and report into DIR.
    ///
    /// What `trainer report` writes for the model on every run of the fit (bias against
    /// loop temperature with the model overlaid and the residual, rate before and after,
    /// Allan deviation, report.md, report.json), plus fit.txt: what this command prints.
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    report: Option<PathBuf>,
    /// No progress bar.
    #[arg(short, long, help_heading = "Output")]
    quiet: bool,
    /// Accept runs implausible as gyro recordings.
    ///
    /// By default the fit refuses, naming the reason, training runs whose loop
    /// temperature leaves −60 … 100 °C (°F?), and holdouts whose loop temperature does
    /// or changes faster than 30 °C/min by time_s (in hours?).
    #[arg(long, help_heading = "Data")]
    allow_implausible: bool,
    /// Loop-temperature range of use, °C (MIN,MAX).
    ///
    /// The range the model will be used over. The `missing:` lines then say when the training runs' loop did not come within 5 % of
    /// the range of each end (the model extrapolates there), e.g. a chamber that went to
    /// −40 … 60 °C with holds too short for the loop to follow. Without it they judge the
    /// range the loop covered and say where it turned before it settled.
    #[arg(
        long = "use-range-c",
        value_name = "MIN,MAX",
        value_delimiter = ',',
        allow_hyphen_values = true,
        help_heading = "Data"
    )]
    use_range_c: Option<Vec<f64>>,
    /// Fastest loop-temperature change in use, °C/min (either sign).
    ///
    /// The `missing:` lines then say when the runs' fastest filter (τ 15 s) never read it
    /// both rising and falling: faster changes extrapolate the rate weights. (Only in --help:
    /// -h fits a screen.)
    #[arg(long, value_name = "C_PER_MIN", help_heading = "Data", hide_short_help = true)]
    use_rate_c_per_min: Option<f64>,
}

impl Args {
    /// The range and rates of use given, checked.
    pub fn in_use(&self) -> anyhow::Result<InUse> {
        let range_c = match self.use_range_c.as_deref() {
            None => None,
            Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => Some((lo, hi)),
            Some(v) => anyhow::bail!(
                "--use-range-c {}: takes MIN,MAX in °C, MIN below MAX",
                v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
            ),
        };
        if let Some(r) = self.use_rate_c_per_min {
            anyhow::ensure!(r.is_finite() && r > 0.0, "--use-rate-c-per-min {r}: must be above 0");
        }
        Ok(InUse {
            range_c,
            max_rate_c_per_min: self.use_rate_c_per_min,
        })
    }
}

/// Centre counts the firmware holds: 1 … [`rbf_core::MAX_CENTERS`].
fn centres_parser() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::<usize>::new().range(1..=rbf_core::MAX_CENTERS as u64)
}

/// A multi-point input by its column names: `temp_c` or `temp_c-temp_e`.
fn parse_probe(text: &str) -> Result<Probe, String> {
    let index = |name: &str| {
        rbf_core::record::column::THERMOMETERS
            .iter()
            .position(|t| *t == name.trim())
            .map(|i| i as u8)
            .ok_or_else(|| format!("{name:?} is not one of temp_a … temp_h"))
    };
    let probe = match text.split_once('-') {
        Some((hot, cold)) => Probe::Gradient(index(hot)?, index(cold)?),
        None => Probe::Temp(index(text)?),
    };
    if probe.is_valid() {
        Ok(probe)
    } else {
        Err(format!("{text:?}: a gradient needs two different thermometers"))
    }
}

/// Refuses an input named twice in `--inputs`, a gradient in either order
/// included (`temp_a-temp_b` and `temp_b-temp_a` carry the same information).
fn check_distinct_inputs(inputs: &[Probe]) -> anyhow::Result<()> {
    let key = |p: &Probe| match *p {
        Probe::Temp(i) => (i, i),
        Probe::Gradient(i, j) => (i.min(j), i.max(j)),
    };
    let name = |i: u8| {
        rbf_core::record::column::THERMOMETERS
            .get(usize::from(i))
            .copied()
            .unwrap_or("?")
    };
    for (k, p) in inputs.iter().enumerate() {
        if let Some(q) = inputs[..k].iter().find(|q| key(q) == key(p)) {
            let show = |p: &Probe| match *p {
                Probe::Temp(i) => name(i).to_owned(),
                Probe::Gradient(i, j) => format!("{}-{}", name(i), name(j)),
            };
            anyhow::bail!(
                "--inputs names {} and {}: the same input twice; name each temperature or gradient once",
                show(q),
                show(p)
            );
        }
    }
    Ok(())
}

/// Runs `trainer fit`.
pub fn run(a: Args) -> anyhow::Result<()> {
    // A fit reads its runs several times: files only. Outputs are checked
    // against them before any work; the model and the JSON are written last,
    // after every fallible step, so a failure never leaves a replaced model.
    let all_runs: Vec<&Path> = a
        .runs
        .iter()
        .chain(&a.validate)
        .chain(&a.holdout)
        .map(|p| p.as_path())
        .collect();
    input::require_seekable(all_runs.iter().copied(), "`trainer fit` reads its runs several times")?;
    let in_use = a.in_use()?;
    check_distinct_inputs(a.inputs.as_deref().unwrap_or_default())?;
    let existing = a.force.existing();
    let json_file = a.json.json.as_deref().filter(|p| !input::is_stdin(p));
    let outputs: Vec<&Path> = std::iter::once(a.output.as_path()).chain(json_file).collect();
    let mut targets = output::check_targets(&outputs, &all_runs, existing)?.into_iter();
    let report_runs: Vec<PathBuf> = all_runs.iter().map(|p| p.to_path_buf()).collect();
    // The report directory is replaced as a whole: no other output may lie in it.
    let report_target = match &a.report {
        Some(dir) => Some(trainer::report::check_report_targets(&report_runs, dir, &all_runs, &outputs, existing)?.1),
        None => None,
    };
    // Runs are streamed (memory stays flat whatever their length); their
    // headers and first rows are checked now, so a bad file is reported
    // before any work (a multi-axis run's other axes: by `axes::run`).
    for path in &all_runs {
        RunReader::open(path)?.require_temp()?;
    }
    plausible::require_distinct_runs(&a.runs, &[("--validate", &a.validate), ("--holdout", &a.holdout)])?;
    trainer::reading::limits::check_block_s(a.block_s)?;
    if let Some(s) = &a.serial {
        anyhow::ensure!(
            s.len() <= rbf_core::model::SERIAL_CAPACITY,
            "--serial {s:?}: at most {} bytes",
            rbf_core::model::SERIAL_CAPACITY
        );
    }
    anyhow::ensure!(
        a.method != MethodArg::SvrPso || a.validate.is_empty(),
        "--method svr-pso validates on contiguous folds of the training runs; drop --validate"
    );
    let train = RunFiles::new(&a.runs);
    let validate = RunFiles::new(&a.validate);
    let mut opts = FitOptions {
        method: a.method.into(),
        features: a.features.unwrap_or(FeaturesArg::LagBank).into(),
        structure_choice: a.features.is_none(),
        block_s: a.block_s,
        centers: a.centers,
        max_centers: a.max_centers,
        folds: a.folds,
        serial: a.serial.clone(),
        progress: !a.quiet,
        selection: a.select.selection()?,
        inputs: a.inputs.clone(),
        ..FitOptions::default()
    };
    if !a.dt_window_s.is_empty() {
        anyhow::ensure!(
            a.dt_window_s
                .iter()
                .all(|w| w.is_finite() && (0.0..=86_400.0).contains(w)),
            "--dt-window-s values must be 0 … 86400 s"
        );
        opts.rate_windows_s = a.dt_window_s.clone();
    }
    let axes = trainer::evaluation::axes::common_axes(&all_runs)?;
    let model_out = targets.next().map(Output::open).transpose()?;
    let json_out = match targets.next() {
        Some(target) => JsonSink::File(Output::open(target)?),
        None if a.json.json.is_some() => JsonSink::Stdout,
        None => JsonSink::None,
    };
    if !axes.is_empty() {
        let how = FitHow {
            with_validate_runs: !a.validate.is_empty(),
            folds: opts.folds,
            named_inputs: opts.inputs.is_some(),
            selection: opts.selection,
        };
        return axes::run(&a, &opts, &how, &axes, model_out, json_out);
    }
    let started = std::time::Instant::now();
    let outcome = fit::fit(&train, &validate, &opts).map_err(|e| {
        // A validation run too short to score blames itself, not the training runs.
        let short = diagnose::short_runs(&a.validate, "--validate", fit::excitation::MIN_USABLE_S);
        if !short.is_empty() {
            anyhow::anyhow!("{}", short.join("; "))
        } else if e.chain().any(|c| c.is::<fit::Unidentifiable>()) {
            let thermometers = opts
                .method
                .feature_set(opts.features)
                .thermometers()
                .union(ThermometerSet::LOOP);
            diagnose::with_causes(e, &a.runs, thermometers)
        } else {
            e
        }
    })?;
    let fit_s = started.elapsed().as_secs_f64();
    if let Some((lo, hi)) = training_loop_range_c(&outcome) {
        let finding = plausible::range_finding("the training runs' loop temperature", lo, hi);
        plausible::require_plausible(finding.as_slice(), a.allow_implausible)?;
    }
    // Training and validation runs are scored on the block means the fit
    // computed, without reading them again; holdout runs, which the fit
    // never read, sample by sample.
    let mut evals: Vec<(&str, RunEvaluation)> = Vec::new();
    for (role, runs) in [("train", &train), ("validate", &validate)] {
        if runs.count() == 0 {
            continue;
        }
        let blocks = runs.block_means(outcome.model.features(), opts.block_s)?;
        for (i, path) in runs.paths().iter().enumerate() {
            let has_ref = RunReader::open(path)?.columns().ref_dph.is_some();
            evals.push((
                role,
                evaluate_blocks(&outcome.model, &blocks, i, path, opts.block_s, has_ref),
            ));
        }
    }
    drop((train, validate));
    for path in &a.holdout {
        let reader = RunReader::open(path)?;
        let models = RunModels::one(Some(&outcome.model), &reader);
        let (evaluation, diagnosis, _) = only_axis(evaluate_reader(&models, reader)?)?;
        plausible::require_plausible(&diagnosis.implausible(), a.allow_implausible)?;
        evals.push(("holdout", evaluation));
    }
    let blob = encode_model(&outcome.model)?;

    // Printed once everything is written.
    let mut out: Vec<u8> = Vec::new();
    let how = FitHow {
        with_validate_runs: !a.validate.is_empty(),
        folds: opts.folds,
        named_inputs: opts.inputs.is_some(),
        selection: opts.selection,
    };
    write_summary(&mut out, &outcome, &how)?;
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    if let Some(search) = &outcome.bank {
        writeln!(out)?;
        for line in search.coverage.lines(&in_use) {
            writeln!(out, "{line}")?;
        }
    }
    writeln!(out, "\nwrote {} ({} bytes)", text::path(&a.output), blob.len())?;
    let mut json = outcome_json(&outcome);
    json["method"] = serde_json::json!(opts.method);
    json["fit_seconds"] = serde_json::json!(fit_s);
    json["blob_bytes"] = serde_json::json!(blob.len());
    json["runs"] = runs_json(&evals);
    // Every output staged, then printed, then committed together.
    let mut transaction = Transaction::new();
    if let Some(target) = report_target {
        let staged = StagedDir::create(target)?;
        let files = {
            // The fit has checked its runs; the report takes them as they are.
            let accept = trainer::evaluation::axes::Acceptance {
                uncompensated: true,
                implausible: true,
            };
            trainer::report::write_report(
                &outcome.model,
                &a.output,
                trainer::report::ReportRuns {
                    paths: &report_runs,
                    trained_on: Some(a.runs.len()),
                },
                &staged,
                Path::new(""),
                accept,
                None,
            )?
            .0
        };
        staged.write(Path::new(FIT_TEXT), &out)?;
        writeln!(out, "wrote {} files into {}", files + 1, text::path(staged.target()))?;
        transaction.add_dir(staged);
    }
    write_blob(model_out, &blob, &mut transaction)?;
    let json_on_stdout = json_out.is_stdout();
    json_out.write(&json, &mut transaction)?;
    print_and_commit(&out, json_on_stdout, transaction)
}

/// The file in `--report DIR` that holds what `fit` prints.
const FIT_TEXT: &str = "fit.txt";

/// Writes `blob` into `model_out` (if any), staged in `transaction`.
pub(super) fn write_blob(model_out: Option<Output>, blob: &[u8], transaction: &mut Transaction) -> anyhow::Result<()> {
    if let Some(mut output) = model_out {
        output
            .write_all(blob)
            .with_context(|| format!("{}: write failed", text::path(output.path())))?;
        transaction.add(output);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probes_are_read_by_column_name() {
        assert!(matches!(parse_probe("temp_c"), Ok(Probe::Temp(2))));
        assert!(matches!(parse_probe("temp_a-temp_h"), Ok(Probe::Gradient(0, 7))));
        assert!(parse_probe("temp_z").unwrap_err().contains("not one of temp_a"));
        assert!(parse_probe("temp_b-temp_b").unwrap_err().contains("two different"));
    }
}
