//! `cargo xtask bench-accuracy`'s in-use section: train on a chamber run,
//! verify on in-use histories the model never saw.
//!
//! For each plant (the documented gyro, two `--unit` draws, a gyro of another
//! mechanical design, then `--units` and `--designs` draws) and each training
//! scenario (the 12-h planned run `trainer plan --min-c -40 --max-c 60`
//! designs, through `trainer simulate --chamber-profile`; the −40 … 60 °C
//! cycle at 1 °C/min with 2-h holds; the designed 10.9-h multi-rate run), the
//! default `trainer fit` (or `--fit-args`) is fitted by the CLI, `trainer
//! compensate` runs on four in-use histories (two random set-point runs
//! −20 … 50 °C at 0.2 … 3 °C/min, two field histories), and the output is
//! scored by its 100-s cluster STD against the known rate (`ref_dph`), beside
//! the fit's forecast of that figure (`predicted_in_use_std100_dph`), and on
//! two soak tests of the same plant (`trainer simulate --profile soak`: 3-h
//! holds at eight levels across −40 … 60 °C, in two orders; module `soak`) by the
//! worse spread of their settled bias (`trainer eval --json`'s
//! `settled_spread_dph`), split into a static part and the order's. Beside
//! it: the lag-bank reference (bench/accuracy/lag_bank.py) on the same runs,
//! and each run's noise ceiling (the same run with `--noise-only`; for the
//! soak tests the settled spread of their noise alone, what no fit takes out,
//! and the model's own spread, each plateau less its noise alone);
//! `summary`: the forecasts' factors and each plant against the targets.

mod settled;
mod soak;
mod summary;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use serde_json::{Value, json};
use trainer::metrics::{cluster_std, improvement_pct};

use self::soak::SoakScores;
use self::summary::{
    PlantSummary, TARGET_CYCLE_MEAN_PCT, TARGET_FORECAST_FACTOR, TARGET_PLANNED_MEAN_PCT, TARGET_PLANNED_WORST_PCT,
    Training, forecast_factor, summary_table, worst_forecast_factor,
};
use super::{SoakReading, path, read_columns, run_tool};
use crate::workspace_root;

/// What the in-use section runs and where its results go.
#[derive(Clone, Debug, Default)]
pub struct InUseOptions {
    /// Two plants (the documented gyro and unit 1) instead of four.
    pub quick: bool,
    /// Also `trainer simulate --unit 3` … `--unit N` (0: none): plants the
    /// default was not developed on.
    pub units: u64,
    /// Also `trainer simulate --design 1` … `--design N` (0: none): gyros of
    /// other mechanical designs, drawn from ranges as wide as real ones.
    pub designs: u64,
    /// The trainer whose `fit` and `compensate` are judged; `None`: this
    /// workspace's release build. The simulator is always this workspace's.
    pub trainer: Option<PathBuf>,
    /// Options added to `trainer fit` (default: none, the default model).
    pub fit_args: Vec<String>,
    /// The planned chamber run every plant is trained on (`trainer simulate
    /// --chamber-profile`); `None`: the plans [`DEFAULT_PLAN`] makes.
    pub plan: Option<PathBuf>,
    /// Without `plan`: the plans of [`DEFAULT_PLAN`] with seeds 1 … this
    /// (at least 1), each a planned training of its own.
    pub plan_seeds: u64,
    /// Without `plan`: the lengths of those plans, h, each with every seed
    /// (empty: [`DEFAULT_PLAN_HOURS`]). Issue 48 judges 12 and 24.
    pub plan_hours: Vec<f64>,
}

/// A simulated gyro: label, `trainer simulate` options, whether `--quick` keeps it.
struct Plant {
    name: &'static str,
    args: &'static [&'static str],
    quick: bool,
}

/// A plant of this bench: label and `trainer simulate` options.
struct PlantSpec {
    name: String,
    args: Vec<String>,
}

/// The plants `opts` asks for: [`PLANTS`] (the first two with `--quick`), then
/// units 3 … `opts.units`, then designs 1 … `opts.designs`.
fn plants(opts: &InUseOptions) -> Vec<PlantSpec> {
    let named = PLANTS.iter().filter(|p| p.quick || !opts.quick).map(|p| PlantSpec {
        name: p.name.to_owned(),
        args: p.args.iter().map(|a| (*a).to_owned()).collect(),
    });
    let drawn = |family: &'static str, numbers: std::ops::RangeInclusive<u64>| {
        numbers.map(move |n| PlantSpec {
            name: format!("{family} {n}"),
            args: vec![format!("--{family}"), n.to_string()],
        })
    };
    named
        .chain(drawn("unit", 3..=opts.units))
        .chain(drawn("design", 1..=opts.designs))
        .collect()
}

const PLANTS: [Plant; 4] = [
    Plant {
        name: "documented gyro",
        args: &[],
        quick: true,
    },
    Plant {
        name: "unit 1",
        args: &["--unit", "1"],
        quick: true,
    },
    Plant {
        name: "unit 2",
        args: &["--unit", "2"],
        quick: false,
    },
    Plant {
        name: "other design",
        args: &["--params", "bench/accuracy/other-design.json"],
        quick: false,
    },
];

/// A simulated run: label, `trainer simulate` options, seed (plus
/// [`PLANT_SEED_STEP`] × the plant's index, so every plant meets other histories).
struct RunSpec {
    name: String,
    args: Vec<String>,
    seed: u64,
}

