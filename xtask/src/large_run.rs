//! `cargo xtask bench-large-run`: `trainer fit` against a pandas +
//! scikit-learn pipeline doing the same job on a 20-h, 100-Hz chamber run
//! (7.2 million rows, 277 MB), one after the other, with peak memory.

use std::process::Command;

use anyhow::{Context, bail};

use crate::{python_venv, run, workspace_root};

/// Hours of the generated run.
pub const HOURS: &str = "20";
/// Its sample rate, Hz.
pub const RATE_HZ: &str = "100";

/// Generates the run (once), then runs bench/large-run/run.py, which prints both.
pub fn bench_large_run() -> anyhow::Result<()> {
    let root = workspace_root();
    let dir = root.join("target/bench-large-run");
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    run("cargo", &["build", "--release", "--quiet", "--package", "trainer"])?;
    let trainer = root.join("target/release/trainer");
    let csv = dir.join("run_20h_100hz.csv");
    if !csv.exists() {
        let path = csv.to_str().context("UTF-8 path")?;
        let status = Command::new(&trainer)
            .args(["simulate", "--profile", "ifog", "--hours", HOURS, "--rate-hz", RATE_HZ])
            .args(["--seed", "11", "-o", path])
            .status()
            .context("cannot run trainer simulate")?;
        if !status.success() {
            bail!("trainer simulate failed");
        }
    }
    let python = python_venv(&dir, &["pandas", "scikit-learn", "numpy"], "pandas, sklearn, numpy")?;
    let status = Command::new(python)
        .arg(root.join("bench/large-run/run.py"))
        .arg(&trainer)
        .arg(&csv)
        .arg(&dir)
        .status()
        .context("cannot run bench/large-run/run.py")?;
    if !status.success() {
        bail!("the large-run benchmark failed");
    }
    Ok(())
}
