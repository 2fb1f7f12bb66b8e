//! `trainer`: fit, apply and evaluate IFOG temperature-drift models.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::builder::RangedU64ValueParser;
use clap::{Args, Parser, Subcommand};
use rbf_core::blob::{self, Header};
use rbf_core::features::Probe;
use rbf_core::model::ModelBody;
use rbf_core::{FeatureConfig, FeatureSet, Model};
use trainer::blobfile::{encode_model, file_problem, read_blob, read_model};
use trainer::dataset::{RunFiles, RunSet};
use trainer::evaluate::{
    RunEvaluation, compensate_command, evaluate_file, evaluate_files, print_allan_table, print_table,
};
use trainer::fit::{self, FitOptions, Method, RbfFeatures};
use trainer::limits::{MAX_BLOCK_SAMPLES, MAX_FOLDS, MAX_PARAMS_BYTES};
use trainer::output::{self, Existing, Output};
use trainer::run::RunReader;
use trainer::simulate::{ChamberRun, ParamsError, Profile, SimParams};
use trainer::text::{self, SafeWriter};
use trainer::{diagnose, input};

/// Standard output, control characters from outside escaped on the way.
fn stdout() -> SafeWriter<std::io::StdoutLock<'static>> {
    SafeWriter::new(std::io::stdout().lock())
}

/// Options every command that writes files shares.
#[derive(Args, Debug)]
struct ForceArg {
    /// Replace the output if it exists (by default an existing file is never replaced;
    /// even with --force a link, a device, a read-only file or an input is not).
    #[arg(long)]
    force: bool,
}

impl ForceArg {
    fn existing(&self) -> Existing {
        Existing::from_force(self.force)
    }
}

/// Removes temperature drift from fiber-optic gyros.
///
/// Typical session: record chamber runs (recorded-run CSV: time_s, rate_dph,
/// temp_c, optionally ref_dph), `trainer fit` them into MODEL.bin, check the
/// result on other runs with `trainer eval`, flash MODEL.bin into the
/// firmware's model region. `trainer compensate` applies a model to a run
/// exactly as the firmware would.
#[derive(Parser, Debug)]
#[command(version, about, long_about, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    Fit(FitArgs),
    Compensate(CompensateArgs),
    Eval(EvalArgs),
    Inspect(InspectArgs),
    Simulate(SimulateArgs),
    Plan(PlanArgs),
    Decode(DecodeArgs),
    Report(ReportArgs),
    Blocks(BlocksArgs),
    Correlate(CorrelateArgs),
}

/// Which temperatures and gradients explain the bias: the RLG paper's input selection.
///
/// Reads the thermometers temp_a … temp_h of multi-point runs (`trainer simulate --multi`
/// writes them), averages every --block-samples rows (the paper: 100), and prints the Pearson
/// correlation with the bias (rate_dph − ref_dph) of each temperature (diagonal) and each
/// gradient T_i − T_j (row i, column j), like the paper's Table 3, marking the inputs selected
/// by --select-threshold (|r| ≥ 0.9 by default) or --select-top N. (`trainer fit --method
/// svr-pso` prints the same table, then by default chooses its thermometers by validation.)
#[derive(Args, Debug)]
struct CorrelateArgs {
    /// Multi-point runs (the same thermometers in each; - reads standard input).
    #[arg(required = true, value_name = "RUN.csv")]
    runs: Vec<PathBuf>,
    /// Rows averaged per block (the paper's smoothing).
    #[arg(long, value_name = "N", default_value_t = 100,
          value_parser = RangedU64ValueParser::<usize>::new().range(1..=MAX_BLOCK_SAMPLES))]
    block_samples: usize,
    #[command(flatten)]
    select: SelectArgs,
    /// Print JSON (matrix, names, selection) instead of the table.
    #[arg(long)]
    json: bool,
}

/// How multi-point inputs are selected from their correlations with the bias.
#[derive(Args, Debug)]
struct SelectArgs {
    /// Select every temperature and gradient with |r| at least R (the RLG paper's rule:
    /// `--select-threshold 0.9`). `correlate` uses 0.9 when neither this nor --select-top is
    /// given; `fit --method svr-pso` then chooses the thermometers by validation instead.
    #[arg(long, value_name = "R", conflicts_with = "select_top")]
    select_threshold: Option<f64>,
    /// Select the N candidates of largest |r| instead (8 temperatures and 28 gradients at most).
    #[arg(long, value_name = "N", value_parser = RangedU64ValueParser::<usize>::new().range(1..=36))]
    select_top: Option<usize>,
}

/// The RLG paper's correlation threshold.
const PAPER_THRESHOLD: f64 = 0.9;

impl SelectArgs {
    /// The correlation rule asked for, if any.
    fn selection(&self) -> anyhow::Result<Option<trainer::gradients::Selection>> {
        use trainer::gradients::Selection;
        if let Some(r) = self.select_threshold {
            anyhow::ensure!(
                (0.0..=1.0).contains(&r),
                "--select-threshold {r}: a correlation magnitude, 0 … 1"
            );
        }
        Ok(match (self.select_top, self.select_threshold) {
            (Some(n), _) => Some(Selection::Top(n)),
            (None, Some(r)) => Some(Selection::Threshold(r)),
            (None, None) => None,
        })
    }
}

