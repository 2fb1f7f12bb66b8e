//! `trainer plan`: design the chamber run to calibrate on.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::builder::RangedU64ValueParser;
use trainer::output::{self, Output, Transaction};
use trainer::text;

use super::common::{ForceArg, JsonArg, print_json_and_commit};

/// Design the chamber run to calibrate on: a profile the default model can be identified from.
///
/// Draws --candidates profiles from a family that holds what the lag bank needs (a power-on
/// soak at the cold end whose self-heating transient is recorded, levels across the range,
/// full-rate steps, bursts of swings, slow ramps, holds as long as the coil's slowest mode)
/// and keeps the one of largest D-criterion: the log-determinant of the information matrix of
/// the lag-bank regression on the documented gyro's plant (docs/plan.md). From 18 h (not with
/// --plain) it keeps instead the least sum of that rank and the rank by how loosely the
/// response bank's fit would pin the static curve a soak test reads. Prints the loop
/// range it predicts on that plant and on one 1.5× as slow, and warns when the loop stays short
/// of the asked range (--soak-ends closes the gap). Predicts, on both plants, what the default
/// fit on the plan's run gives: the settled spread a soak test reads and the in-use 100-s
/// cluster STD improvement (simulated, fitted and evaluated here; docs/plan.md, "Predicted
/// figures"); --settled-spread-dph designs the shortest run predicted to meet a soak spec. Writes the set
/// points `trainer simulate --chamber-profile` reads (time_s,chamber_c, piecewise linear), or
/// with --format segments the segment table a chamber controller takes. Same seed, same plan.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Example:\n  trainer plan --min-c -40 --max-c 60 --max-rate-c-per-min 5 --hours 12 -o plan.csv\n  trainer plan --min-c -40 --max-c 60 --max-rate-c-per-min 5 --hours 12 --format segments --plot plan.svg -o segments.csv\n  trainer plan --min-c -40 --max-c 60 --max-rate-c-per-min 5 --hours 36 --settled-spread-dph 0.02 -o plan.csv --json plan.json"
)]
pub struct Args {
    /// Lowest set point, °C.
    #[arg(long, value_name = "C", allow_hyphen_values = true, help_heading = "Chamber limits")]
    min_c: f64,
    /// Highest set point, °C.
    #[arg(long, value_name = "C", allow_hyphen_values = true, help_heading = "Chamber limits")]
    max_c: f64,
    /// Fastest ramp the chamber may run, °C/min (every segment stays at or below it).
    #[arg(
        long,
        value_name = "C_PER_MIN",
        allow_hyphen_values = true,
        help_heading = "Chamber limits"
    )]
    max_rate_c_per_min: f64,
    /// Longest run, hours (the last set point is at most this far in).
    #[arg(long, value_name = "H", allow_hyphen_values = true, help_heading = "Chamber limits")]
    hours: f64,
    /// What -o holds: set-points (time_s,chamber_c; what `trainer simulate --chamber-profile`
    /// reads) or segments (segment,target_c,ramp_min,hold_min; what chamber controllers take).
    #[arg(long, value_enum, default_value_t = PlanFormat::SetPoints, help_heading = "Output")]
    format: PlanFormat,
    /// Candidate profiles scored, 1–1000 (more: a higher criterion, a longer design).
    #[arg(long, value_name = "N", default_value_t = trainer::plan::limits::DEFAULT_CANDIDATES,
          value_parser = RangedU64ValueParser::<usize>::new().range(1..=1000))]
    candidates: usize,
    /// Random seed of the candidates.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Soak at both ends of the range until a loop 1.5× slower than nominal settles there.
    ///
    /// What it buys: the loop reaches the asked range (within 5 % of it), on the documented
    /// gyro and on slower designs. What it costs: the soaks take hours the steps, swings and
    /// ramps would have used, so the run excites the lags less, and on some plants the fit
    /// after it is less accurate in use (measured in docs/decisions.md). Refuses --hours too
    /// short for the soaks, saying how long they need. Without it (and without --plain), a run
    /// of 12 h or more soaks each end as long as leaves 12 h for the rest, 1.5 … 3 h (docs/plan.md,
    /// "End soaks"), a shorter one not at all: the plan drawn before end soaks existed. Its
    /// soaks are the slow plant's at the ends only.
    #[arg(long, conflicts_with = "plain")]
    soak_ends: bool,
    /// Insist on the default's band soaks: refuse a run too short for them.
    ///
    /// Besides its end soaks, the default soaks each interior 20-°C band of the range once
    /// where the run has the time: 1.5 h a band at least, 3 h at most, from the hours beyond
    /// 12 h of dynamics and the end soaks (2 h each at 24 h over −40 … 60 °C, from 22.5 h on).
    /// What they buy: a settled level in the middle of each band (−10, 10 and 30 °C over
    /// −40 … 60 °C); over twelve 24-h plan draws they lowered the soak test's settled spread
    /// on gyros that settle within a 3-h hold, as the handed-out designs do, by about a
    /// quarter, at better in-use accuracy. What they cost: dynamics; on some of the
    /// simulator's slower designs near the 0.01-°/h aim the spread rises (docs/plan.md, "Band
    /// soaks"). With this flag a run without the time is refused, saying how long it must be.
    #[arg(long, conflicts_with_all = ["plain", "soak_ends", "settled_spread_dph", "no_band_soaks"])]
    band_soaks: bool,
    /// The default's end soaks without its band soaks, whatever --hours.
    ///
    /// The default of before band soaks were: the run keeps its hours beyond the end soaks for
    /// the dynamics (docs/plan.md, "Band soaks").
    #[arg(long, conflicts_with_all = ["plain", "soak_ends", "settled_spread_dph"])]
    no_band_soaks: bool,
    /// No end soaks, whatever --hours: the plan drawn before end soaks existed.
    ///
    /// The default soaks each end of the range in a run of 12 h or more, as long as leaves 12 h
    /// for the rest, 1.5 h at least and 3 h at most: over plan draws that lowered the soak
    /// test's settled spread at about the same in-use accuracy (measured in docs/decisions.md).
    /// --plain gives the dynamics those hours instead; the handed-out designs' 12-h planned
    /// runs are --plain.
    #[arg(long, conflicts_with = "settled_spread_dph")]
    plain: bool,
    /// Design the shortest run predicted to meet this settled spread on both plants, °/h.
    ///
    /// The spread of settled bias a soak test reads after the default fit on the run (3-h
    /// holds at 25, 0, 40, -20, 60, 20, -40, 10 °C and at 10, -40, 50, -10, 30, 60, -30,
    /// 0 °C, the worse), on the documented gyro and on one 1.5× as slow. Tries whole hours from
    /// the shortest the limits allow, up to --hours, each as a plain plan, from 12 h with the
    /// default's end soaks and, where its end soaks fit, as a --soak-ends
    /// plan; writes the first length that meets it and says which family.
    /// When none within --hours does: exit 1, nothing written, the best length's figures in
    /// the message. About 10–20 s a length in a release build.
    #[arg(long, value_name = "DPH", conflicts_with = "soak_ends", help_heading = "Spec")]
    settled_spread_dph: Option<f64>,
    /// Also draw the plan (set points and the nominal loop temperature) as SVG or PNG, by extension.
    #[arg(long, value_name = "FILE.svg|png", help_heading = "Output")]
    plot: Option<PathBuf>,
    /// Plan to write.
    #[arg(short, long, value_name = "PLAN.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    json: JsonArg,
    #[command(flatten)]
    force: ForceArg,
}