impl RunSpec {
    fn new(name: &str, args: &[&str], seed: u64) -> Self {
        RunSpec {
            name: name.into(),
            args: args.iter().map(|a| a.to_string()).collect(),
            seed,
        }
    }
}

const PLANT_SEED_STEP: u64 = 1000;

/// Sample rate of every run, Hz: one 100-s cluster is 100 samples.
const RATE_HZ: f64 = 1.0;

/// `trainer plan` limits of the planned runs every plant is trained on
/// unless `--plan` names another: −40 … 60 °C at 5 °C/min, the command the
/// handed-out designs' planned runs name, for `--hours` of
/// [`InUseOptions::plan_hours`].
pub const DEFAULT_PLAN: [&str; 6] = ["--min-c", "-40", "--max-c", "60", "--max-rate-c-per-min", "5"];

/// The default plan's length, h: the 12-h plan of the handed-out designs.
pub const DEFAULT_PLAN_HOURS: f64 = 12.0;

/// One planned training run's plan.
#[derive(Clone, Debug)]
struct PlannedRun {
    /// The set-point file (`trainer simulate --chamber-profile`).
    plan: PathBuf,
    /// How the tables name it.
    name: String,
    /// The plan's length, h (`None`: a `--plan` file, not designed here).
    hours: Option<f64>,
}

/// The training runs, in print order: a planned run per plan of `plans`,
/// the cycle, the designed run.
fn training_runs(plans: &[PlannedRun]) -> Vec<(Training, RunSpec)> {
    let planned = plans.iter().map(|PlannedRun { plan, name, .. }| {
        let plan = plan.to_str().expect("a UTF-8 path for the plan");
        // The same run seed: only the plan differs between the planned runs.
        (
            Training::Planned,
            RunSpec::new(&format!("planned {name}"), &["--chamber-profile", plan], 503),
        )
    });
    planned
        .chain([
            (
                Training::Cycle,
                RunSpec::new(
                    "cycle −40…60 °C, 1 °C/min, 2-h holds",
                    &["--profile", "cycle", "--ramp", "1", "--hold-min", "120"],
                    501,
                ),
            ),
            (
                Training::Designed,
                RunSpec::new("designed 10.9 h, 5 °C/min", &["--profile", "designed"], 502),
            ),
        ])
        .collect()
}

/// The in-use histories: random set points −20 … 50 °C at 0.2 … 3 °C/min
/// for 8 h, twice, and two field histories.
fn in_use_runs() -> Vec<RunSpec> {
    let random = [
        "--profile",
        "random",
        "--random-range=-20,50",
        "--ramp-range",
        "0.2,3",
        "--hours",
        "8",
    ];
    vec![
        RunSpec::new("random 1", &random, 511),
        RunSpec::new("random 2", &random, 512),
        RunSpec::new("field 1", &["--profile", "field"], 513),
        RunSpec::new("field 2", &["--profile", "field"], 514),
    ]
}

/// The plant's soak tests: issue 48's (3-h holds at 25, 0, 40, −20, 60, 20,
/// −40, 10 °C, 1 °C/min between) and one of other levels in another order
/// (the second of `bench/accuracy/one_unit_soak.py`).
fn soak_runs() -> [RunSpec; 2] {
    [
        RunSpec::new(
            "soak 25/0/40/−20/60/20/−40/10 °C, 3-h holds",
            &["--profile", "soak"],
            515,
        ),
        RunSpec::new(
            "soak 10/−40/50/−10/30/60/−30/0 °C, 3-h holds",
            &["--profile", "soak", "--soak-levels-c", "10,-40,50,-10,30,60,-30,0"],
            516,
        ),
    ]
}

/// The models compared, in print order.
const DEFAULT_MODEL: &str = "trainer fit (default)";
const LAG_BANK: &str = "lag-bank reference";

/// One model's scores on the in-use runs of one training scenario.
struct ModelScores {
    model: String,
    fit_s: f64,
    refusal: Option<String>,
    /// Residual 100-s cluster STD per in-use run, °/h.
    after_dph: Vec<f64>,
    /// Share of samples `trainer compensate` flagged as clamped (input outside
    /// the training range), per run; `None` for the lag bank.
    clamped_pct: Vec<Option<f64>>,
    /// The fit's forecast of the residual 100-s cluster STD in use
    /// (`predicted_in_use_std100_dph`), °/h; `None` for the lag bank.
    forecast_dph: Option<f64>,
    /// The structure the fit took (`structure.response_bank` of its `--json`):
    /// "response bank" or "lag bank"; `None` when it does not say.
    structure: Option<&'static str>,
    /// The fit's `--json` report (`None` for the lag bank and refusals): what
    /// a forecast can be built from, kept in the bench's JSON to study it.
    fit_report: Option<Value>,
}

impl ModelScores {
    /// The improvement on each in-use run over `before` (the uncompensated
    /// residual per run, °/h), %.
    fn improvement_pcts(&self, before: &[f64]) -> Vec<f64> {
        self.after_dph
            .iter()
            .zip(before)
            .map(|(a, b)| improvement_pct(*b, *a))
            .collect()
    }
}

/// 100-s cluster STD of `rate − ref` (`time_s`, `rate`, `ref` columns), °/h.
fn residual_std(columns: &[Vec<f64>]) -> f64 {
    let deviation: Vec<f64> = columns[1].iter().zip(&columns[2]).map(|(r, q)| r - q).collect();
    cluster_std(&columns[0], &deviation, 1.0 / RATE_HZ)
}