/// Write the training data a fit sees: block means of the features and the bias target.
///
/// The features are rbf-core's (the firmware's own computation), averaged with
/// the target rate_dph − ref_dph (or minus the run mean) over blocks; warm-up
/// and sensor-fault samples are left out. For comparing other learners on
/// exactly the same data (bench/accuracy).
#[derive(Args, Debug)]
struct BlocksArgs {
    /// Runs to read (blocks are written in order, with a run column; - reads standard input).
    #[arg(required = true, value_name = "RUN.csv")]
    runs: Vec<PathBuf>,
    /// Inputs: multiscale (default; the first-order set), multiscale-second-order (also for
    /// multiscale-validated, the fit's default, which chooses between the two) or paper
    /// (T, ΔT, T×ΔT).
    #[arg(long, value_enum, default_value_t = RbfFeatures::Multiscale)]
    features: RbfFeatures,
    /// Fastest ΔT window, s.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0)]
    rate_window_s: f32,
    /// With the second-order set: its lagged form, input 0 the mean coil temperature
    /// estimate T − L·ΔT₃ for a coil lag L in minutes (what `trainer fit` reports as
    /// `MultiScaleLagged`).
    #[arg(long, value_name = "MINUTES")]
    coil_lag_min: Option<u16>,
    /// Instead of --features, --rate-window-s and --coil-lag-min: the inputs of a fitted
    /// model, every setting as its blob holds it (set, all three ΔT windows, coil lag).
    /// How bench/accuracy gives the Python peers the features the default fit chose.
    #[arg(long, value_name = "MODEL.bin", conflicts_with_all = ["features", "rate_window_s", "coil_lag_min"])]
    model: Option<PathBuf>,
    /// Block length, s.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    block_s: f64,
    /// CSV to write.
    #[arg(short, long, value_name = "BLOCKS.csv")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Plots and a written summary of a model on runs, for people who would rather look.
///
/// Writes into DIR, as SVG and PNG: per run the raw and compensated rate − reference
/// (10-s means) with the loop temperature, and the overlapping Allan deviation before
/// and after on log-log axes; the model's bias over T and a steady ramp ΔT. Plus
/// report.json (every figure of `trainer eval --json`) and report.md.
#[derive(Args, Debug)]
struct ReportArgs {
    /// Model blob.
    #[arg(long, value_name = "MODEL.bin")]
    model: PathBuf,
    /// Runs to report on (- reads standard input).
    #[arg(required = true, value_name = "RUN.csv")]
    runs: Vec<PathBuf>,
    /// Directory to write into (created if missing).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Replace report files that exist in DIR (by default none is replaced).
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// What to do with a run where no row could be compensated.
#[derive(Args, Debug)]
struct AllowUncompensated {
    /// Accept a run where no row could be compensated (every row flag 4); by default that
    /// is an error naming the cause (temperatures out of range, sensor faults).
    #[arg(long)]
    allow_uncompensated: bool,
}

/// Decode firmware output frames (a UART capture) into CSV.
///
/// Frames are postcard + COBS, each ended by 0x00. Writes
/// seq, rate_dph [°/h], bias_dph [°/h], rate_comp_dph [°/h], temp_c [°C], flags.
/// A damaged frame is skipped and reported (the seq gap shows where); a capture
/// that starts mid-frame loses only that first partial frame.
#[derive(Args, Debug)]
struct DecodeArgs {
    /// Captured frame bytes (- reads standard input).
    #[arg(value_name = "FRAMES.bin")]
    frames: PathBuf,
    /// CSV to write.
    #[arg(short, long, value_name = "OUT.csv")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Write a simulated IFOG run, in a thermal chamber or in use (recorded-run CSV with ref_dph).
///
/// A physics-based plant (docs/simulator.md): air → housing base and top →
/// self-heated electronics → fiber coil in 2 … 8 radial layers on its hub →
/// thermometers with their own lags, noise and TMP117 quantisation. Bias =
/// static cubic in the coil temperature + Shupe term in the layers'
/// temperature rates with a T-dependent gain + thermal stress and radial
/// gradient terms (+ axial gradient with --multi) + bias instability + angle
/// random walk. ref_dph is the Earth-rate projection at 39.9° N, axis heading
/// 30°. Every run starts at power-on, soaked at its first temperature; the
/// chamber protocols ifog, cycle and random start with a 1-h hold. --unit N
/// draws a whole gyro from documented ranges. Same seed, same file.
///
/// Example: trainer simulate --profile field --unit 3 --seed 7 -o field.csv
#[derive(Args, Debug)]
struct SimulateArgs {
    /// Temperature history: chamber ifog, cycle, random, designed; in use cold-start,
    /// ambient-steps, swings, day-cycle, field (docs/simulator.md, "Profiles").
    #[arg(long, value_enum, default_value_t = Profile::Ifog, conflicts_with = "chamber_profile")]
    profile: Profile,
    /// Simulate a planned chamber run: a CSV with time_s,chamber_c set points
    /// (piecewise linear, as `trainer plan` writes it).
    #[arg(long, value_name = "PLAN.csv")]
    chamber_profile: Option<PathBuf>,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Another gyro of the same kind: draw every plant and bias constant from the
    /// documented unit-to-unit ranges, seeded by N (--params overrides fields of it).
    #[arg(long, value_name = "N")]
    unit: Option<u64>,
    /// Chamber ramp rate between set points, °C/min (ifog and cycle: 1, the RLG paper
    /// used 1, 2, 3, 5; designed: 5).
    #[arg(long, value_name = "C_PER_MIN")]
    ramp: Option<f64>,
    /// Gyro sample rate, Hz.
    #[arg(long, value_name = "F", default_value_t = 1.0)]
    rate_hz: f64,
    /// Hold at each set point, minutes (ifog and cycle).
    #[arg(long, value_name = "MINUTES", default_value_t = 120.0)]
    hold_min: f64,
    /// Total length, hours: cuts the profile or extends its last hold (random: 8 h and the hold
    /// it is in; cold-start 4, ambient-steps 6, swings 4, day-cycle 24, field 8 h).
    #[arg(long, value_name = "H")]
    hours: Option<f64>,
    /// Set-point range of the random profile, °C, as MIN,MAX.
    #[arg(long, value_name = "MIN,MAX", value_delimiter = ',', allow_hyphen_values = true, default_values_t = [-40.0, 60.0])]
    random_range: Vec<f64>,
    /// Ramp-rate range of the random profile, °C/min, as SLOWEST,FASTEST.
    #[arg(long, value_name = "MIN,MAX", value_delimiter = ',', default_values_t = [0.5, 5.0])]
    ramp_range: Vec<f64>,
    /// The same run with every thermal bias term zeroed: its noise alone, sample
    /// for sample (the run's noise ceiling).
    #[arg(long)]
    noise_only: bool,
    /// Write 8 thermometers temp_a … temp_h at different places (temp_c is the loop
    /// sensor) and add the axial-gradient bias they reveal (RLG paper).
    #[arg(long)]
    multi: bool,
    /// Another gyro: a JSON file overriding any of the thermal network's time
    /// constants and the bias and noise coefficients (docs/simulator.md lists
    /// every field, its unit and default; with --unit, over that unit's), e.g.
    /// {"plant": {"tau_top_s": 2400}, "gyro": {"axial_gradient_dph_per_c": 0.05}}.
    /// The run's header records them (# simulator_params).
    #[arg(long, value_name = "FILE.json")]
    params: Option<PathBuf>,
    /// Run to write.
    #[arg(short, long, value_name = "RUN.csv")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Design the chamber run to calibrate on: a profile the default model can be identified from.
///
/// Draws --candidates profiles from a family that holds what the lag bank needs (a power-on
/// soak at the cold end whose self-heating transient is recorded, levels across the range,
/// full-rate steps, bursts of swings, slow ramps, holds as long as the coil's slowest mode)
/// and keeps the one of largest D-criterion: the log-determinant of the information matrix of
/// the lag-bank regression on the documented gyro's plant (docs/plan.md). Writes the set
/// points `trainer simulate --chamber-profile` reads (time_s,chamber_c, piecewise linear), or
/// with --format segments the segment table a chamber controller takes. Same seed, same plan.
///
/// Example: trainer plan --min-c -40 --max-c 60 --max-rate-c-per-min 5 --hours 12 -o plan.csv
#[derive(Args, Debug)]
struct PlanArgs {
    /// Lowest set point, °C.
    #[arg(long, value_name = "C", allow_hyphen_values = true)]
    min_c: f64,
    /// Highest set point, °C.
    #[arg(long, value_name = "C", allow_hyphen_values = true)]
    max_c: f64,
    /// Fastest ramp the chamber may run, °C/min (every segment stays at or below it).
    #[arg(long, value_name = "C_PER_MIN", allow_hyphen_values = true)]
    max_rate_c_per_min: f64,
    /// Longest run, hours (the last set point is at most this far in).
    #[arg(long, value_name = "H", allow_hyphen_values = true)]
    hours: f64,
    /// What -o holds: set-points (time_s,chamber_c; what `trainer simulate --chamber-profile`
    /// reads) or segments (segment,target_c,ramp_min,hold_min; what chamber controllers take).
    #[arg(long, value_enum, default_value_t = PlanFormat::SetPoints)]
    format: PlanFormat,
    /// Candidate profiles scored, 1–1000 (more: a higher criterion, a longer design).
    #[arg(long, value_name = "N", default_value_t = trainer::plan::DEFAULT_CANDIDATES,
          value_parser = RangedU64ValueParser::<usize>::new().range(1..=1000))]
    candidates: usize,
    /// Random seed of the candidates.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also draw the plan (set points and the nominal loop temperature) as SVG or PNG, by extension.
    #[arg(long, value_name = "FILE.svg|png")]
    plot: Option<PathBuf>,
    /// Plan to write.
    #[arg(short, long, value_name = "PLAN.csv")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// What `trainer plan` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum PlanFormat {
    /// Piecewise-linear set points, time_s,chamber_c.
    SetPoints,
    /// Segment table: target °C, ramp minutes, hold minutes.
    Segments,
}

/// Fit a bias model to recorded chamber runs and write the model blob.
///
/// Features (T [°C], ΔT [°C/min], T×ΔT) are computed per sample by rbf-core, as
/// the firmware does, then averaged over blocks together with the bias target
/// `rate_dph − ref_dph` (or minus the run mean without ref_dph). The RBF
/// methods choose centres by orthogonal least squares and ridge output weights;
/// the ΔT window, Gaussian width, ridge strength and number of centres are
/// chosen on the --validate runs, or by contiguous 5-fold validation over the
/// training runs. Prints a before/after accuracy table, then writes the blob.
#[derive(Args, Debug)]
struct FitArgs {
    /// Training runs (recorded-run CSV with temp_c).
    #[arg(required = true, value_name = "RUN.csv")]
    runs: Vec<PathBuf>,
    /// Model blob to write (postcard + CRC-32; flash it into the firmware's model region).
    #[arg(short, long, value_name = "MODEL.bin")]
    output: PathBuf,
    /// Runs used only to choose hyper-parameters and report generalisation (repeatable).
    #[arg(long, value_name = "RUN.csv")]
    validate: Vec<PathBuf>,
    /// Runs only reported in the accuracy table, never used to choose anything
    /// (an honest test of generalisation; repeatable).
    #[arg(long, value_name = "RUN.csv")]
    holdout: Vec<PathBuf>,
    /// Model form: rbf = Gaussian RBF network (inputs: --features); rbf2 = RBF on (T, ΔT),
    /// the IFOG paper's model before its modification; poly3 = cubic in T (PX4/ArduPilot form);
    /// svr-pso = ε-SVR with σ, C, ε tuned by particle swarm on 3 contiguous folds (the RLG
    /// paper's method), deployed as an RBF network with one width (support vectors reduced by
    /// OLS to --centers, else --max-centers, when there are more); its inputs: on runs with
    /// thermometers temp_a … temp_h, the subset of thermometers that validates best on the
    /// same folds (every subset scored by a fast Gaussian + linear ridge network; the gradients
    /// between the chosen ones are in the model's linear span), or the temperatures and
    /// gradients the RLG paper's correlation rule selects (--select-threshold 0.9,
    /// --select-top N), or named ones (--inputs); else (T, ΔT, T×ΔT) (ΔT window: the middle of
    /// --rate-window-s).
    #[arg(long, value_enum, default_value_t = Method::Rbf)]
    method: Method,
    /// Inputs of --method rbf. lag-bank (default) = the thermal lag bank: the mean coil
    /// temperature T̂ = T + Σ a_k·ΔT_k and the loop temperature's rates ΔT_k through 4–6
    /// derivative filters from 15 s to 4 h, times a Shupe gain linear in T; a cubic in T̂
    /// (extrapolated along its tangent past the covered range) and the rates linear; filter
    /// set, coil lags a_k and gain identified from the runs and chosen by how well they
    /// predict held-out thermal events (or whole runs, or --validate runs); Gaussians over T̂
    /// only where that validation wants them. It holds on temperature histories unlike the
    /// chamber's (cold starts, ambient steps, fast swings). multiscale = T, ΔT over three time
    /// scales (τ, 16τ, 256τ), T×ΔT₁, T×ΔT₂, T×ΔT₃ and T²×ΔT₂, Gaussians over T and the ΔT
    /// terms linear (the mean coil temperature lags the sensor in proportion to the rate:
    /// first-order terms of that lag); multiscale-second-order = the same with the
    /// second-order term ΔT₃² in place of T×ΔT₁; multiscale-validated = both fitted from one
    /// pass over the data, the
    /// second-order set also in its lagged forms (Gaussians over the mean coil temperature
    /// estimate T − L·ΔT₃, coil lag L of 10, 20, 40 or 80 min, at the second-order set's
    /// window and width) and, when that family already validates better than the first-order
    /// set, all of them again with the slowest window 1.25× longer (320τ: it should follow the
    /// coil's slowest radial mode), the best of these kept only when its validation RMS is below 0.9 ×
    /// the first-order one (a term fitted at one ramp rate must earn its extrapolation: it does
    /// on cycle runs, not on the bundled IFOG run); paper = (T, ΔT, T×ΔT) with Gaussians over all, the IFOG paper's
    /// network.
    #[arg(long, value_enum, default_value_t = RbfFeatures::LagBank)]
    features: RbfFeatures,
    /// Use K Gaussian centres (1–64; fewer if OLS finds fewer independent ones) instead of
    /// choosing K ≤ --max-centers on validation.
    #[arg(long, value_name = "K", value_parser = centres_parser())]
    centers: Option<usize>,
    /// Most centres considered when K is chosen on validation (1–64; firmware cost grows with K).
    #[arg(long, value_name = "K", default_value_t = 32, value_parser = centres_parser())]
    max_centers: usize,
    /// ΔT derivative-filter time constant(s) to choose from, in seconds (for multiscale the
    /// fastest of three, the others 16 and 256 times it); 0 = one-sample difference (IFOG
    /// Eq. 22). Default: choose among 15, 60 and 240 s.
    #[arg(long, value_name = "SECONDS", value_delimiter = ',')]
    rate_window_s: Vec<f32>,
    /// Averaging block for training, seconds.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    block_s: f64,
    /// Contiguous folds per run for validation when no --validate runs are given (2–20).
    #[arg(long, value_name = "N", default_value_t = 5,
          value_parser = RangedU64ValueParser::<usize>::new().range(2..=MAX_FOLDS))]
    folds: usize,
    /// Serial number of the gyro, stored in the blob (at most 32 bytes).
    #[arg(long)]
    serial: Option<String>,
    /// Also write the fit report (choice and per-run accuracy) as JSON.
    #[arg(long, value_name = "REPORT.json")]
    json: Option<PathBuf>,
    /// Overwrite MODEL.bin if it exists (by default an existing model is never replaced).
    #[arg(long)]
    force: bool,
    /// No progress bar.
    #[arg(short, long)]
    quiet: bool,
    #[command(flatten)]
    select: SelectArgs,
    /// svr-pso on multi-point runs: use these inputs instead of a selection, comma-separated
    /// temperatures and gradients, e.g. `temp_d,temp_c-temp_d,temp_a-temp_b` (at most 8).
    #[arg(long, value_name = "LIST", value_delimiter = ',', value_parser = parse_probe)]
    inputs: Option<Vec<Probe>>,
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

/// Compensate a run with a model, exactly as the firmware does.
///
/// Writes the input lines unchanged followed by bias_dph [°/h], rate_comp_dph
/// [°/h] and flags (1 clamped · 2 temperature-sensor fault · 4 no valid model ·
/// 8 warming up · 16 rate invalid); one output row per input row. Rows with
/// temp_fault = 1 are treated as a sensor that does not answer.
#[derive(Args, Debug)]
struct CompensateArgs {
    /// Model blob written by `trainer fit`.
    #[arg(long, value_name = "MODEL.bin")]
    model: PathBuf,
    /// Run to compensate (- reads standard input).
    #[arg(value_name = "RUN.csv")]
    run: PathBuf,
    /// Compensated run to write.
    #[arg(short, long, value_name = "OUT.csv")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Before/after accuracy of a model on runs.
///
/// Per run: MSD (IFOG paper Eq. 24) of 1-s means against ref_dph (or about the
/// mean), and the bias STD of 100-s cluster means (RLG paper), before and after
/// compensation, with the improvement in %; then the overlapping Allan
/// deviation (IEEE Std 952) before and after, with angle random walk [°/√h] and
/// bias instability [°/h] read off it (--json has the whole curves).
#[derive(Args, Debug)]
struct EvalArgs {
    /// Model blob.
    #[arg(long, value_name = "MODEL.bin")]
    model: PathBuf,
    /// Runs to evaluate (- reads standard input).
    #[arg(required = true, value_name = "RUN.csv")]
    runs: Vec<PathBuf>,
    /// Also write the figures as JSON.
    #[arg(long, value_name = "REPORT.json")]
    json: Option<PathBuf>,
    #[command(flatten)]
    force: ForceArg,
    #[command(flatten)]
    uncompensated: AllowUncompensated,
}

/// Show what a model blob holds and whether it is intact.
#[derive(Args, Debug)]
struct InspectArgs {
    /// Model blob (- reads standard input).
    #[arg(
        value_name = "MODEL.bin",
        required_unless_present = "model_option",
        conflicts_with = "model_option"
    )]
    model: Option<PathBuf>,
    /// Model blob, as the other commands name it.
    #[arg(long = "model", id = "model_option", value_name = "MODEL.bin")]
    model_option: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    // A command line clap refuses exits 1 like every other error (--help and
    // --version print to stdout and exit 0).
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // File names, fields and serials from outside may hold control characters.
            eprintln!("error: {}", text::terminal_safe(&format!("{e:#}")));
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Fit(a) => cmd_fit(a),
        Command::Compensate(a) => {
            let c = compensate_command(
                &a.model,
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
        Command::Eval(a) => cmd_eval(a),
        Command::Inspect(a) => cmd_inspect(a),
        Command::Simulate(a) => cmd_simulate(a),
        Command::Plan(a) => cmd_plan(a),
        Command::Decode(a) => cmd_decode(a),
        Command::Blocks(a) => cmd_blocks(a),
        Command::Correlate(a) => cmd_correlate(a),
        Command::Report(a) => {
            let (model, _) = read_model(&a.model)?;
            let existing = Existing::from_force(a.force);
            let files = trainer::report::write_report(
                &model,
                &a.model,
                &a.runs,
                &a.output,
                existing,
                a.uncompensated.allow_uncompensated,
            )?;
            writeln!(stdout(), "wrote {} files into {}", files.len(), text::path(&a.output))?;
            Ok(())
        }
    }
}

fn cmd_fit(a: FitArgs) -> anyhow::Result<()> {
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
    let existing = Existing::from_force(a.force);
    let outputs: Vec<&Path> = std::iter::once(a.output.as_path()).chain(a.json.as_deref()).collect();
    let mut targets = output::check_targets(&outputs, &all_runs, existing)?.into_iter();
    // Runs are streamed (memory stays flat whatever their length); their
    // headers and first rows are checked now, so a bad file is reported before any work.
    for path in &all_runs {
        RunReader::open(path)?.require_temp()?;
    }
    let train = RunFiles::new(&a.runs);
    let validate = RunFiles::new(&a.validate);
    let mut opts = FitOptions {
        method: a.method,
        features: a.features,
        block_s: a.block_s,
        centers: a.centers,
        max_centers: a.max_centers,
        folds: a.folds,
        serial: a.serial,
        progress: !a.quiet,
        selection: a.select.selection()?,
        inputs: a.inputs.clone(),
        ..FitOptions::default()
    };
    anyhow::ensure!(
        a.block_s.is_finite() && a.block_s > 0.0,
        "--block-s must be a positive number of seconds"
    );
    if !a.rate_window_s.is_empty() {
        anyhow::ensure!(
            a.rate_window_s
                .iter()
                .all(|w| w.is_finite() && (0.0..=86_400.0).contains(w)),
            "--rate-window-s values must be 0 … 86400 s"
        );
        opts.rate_windows_s = a.rate_window_s;
    }
    let model_out = targets.next().map(Output::open).transpose()?;
    let json_out = targets.next().map(Output::open).transpose()?;
    let started = std::time::Instant::now();
    let outcome = fit::fit(&train, &validate, &opts).map_err(|e| {
        if e.chain().any(|c| c.is::<fit::Unidentifiable>()) {
            let mask =
                opts.method.feature_set(opts.features).thermometer_mask() | (1 << rbf_core::features::LOOP_THERMOMETER);
            diagnose::with_causes(e, &a.runs, mask)
        } else {
            e
        }
    })?;
    let fit_s = started.elapsed().as_secs_f64();
    // The cached block means are done with: freed before the evaluation pass.
    drop((train, validate));
    let blob = encode_model(&outcome.model)?;

    // Printed once everything is written.
    let mut out: Vec<u8> = Vec::new();
    writeln!(out, "method {:?}: {}", a.method, describe(&outcome.model))?;
    if let Some(c) = &outcome.choice {
        writeln!(
            out,
            "chosen on {}: {}width σ {} (normalised), ridge λ {:e}, {} centres; validation RMS {:.4e} °/h",
            if !a.validate.is_empty() {
                "--validate runs".into()
            } else if let Some(search) = &outcome.bank {
                format!("the same {} folds as the bank's structure", search.fold_count)
            } else {
                format!("{}-fold contiguous validation", opts.folds.max(2))
            },
            // The lag bank's filters are its structure (printed below), not one window.
            if outcome.bank.is_some() {
                String::new()
            } else {
                format!("ΔT window {} s, ", c.rate_window_s)
            },
            c.width,
            c.ridge,
            c.centers,
            c.validation_rms_dph
        )?;
    }
    if let Some(search) = &outcome.bank {
        print_bank(&mut out, &outcome.model, search)?;
    }
    if let Some(s) = &outcome.sets {
        let kept = outcome.model.features();
        let slowest_s = kept.windows_s()[2];
        let kept = match kept.set {
            FeatureSet::MultiScale => "first-order".to_owned(),
            FeatureSet::MultiScaleLagged { coil_lag_min } => {
                format!("second-order, coil lag {coil_lag_min} min, slowest window {slowest_s} s")
            }
            _ => format!("second-order, slowest window {slowest_s} s"),
        };
        writeln!(
            out,
            "feature sets: first-order validation RMS {:.4e} °/h, second-order (ΔT₃², coil lags {:?} min and slowest window ×{:?} tried) {:.4e} °/h (ratio {:.3}; kept when < {}): {}",
            s.first_order_rms_dph,
            fit::COIL_LAGS_MIN,
            fit::rbf::SLOWEST_WINDOW_FACTORS,
            s.second_order_rms_dph,
            s.second_order_rms_dph / s.first_order_rms_dph,
            fit::SECOND_ORDER_GAIN,
            kept
        )?;
    }
    if let Some(c) = &outcome.svr {
        if let Some(sel) = &c.selection {
            let rule = match (&opts.inputs, opts.selection) {
                (Some(_), _) => "--inputs".to_owned(),
                (None, Some(rule)) => rule_name(rule),
                (None, None) => format!(
                    "the best of {} subsets of thermometers on 3-fold contiguous validation",
                    (1u32 << sel.table.names.len()) - 1
                ),
            };
            write!(out, "{}", describe_selection(&sel.table, &sel.selected, &rule))?;
            if !sel.ranking.is_empty() {
                writeln!(out, "validation RMS of the best subsets (°/h):")?;
                for s in &sel.ranking {
                    let names: Vec<&str> = s.sensors.iter().map(|&k| sel.table.names[k].as_str()).collect();
                    writeln!(out, "  {:.4e}  {}", s.validation_rms_dph, names.join(", "))?;
                }
            }
        }
        writeln!(out, "inputs: {}", c.inputs.join(", "))?;
        writeln!(
            out,
            "PSO on 3-fold contiguous validation of the deployed network ({} particles × {} iterations): ΔT window {} s, σ {:.4} (normalised), C {:.4e}, ε {:.3e} °/h; the SVR's own validation RMS {:.4e} °/h",
            c.pso.particles,
            c.pso.iterations,
            c.rate_window_s,
            c.params.sigma,
            c.params.c,
            c.params.epsilon,
            c.validation_rms_dph
        )?;
        writeln!(
            out,
            "{} support vectors → {} centres deployed (OLS, weights refitted); validation RMS of the deployed network {:.4e} °/h (the swarm's fitness)",
            c.support_vectors, c.centers, c.deployed_validation_rms_dph
        )?;
    }
    writeln!(out, "fit took {fit_s:.1} s\n")?;
    let roles = [("train", &a.runs), ("validate", &a.validate), ("holdout", &a.holdout)];
    let evals: Vec<(&str, RunEvaluation)> = roles
        .iter()
        .flat_map(|(role, paths)| paths.iter().map(move |p| (*role, p)))
        .map(|(role, p)| evaluate_file(&outcome.model, p).map(|e| (role, e)))
        .collect::<anyhow::Result<_>>()?;
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|(r, e)| (*r, e)).collect();
    print_table(&mut out, &rows)?;
    if let Some(search) = &outcome.bank {
        writeln!(out)?;
        for line in search.coverage.lines() {
            writeln!(out, "{line}")?;
        }
    }
    writeln!(out, "\nwrote {} ({} bytes)", text::path(&a.output), blob.len())?;
    let json = match &a.json {
        None => None,
        Some(_) => Some(serde_json::to_string_pretty(&serde_json::json!({
            "method": a.method,
            "choice": outcome.choice,
            "feature_sets": outcome.sets,
            "lag_bank_search": outcome.bank,
            "features": features_json(outcome.model.features()),
            "svr": outcome.svr,
            "fit_seconds": fit_s,
            "blob_bytes": blob.len(),
            "runs": evals.iter().map(|(role, e)| serde_json::json!({"role": role, "evaluation": e})).collect::<Vec<_>>(),
        }))?),
    };
    for (output, bytes) in [
        (model_out, Some(blob.clone())),
        (json_out, json.map(String::into_bytes)),
    ] {
        if let (Some(mut output), Some(bytes)) = (output, bytes) {
            output
                .write_all(&bytes)
                .with_context(|| format!("{}: write failed", text::path(output.path())))?;
            output.commit()?;
        }
    }
    stdout().write_all(&out)?;
    Ok(())
}

