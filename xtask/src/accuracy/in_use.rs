//! `cargo xtask bench-accuracy`'s in-use section: train on a chamber run,
//! verify on in-use histories the model never saw.
//!
//! For each plant (the documented gyro, two `--unit` draws, a gyro of another
//! mechanical design) and each training scenario (the −40 … 60 °C cycle at
//! 1 °C/min with 2-h holds; the designed 10.9-h multi-rate run), the default
//! `trainer fit` (or `--fit-args`) is fitted by the CLI, `trainer compensate`
//! runs on four in-use histories (two random set-point runs −20 … 50 °C at
//! 0.2 … 3 °C/min, two field histories), and the output is scored by its
//! 100-s cluster STD against the known rate (`ref_dph`). Beside it: the
//! lag-bank reference (bench/accuracy/lag_bank.py) on the same runs, and each
//! run's noise ceiling (the same run with `--noise-only`).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use serde_json::{Value, json};
use trainer::metrics::{cluster_std, improvement_pct};

use super::{path, run_tool};
use crate::workspace_root;

/// What the in-use section runs and where its results go.
#[derive(Clone, Debug, Default)]
pub struct InUseOptions {
    /// Two plants (the documented gyro and unit 1) instead of four.
    pub quick: bool,
    /// Also `trainer simulate --unit 3` … `--unit N` (0: none): plants the
    /// default was not developed on.
    pub units: u64,
    /// The trainer whose `fit` and `compensate` are judged; `None`: this
    /// workspace's release build. The simulator is always this workspace's.
    pub trainer: Option<PathBuf>,
    /// Options added to `trainer fit` (default: none, the default model).
    pub fit_args: Vec<String>,
    /// A planned chamber run (`trainer simulate --chamber-profile`) to train on
    /// as a third scenario.
    pub plan: Option<PathBuf>,
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
/// units 3 … `opts.units`.
fn plants(opts: &InUseOptions) -> Vec<PlantSpec> {
    let named = PLANTS.iter().filter(|p| p.quick || !opts.quick).map(|p| PlantSpec {
        name: p.name.to_owned(),
        args: p.args.iter().map(|a| (*a).to_owned()).collect(),
    });
    let units = (3..=opts.units).map(|u| PlantSpec {
        name: format!("unit {u}"),
        args: vec!["--unit".into(), u.to_string()],
    });
    named.chain(units).collect()
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

/// The training runs: the cycle, the designed run and, when given, a planned chamber run.
fn training_runs(plan: Option<&Path>) -> Vec<RunSpec> {
    let mut runs = vec![
        RunSpec::new(
            "cycle −40…60 °C, 1 °C/min, 2-h holds",
            &["--profile", "cycle", "--ramp", "1", "--hold-min", "120"],
            501,
        ),
        RunSpec::new("designed 10.9 h, 5 °C/min", &["--profile", "designed"], 502),
    ];
    if let Some(plan) = plan {
        let name = plan.file_name().map_or("plan".into(), |n| n.to_string_lossy());
        let plan = plan.to_str().expect("a UTF-8 path for the plan");
        runs.push(RunSpec::new(
            &format!("planned {name}"),
            &["--chamber-profile", plan],
            503,
        ));
    }
    runs
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
}

/// The named columns of a CSV with `#` metadata lines, in the order asked.
pub(super) fn read_columns(file: &Path, names: &[&str]) -> anyhow::Result<Vec<Vec<f64>>> {
    let text = std::fs::read_to_string(file).with_context(|| format!("cannot read {}", file.display()))?;
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let index: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .with_context(|| format!("{}: no column {n}", file.display()))
        })
        .collect::<anyhow::Result<_>>()?;
    let mut columns = vec![Vec::new(); names.len()];
    for (row, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        for (column, &i) in columns.iter_mut().zip(&index) {
            let value = fields.get(i).and_then(|f| f.parse().ok());
            column.push(value.with_context(|| format!("{}: data row {}: bad field", file.display(), row + 1))?);
        }
    }
    Ok(columns)
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
    let simulator = workspace_root().join("target/release/trainer");
    let judged = opts.trainer.clone().unwrap_or_else(|| simulator.clone());
    let lag_bank = workspace_root().join("bench/accuracy/lag_bank.py");
    let dir = dir.join("in-use");
    // A fresh directory each time: the trainer refuses to replace outputs
    // without --force, and a judged build (--trainer) may predate that flag.
    if dir.exists() {
        std::fs::remove_dir_all(&dir).with_context(|| format!("{}: cannot clear", dir.display()))?;
    }
    std::fs::create_dir_all(&dir)?;
    let fit_args: Vec<&str> = opts.fit_args.iter().map(String::as_str).collect();
    let training = training_runs(opts.plan.as_deref());
    let in_use = in_use_runs();
    println!("\nin use: trained on one chamber run, verified on in-use histories it never saw");
    println!(
        "(1 Hz; 100-s cluster STD improvement against ref_dph [%], residual STD [°/h] in brackets; judged: {} fit {})",
        judged.display(),
        if fit_args.is_empty() {
            "(default)".to_owned()
        } else {
            fit_args.join(" ")
        }
    );
    let mut plants_json = Vec::new();
    let mut summary = Vec::new();
    let plants = plants(opts);
    for (p, plant) in plants.iter().enumerate() {
        let tag = format!("p{p}");
        let simulate = |spec: &RunSpec, name: &str, noise_only: bool| -> anyhow::Result<PathBuf> {
            let file = dir.join(format!("{tag}_{name}.csv"));
            let seed = (spec.seed + PLANT_SEED_STEP * p as u64).to_string();
            let mut args = vec!["simulate", "--rate-hz", "1", "--seed", &seed, "-o", path(&file)];
            args.extend(spec.args.iter().map(String::as_str));
            let params;
            match plant.args.as_slice() {
                [flag, file] if flag == "--params" => {
                    params = workspace_root().join(file);
                    args.extend([flag.as_str(), path(&params)]);
                }
                other => args.extend(other.iter().map(String::as_str)),
            }
            if noise_only {
                args.push("--noise-only");
            }
            run_tool(&simulator, &args)?;
            Ok(file)
        };
        let verify: Vec<PathBuf> = in_use
            .iter()
            .enumerate()
            .map(|(i, spec)| simulate(spec, &format!("use{i}"), false))
            .collect::<anyhow::Result<_>>()?;
        let noise: Vec<PathBuf> = in_use
            .iter()
            .enumerate()
            .map(|(i, spec)| simulate(spec, &format!("use{i}_noise"), true))
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
        let mut training_json = Vec::new();
        match plant.args.as_slice() {
            [] => println!("\nplant: {} (trainer simulate's defaults)", plant.name),
            args => println!("\nplant: {} (trainer simulate {})", plant.name, args.join(" ")),
        }
        print_header(&in_use);
        print_cells("no compensation (STD [°/h])", before.iter().map(|b| format!("{b:.4}")));
        println!();
        for (s, scenario) in training.iter().enumerate() {
            let train = simulate(scenario, &format!("train{s}"), false)?;
            let model = dir.join(format!("{tag}_train{s}.bin"));
            let default = fit_and_compensate(&judged, &fit_args, &train, &model, &verify, &raw)?;
            let reference = lag_bank_scores(python, &lag_bank, &train, &verify, &raw)?;
            println!("trained on {}:", scenario.name);
            let mut models_json = Vec::new();
            for scores in [&default, &reference] {
                print_model(scores, &before);
                let pct: Vec<f64> = scores
                    .after_dph
                    .iter()
                    .zip(&before)
                    .map(|(a, b)| improvement_pct(*b, *a))
                    .collect();
                let (mean, worst) = mean_and_worst(&pct);
                summary.push((
                    plant.name.as_str(),
                    s,
                    scores.model.clone(),
                    mean,
                    worst,
                    scores.refusal.is_some(),
                ));
                models_json.push(json!({
                    "model": scores.model,
                    "fit_s": finite(scores.fit_s),
                    "refusal": scores.refusal,
                    "runs": scores.after_dph.iter().zip(&pct).zip(&scores.clamped_pct).map(|((a, i), c)| json!({
                        "after_dph": finite(*a), "improvement_pct": finite(*i), "clamped_pct": c,
                    })).collect::<Vec<_>>(),
                    "mean_pct": finite(mean),
                    "worst_pct": finite(worst),
                }));
            }
            training_json.push(json!({
                "training": scenario.name,
                "simulate_args": scenario.args,
                "seed": scenario.seed + PLANT_SEED_STEP * p as u64,
                "models": models_json,
            }));
        }
        let ceiling_pct: Vec<f64> = ceiling
            .iter()
            .zip(&before)
            .map(|(n, b)| improvement_pct(*b, *n))
            .collect();
        print_cells(
            "noise ceiling (thermal bias zeroed)",
            ceiling_pct
                .iter()
                .zip(&ceiling)
                .map(|(i, n)| format!("{i:.1} ({n:.4})")),
        );
        let (mean, worst) = mean_and_worst(&ceiling_pct);
        println!(" {mean:>7.1} {worst:>7.1}");
        summary.push((
            plant.name.as_str(),
            training.len(),
            "noise ceiling".into(),
            mean,
            worst,
            false,
        ));
        plants_json.push(json!({
            "plant": plant.name,
            "simulate_args": plant.args,
            "runs": in_use.iter().enumerate().map(|(i, spec)| json!({
                "run": spec.name,
                "simulate_args": spec.args,
                "seed": spec.seed + PLANT_SEED_STEP * p as u64,
                "before_dph": before[i],
                "noise_dph": ceiling[i],
                "noise_ceiling_pct": ceiling_pct[i],
            })).collect::<Vec<_>>(),
            "training": training_json,
        }));
    }
    print_summary(&summary, &training);
    let runtime_s = started.elapsed().as_secs_f64();
    println!("in-use section: {runtime_s:.0} s");
    Ok(json!({
        "judged_trainer": judged.display().to_string(),
        "fit_args": opts.fit_args,
        "rate_hz": RATE_HZ,
        "plants": plants_json,
        "runtime_s": runtime_s,
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

/// `trainer fit` on `train`, then `trainer compensate` on each of `verify`,
/// scored against `raw` (their time, rate and reference columns).
fn fit_and_compensate(
    trainer: &Path,
    fit_args: &[&str],
    train: &Path,
    model: &Path,
    verify: &[PathBuf],
    raw: &[Vec<Vec<f64>>],
) -> anyhow::Result<ModelScores> {
    let mut args = vec!["fit", "-q", "--force", path(train), "-o", path(model)];
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
        });
    }
    let fit_s = started.elapsed().as_secs_f64();
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
    })
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
    let pct: Vec<f64> = scores
        .after_dph
        .iter()
        .zip(before)
        .map(|(a, b)| improvement_pct(*b, *a))
        .collect();
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
}

