//! `cargo xtask bench-batch`: the production-batch benchmark (docs/benchmarks.md,
//! "trainer batch"). 32 simulated units of four gyro designs, each a 17-h `trainer plan`
//! run at 10 Hz to train on and a 4-h cycle to hold out (generated once under
//! target/bench-batch/), then one `trainer batch` without records and one with
//! `--records` into a fresh SQLite file; for each, wall time, units per minute, peak
//! memory (GNU time's maximum resident set size: the batch or its largest fit child) and
//! the time the summaries and records took as the batch reports it.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};

use crate::workspace_root;

/// Units in the batch.
pub const UNITS: usize = 32;

/// `trainer` with `args`, which must succeed.
fn trainer(trainer: &Path, args: &[&str]) -> anyhow::Result<()> {
    let o = Command::new(trainer)
        .args(args)
        .output()
        .with_context(|| format!("cannot run {}", trainer.display()))?;
    if !o.status.success() {
        bail!(
            "trainer {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr)
        );
    }
    Ok(())
}

/// Writes the runs and the manifest into `dir` (once: kept when the manifest exists).
fn generate(trainer_bin: &Path, dir: &Path) -> anyhow::Result<PathBuf> {
    let manifest = dir.join("batch.toml");
    if manifest.exists() {
        return Ok(manifest);
    }
    std::fs::create_dir_all(dir.join("runs")).with_context(|| format!("{}: cannot create", dir.display()))?;
    let plan = dir.join("plan.csv");
    let plan_s = plan.to_str().context("UTF-8 path")?;
    trainer(
        trainer_bin,
        &[
            "plan",
            "--min-c",
            "-40",
            "--max-c",
            "60",
            "--max-rate-c-per-min",
            "1",
            "--hours",
            "17",
        ]
        .into_iter()
        .chain(["-o", plan_s, "--force"])
        .collect::<Vec<_>>(),
    )?;
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get());
    let next = std::sync::atomic::AtomicUsize::new(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                s.spawn(|| -> anyhow::Result<()> {
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if i > UNITS {
                            return Ok(());
                        }
                        let design = ((i % 4) + 1).to_string();
                        let (train, holdout) = (dir.join(format!("runs/u{i}.csv")), dir.join(format!("runs/h{i}.csv")));
                        let (seed, holdout_seed) = (i.to_string(), (1000 + i).to_string());
                        trainer(
                            trainer_bin,
                            &[
                                "simulate",
                                "--chamber-profile",
                                plan_s,
                                "--sample-rate-hz",
                                "10",
                                "--design",
                                &design,
                            ]
                            .into_iter()
                            .chain(["--seed", &seed, "-o", train.to_str().context("UTF-8 path")?, "--force"])
                            .collect::<Vec<_>>(),
                        )?;
                        trainer(
                            trainer_bin,
                            &[
                                "simulate",
                                "--profile",
                                "cycle",
                                "--hours",
                                "4",
                                "--sample-rate-hz",
                                "10",
                            ]
                            .into_iter()
                            .chain(["--design", &design, "--seed", &holdout_seed])
                            .chain(["-o", holdout.to_str().context("UTF-8 path")?, "--force"])
                            .collect::<Vec<_>>(),
                        )?;
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .try_for_each(|h| h.join().unwrap_or_else(|_| bail!("a generating thread panicked")))
    })?;
    let mut text = "batch = \"BENCH-32\"\n".to_owned();
    for i in 1..=UNITS {
        text +=
            &format!("[[unit]]\nserial = \"FOG-{i:04}\"\ntrain = [\"runs/u{i}.csv\"]\nholdout = [\"runs/h{i}.csv\"]\n");
    }
    std::fs::write(&manifest, text).with_context(|| format!("{}: cannot write", manifest.display()))?;
    Ok(manifest)
}

/// One timed `trainer batch` of `manifest` into `out` (replaced) with `extra` options;
/// prints its line of figures.
fn timed_batch(trainer_bin: &Path, manifest: &Path, out: &Path, extra: &[&str], label: &str) -> anyhow::Result<()> {
    let _ = std::fs::remove_dir_all(out);
    let started = Instant::now();
    let o = Command::new("/usr/bin/time")
        .arg("-v")
        .arg(trainer_bin)
        .arg("batch")
        .arg(manifest)
        .arg("-o")
        .arg(out)
        .args(extra)
        .output()
        .context("cannot run /usr/bin/time (GNU time) with the trainer")?;
    let wall_s = started.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&o.stderr);
    if !o.status.success() {
        bail!("trainer batch failed: {stderr}");
    }
    let peak_kb: f64 = stderr
        .lines()
        .find_map(|l| l.trim().strip_prefix("Maximum resident set size (kbytes): "))
        .and_then(|v| v.trim().parse().ok())
        .context("GNU time printed no maximum resident set size")?;
    let shares = stderr
        .lines()
        .find(|l| l.contains("; summaries "))
        .and_then(|l| l.split_once("; "))
        .map_or("", |(_, rest)| rest);
    println!(
        "bench-batch {label}: {UNITS} units in {wall_s:.1} s: {:.1} units/min; peak memory {:.1} MB; {shares}",
        UNITS as f64 * 60.0 / wall_s,
        peak_kb / 1000.0
    );
    Ok(())
}

/// Runs the benchmark with `trainer_bin` (default: a release build of the trainer).
pub fn bench_batch(trainer_bin: Option<&Path>) -> anyhow::Result<()> {
    let root = workspace_root();
    let trainer_bin = match trainer_bin {
        Some(t) => std::path::absolute(t)?,
        None => {
            crate::run("cargo", &["build", "--release", "--quiet", "--package", "trainer"])?;
            root.join("target/release/trainer")
        }
    };
    let dir = root.join("target/bench-batch");
    let manifest = generate(&trainer_bin, &dir)?;
    timed_batch(&trainer_bin, &manifest, &dir.join("out"), &[], "no records")?;
    let store = dir.join("records.sqlite");
    for stale in ["", "-wal", "-shm"] {
        let _ = std::fs::remove_file(format!("{}{stale}", store.display()));
    }
    let store = store.to_str().context("UTF-8 path")?;
    timed_batch(
        &trainer_bin,
        &manifest,
        &dir.join("out"),
        &["--records", store],
        "records in SQLite",
    )
}