fn cmd_correlate(a: CorrelateArgs) -> anyhow::Result<()> {
    use trainer::gradients::{Selection, block_means, candidate_name, correlations, select};
    input::check_stdin_once(a.runs.iter().map(|p| p.as_path()))?;
    let selection = a.select.selection()?.unwrap_or(Selection::Threshold(PAPER_THRESHOLD));
    let blocks = block_means(&a.runs, a.block_samples)?;
    anyhow::ensure!(
        blocks.bias.len() >= 3,
        "only {} blocks of {} rows: too few to correlate",
        blocks.bias.len(),
        a.block_samples
    );
    let table = correlations(&blocks);
    let selected = select(&table, selection);
    if a.json {
        let names: Vec<String> = selected.iter().map(|&c| candidate_name(&table, c)).collect();
        let report = serde_json::json!({ "table": table, "selected": selected, "selected_names": names });
        writeln!(stdout(), "{}", serde_json::to_string_pretty(&report)?)?;
        return Ok(());
    }
    write!(
        stdout(),
        "{}",
        describe_selection(&table, &selected, &rule_name(selection))
    )?;
    Ok(())
}

/// A correlation rule as the selection line names it.
fn rule_name(selection: trainer::gradients::Selection) -> String {
    use trainer::gradients::Selection;
    match selection {
        Selection::Top(n) => format!("top {n} by |r|"),
        Selection::Threshold(t) => format!("|r| ≥ {t}"),
    }
}

