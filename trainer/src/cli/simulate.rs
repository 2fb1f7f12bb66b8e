//! `trainer simulate`: write a simulated IFOG run.

use std::path::{Path, PathBuf};

use anyhow::Context;
use trainer::output::{self, Output, Transaction};
use trainer::reading::limits::{
    MAX_PARAMS_BYTES, MAX_SIM_HOURS, MAX_SIM_OUTPUT_BYTES, MIN_RUN_ROWS, MIN_SAMPLE_RATE_HZ, SIM_BYTES_PER_FIELD,
};
use trainer::simulate::unit::Family;
use trainer::simulate::{ChamberRun, ParamsError, Profile, SimParams};
use trainer::{reading::input, text};

use super::common::{ForceArg, print_and_commit};
use super::values::ProfileArg;

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
/// draws a whole gyro from documented ranges, --design N one of another
/// mechanical design from wider ones. Same seed, same file.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  trainer simulate --profile field --unit 3 --seed 7 -o field.csv\n  \
                        trainer simulate --chamber-profile plan.csv --design 7 -o planned.csv\n  \
                        trainer simulate --profile cycle --axes 3 -o imu-cycle.csv\n  \
                        trainer simulate --profile soak --design 7 -o soak.csv"
)]
pub struct Args {
    /// Temperature history (docs/simulator.md, "Profiles").
    ///
    /// Chamber: ifog, cycle, random, designed, soak; in use: cold-start, ambient-steps, swings,
    /// day-cycle, field.
    #[arg(long, value_enum, default_value_t = ProfileArg::Ifog, conflicts_with = "chamber_profile",
          help_heading = "Data")]
    profile: ProfileArg,
    /// A planned chamber run: CSV of time_s,chamber_c set points.
    ///
    /// Piecewise linear, as `trainer plan` writes it.
    #[arg(long, value_name = "PLAN.csv", help_heading = "Data")]
    chamber_profile: Option<PathBuf>,
    /// Random seed.
    #[arg(long, default_value_t = 1, help_heading = "Data")]
    seed: u64,
    /// Another gyro of the same kind, drawn by seed N.
    ///
    /// Every plant and bias constant drawn from the documented unit-to-unit ranges,
    /// seeded by N (--params overrides fields of it).
    #[arg(long, value_name = "N", help_heading = "Model")]
    unit: Option<u64>,
    /// A gyro of another mechanical design, drawn by seed N.
    ///
    /// Every plant and bias constant drawn from the documented design ranges, wider than a
    /// unit's: time constants, self-heating, thermometer lag, each coil layer with its own
    /// Shupe residual of either sign (--params overrides fields of it).
    #[arg(long, value_name = "N", conflicts_with = "unit", help_heading = "Model")]
    design: Option<u64>,
    /// Chamber ramp between set points, °C/min.
    ///
    /// ifog and cycle: 1 (the RLG paper used 1, 2, 3, 5); designed: 5.
    #[arg(
        long = "ramp-c-per-min",
        alias = "ramp",
        value_name = "C_PER_MIN",
        help_heading = "Data"
    )]
    ramp_c_per_min: Option<f64>,
    /// Gyro sample rate, Hz.
    #[arg(
        long = "sample-rate-hz",
        alias = "rate-hz",
        value_name = "HZ",
        default_value_t = 1.0,
        help_heading = "Data"
    )]
    sample_rate_hz: f64,
    /// Hold at each set point, minutes (ifog and cycle).
    #[arg(long, value_name = "MINUTES", default_value_t = 120.0, help_heading = "Data")]
    hold_min: f64,
    /// Total length, hours.
    ///
    /// Cuts the profile or extends its last hold (random: 8 h and the hold it is in;
    /// cold-start 4, ambient-steps 6, swings 4, day-cycle 24, field 8 h).
    #[arg(long, value_name = "H", help_heading = "Data")]
    hours: Option<f64>,
    /// Set-point range of the random profile, °C, as MIN,MAX.
    #[arg(long = "random-range-c", alias = "random-range", value_name = "MIN,MAX", value_delimiter = ',',
          allow_hyphen_values = true, default_values_t = [-40.0, 60.0], help_heading = "Data")]
    random_range_c: Vec<f64>,
    /// Ramp range of the random profile, °C/min, as SLOWEST,FASTEST.
    #[arg(long = "ramp-range-c-per-min", alias = "ramp-range", value_name = "MIN,MAX",
          value_delimiter = ',', default_values_t = [0.5, 5.0], help_heading = "Data")]
    ramp_range_c_per_min: Vec<f64>,
    /// Levels of the soak profile, °C, in order, as A,B,C,….
    ///
    /// Default 25,0,40,-20,60,20,-40,10 (issue 48's soak test); 1 … 32 levels within
    /// −55 … 150 °C.
    #[arg(
        long = "soak-levels-c",
        value_name = "C,...",
        value_delimiter = ',',
        allow_hyphen_values = true,
        help_heading = "Data"
    )]
    soak_levels_c: Option<Vec<f64>>,
    /// Hold at each level of the soak profile, hours [default: 3].
    #[arg(long = "soak-hold-h", value_name = "H", help_heading = "Data")]
    soak_hold_h: Option<f64>,
    /// Zero every thermal bias term: the run's noise alone.
    ///
    /// The same run sample for sample without its thermal bias (the run's noise ceiling).
    #[arg(long, help_heading = "Model")]
    noise_only: bool,
    /// Write 8 thermometers temp_a … temp_h (multi-point runs).
    ///
    /// At different places (temp_c is the loop sensor), with the axial-gradient bias they
    /// reveal (RLG paper).
    #[arg(long, help_heading = "Multi-point")]
    multi: bool,
    /// Write a multi-axis IMU run of N axes (1–3): x, y, z.
    ///
    /// Up to three coils in one housing, each with its own static and Shupe coefficients,
    /// radial-gradient gain and coil time constants (docs/simulator.md, "Multi-axis IMUs"),
    /// written as rate_<axis>_dph, temp_<axis>_c (its loop sensor) and ref_<axis>_dph.
    #[arg(long, value_name = "N", conflicts_with = "multi", help_heading = "Multi-axis",
          value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=3))]
    axes: Option<usize>,
    /// With --axes: one temp_c (the x coil's loop sensor) serves every axis.
    #[arg(long, requires = "axes", help_heading = "Multi-axis")]
    shared_thermometer: bool,
    /// JSON overriding simulator constants (another gyro).
    ///
    /// Overrides any of the thermal network's time constants and the bias and noise
    /// coefficients (docs/simulator.md lists every field, its unit and default; with --unit,
    /// over that unit's), e.g.
    /// {"plant": {"tau_top_s": 2400}, "gyro": {"axial_gradient_dph_per_c": 0.05}}.
    /// The run's header records them (# simulator_params).
    #[arg(long, value_name = "FILE.json", help_heading = "Model")]
    params: Option<PathBuf>,
    /// Run to write.
    #[arg(short, long, value_name = "RUN.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Runs `trainer simulate`.