/// Runs the in-use section with `python` (numpy) for the lag bank; prints its
/// tables and returns its results as JSON.
pub fn bench_in_use(opts: &InUseOptions, python: &Path, dir: &Path) -> anyhow::Result<Value> {
    let started = Instant::now();
    let simulator = crate::release_trainer();
    let judged = opts.trainer.clone().unwrap_or_else(|| simulator.clone());
    let dir = dir.join("in-use");
    // A fresh directory each time: the trainer refuses to replace outputs
    // without --force, and a judged build (--trainer) may predate that flag.
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("{}: cannot clear", dir.display()))?;
    }
    std::fs::create_dir_all(&dir)?;
    let bench = Bench {
        simulator: &simulator,
        judged: &judged,
        fit_args: opts.fit_args.iter().map(String::as_str).collect(),
        python,
        lag_bank: workspace_root().join("bench/accuracy/lag_bank.py"),
        dir: &dir,
    };
    let plans = planned_runs(opts, &simulator, &dir)?;
    let training = training_runs(&plans);
    let in_use = in_use_runs();
    println!("\nin use: trained on one chamber run, verified on in-use histories it never saw");
    println!(
        "(1 Hz; 100-s cluster STD improvement against ref_dph [%], residual STD [°/h] in brackets; judged: {} fit {})",
        judged.display(),
        if bench.fit_args.is_empty() {
            "(default)".to_owned()
        } else {
            bench.fit_args.join(" ")
        }
    );
    let mut plants_json = Vec::new();
    let mut summary = Vec::new();
    let mut soak_table: Vec<SoakRow> = Vec::new();
    let mut settled_rows = Vec::new();
    let plan_hours: Vec<Option<f64>> = plans.iter().map(|p| p.hours).collect();
    for (p, plant) in plants(opts).iter().enumerate() {
        let runs = PlantRuns {
            bench: &bench,
            plant,
            index: p,
        };
        let (mut plant_json, plant_summary, soak_row) = runs.bench_plant(&training, &in_use)?;
        let verdicts = settled::verdicts(&plant_summary, &soak_row.spreads_dph, &plan_hours);
        plant_json["settled_summary"] = json!(verdicts.iter().map(settled::LengthVerdict::to_json).collect::<Vec<_>>());
        plants_json.push(plant_json);
        settled_rows.push((plant.name.clone(), verdicts));
        soak_table.push(soak_row);
        summary.push(plant_summary);
    }
    let columns: Vec<(Training, &str)> = training.iter().map(|(kind, run)| (*kind, run.name.as_str())).collect();
    print!("{}", summary_table(&summary, &columns));
    print_soak_table(&soak_table, &training);
    print!("{}", settled::settled_table(&settled_rows));
    let runtime_s = started.elapsed().as_secs_f64();
    println!("in-use section: {runtime_s:.0} s");
    Ok(json!({
        "judged_trainer": judged.display().to_string(),
        "fit_args": opts.fit_args,
        "plan": plans.first().map(|p| p.plan.display().to_string()),
        "plans": plans.iter().map(|p| p.plan.display().to_string()).collect::<Vec<_>>(),
        "plan_hours": plan_hours,
        "rate_hz": RATE_HZ,
        "targets": {
            "planned_mean_pct": TARGET_PLANNED_MEAN_PCT,
            "planned_worst_pct": TARGET_PLANNED_WORST_PCT,
            "cycle_mean_pct": TARGET_CYCLE_MEAN_PCT,
            "forecast_factor": TARGET_FORECAST_FACTOR,
            "settled_spread_dph": settled::SOAK_TARGETS_DPH
                .iter()
                .map(|(hours, dph)| json!({ "plan_hours": hours, "max_dph": dph }))
                .collect::<Vec<_>>(),
        },
        "plants": plants_json,
        "runtime_s": runtime_s,
    }))
}

/// What every plant of one bench run shares: the trainers, the lag-bank
/// reference and the directory the runs go to.
struct Bench<'a> {
    /// This workspace's trainer: the plans and every simulated run.
    simulator: &'a Path,
    /// The trainer whose `fit` and `compensate` are judged.
    judged: &'a Path,
    fit_args: Vec<&'a str>,
    /// Python with numpy, for the lag-bank reference.
    python: &'a Path,
    lag_bank: PathBuf,
    dir: &'a Path,
}

/// The planned training runs: `--plan`'s, or the default plan of each length
/// of `--plan-hours` and seeds 1 … `--plan-seeds`, made by `simulator` (the
/// plan is part of the protocol, not of the judged model).
fn planned_runs(opts: &InUseOptions, simulator: &Path, dir: &Path) -> anyhow::Result<Vec<PlannedRun>> {
    if let Some(plan) = &opts.plan {
        return Ok(vec![PlannedRun {
            plan: plan.clone(),
            name: plan
                .file_name()
                .map_or("plan".into(), |n| n.to_string_lossy().into_owned()),
            hours: None,
        }]);
    }
    let lengths = if opts.plan_hours.is_empty() {
        vec![DEFAULT_PLAN_HOURS]
    } else {
        opts.plan_hours.clone()
    };
    let mut runs = Vec::new();
    for hours in lengths {
        for seed in 1..=opts.plan_seeds.max(1) {
            // 12-h plans keep the file name of the figures measured before lengths were asked.
            let plan = if hours == DEFAULT_PLAN_HOURS {
                dir.join(format!("plan_seed{seed}.csv"))
            } else {
                dir.join(format!("plan_{hours}h_seed{seed}.csv"))
            };
            let (seed_text, hours_text) = (seed.to_string(), hours.to_string());
            let mut args = vec!["plan"];
            args.extend(DEFAULT_PLAN);
            args.extend(["--hours", &hours_text, "--seed", &seed_text, "-o", path(&plan)]);
            run_tool(simulator, &args)?;
            let name = format!("trainer plan {} --hours {hours} --seed {seed}", DEFAULT_PLAN.join(" "));
            runs.push(PlannedRun {
                plan,
                name,
                hours: Some(hours),
            });
        }
    }
    Ok(runs)
}