/// The correlation matrix and the selection's line (chosen by `rule`), as
/// `correlate` and `fit` print them.
fn describe_selection(
    table: &trainer::gradients::CorrelationTable,
    selected: &[trainer::gradients::Candidate],
    rule: &str,
) -> String {
    use trainer::gradients::{candidate_name, format_table};
    let names: Vec<String> = selected
        .iter()
        .map(|&c| format!("{} (r = {:.3})", candidate_name(table, c), table.r[c.i][c.j]))
        .collect();
    format!(
        "{}selected ({rule}): {}\n",
        format_table(table, selected),
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join(", ")
        }
    )
}

fn cmd_blocks(a: BlocksArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.block_s.is_finite() && a.block_s > 0.0,
        "--block-s must be a positive number of seconds"
    );
    anyhow::ensure!(
        a.rate_window_s.is_finite() && (0.0..=86_400.0).contains(&a.rate_window_s),
        "--rate-window-s must be 0 … 86400 s"
    );
    let inputs: Vec<&Path> = a.runs.iter().map(|p| p.as_path()).chain(a.model.as_deref()).collect();
    input::check_stdin_once(inputs.iter().copied())?;
    let target = output::check_target(&a.output, &inputs, a.force.existing())?;
    let features = match &a.model {
        Some(model) => *read_model(model)?.0.features(),
        None => {
            let set = match (Method::Rbf.feature_set(a.features), a.coil_lag_min) {
                (set, None) => set,
                (FeatureSet::MultiScaleSecondOrder, Some(coil_lag_min)) => {
                    FeatureSet::MultiScaleLagged { coil_lag_min }
                }
                (_, Some(_)) => anyhow::bail!("--coil-lag-min needs --features multiscale-second-order"),
            };
            trainer::fit::rbf::feature_config(set, a.rate_window_s, 1.0)
        }
    };
    let set = features.set;
    // Streamed: one pass per run, only block means held.
    let blocks = RunFiles::new(&a.runs).block_means(&features, a.block_s)?;
    let mut out = Output::open(target)?;
    let names: Vec<String> = (0..set.dims()).map(|i| format!("x{i}")).collect();
    let write = |out: &mut Output| -> std::io::Result<()> {
        writeln!(out, "# features: {}", input_names(set).join(", "))?;
        writeln!(out, "run,{},target_dph", names.join(","))?;
        for i in 0..blocks.len() {
            let x: Vec<String> = (0..set.dims()).map(|k| blocks.feature(i, k).to_string()).collect();
            writeln!(out, "{},{},{}", blocks.run[i], x.join(","), blocks.y[i])?;
        }
        Ok(())
    };
    write(&mut out).with_context(|| format!("{}: write failed", text::path(&a.output)))?;
    out.commit()?;
    writeln!(stdout(), "wrote {} ({} blocks)", text::path(&a.output), blocks.len())?;
    Ok(())
}

