//! `cargo xtask bench-accuracy`: every method against the peers on simulated
//! chamber runs of both protocols, trained on one run and verified on runs at
//! other ramp rates and on a random profile; then the RLG paper's comparison
//! (its Tables 4 and 5): traditional three-point against multi-point inputs
//! on 8-thermometer runs (`trainer simulate --multi`); then [`in_use`]:
//! trained on a chamber run, verified on in-use histories, over several plants.

pub mod designs;
pub mod in_use;
mod tools;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};

use crate::workspace_root;
// Re-exported for the benches below this module (`super::run_tool`), which
// would otherwise import their parent.
pub(crate) use self::tools::{SoakReading, path, read_columns, run_tool, soak_spread};

/// One protocol: a training run and verification runs (simulate arguments),
/// the methods compared and whether the Python peers join.
struct Protocol {
    name: &'static str,
    rate_hz: f64,
    train: &'static [&'static str],
    verify: &'static [(&'static str, &'static [&'static str])],
    methods: &'static [(&'static str, &'static [&'static str])],
    peers: bool,
}

/// Our methods: (label, `trainer fit` options).
const METHODS: [(&str, &[&str]); 5] = [
    ("poly3 (PX4/ArduPilot form)", &["--method", "poly3"]),
    ("rbf2 (IFOG paper, before)", &["--method", "rbf2"]),
    ("rbf --features paper (IFOG)", &["--features", "paper"]),
    ("svr-pso, single-point (RLG)", &["--method", "svr-pso"]),
    ("default (lag-bank rbf)", &[]),
];

/// The RLG paper's comparison on 8-thermometer runs: single-point models,
/// the traditional three temperatures (base, loop, electronics), and
/// multi-point inputs by the paper's selection, by validation (svr-pso's
/// default) and by hand.
const MULTI_POINT_METHODS: [(&str, &[&str]); 6] = [
    ("rbf --features paper (loop only)", &["--features", "paper"]),
    ("default rbf (loop only)", &[]),
    (
        "svr-pso three-point a, c, e",
        &["--method", "svr-pso", "--inputs", "temp_a,temp_c,temp_e"],
    ),
    (
        "svr-pso multi-point |r| ≥ 0.9 (paper)",
        &["--method", "svr-pso", "--select-threshold", "0.9"],
    ),
    ("svr-pso multi-point, validated", &["--method", "svr-pso"]),
    (
        "svr-pso multi-point a … f (on-gyro)",
        &[
            "--method",
            "svr-pso",
            "--inputs",
            "temp_a,temp_b,temp_c,temp_d,temp_e,temp_f",
        ],
    ),
];

const PROTOCOLS: [Protocol; 3] = [
    Protocol {
        name: "ifog",
        rate_hz: 1.0,
        train: &["--profile", "ifog", "--ramp", "1", "--seed", "101"],
        verify: &[
            (
                "ifog 0.5 °C/min",
                &["--profile", "ifog", "--ramp", "0.5", "--seed", "102"],
            ),
            ("ifog 3 °C/min", &["--profile", "ifog", "--ramp", "3", "--seed", "103"]),
            (
                "random 10…40 °C",
                &["--profile", "random", "--random-range", "10,40", "--seed", "104"],
            ),
        ],
        methods: &METHODS,
        peers: true,
    },
    Protocol {
        name: "cycle",
        rate_hz: 0.2,
        train: &["--profile", "cycle", "--ramp", "1", "--seed", "201"],
        verify: &[
            (
                "cycle 2 °C/min",
                &["--profile", "cycle", "--ramp", "2", "--seed", "202"],
            ),
            (
                "cycle 5 °C/min",
                &["--profile", "cycle", "--ramp", "5", "--seed", "203"],
            ),
            ("random −40…60 °C", &["--profile", "random", "--seed", "204"]),
        ],
        methods: &METHODS,
        peers: true,
    },
    Protocol {
        name: "multi-point",
        rate_hz: 1.0,
        train: &["--profile", "cycle", "--ramp", "1", "--seed", "301", "--multi"],
        verify: &[
            (
                "cycle 2 °C/min",
                &["--profile", "cycle", "--ramp", "2", "--seed", "302", "--multi"],
            ),
            (
                "cycle 5 °C/min",
                &["--profile", "cycle", "--ramp", "5", "--seed", "303", "--multi"],
            ),
            ("random −40…60 °C", &["--profile", "random", "--seed", "304", "--multi"]),
        ],
        methods: &MULTI_POINT_METHODS,
        peers: false,
    },
];