/// The in-use histories of one plant, simulated, and what they measure
/// before any compensation.
struct Histories {
    verify: Vec<PathBuf>,
    /// Each history's `time_s`, `rate_dph`, `ref_dph` columns.
    raw: Vec<Vec<Vec<f64>>>,
    /// Residual 100-s cluster STD uncompensated, °/h.
    before: Vec<f64>,
    /// The same of the noise-only run (thermal bias zeroed), °/h.
    ceiling: Vec<f64>,
}

/// One plant of the bench: its runs are simulated with its options and
/// seeds offset by its index.
struct PlantRuns<'a> {
    bench: &'a Bench<'a>,
    plant: &'a PlantSpec,
    index: usize,
}

impl PlantRuns<'_> {
    /// `spec` simulated for this plant as `NAME.csv` (tagged with the plant).
    fn simulate(&self, spec: &RunSpec, name: &str, noise_only: bool) -> anyhow::Result<PathBuf> {
        let file = self.bench.dir.join(format!("p{}_{name}.csv", self.index));
        let seed = self.seed(spec).to_string();
        let mut args = vec!["simulate", "--rate-hz", "1", "--seed", &seed, "-o", path(&file)];
        args.extend(spec.args.iter().map(String::as_str));
        let params;
        match self.plant.args.as_slice() {
            [flag, file] if flag == "--params" => {
                params = workspace_root().join(file);
                args.extend([flag.as_str(), path(&params)]);
            }
            other => args.extend(other.iter().map(String::as_str)),
        }
        if noise_only {
            args.push("--noise-only");
        }
        run_tool(self.bench.simulator, &args)?;
        Ok(file)
    }

    /// `spec`'s seed for this plant.
    fn seed(&self, spec: &RunSpec) -> u64 {
        spec.seed + PLANT_SEED_STEP * self.index as u64
    }

    /// The in-use histories and their noise-only twins, read and scored.
    fn histories(&self, in_use: &[RunSpec]) -> anyhow::Result<Histories> {
        let verify: Vec<PathBuf> = in_use
            .iter()
            .enumerate()
            .map(|(i, spec)| self.simulate(spec, &format!("use{i}"), false))
            .collect::<anyhow::Result<_>>()?;
        let noise: Vec<PathBuf> = in_use
            .iter()
            .enumerate()
            .map(|(i, spec)| self.simulate(spec, &format!("use{i}_noise"), true))
            .collect::<anyhow::Result<_>>()?;
        let raw: Vec<Vec<Vec<f64>>> = verify
            .iter()
            .map(|v| read_columns(v, &["time_s", "rate_dph", "ref_dph"]))
            .collect::<anyhow::Result<_>>()?;
        let before: Vec<f64> = raw.iter().map(|c| residual_std(c)).collect();
        let ceiling: Vec<f64> = noise
            .iter()
            .map(|n| Ok(residual_std(&read_columns(n, &["time_s", "rate_dph", "ref_dph"])?)))
            .collect::<anyhow::Result<_>>()?;
        Ok(Histories {
            verify,
            raw,
            before,
            ceiling,
        })
    }

    /// The soak tests' noise alone, per soak test: each simulated again with
    /// its thermal bias zeroed (`--noise-only`, same seed: the same noise the
    /// compensated test carries) and read uncompensated. Its settled spread
    /// (`before_dph`) is what no thermal model takes out of the figure; its
    /// plateaus give the model's own error ([`SoakScores::model_error_dph`]).
    /// `model`: any model of the plant (`trainer eval` asks for one; the
    /// uncompensated readings do not depend on it).
    fn soak_noise(&self, model: &Path) -> anyhow::Result<Vec<SoakReading>> {
        soak_runs()
            .iter()
            .enumerate()
            .map(|(i, spec)| {
                let noise = self.simulate(spec, &format!("soak{i}_noise"), true)?;
                let json = self.bench.dir.join(format!("p{}_soak{i}_noise.json", self.index));
                super::soak_spread(self.bench.judged, model, &noise, &json)
            })
            .collect()
    }

    /// Every training of this plant, fitted and scored on its histories;
    /// prints its table and returns its JSON, its summary row and its row
    /// of the soak table.
    fn bench_plant(
        &self,
        training: &[(Training, RunSpec)],
        in_use: &[RunSpec],
    ) -> anyhow::Result<(Value, PlantSummary, SoakRow)> {
        let plant = self.plant;
        let histories = self.histories(in_use)?;
        let before = &histories.before;
        let soaks = soak_runs()
            .iter()
            .enumerate()
            .map(|(i, spec)| self.simulate(spec, &format!("soak{i}"), false))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let mut soak_spreads = Vec::new();
        let mut training_json = Vec::new();
        let mut plant_summary = PlantSummary {
            name: plant.name.clone(),
            ..PlantSummary::default()
        };
        match plant.args.as_slice() {
            [] => println!("\nplant: {} (trainer simulate's defaults)", plant.name),
            args => println!("\nplant: {} (trainer simulate {})", plant.name, args.join(" ")),
        }
        print_header(in_use);
        print_cells("no compensation (STD [°/h])", before.iter().map(|b| format!("{b:.4}")));
        println!();
        for (s, (kind, scenario)) in training.iter().enumerate() {
            let (json, soak_spread) =
                self.bench_training(s, *kind, scenario, &histories, &soaks, &mut plant_summary)?;
            soak_spreads.push((scenario.name.clone(), soak_spread));
            training_json.push(json);
        }
        let model = (0..training.len())
            .map(|s| self.bench.dir.join(format!("p{}_train{s}.bin", self.index)))
            .find(|m| m.exists());
        let soak_noise = match model {
            Some(model) => self.soak_noise(&model)?,
            None => Vec::new(),
        };
        let soak_noise = SoakScores { readings: soak_noise };
        let soak_noise_worst = soak_noise.worst_of(|n| n.before_dph);
        let model_error: Vec<Option<f64>> = soak_spreads
            .iter()
            .map(|s| s.1.model_error_dph(&soak_noise.readings))
            .collect();
        let ceiling = &histories.ceiling;
        let ceiling_pct: Vec<f64> = ceiling
            .iter()
            .zip(before)
            .map(|(n, b)| improvement_pct(*b, *n))
            .collect();
        print_cells(
            "noise ceiling (thermal bias zeroed)",
            ceiling_pct.iter().zip(ceiling).map(|(i, n)| format!("{i:.1} ({n:.4})")),
        );
        let (mean, worst) = mean_and_worst(&ceiling_pct);
        println!(" {mean:>7.1} {worst:>7.1}");
        println!(
            "soak tests' worse settled spread [°/h] after {}",
            soak_spreads
                .iter()
                .map(|(name, s)| format!("{name}: {}", s.worst_dph().map_or("-".into(), |s| format!("{s:.4}"))))
                .collect::<Vec<_>>()
                .join("; ")
        );
        if let Some(n) = soak_noise_worst {
            println!("soak tests' settled spread from the noise alone (thermal bias zeroed): {n:.4} °/h, the worse");
            println!(
                "the model's own settled spread (each plateau less its noise alone) [°/h] after {}",
                soak_spreads
                    .iter()
                    .zip(&model_error)
                    .map(|((name, _), e)| format!("{name}: {}", e.map_or("-".into(), |e| format!("{e:.4}"))))
                    .collect::<Vec<_>>()
                    .join("; ")
            );
        }
        plant_summary.ceiling_pct = (mean, worst);
        let plant_json = json!({
            "plant": plant.name,
            "simulate_args": plant.args,
            "runs": in_use.iter().enumerate().map(|(i, spec)| json!({
                "run": spec.name,
                "simulate_args": spec.args,
                "seed": self.seed(spec),
                "before_dph": before[i],
                "noise_dph": ceiling[i],
                "noise_ceiling_pct": ceiling_pct[i],
            })).collect::<Vec<_>>(),
            "training": training_json,
            "soak_runs": soak_runs().iter().enumerate().map(|(i, spec)| json!({
                "simulate_args": spec.args,
                "seed": self.seed(spec),
                "noise_settled_spread_dph": soak_noise.readings.get(i).and_then(|n| n.before_dph).map(finite),
            })).collect::<Vec<_>>(),
            "soak_noise_settled_spread_dph": soak_noise_worst.map(finite),
            "soak_model_error_dph": model_error.iter().map(|e| e.map(finite)).collect::<Vec<_>>(),
            "forecast_worst_factor": plant_summary.target_forecast(),
            "targets_missed": plant_summary.missed_targets(),
        });
        let soak_row = SoakRow {
            plant: plant.name.clone(),
            spreads_dph: soak_spreads.into_iter().map(|s| s.1.worst_dph()).collect(),
            noise_dph: soak_noise_worst,
        };
        Ok((plant_json, plant_summary, soak_row))
    }

    /// Training `s` of this plant (`kind`, simulated from `scenario`): the
    /// judged fit and the lag-bank reference scored on the histories, the
    /// default's soak tests read; prints their rows, adds the default's
    /// scores to `summary` and returns the training's JSON and the soak tests' readings.
    fn bench_training(
        &self,
        s: usize,
        kind: Training,
        scenario: &RunSpec,
        histories: &Histories,
        soaks: &[PathBuf],
        summary: &mut PlantSummary,
    ) -> anyhow::Result<(Value, SoakScores)> {
        let (bench, tag) = (self.bench, format!("p{}", self.index));
        let train = self.simulate(scenario, &format!("train{s}"), false)?;
        let loop_c = loop_range_c(&train)?;
        let model = bench.dir.join(format!("{tag}_train{s}.bin"));
        let default = fit_and_compensate(
            bench.judged,
            &bench.fit_args,
            &train,
            &model,
            &histories.verify,
            &histories.raw,
        )?;
        let reference = lag_bank_scores(bench.python, &bench.lag_bank, &train, &histories.verify, &histories.raw)?;
        let soak_scores = match default.refusal {
            None => SoakScores {
                readings: soaks
                    .iter()
                    .enumerate()
                    .map(|(i, soak)| {
                        let json = bench.dir.join(format!("{tag}_train{s}_soak{i}.json"));
                        super::soak_spread(bench.judged, &model, soak, &json)
                    })
                    .collect::<anyhow::Result<_>>()?,
            },
            Some(_) => SoakScores::default(),
        };
        println!(
            "trained on {} (loop {:.1} … {:.1} °C):",
            scenario.name, loop_c.0, loop_c.1
        );
        // The loop range of the first plan's run (the default plan's, seed 1).
        if kind == Training::Planned && s == 0 {
            summary.planned_loop_c = loop_c;
        }
        let mut models_json = Vec::new();
        for scores in [&default, &reference] {
            models_json.push(model_row(scores, &histories.before, &soak_scores, kind, summary));
        }
        let json = json!({
            "training": scenario.name,
            "simulate_args": scenario.args,
            "seed": self.seed(scenario),
            "loop_c": [loop_c.0, loop_c.1],
            "models": models_json,
        });
        Ok((json, soak_scores))
    }
}