fn cmd_decode(a: DecodeArgs) -> anyhow::Result<()> {
    let target = output::check_target(&a.output, &[&a.frames], a.force.existing())?;
    let capture = input::open(&a.frames).with_context(|| format!("{}: cannot read", text::path(&a.frames)))?;
    let mut out = Output::open(target)?;
    let decoded = trainer::frames::decode_capture(capture, &mut out).with_context(|| text::path(&a.frames))?;
    out.commit()?;
    writeln!(stdout(), "wrote {} ({} frames)", text::path(&a.output), decoded.frames)?;
    if decoded.damaged > 0 {
        eprintln!(
            "warning: {}: {} damaged frame(s) skipped, at byte offsets {:?}",
            text::path(&a.frames),
            decoded.damaged,
            decoded.damaged_at
        );
    }
    Ok(())
}

fn cmd_simulate(a: SimulateArgs) -> anyhow::Result<()> {
    if let Some(ramp) = a.ramp {
        anyhow::ensure!(
            ramp.is_finite() && ramp > 0.0 && ramp <= 20.0,
            "--ramp must be 0 … 20 °C/min"
        );
    }
    anyhow::ensure!(
        a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 10_000.0,
        "--rate-hz must be 0 … 10000 Hz"
    );
    anyhow::ensure!(
        a.hold_min.is_finite() && (1.0..=1440.0).contains(&a.hold_min),
        "--hold-min must be 1 … 1440 min"
    );
    let [lo, hi] = a.random_range[..] else {
        anyhow::bail!("--random-range takes MIN,MAX in °C")
    };
    anyhow::ensure!(
        lo.is_finite() && hi.is_finite() && lo >= -55.0 && hi <= 150.0 && hi - lo >= 5.0,
        "--random-range must lie within −55 … 150 °C (the TMP117's range) and span at least 5 °C"
    );
    let [slowest, fastest] = a.ramp_range[..] else {
        anyhow::bail!("--ramp-range takes SLOWEST,FASTEST in °C/min")
    };
    anyhow::ensure!(
        slowest.is_finite() && fastest.is_finite() && 0.01 <= slowest && slowest <= fastest && fastest <= 20.0,
        "--ramp-range must lie within 0.01 … 20 °C/min, slowest first"
    );
    if let Some(h) = a.hours {
        anyhow::ensure!(h.is_finite() && h > 0.0 && h <= 1000.0, "--hours must be 0 … 1000");
    }
    let inputs: Vec<&Path> = a
        .params
        .iter()
        .chain(&a.chamber_profile)
        .map(PathBuf::as_path)
        .collect();
    let target = output::check_target(&a.output, &inputs, a.force.existing())?;
    let unit_params = a
        .unit
        .map_or_else(SimParams::default, trainer::simulate::unit::unit_params);
    let mut run = match &a.chamber_profile {
        Some(path) => ChamberRun::planned(
            trainer::simulate::chamber_file::read_chamber_profile(path)?,
            &path.display().to_string(),
            a.seed,
        ),
        None => ChamberRun::with_profile(a.profile, a.seed),
    };
    run.ramp_c_per_min = a.ramp.unwrap_or(match a.profile {
        Profile::Designed => trainer::simulate::profile::DESIGNED_RAMP_C_PER_MIN,
        _ => 1.0,
    });
    run.hold_s = a.hold_min * 60.0;
    run.duration_s = a.hours.map(|h| h * 3600.0);
    run.sample_rate_hz = a.rate_hz;
    run.multi = a.multi;
    run.random_range_c = (lo, hi);
    run.ramp_range_c_per_min = (slowest, fastest);
    run.unit = a.unit;
    run.noise_only = a.noise_only;
    run.params = match &a.params {
        Some(path) => read_sim_params(path, &unit_params)?,
        None => unit_params,
    };
    run.params
        .check()
        .map_err(|reason| anyhow::anyhow!("cannot simulate these parameters: {reason}"))?;
    let mut out = Output::open(target)?;
    run.write_csv(&mut out)
        .with_context(|| format!("{}: write failed", text::path(&a.output)))?;
    out.commit()?;
    writeln!(stdout(), "wrote {}", text::path(&a.output))?;
    Ok(())
}