fn trainer(args: &[&str]) -> anyhow::Result<String> {
    run_tool(&crate::release_trainer(), args)
}

/// A result line: improvement % and residual 100-s STD per verification run.
struct Row {
    method: String,
    fit_s: f64,
    runs: Vec<(f64, f64)>,
    /// Why the method refused the training data, if it did (then `runs` is empty).
    refusal: Option<String>,
}

/// What `cargo xtask bench-accuracy` runs.
#[derive(Clone, Debug, Default)]
pub struct AccuracyOptions {
    /// Simulate another gyro in the chamber protocols (`trainer simulate --params`).
    pub params: Option<PathBuf>,
    /// Only the in-use section.
    pub in_use_only: bool,
    /// The in-use section's options.
    pub in_use: in_use::InUseOptions,
    /// Write the in-use section's results here as JSON (`-`: stdout).
    pub json: Option<PathBuf>,
}

/// Runs the benchmark: one table per chamber protocol (unless
/// `in_use_only`), then the in-use section.
pub fn bench_accuracy(opts: &AccuracyOptions) -> anyhow::Result<()> {
    crate::run("cargo", &["build", "--release", "--quiet", "--package", "trainer"])?;
    let venv_dir = crate::target_dir().join("bench-accuracy");
    std::fs::create_dir_all(&venv_dir)?;
    let python = crate::python_venv(&venv_dir, &["scikit-learn", "numpy"], "sklearn, numpy")?;
    if !opts.in_use_only {
        chamber_protocols(opts.params.as_deref(), &python, &venv_dir)?;
    }
    let results = in_use::bench_in_use(&opts.in_use, &python, &venv_dir)?;
    if let Some(file) = &opts.json {
        let text = serde_json::to_string_pretty(&results)?;
        if file.as_os_str() == "-" {
            println!("{text}");
        } else {
            std::fs::write(file, text).with_context(|| format!("cannot write {}", file.display()))?;
        }
    }
    Ok(())
}