/// One model's row of a training: printed, its JSON returned, and for the
/// default its scores and forecast added to `summary`. `soak`: the
/// default's readings on the plant's soak tests.
fn model_row(
    scores: &ModelScores,
    before: &[f64],
    soak: &SoakScores,
    kind: Training,
    summary: &mut PlantSummary,
) -> Value {
    print_model(scores, before);
    let default = scores.model == DEFAULT_MODEL;
    if default && !soak.readings.is_empty() {
        let cells = |f: &dyn Fn(&SoakReading) -> Option<f64>| {
            let cells: Vec<String> = soak
                .readings
                .iter()
                .map(|r| f(r).map_or("- (under 2 plateaus)".into(), |s| format!("{s:.4}")))
                .collect();
            cells.join(" / ")
        };
        let split = soak.split().map_or(String::new(), |s| {
            format!(
                "; a cubic in T {:.4}, off it {:.4} RMS",
                s.static_range_dph, s.off_static_rms_dph
            )
        });
        println!(
            "    soak tests: settled spread {} °/h (inside the training range {}; uncompensated {}){split}",
            cells(&|r| r.after_dph),
            cells(&|r| r.in_range_dph),
            cells(&|r| r.before_dph)
        );
    }
    let pct = scores.improvement_pcts(before);
    let (mean, worst) = mean_and_worst(&pct);
    let forecast = worst_forecast_factor(scores.forecast_dph, &scores.after_dph);
    let predicted_settled_dph = scores
        .fit_report
        .as_ref()
        .and_then(|r| r["predicted_settled_spread_dph"].as_f64());
    let soak_read_dph: Vec<f64> = soak.readings.iter().filter_map(|r| r.after_dph).collect();
    let settled_forecast = predicted_settled_dph
        .filter(|_| !soak_read_dph.is_empty())
        .and_then(|p| worst_forecast_factor(Some(p), &soak_read_dph));
    if scores.model == DEFAULT_MODEL {
        let scored = scores.refusal.is_none().then_some((mean, worst));
        summary.default_pct.push((kind, scored));
        summary.forecast.push((kind, forecast));
        summary.settled_forecast.push((kind, settled_forecast));
    }
    json!({
        "model": scores.model,
        "fit_s": finite(scores.fit_s),
        "refusal": scores.refusal,
        "predicted_in_use_std100_dph": scores.forecast_dph.map(finite),
        "structure": scores.structure,
        "runs": scores.after_dph.iter().zip(&pct).zip(&scores.clamped_pct).map(|((a, i), c)| json!({
            "after_dph": finite(*a), "improvement_pct": finite(*i), "clamped_pct": c,
            "forecast_factor": forecast_factor(scores.forecast_dph, *a),
        })).collect::<Vec<_>>(),
        "mean_pct": finite(mean),
        "worst_pct": finite(worst),
        "forecast_worst_factor": forecast,
        "soak_settled_spread_dph": default.then(|| soak.worst_dph().map(finite)).flatten(),
        "settled_forecast_factor": default.then_some(settled_forecast).flatten(),
        "soak_tests": default.then(|| soak.readings.iter().map(|r| json!({
            "settled_spread_dph": r.after_dph.map(finite),
            "settled_spread_before_dph": r.before_dph.map(finite),
            "settled_spread_in_range_dph": r.in_range_dph.map(finite),
        })).collect::<Vec<_>>()),
        "soak_split": default.then(|| soak.split().map(|s| json!({
            "static_range_dph": finite(s.static_range_dph),
            "off_static_rms_dph": finite(s.off_static_rms_dph),
        }))).flatten(),
        "fit_report": scores.fit_report,
    })
}