/// What `trainer plan` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlanFormat {
    /// Piecewise-linear set points, time_s,chamber_c.
    SetPoints,
    /// Segment table: target °C, ramp minutes, hold minutes.
    Segments,
}

/// Runs `trainer plan`.
pub fn run(a: Args) -> anyhow::Result<()> {
    use trainer::plan::limits::PlanLimits;
    use trainer::plan::plot::PlotFormat;
    let limits = PlanLimits {
        min_c: a.min_c,
        max_c: a.max_c,
        max_rate_c_per_min: a.max_rate_c_per_min,
        hours: a.hours,
    };
    if a.soak_ends {
        limits.check_soaking_ends()
    } else {
        limits.check()
    }
    .map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
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
    if let Some(x) = a.settled_spread_dph {
        anyhow::ensure!(
            x.is_finite() && x > 0.0,
            "--settled-spread-dph {x}: must be a positive number of °/h"
        );
    }
    let outputs: Vec<&Path> = std::iter::once(a.output.as_path()).chain(a.plot.as_deref()).collect();
    let mut targets = output::check_targets(&outputs, &[], a.force.existing())?.into_iter();
    let json_out = a.json.sink(&outputs, a.force.existing())?;
    let progress = trainer::fit::Progress::new(true);
    let (plan, spec, no_prediction) = designed(&a, &limits, &progress)?;
    let text_out = match a.format {
        PlanFormat::SetPoints => plan.set_points_csv(),
        PlanFormat::Segments => plan.segments_csv(),
    };
    let plot = plot_format.map(|f| trainer::plan::plot::plot(&plan, f)).transpose()?;
    let mut transaction = Transaction::new();
    for bytes in std::iter::once(text_out.into_bytes()).chain(plot) {
        let Some(target) = targets.next() else { break };
        let mut out = Output::open(target)?;
        out.write_all(&bytes)
            .with_context(|| format!("{}: write failed", text::path(out.path())))?;
        transaction.add(out);
    }
    let mut out = Vec::new();
    writeln!(
        out,
        "wrote {} ({} segments, {:.2} h, D-criterion {:.4}, {}; median {:.4})",
        text::path(&a.output),
        plan.segments.len(),
        plan.duration_s() / 3600.0,
        plan.criterion,
        plan.choice(),
        plan.median_criterion
    )?;
    writeln!(
        out,
        "before it: the gyro unpowered at {} °C for at least {:.0} min (pre-soak)",
        plan.segments[0].target_c,
        plan.pre_soak_s() / 60.0
    )?;
    for line in plan.loop_range_lines() {
        writeln!(out, "{line}")?;
    }
    for line in plan.prediction.iter().flat_map(|p| p.lines()) {
        writeln!(out, "{line}")?;
    }
    if let Some(spec) = &spec {
        writeln!(out, "{}", spec.summary())?;
    }
    if let Some(warning) = &no_prediction {
        writeln!(out, "{warning}")?;
    }
    if let Some(p) = &a.plot {
        writeln!(out, "wrote {}", text::path(p))?;
    }
    let json_on_stdout = json_out.is_stdout();
    let json = json_out.write(&json_report(&plan, spec.as_ref()), &mut transaction)?;
    print_json_and_commit(&out, json_on_stdout, json, transaction)
}