/// Mean and worst improvement per plant, training scenario and model, then over all plants.
fn print_summary(rows: &[(&str, usize, String, f64, f64, bool)], training: &[RunSpec]) {
    println!("\nin-use summary: mean / worst improvement over the four in-use runs [%]");
    print!("{:<18}", "plant");
    for scenario in training {
        let short = scenario.name.split(' ').next().unwrap_or_default();
        print!(
            " {:>22} {:>22}",
            format!("{short}: default"),
            format!("{short}: lag bank")
        );
    }
    println!(" {:>16}", "noise ceiling");
    let mut plants: Vec<&str> = rows.iter().map(|r| r.0).collect();
    plants.dedup();
    let cell = |plant: Option<&str>, scenario: usize, model: &str| -> String {
        let picked: Vec<&(&str, usize, String, f64, f64, bool)> = rows
            .iter()
            .filter(|r| plant.is_none_or(|p| r.0 == p) && r.1 == scenario && r.2 == model)
            .collect();
        if picked.iter().any(|r| r.5) {
            return "refused".into();
        }
        let mean = picked.iter().map(|r| r.3).sum::<f64>() / picked.len().max(1) as f64;
        let worst = picked.iter().map(|r| r.4).fold(f64::INFINITY, f64::min);
        format!("{mean:.1} / {worst:.1}")
    };
    for plant in plants.iter().map(|p| Some(*p)).chain([None]) {
        print!("{:<18}", plant.unwrap_or("all plants"));
        for s in 0..training.len() {
            print!(
                " {:>22} {:>22}",
                cell(plant, s, DEFAULT_MODEL),
                cell(plant, s, LAG_BANK)
            );
        }
        println!(" {:>16}", cell(plant, training.len(), "noise ceiling"));
    }
}