/// The chamber protocols' tables; `params` simulates another gyro
/// (`trainer simulate --params`).
fn chamber_protocols(params: Option<&Path>, python: &Path, venv_dir: &Path) -> anyhow::Result<()> {
    let venv_dir = venv_dir.to_owned();
    let (dir, params) = match params {
        Some(file) => {
            let file = std::path::absolute(file)?;
            let stem = file
                .file_stem()
                .map_or("params".into(), |s| s.to_string_lossy().into_owned());
            (venv_dir.join(stem), Some(file))
        }
        None => (venv_dir, None),
    };
    std::fs::create_dir_all(&dir)?;
    match &params {
        Some(file) => println!("gyro: {} (trainer simulate --params)", file.display()),
        None => println!("gyro: the simulator's documented default (docs/simulator.md)"),
    }
    let script = workspace_root().join("bench/accuracy/peers.py");
    let mut means = Vec::new();
    for p in &PROTOCOLS {
        let rate = p.rate_hz.to_string();
        let sim = |name: &str, args: &[&str]| -> anyhow::Result<PathBuf> {
            let file = dir.join(format!("{}_{name}.csv", p.name));
            let mut all = vec!["simulate", "--force", "--rate-hz", &rate, "-o", path(&file)];
            all.extend(args);
            if let Some(params) = &params {
                all.extend(["--params", path(params)]);
            }
            trainer(&all)?;
            Ok(file)
        };
        let train = sim("train", p.train)?;
        let verify: Vec<PathBuf> = p
            .verify
            .iter()
            .enumerate()
            .map(|(i, (_, a))| sim(&format!("verify{i}"), a))
            .collect::<anyhow::Result<_>>()?;
        // Each verification run again with its thermal bias zeroed: its noise alone.
        let noise: Vec<PathBuf> = p
            .verify
            .iter()
            .enumerate()
            .map(|(i, (_, a))| sim(&format!("verify{i}_noise"), &[a, &["--noise-only"][..]].concat()))
            .collect::<anyhow::Result<_>>()?;
        let mut rows: Vec<Row> = Vec::new();
        let mut before: Vec<f64> = Vec::new();
        // The default's model: its inputs are the peers' (`trainer blocks --model`).
        let default_model = dir.join(format!("{}_default.bin", p.name));
        let mut default_fitted = false;
        for &(label, opts) in p.methods {
            let is_default = opts.is_empty();
            let model = match is_default {
                true => default_model.clone(),
                false => dir.join(format!("{}_model.bin", p.name)),
            };
            let mut args = vec!["fit", "-q", "--force", path(&train), "-o", path(&model)];
            args.extend(opts);
            let started = Instant::now();
            if let Err(e) = trainer(&args) {
                // A method that refuses this data (e.g. no input passes the
                // paper's selection rule) is a result, not the end of the benchmark.
                let reason = e.to_string();
                let last = reason.lines().last().unwrap_or_default();
                // The trainer's own message, without the command line before it.
                let reason = last.rsplit("error: ").next().unwrap_or(last).trim().to_owned();
                rows.push(Row {
                    method: label.into(),
                    fit_s: f64::NAN,
                    runs: Vec::new(),
                    refusal: Some(reason),
                });
                continue;
            }
            let fit_s = started.elapsed().as_secs_f64();
            default_fitted |= is_default;
            let json = dir.join(format!("{}_eval.json", p.name));
            let mut eval = vec!["eval", "--force", "--model", path(&model), "--json", path(&json)];
            eval.extend(verify.iter().map(|v| path(v)));
            trainer(&eval)?;
            let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json)?)?;
            let runs: Vec<(f64, f64)> = v
                .as_array()
                .into_iter()
                .flatten()
                .map(|e| {
                    (
                        e["cluster_std_improvement_pct"].as_f64().unwrap_or(f64::NAN),
                        e["cluster_std_after_dph"].as_f64().unwrap_or(f64::NAN),
                    )
                })
                .collect();
            before = v
                .as_array()
                .into_iter()
                .flatten()
                .map(|e| e["cluster_std_before_dph"].as_f64().unwrap_or(f64::NAN))
                .collect();
            rows.push(Row {
                method: label.into(),
                fit_s,
                runs,
                refusal: None,
            });
        }
        if p.peers {
            anyhow::ensure!(
                default_fitted,
                "the peers need the default's features, and the default fit was refused"
            );
            rows.extend(peer_rows(python, &script, p, &default_model, &train, &verify)?);
        }
        if default_fitted {
            rows.push(noise_ceiling(
                &default_model,
                &noise,
                &before,
                &dir.join(format!("{}_noise.json", p.name)),
            )?);
        }
        print_protocol(p, &before, &rows, &mut means);
    }
    let overall = means.iter().sum::<f64>() / means.len().max(1) as f64;
    println!(
        "\n(improvement % and, in brackets, residual 100-s STD in °/h; ours compensate every sample as the firmware does,"
    );
    println!(" the peers are scored on the 1-s block residuals of the same data; the noise ceiling is each run");
    println!(" simulated again with every thermal bias term zeroed, same seed: what no compensation can remove)");
    println!("default: mean improvement over the ifog and cycle protocols' verification runs {overall:.1} %");
    Ok(())
}