/// The plan to write, with its prediction: designed within `limits` as
/// asked, or, with --settled-spread-dph, the shortest that meets it (an
/// error saying the best figures when none within --hours does); and the
/// warning to print when the plan is written without a prediction.
fn designed(
    a: &Args,
    limits: &trainer::plan::limits::PlanLimits,
    progress: &trainer::fit::Progress,
) -> anyhow::Result<(
    trainer::plan::Plan,
    Option<trainer::plan::spec::SpecOutcome>,
    Option<String>,
)> {
    use trainer::plan::predict::{TestBench, predict};
    progress.start("soaks and histories", 1);
    let benches = TestBench::both()?;
    progress.finish();
    match a.settled_spread_dph {
        Some(target_dph) => {
            let outcome = trainer::plan::spec::design_for_settled_spread(
                limits,
                a.seed,
                a.candidates,
                target_dph,
                &benches,
                progress,
            )?;
            match outcome.plan() {
                Some(t) => Ok((t.plan.clone(), Some(outcome), None)),
                None => anyhow::bail!("cannot plan for the spec: {}", outcome.summary()),
            }
        }
        None => {
            use trainer::plan::ends::Ends;
            let ends = match (a.soak_ends, a.plain, a.band_soaks, a.no_band_soaks) {
                (true, ..) => Ends::SlowPlant,
                (false, true, ..) => Ends::Plain,
                (false, false, true, _) => Ends::Bands,
                (false, false, false, true) => Ends::EndsOnly,
                (false, false, false, false) => Ends::Default,
            };
            let mut plan = trainer::plan::design(limits, a.seed, a.candidates, ends)
                .map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
            progress.start("predicting", 2);
            // A plan the default fit cannot learn from is still a plan: written, with the reason.
            let prediction = predict(&plan, &benches, progress);
            progress.finish();
            match prediction {
                Ok(p) => plan.prediction = Some(p),
                Err(e) => return Ok((plan, None, Some(format!("warning: no prediction for this plan: {e:#}")))),
            }
            Ok((plan, None, None))
        }
    }
}

/// `--json`: the plan's length and family, its predicted figures and, with
/// --settled-spread-dph, what the search tried.
fn json_report(plan: &trainer::plan::Plan, spec: Option<&trainer::plan::spec::SpecOutcome>) -> serde_json::Value {
    let seeds = {
        use trainer::plan::predict::*;
        serde_json::json!({
            "plan_run": PLAN_RUN_SEED,
            "soak_tests": SOAK_SEEDS,
            "random_history": RANDOM_SEED,
            "field_history": FIELD_SEED,
        })
    };
    serde_json::json!({
        "hours": plan.limits.hours,
        "duration_h": plan.duration_s() / 3600.0,
        "soak_ends": plan.end_soak_s.is_some(),
        "family": plan.ends.name(plan.end_soak_s, plan.band_soak_s),
        "end_soak_min": plan.end_soak_s.map(|s| s / 60.0),
        "hot_end_soak_min": plan.hot_end_soak_s().map(|s| s / 60.0),
        "cold_end_by_power_on": plan.pooled_hot_end_soak_s().is_some(),
        "band_soak_min": plan.band_soak_s.map(|s| s / 60.0),
        "seed": plan.seed,
        "criterion": plan.criterion,
        "static_curve_variance": plan.static_curve_variance,
        "chosen_by": if plan.chosen_by_d_alone { "d_criterion" } else { "rank_sum_d_and_static_curve" },
        "predicted": plan.prediction,
        "prediction_seeds": seeds,
        "soak_orders_c": trainer::plan::predict::SOAK_ORDERS_C,
        "settled_spread_target_dph": spec.map(|s| s.target_dph),
        "tried": spec.map(|s| s.tried.iter().map(|(h, family, spread)| serde_json::json!({
            "hours": h, "family": family, "worse_settled_spread_dph": spread,
        })).collect::<Vec<_>>()),
    })
}
