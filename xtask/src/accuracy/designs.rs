//! `cargo xtask bench-designs`: the default `trainer fit` on recorded gyros
//! of other designs (a directory of `NAME_planned.csv`, `NAME_cycle.csv`,
//! `NAME_random.csv`, `NAME_field.csv`, and where present
//! `NAME_planned24.csv` and `NAME_soak.csv`, as ../shared/data/other-designs
//! holds): each design trained on its planned run, its 24-h planned run and
//! its cycle, verified on its two in-use histories by the 100-s cluster STD
//! against `ref_dph`, beside the forecast the fit wrote
//! (`predicted_in_use_std100_dph`), and on its soak test by the spread of
//! the settled bias across the plateaus (`trainer eval --json`'s
//! `settled_spread_dph`, the rule of `trainer::dataset::plateaus`).

use std::path::{Path, PathBuf};

use anyhow::Context;
use trainer::metrics::{cluster_std, improvement_pct};

use super::{path, run_tool};
use super::{read_columns, soak_spread};

/// The chamber runs a design is trained on, in print order (a design
/// without one of them skips it).
const TRAININGS: [&str; 3] = ["planned", "planned24", "cycle"];
/// The soak test a design's models are compensated on, where it has one.
const SOAK: &str = "soak";
/// The in-use histories a design is verified on.
const IN_USE: [&str; 2] = ["random", "field"];

/// Fits (with `fit_args` after the default options, if any), compensates and
/// scores every design in `dir` with `trainer`; prints one line per design and
/// training run, then the means.
pub fn bench_designs(dir: &Path, trainer: &Path, fit_args: &[String]) -> anyhow::Result<()> {
    let mut designs: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot read {}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| e.file_name().to_str()?.strip_suffix("_planned.csv").map(str::to_owned))
        .collect();
    designs.sort();
    anyhow::ensure!(!designs.is_empty(), "{}: no NAME_planned.csv", dir.display());
    let work = tempfile::TempDir::new().context("cannot create a working directory")?;
    println!(
        "designs in {} (judged: {} fit, {})",
        dir.display(),
        trainer.display(),
        if fit_args.is_empty() {
            "default model".to_owned()
        } else {
            fit_args.join(" ")
        }
    );
    println!(
        "{:<10} {:<9} {:>9} {:>9} {:>9} {:>13} {:>13} {:>10}  structure",
        "design", "trained", "random %", "field %", "mean %", "forecast °/h", "measured °/h", "soak °/h"
    );
    let mut means = [Vec::new(), Vec::new(), Vec::new()];
    let mut soak_spreads = [Vec::new(), Vec::new(), Vec::new()];
    for design in &designs {
        let file = |kind: &str| dir.join(format!("{design}_{kind}.csv"));
        let mut soak_before = None;
        for (t, training) in TRAININGS.iter().enumerate() {
            if !file(training).exists() {
                continue;
            }
            let model = work.path().join(format!("{design}_{training}.bin"));
            let json = work.path().join(format!("{design}_{training}.json"));
            let training_run = file(training);
            let mut args = vec![
                "fit",
                "-q",
                path(&training_run),
                "-o",
                path(&model),
                "--json",
                path(&json),
            ];
            args.extend(fit_args.iter().map(String::as_str));
            run_tool(trainer, &args)?;
            let fit: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json)?)?;
            let forecast = fit["predicted_in_use_std100_dph"].as_f64();
            let structure = match fit["structure"]["response_bank"].as_bool() {
                Some(true) => "response bank",
                Some(false) => "lag bank",
                None => "-",
            };
            let mut scores = Vec::new();
            let mut residuals = Vec::new();
            for history in IN_USE {
                let out: PathBuf = work.path().join(format!("{design}_{training}_{history}.csv"));
                run_tool(
                    trainer,
                    &[
                        "compensate",
                        "--model",
                        path(&model),
                        path(&file(history)),
                        "-o",
                        path(&out),
                    ],
                )?;
                let c = read_columns(&out, &["time_s", "rate_dph", "ref_dph", "rate_comp_dph"])?;
                let period_s = c[0].get(1).zip(c[0].first()).map_or(1.0, |(b, a)| b - a);
                let before: Vec<f64> = c[1].iter().zip(&c[2]).map(|(r, q)| r - q).collect();
                let after: Vec<f64> = c[3].iter().zip(&c[2]).map(|(r, q)| r - q).collect();
                let (b, a) = (
                    cluster_std(&c[0], &before, period_s),
                    cluster_std(&c[0], &after, period_s),
                );
                scores.push(improvement_pct(b, a));
                residuals.push(a);
            }
            let mean = scores.iter().sum::<f64>() / scores.len() as f64;
            means[t].push(mean);
            let soak = if file(SOAK).exists() {
                let json = work.path().join(format!("{design}_{training}_soak.json"));
                let reading = soak_spread(trainer, &model, &file(SOAK), &json)?;
                soak_before = soak_before.or(reading.before_dph);
                reading.after_dph
            } else {
                None
            };
            if let Some(s) = soak {
                soak_spreads[t].push(s);
            }
            println!(
                "{:<10} {:<9} {:>9.1} {:>9.1} {:>9.1} {:>13} {:>13} {:>10}  {}",
                design,
                training,
                scores[0],
                scores[1],
                mean,
                forecast.map_or("-".into(), |f| format!("{f:.4}")),
                residuals
                    .iter()
                    .map(|r| format!("{r:.4}"))
                    .collect::<Vec<_>>()
                    .join("/"),
                soak.map_or("-".into(), |s| format!("{s:.4}")),
                structure
            );
        }
        if let Some(before) = soak_before {
            println!(
                "{:<10} {:<9} {:>69.3}  (soak test uncompensated)",
                design, "none", before
            );
        }
    }
    for ((training, m), soak) in TRAININGS.iter().zip(&means).zip(&soak_spreads) {
        if m.is_empty() {
            continue;
        }
        let worst = m.iter().copied().fold(f64::INFINITY, f64::min);
        let soak = match soak.iter().copied().reduce(f64::max) {
            Some(worst_soak) => format!(", soak spread worst {worst_soak:.4} °/h"),
            None => String::new(),
        };
        println!(
            "trained on the {training}: mean of the designs' means {:.1} %, worst design {:.1} %{soak}",
            m.iter().sum::<f64>() / m.len() as f64,
            worst
        );
    }
    println!(
        "(soak °/h: max − min of the settled bias (`trainer eval`'s settled_spread_dph) over the soak test's plateaus, \
         after compensation; the uncompensated row: before)"
    );
    Ok(())
}