fn cmd_plan(a: PlanArgs) -> anyhow::Result<()> {
    use trainer::plan::{PlanLimits, PlotFormat};
    let limits = PlanLimits {
        min_c: a.min_c,
        max_c: a.max_c,
        max_rate_c_per_min: a.max_rate_c_per_min,
        hours: a.hours,
    };
    limits.check().map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
    let plot_format = match &a.plot {
        None => None,
        Some(path) => Some(
            match path
                .extension()
                .and_then(|e| e.to_str())
                .map(str::to_ascii_lowercase)
                .as_deref()
            {
                Some("svg") => PlotFormat::Svg,
                Some("png") => PlotFormat::Png,
                _ => anyhow::bail!("--plot {}: the file name must end in .svg or .png", text::path(path)),
            },
        ),
    };
    let outputs: Vec<&Path> = std::iter::once(a.output.as_path()).chain(a.plot.as_deref()).collect();
    let mut targets = output::check_targets(&outputs, &[], a.force.existing())?.into_iter();
    let plan = trainer::plan::design(&limits, a.seed, a.candidates).map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
    let text_out = match a.format {
        PlanFormat::SetPoints => plan.set_points_csv(),
        PlanFormat::Segments => plan.segments_csv(),
    };
    let plot = plot_format.map(|f| trainer::plan::plot(&plan, f)).transpose()?;
    for bytes in std::iter::once(text_out.into_bytes()).chain(plot) {
        let Some(target) = targets.next() else { break };
        let mut out = Output::open(target)?;
        out.write_all(&bytes)
            .with_context(|| format!("{}: write failed", text::path(out.path())))?;
        out.commit()?;
    }
    let mut out = stdout();
    writeln!(
        out,
        "wrote {} ({} segments, {:.2} h, D-criterion {:.4}, best of {} candidates; median {:.4})",
        text::path(&a.output),
        plan.segments.len(),
        plan.duration_s() / 3600.0,
        plan.criterion,
        plan.candidates,
        plan.median_criterion
    )?;
    if let Some(p) = &a.plot {
        writeln!(out, "wrote {}", text::path(p))?;
    }
    Ok(())
}