pub fn run(a: Args) -> anyhow::Result<()> {
    if let Some(ramp) = a.ramp_c_per_min {
        anyhow::ensure!(
            ramp.is_finite() && ramp > 0.0 && ramp <= 20.0,
            "--ramp-c-per-min {ramp}: must be more than 0 and at most 20 °C/min"
        );
    }
    anyhow::ensure!(
        a.sample_rate_hz.is_finite() && (MIN_SAMPLE_RATE_HZ..=MAX_SIM_RATE_HZ).contains(&a.sample_rate_hz),
        "--sample-rate-hz {}: must be {MIN_SAMPLE_RATE_HZ} … {MAX_SIM_RATE_HZ} Hz (the lowest rate a recorded run may have, the fastest simulated)",
        a.sample_rate_hz
    );
    anyhow::ensure!(
        a.hold_min.is_finite() && (1.0..=1440.0).contains(&a.hold_min),
        "--hold-min must be 1 … 1440 min"
    );
    let [lo, hi] = a.random_range_c[..] else {
        anyhow::bail!("--random-range-c takes MIN,MAX in °C")
    };
    anyhow::ensure!(
        lo.is_finite() && hi.is_finite() && lo >= -55.0 && hi <= 150.0 && hi - lo >= 5.0,
        "--random-range-c must lie within −55 … 150 °C (the TMP117's range) and span at least 5 °C"
    );
    let [slowest, fastest] = a.ramp_range_c_per_min[..] else {
        anyhow::bail!("--ramp-range-c-per-min takes SLOWEST,FASTEST in °C/min")
    };
    anyhow::ensure!(
        slowest.is_finite() && fastest.is_finite() && 0.01 <= slowest && slowest <= fastest && fastest <= 20.0,
        "--ramp-range-c-per-min must lie within 0.01 … 20 °C/min, slowest first"
    );
    if let Some(levels) = &a.soak_levels_c {
        anyhow::ensure!(
            (1..=32).contains(&levels.len()) && levels.iter().all(|c| c.is_finite() && (-55.0..=150.0).contains(c)),
            "--soak-levels-c takes 1 … 32 levels within −55 … 150 °C (the TMP117's range)"
        );
    }
    if let Some(h) = a.soak_hold_h {
        anyhow::ensure!(
            h.is_finite() && h > 0.0 && h <= 48.0,
            "--soak-hold-h {h}: must be more than 0 and at most 48 h"
        );
    }
    anyhow::ensure!(
        profile_is_soak(a.profile) || (a.soak_levels_c.is_none() && a.soak_hold_h.is_none()),
        "--soak-levels-c and --soak-hold-h shape the soak profile: add --profile soak"
    );
    if let Some(h) = a.hours {
        anyhow::ensure!(
            h.is_finite() && h > 0.0 && h <= MAX_SIM_HOURS,
            "--hours {h}: must be more than 0 and at most {MAX_SIM_HOURS} h"
        );
    }
    let inputs: Vec<&Path> = a
        .params
        .iter()
        .chain(&a.chamber_profile)
        .map(PathBuf::as_path)
        .collect();
    let target = output::check_target(&a.output, &inputs, a.force.existing())?;
    let drawn = match (a.unit, a.design) {
        (Some(n), _) => Some((Family::Unit, n)),
        (None, Some(n)) => Some((Family::Design, n)),
        (None, None) => None,
    };
    let drawn_params = drawn.map_or_else(SimParams::default, |(family, n)| family.params(n));
    let profile = Profile::from(a.profile);
    let mut run = match &a.chamber_profile {
        Some(path) => ChamberRun::planned(
            trainer::simulate::chamber_file::read_chamber_profile(path)?,
            &path.display().to_string(),
            a.seed,
        ),
        None => ChamberRun::with_profile(profile, a.seed),
    };
    run.ramp_c_per_min = a.ramp_c_per_min.unwrap_or(match profile {
        Profile::Designed => trainer::simulate::profile::DESIGNED_RAMP_C_PER_MIN,
        _ => 1.0,
    });
    run.hold_s = a.hold_min * 60.0;
    run.duration_s = a.hours.map(|h| h * 3600.0);
    run.sample_rate_hz = a.sample_rate_hz;
    run.multi = a.multi;
    run.random_range_c = (lo, hi);
    run.ramp_range_c_per_min = (slowest, fastest);
    if let Some(levels) = &a.soak_levels_c {
        run.soak_levels_c.clone_from(levels);
    }
    if let Some(h) = a.soak_hold_h {
        run.soak_hold_s = h * 3600.0;
    }
    run.drawn = drawn;
    run.noise_only = a.noise_only;
    run.params = match &a.params {
        Some(path) => read_sim_params(path, &drawn_params)?,
        None => drawn_params,
    };
    run.params
        .check()
        .map_err(|reason| anyhow::anyhow!("cannot simulate these parameters: {reason}"))?;
    check_extent(&run, a.axes, a.chamber_profile.as_deref())?;
    let mut out = Output::open(target)?;
    match a.axes {
        Some(axes) => trainer::simulate::axes::write_axes_csv(&run, axes, a.shared_thermometer, &mut out),
        None => run.write_csv(&mut out),
    }
    .with_context(|| format!("{}: write failed", text::path(&a.output)))?;
    let printed = format!("wrote {}\n", text::path(&a.output));
    print_and_commit(printed.as_bytes(), false, Transaction::of(out))
}