/// The best any model can do on each verification run: the 100-s cluster STD
/// of its noise alone (`noise`: simulated again with `--noise-only`) against
/// the raw run's (`before`). `model` is only there for `trainer eval`, which reports
/// the uncompensated STD of any run.
fn noise_ceiling(model: &Path, noise: &[PathBuf], before: &[f64], json: &Path) -> anyhow::Result<Row> {
    let mut eval = vec!["eval", "--force", "--model", path(model), "--json", path(json)];
    eval.extend(noise.iter().map(|n| path(n)));
    trainer(&eval)?;
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(json)?)?;
    let noise_std = v
        .as_array()
        .into_iter()
        .flatten()
        .map(|e| e["cluster_std_before_dph"].as_f64().unwrap_or(f64::NAN));
    Ok(Row {
        method: "noise ceiling (thermal bias zeroed)".into(),
        fit_s: f64::NAN,
        runs: noise_std.zip(before).map(|(n, b)| (100.0 * (1.0 - n / b), n)).collect(),
        refusal: None,
    })
}

/// The Python peers' rows for protocol `p`, on the inputs of the default's
/// model `default_model` as `trainer blocks --model` writes them.
fn peer_rows(
    python: &Path,
    script: &Path,
    p: &Protocol,
    default_model: &Path,
    train: &Path,
    verify: &[PathBuf],
) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    let blocks = |file: &Path| -> anyhow::Result<PathBuf> {
        let out = file.with_extension("blocks.csv");
        trainer(&[
            "blocks",
            "--force",
            path(file),
            "--model",
            path(default_model),
            "-o",
            path(&out),
        ])?;
        Ok(out)
    };
    let mut cmd = Command::new(python);
    cmd.arg(script).args(["--train", path(&blocks(train)?)]);
    cmd.args([
        "--cluster-blocks",
        &((100.0 * p.rate_hz).round().max(1.0) as u32).to_string(),
    ]);
    for (i, v) in verify.iter().enumerate() {
        cmd.args(["--verify", &format!("v{i}={}", path(&blocks(v)?))]);
    }
    let out = cmd.output().context("cannot run peers.py")?;
    if !out.status.success() {
        bail!("peers.py failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let peers: serde_json::Value = serde_json::from_slice(&out.stdout)?;
    for (name, r) in peers.as_object().into_iter().flatten() {
        let runs = (0..verify.len())
            .map(|i| {
                let run = &r["runs"][format!("v{i}")];
                (
                    run["improvement_pct"].as_f64().unwrap_or(f64::NAN),
                    run["after_dph"].as_f64().unwrap_or(f64::NAN),
                )
            })
            .collect();
        rows.push(Row {
            method: format!("{name} (same features)"),
            fit_s: r["fit_s"].as_f64().unwrap_or(f64::NAN),
            runs,
            refusal: None,
        });
    }
    Ok(rows)
}

/// Prints protocol `p`'s table; the default's mean joins `means` (ifog and cycle only).
fn print_protocol(p: &Protocol, before: &[f64], rows: &[Row], means: &mut Vec<f64>) {
    println!(
        "\nprotocol {}: trained on one 1 °C/min run, verified on runs it never saw",
        p.name
    );
    print!("{:<38}", "100-s cluster STD improvement [%]");
    for (label, _) in p.verify {
        print!(" {label:>18}");
    }
    println!(" {:>8} {:>9}", "mean", "fit [s]");
    print!("{:<38}", "no compensation (STD [°/h])");
    for b in before {
        print!(" {:>18}", format!("{b:.4}"));
    }
    println!();
    for r in rows {
        print!("{:<38}", r.method);
        if let Some(reason) = &r.refusal {
            println!(" fit refused: {reason}");
            continue;
        }
        for (imp, after) in &r.runs {
            print!(" {:>18}", format!("{imp:.1} ({after:.4})"));
        }
        let mean = r.runs.iter().map(|x| x.0).sum::<f64>() / r.runs.len() as f64;
        match r.fit_s.is_nan() {
            true => println!(" {mean:>8.1} {:>9}", "-"),
            false => println!(" {mean:>8.1} {:>9.2}", r.fit_s),
        }
        if p.peers && r.method.starts_with("default") {
            means.push(mean);
        }
    }
}