/// The simulator's parameters `base` with a JSON file's fields over them:
/// syntax errors and unknown fields name the file, line and column;
/// impossible values the field.
fn read_sim_params(path: &Path, base: &SimParams) -> anyhow::Result<SimParams> {
    let bytes = input::read_limited(path, MAX_PARAMS_BYTES, "a simulator parameter file")?;
    let json = String::from_utf8(bytes).map_err(|_| anyhow::anyhow!("{}: not UTF-8 text", text::path(path)))?;
    base.overridden(&json).map_err(|e| match e {
        ParamsError::Syntax { .. } => anyhow::anyhow!("{}:{e}", text::path(path)),
        ParamsError::Invalid(_) => anyhow::anyhow!("{}: {e}", text::path(path)),
    })
}

fn cmd_eval(a: EvalArgs) -> anyhow::Result<()> {
    let inputs: Vec<&Path> = a.runs.iter().map(|p| p.as_path()).chain([a.model.as_path()]).collect();
    input::check_stdin_once(inputs.iter().copied())?;
    let json_out = match &a.json {
        Some(path) => Some(Output::create(path, &inputs, a.force.existing())?),
        None => None,
    };
    let (model, _) = read_model(&a.model)?;
    let evals = evaluate_files(&model, &a.runs, a.uncompensated.allow_uncompensated)?;
    if let Some(mut json) = json_out {
        json.write_all(serde_json::to_string_pretty(&evals)?.as_bytes())
            .with_context(|| format!("{}: write failed", text::path(json.path())))?;
        json.commit()?;
    }
    let rows: Vec<(&str, &RunEvaluation)> = evals.iter().map(|e| ("eval", e)).collect();
    let mut out = stdout();
    print_table(&mut out, &rows)?;
    writeln!(out, "\nOverlapping Allan deviation (IEEE Std 952) of rate − reference:")?;
    print_allan_table(&mut out, &rows)?;
    Ok(())
}

/// The lag bank a fit identified, how it was chosen, and what the training runs covered.
fn print_bank(out: &mut impl Write, model: &Model, search: &fit::lag_bank::BankSearch) -> anyhow::Result<()> {
    let FeatureSet::LagBank(bank) = model.features().set else {
        return Ok(());
    };
    let list = |v: &[f32], digits: usize| v.iter().map(|x| format!("{x:.digits$}")).collect::<Vec<_>>().join(", ");
    writeln!(
        out,
        "lag bank: τ [{}] s; coil lags a [{}] min (T̂ = T + Σ a·ΔT); Shupe gain g = 1 {:+.3e}·(T − {}) {:+.3e}·(T − {})²",
        list(bank.taus(), 0),
        list(bank.coil_lags(), 2),
        bank.gain_per_c,
        bank.ref_c,
        bank.gain_per_c2,
        bank.ref_c
    )?;
    let how = match search.folds {
        fit::events::FoldKind::Runs => format!("leave-one-run-out ({} folds)", search.fold_count),
        fit::events::FoldKind::Events => format!(
            "{} folds of whole thermal events ({} events found)",
            search.fold_count, search.events
        ),
        fit::events::FoldKind::Contiguous => format!(
            "{} contiguous folds (only {} thermal events found)",
            search.fold_count, search.events
        ),
    };
    writeln!(
        out,
        "structure chosen on {how} among {} candidates; predicted RMS of 100-s means on unseen histories {:.4e} °/h",
        search.candidates.len(),
        search.predicted_rms_dph()
    )?;
    let dims = model.features().dims();
    let mut covered = Vec::new();
    for i in 0..dims {
        let (Some(name), Some((lo, hi))) = (model.features().set.name(i), model.input_range(i)) else {
            continue;
        };
        if matches!(
            name,
            rbf_core::features::InputName::Bank(rbf_core::lag_bank::BankInput::CoilTemp { power: 2.. })
        ) {
            continue;
        }
        covered.push(format!("{name} {lo:.3} … {hi:.3}"));
    }
    writeln!(out, "training covered: {}", covered.join("; "))?;
    Ok(())
}

/// The names of a feature set's inputs with units, for printing.
fn input_names(set: FeatureSet) -> Vec<String> {
    set.names().map(|n| n.to_string()).collect()
}

fn describe(model: &Model) -> String {
    let f = model.features();
    let all_names = input_names(f.set);
    let names = all_names.join(", ");
    let (taus, filters) = f.filter_taus_s();
    let windows = &taus[..filters];
    match model.body() {
        ModelBody::Rbf(net) => format!(
            "Gaussian RBF, {} centres over ({}), {}, ΔT windows {windows:?} s",
            net.centers_used(),
            all_names[..net.kernel_inputs().min(all_names.len())].join(", "),
            if net.linear().is_empty() {
                "no linear terms".to_owned()
            } else {
                format!("linear in ({names})")
            }
        ),
        ModelBody::Poly3(p) => format!("cubic in T about {} °C", p.ref_temp_c),
    }
}