/// Whether `profile` is the soak profile (the only one `--soak-levels-c` and `--soak-hold-h` shape).
fn profile_is_soak(profile: ProfileArg) -> bool {
    matches!(profile, ProfileArg::Soak)
}

/// Fastest sample rate `trainer simulate` writes, Hz.
const MAX_SIM_RATE_HZ: f64 = 10_000.0;

/// Refuses, before anything is written, a run past the simulator's limits
/// (whatever set its length: --hours, the profile, a --chamber-profile) or
/// one the recorded-run reader would refuse for too few rows.
/// `chamber_profile`: the file that set the schedule, named in the messages.
fn check_extent(run: &ChamberRun, axes: Option<usize>, chamber_profile: Option<&Path>) -> anyhow::Result<()> {
    let (duration_s, rows) = run.extent();
    let from = chamber_profile.map_or(String::new(), |p| format!("{}: ", text::path(p)));
    anyhow::ensure!(
        duration_s.is_finite() && duration_s <= MAX_SIM_HOURS * 3600.0,
        "{from}the run would last {:.1} h; at most {MAX_SIM_HOURS} h are simulated (the limit): cut it with --hours or a shorter profile",
        duration_s / 3600.0
    );
    anyhow::ensure!(
        rows >= MIN_RUN_ROWS,
        "{from}the run would hold {rows} samples ({duration_s:.3e} s at {} Hz); a recorded run needs at least {MIN_RUN_ROWS}: lengthen it (--hours) or raise --sample-rate-hz",
        run.sample_rate_hz
    );
    let columns: u64 = match (axes, run.multi) {
        (Some(n), _) => 1 + 3 * n as u64,
        (None, true) => 3 + 8,
        (None, false) => 4,
    };
    let estimate = rows.saturating_mul(columns * SIM_BYTES_PER_FIELD);
    anyhow::ensure!(
        estimate <= MAX_SIM_OUTPUT_BYTES,
        "the run would take about {:.1} GB ({rows} rows of {columns} columns); at most {} are written (the limit): shorten --hours or lower --sample-rate-hz",
        estimate as f64 / 1e9,
        trainer::reading::limits::bytes(MAX_SIM_OUTPUT_BYTES)
    );
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