/// The range of the loop temperature (`temp_c`) of a run, °C.
fn loop_range_c(run: &Path) -> anyhow::Result<(f64, f64)> {
    let temp_c = read_columns(run, &["temp_c"])?.remove(0);
    Ok(temp_c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
        (lo.min(*t), hi.max(*t))
    }))
}

/// NaN and infinities as JSON null.
fn finite(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn mean_and_worst(pct: &[f64]) -> (f64, f64) {
    let mean = pct.iter().sum::<f64>() / pct.len().max(1) as f64;
    let worst = pct.iter().copied().fold(f64::INFINITY, f64::min);
    (mean, if pct.is_empty() { f64::NAN } else { worst })
}

/// `trainer fit` on `train` (with `--json`, for its forecast), then `trainer
/// compensate` on each of `verify`, scored against `raw` (their time, rate and
/// reference columns).
fn fit_and_compensate(
    trainer: &Path,
    fit_args: &[&str],
    train: &Path,
    model: &Path,
    verify: &[PathBuf],
    raw: &[Vec<Vec<f64>>],
) -> anyhow::Result<ModelScores> {
    let report = model.with_extension("fit.json");
    let mut args = vec![
        "fit",
        "-q",
        "--force",
        path(train),
        "-o",
        path(model),
        "--json",
        path(&report),
    ];
    args.extend(fit_args);
    let started = Instant::now();
    if let Err(e) = run_tool(trainer, &args) {
        let reason = e.to_string();
        let last = reason.lines().last().unwrap_or_default();
        return Ok(ModelScores {
            model: DEFAULT_MODEL.into(),
            fit_s: f64::NAN,
            refusal: Some(last.rsplit("error: ").next().unwrap_or(last).trim().to_owned()),
            after_dph: vec![f64::NAN; verify.len()],
            clamped_pct: vec![None; verify.len()],
            forecast_dph: None,
            structure: None,
            fit_report: None,
        });
    }
    let fit_s = started.elapsed().as_secs_f64();
    let report = std::fs::read_to_string(&report).with_context(|| format!("cannot read {}", report.display()))?;
    let report: Value = serde_json::from_str(&report).context("trainer fit --json: not JSON")?;
    let forecast_dph = report["predicted_in_use_std100_dph"].as_f64();
    let structure = report["structure"]["response_bank"]
        .as_bool()
        .map(|bank| if bank { "response bank" } else { "lag bank" });
    let mut after_dph = Vec::new();
    let mut clamped_pct = Vec::new();
    for (run, raw) in verify.iter().zip(raw) {
        let out = run.with_extension(format!(
            "{}.comp.csv",
            model.file_stem().map_or("m".into(), |s| s.to_string_lossy())
        ));
        run_tool(
            trainer,
            &["compensate", "--model", path(model), path(run), "-o", path(&out)],
        )?;
        let c = read_columns(&out, &["rate_comp_dph", "flags"])?;
        anyhow::ensure!(c[0].len() == raw[0].len(), "{}: a row per input row", out.display());
        after_dph.push(residual_std(&[raw[0].clone(), c[0].clone(), raw[2].clone()]));
        let clamped = c[1].iter().filter(|f| (**f as u32) & 1 != 0).count();
        clamped_pct.push(Some(100.0 * clamped as f64 / c[1].len().max(1) as f64));
    }
    Ok(ModelScores {
        model: DEFAULT_MODEL.into(),
        fit_s,
        refusal: None,
        after_dph,
        clamped_pct,
        forecast_dph,
        structure,
        fit_report: Some(report),
    })
}

/// The lag-bank reference fitted on `train`, scored on `verify`.
fn lag_bank_scores(
    python: &Path,
    script: &Path,
    train: &Path,
    verify: &[PathBuf],
    raw: &[Vec<Vec<f64>>],
) -> anyhow::Result<ModelScores> {
    let bias: Vec<PathBuf> = verify
        .iter()
        .map(|v| {
            let stem = train.file_stem().map_or("t".into(), |s| s.to_string_lossy());
            v.with_extension(format!("{stem}.lagbank.csv"))
        })
        .collect();
    let mut cmd = Command::new(python);
    cmd.arg(script).args(["--train", path(train)]);
    for (v, b) in verify.iter().zip(&bias) {
        cmd.args(["--verify", &format!("{}={}", path(v), path(b))]);
    }
    let started = Instant::now();
    let out = cmd.output().context("cannot run lag_bank.py")?;
    if !out.status.success() {
        bail!("lag_bank.py failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let fit_s = started.elapsed().as_secs_f64();
    let mut after_dph = Vec::new();
    for (b, raw) in bias.iter().zip(raw) {
        let estimate = read_columns(b, &["bias_dph"])?.remove(0);
        anyhow::ensure!(estimate.len() == raw[0].len(), "{}: a row per input row", b.display());
        let compensated: Vec<f64> = raw[1].iter().zip(&estimate).map(|(r, e)| r - e).collect();
        after_dph.push(residual_std(&[raw[0].clone(), compensated, raw[2].clone()]));
    }
    Ok(ModelScores {
        model: LAG_BANK.into(),
        fit_s,
        refusal: None,
        clamped_pct: vec![None; after_dph.len()],
        after_dph,
        forecast_dph: None,
        structure: None,
        fit_report: None,
    })
}

/// One plant's row of the soak table.
struct SoakRow {
    plant: String,
    /// The worse settled spread after each training's default fit, °/h.
    spreads_dph: Vec<Option<f64>>,
    /// The worse of the soak tests' noise alone, °/h
    /// ([`PlantRuns::soak_noise`]; `None` where every fit was refused).
    noise_dph: Option<f64>,
}

/// The soak test's settled spread after the default's fit, °/h: a row per
/// plant, a column per training run (`-`: fit refused, or under two plateaus),
/// and the spread the noise alone gives.
fn print_soak_table(rows: &[SoakRow], training: &[(Training, RunSpec)]) {
    println!(
        "\nsoak tests (simulate --profile soak, two orders): the worse settled spread after compensation [°/h], trained on"
    );
    print!("{:<22}", "plant");
    for (k, (kind, _)) in training.iter().enumerate() {
        print!(" {:>12}", format!("{kind:?} {}", k + 1).to_lowercase());
    }
    println!(" {:>12}", "noise alone");
    let cell = |s: Option<f64>| s.map_or("-".into(), |s| format!("{s:.4}"));
    for row in rows {
        print!("{:<22}", row.plant);
        for s in &row.spreads_dph {
            print!(" {:>12}", cell(*s));
        }
        println!(" {:>12}", cell(row.noise_dph));
    }
    let names: Vec<String> = training
        .iter()
        .enumerate()
        .map(|(k, (_, run))| format!("{} {}", k + 1, run.name))
        .collect();
    println!("({})", names.join("; "));
}

const LABEL_WIDTH: usize = 38;
const CELL_WIDTH: usize = 16;

fn print_cells(label: &str, cells: impl Iterator<Item = String>) {
    print!("{label:<LABEL_WIDTH$}");
    for c in cells {
        print!(" {c:>CELL_WIDTH$}");
    }
}

fn print_header(in_use: &[RunSpec]) {
    print_cells("", in_use.iter().map(|r| r.name.clone()));
    println!(" {:>7} {:>7} {:>8}", "mean", "worst", "fit [s]");
}

fn print_model(scores: &ModelScores, before: &[f64]) {
    let label = format!("  {}", scores.model);
    if let Some(reason) = &scores.refusal {
        println!("{label:<LABEL_WIDTH$} fit refused: {reason}");
        return;
    }
    let pct = scores.improvement_pcts(before);
    print_cells(
        &label,
        pct.iter()
            .zip(&scores.after_dph)
            .map(|(i, a)| format!("{i:.1} ({a:.4})")),
    );
    let (mean, worst) = mean_and_worst(&pct);
    println!(" {mean:>7.1} {worst:>7.1} {:>8.1}", scores.fit_s);
    // trainer compensate's flag 1: inputs outside the training range (extrapolation).
    if scores.clamped_pct.iter().any(Option::is_some) {
        print_cells(
            "    samples flagged clamped [%]",
            scores
                .clamped_pct
                .iter()
                .map(|c| c.map_or("-".into(), |c| format!("{c:.1}"))),
        );
        println!();
    }
    // The forecast against each run's residual (f/m), then the worst factor max(f/m, m/f).
    if let Some(forecast_dph) = scores.forecast_dph {
        print_cells(
            &format!("    forecast {forecast_dph:.4} °/h / measured"),
            scores.after_dph.iter().map(|a| format!("{:.2}", forecast_dph / a)),
        );
        let worst = worst_forecast_factor(scores.forecast_dph, &scores.after_dph);
        let worst = worst.map_or("-".into(), |f| format!("worst ×{f:.2}"));
        println!(" {worst:>15}  {}", scores.structure.unwrap_or_default());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn designs_join_the_plants_after_the_units_so_earlier_plants_keep_their_seeds() {
        let names = |opts: &InUseOptions| -> Vec<(String, Vec<String>)> {
            plants(opts).into_iter().map(|p| (p.name, p.args)).collect()
        };
        let without = names(&InUseOptions {
            units: 4,
            ..InUseOptions::default()
        });
        let with = names(&InUseOptions {
            units: 4,
            designs: 2,
            ..InUseOptions::default()
        });
        // Each plant's seeds follow its index: adding designs moves no plant before them.
        assert_eq!(with[..without.len()], without[..]);
        assert_eq!(without.len(), 6);
        assert_eq!(without[4].1, ["--unit", "3"]);
        assert_eq!(
            with[without.len()..],
            [
                ("design 1".to_owned(), vec!["--design".to_owned(), "1".to_owned()]),
                ("design 2".to_owned(), vec!["--design".to_owned(), "2".to_owned()]),
            ]
        );
        let quick = names(&InUseOptions {
            quick: true,
            designs: 1,
            ..InUseOptions::default()
        });
        let quick: Vec<&str> = quick.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(quick, ["documented gyro", "unit 1", "design 1"]);
    }

    #[test]
    fn every_plant_trains_on_the_planned_run_first_and_the_cycle_keeps_its_seed() {
        let planned = |plan: &str, name: &str| PlannedRun {
            plan: PathBuf::from(plan),
            name: name.to_owned(),
            hours: None,
        };
        let runs = training_runs(&[planned("/tmp/p.csv", "p.csv")]);
        let kinds: Vec<Training> = runs.iter().map(|(k, _)| *k).collect();
        assert_eq!(kinds, [Training::Planned, Training::Cycle, Training::Designed]);
        assert_eq!(runs[0].1.args, ["--chamber-profile", "/tmp/p.csv"]);
        assert_eq!(runs[0].1.name, "planned p.csv");
        // The cycle and designed runs are those of the figures measured before the planned run joined.
        assert_eq!((runs[1].1.seed, runs[2].1.seed), (501, 502));
        assert!(
            runs[1]
                .1
                .args
                .join(" ")
                .contains("--profile cycle --ramp 1 --hold-min 120")
        );
        // Several plans: one planned run each, first, on the same run seed.
        let plans = [1, 2].map(|k| planned(&format!("/tmp/p{k}.csv"), &format!("seed {k}")));
        let seeded = training_runs(&plans);
        let kinds: Vec<Training> = seeded.iter().map(|(k, _)| *k).collect();
        assert_eq!(
            kinds,
            [
                Training::Planned,
                Training::Planned,
                Training::Cycle,
                Training::Designed
            ]
        );
        assert_eq!(seeded[1].1.args, ["--chamber-profile", "/tmp/p2.csv"]);
        assert_eq!(seeded[0].1.seed, seeded[1].1.seed);
    }
}