fn cmd_inspect(a: InspectArgs) -> anyhow::Result<()> {
    let Some(path) = a.model.or(a.model_option) else {
        anyhow::bail!("inspect needs a model: trainer inspect MODEL.bin");
    };
    let bytes = read_blob(&path)?;
    let header = Header::parse(&bytes).map_err(|e| anyhow::anyhow!("{}: model refused: {e}", text::path(&path)))?;
    let crc = blob::crc_status(&bytes, &header);
    let decoded = crc.and_then(|_| blob::decode(&bytes));
    // Also what a valid blob leaves over: a file holds one blob.
    let problem = decoded.as_ref().ok().and_then(|_| file_problem(&bytes));
    let mut info = inspect_json(&path, &bytes, &header, &crc, &decoded);
    if let Some(problem) = &problem {
        info["valid"] = serde_json::json!(false);
        info["error"] = serde_json::json!(problem);
    }
    if a.json {
        writeln!(stdout(), "{}", serde_json::to_string_pretty(&info)?)?;
    } else {
        print_inspect(&info)?;
    }
    match (decoded, problem) {
        (Ok(_), None) => Ok(()),
        (Ok(_), Some(problem)) => Err(anyhow::anyhow!("{}: model refused: {problem}", text::path(&path))),
        (Err(e), _) => Err(anyhow::anyhow!("{}: model refused: {e}", text::path(&path))),
    }
}

fn inspect_json(
    path: &Path,
    bytes: &[u8],
    header: &Header,
    crc: &Result<(), blob::DecodeError>,
    decoded: &Result<blob::Decoded, blob::DecodeError>,
) -> serde_json::Value {
    let mut v = serde_json::json!({
        "file": text::path(path),
        "file_bytes": bytes.len(),
        "blob_bytes": header.blob_len(),
        "format_version": header.version,
        "kind": rbf_core::model::ModelKind::from_code(header.kind_code).map(|k| k.name()),
        "inputs": header.inputs,
        "centers": header.centers,
        "crc": match crc { Ok(()) => "ok".to_owned(), Err(e) => e.to_string() },
        "valid": decoded.is_ok(),
    });
    if let Ok(d) = decoded {
        let m = &d.model;
        let f = m.features();
        let ranges: Vec<_> = (0..f.dims())
            .map(|i| {
                let (lo, hi) = m.input_range(i).unwrap_or((f32::NAN, f32::NAN));
                serde_json::json!({"input": f.set.name(i).map(|n| n.to_string()), "min": lo, "max": hi})
            })
            .collect();
        v["features"] = features_json(f);
        v["training_ranges"] = serde_json::Value::Array(ranges);
        v["units"] = serde_json::json!({"bias": "deg/h", "temperature": "degC", "rate_of_change": "degC/min"});
        v["serial"] = serde_json::json!(m.info().serial.as_ref().map(|s| s.as_str()));
        match m.body() {
            ModelBody::Rbf(net) => {
                v["rbf"] = serde_json::json!({
                    "offset": net.offset(), "scale": net.scale(),
                    "widths": net.widths(), "weights_dph": net.weights(),
                    "linear_dph": net.linear(), "constant_dph": net.constant(),
                });
            }
            ModelBody::Poly3(p) => {
                v["poly3"] = serde_json::json!({"ref_temp_c": p.ref_temp_c, "coeffs": p.coeffs});
            }
        }
    } else if let Err(e) = decoded {
        v["error"] = serde_json::json!(e.to_string());
    }
    v
}

/// A model's inputs as `trainer inspect --json` and `trainer fit --json` give them.
fn features_json(f: &FeatureConfig) -> serde_json::Value {
    serde_json::json!({
        "set": match f.set {
            FeatureSet::MultiPoint(_) => "MultiPoint".to_owned(),
            FeatureSet::MultiScaleLagged { .. } => "MultiScaleLagged".to_owned(),
            FeatureSet::LagBank(_) => "LagBank".to_owned(),
            set => format!("{set:?}"),
        },
        "coil_lag_min": match f.set {
            FeatureSet::MultiScaleLagged { coil_lag_min } => Some(coil_lag_min),
            _ => None,
        },
        "inputs": input_names(f.set),
        "rate_window_s": f.rate_window_s,
        "windows_s": &f.filter_taus_s().0[..f.filter_taus_s().1],
        "lag_bank": match f.set {
            FeatureSet::LagBank(b) => Some(serde_json::json!({
                "taus_s": b.taus(),
                "coil_lag_min": b.coil_lags(),
                "ref_c": b.ref_c,
                "gain_per_c": b.gain_per_c,
                "gain_per_c2": b.gain_per_c2,
                "static_degree": b.static_degree,
                "coil_range_c": [b.coil_min_c, b.coil_max_c],
            })),
            _ => None,
        },
        "warmup_s": f.warmup_s(),
    })
}

fn print_inspect(v: &serde_json::Value) -> std::io::Result<()> {
    // Strings from the blob (the serial) are shown with control characters escaped.
    let s = |k: &str| {
        v.get(k).map_or("-".to_owned(), |x| {
            x.as_str()
                .map_or(x.to_string(), |s| text::escape_controls(s).into_owned())
        })
    };
    let mut out = stdout();
    writeln!(
        out,
        "file            {} ({} bytes, blob {} bytes)",
        s("file"),
        s("file_bytes"),
        s("blob_bytes")
    )?;
    writeln!(out, "format version  {}", s("format_version"))?;
    writeln!(out, "kind            {}", s("kind"))?;
    writeln!(out, "shape           {} inputs, {} centres", s("inputs"), s("centers"))?;
    writeln!(out, "CRC-32          {}", s("crc"))?;
    if let Some(f) = v.get("features") {
        let lag = match f["coil_lag_min"].as_u64() {
            Some(l) => format!(", coil lag L {l} min"),
            None => String::new(),
        };
        writeln!(
            out,
            "features        {} (ΔT window {} s{lag}, warm-up {} s)",
            f["inputs"], f["rate_window_s"], f["warmup_s"]
        )?;
    }
    if let Some(ranges) = v.get("training_ranges").and_then(|r| r.as_array()) {
        for r in ranges {
            writeln!(
                out,
                "  range         {:<16} {} … {}",
                r["input"].as_str().unwrap_or("?"),
                r["min"],
                r["max"]
            )?;
        }
    }
    writeln!(out, "serial          {}", s("serial"))?;
    writeln!(
        out,
        "valid           {}{}",
        s("valid"),
        v.get("error").map_or(String::new(), |e| format!(" ({e})"))
    )
}
