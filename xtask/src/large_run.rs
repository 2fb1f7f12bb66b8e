//! `cargo xtask bench-large-run`: `trainer fit` and `trainer compensate`
//! against pandas pipelines doing the same jobs on a 20-h, 100-Hz chamber
//! run (7.2 million rows), one after the other, with peak memory,
//! throughput, the floor (one pass that only finds line ends) and the peak
//! memory of a fit on a run 10× shorter (memory flat in the run length);
//! with `--repeat N`, the median and range of N more runs of the trainer's
//! jobs.

use std::process::Command;

use anyhow::{Context, bail};

use crate::{python_venv, run, workspace_root};

/// Hours of the generated run.
pub const HOURS: &str = "20";
/// Its sample rate, Hz.
pub const RATE_HZ: &str = "100";
/// Hours of the short run whose fit's peak memory the long run's is compared with.
pub const SHORT_HOURS: &str = "2";

/// Generates the run (once), then runs bench/large-run/run.py, which prints both
/// (and, `repeat` above 0, the trainer's jobs `repeat` more times each).
pub fn bench_large_run(repeat: u32) -> anyhow::Result<()> {
    let root = workspace_root();
    let dir = crate::target_dir().join("bench-large-run");
    std::fs::create_dir_all(&dir).with_context(|| format!("{}: cannot create", dir.display()))?;
    run("cargo", &["build", "--release", "--quiet", "--package", "trainer"])?;
    let trainer = crate::release_trainer();
    let csv = dir.join("run_20h_100hz.csv");
    let short = dir.join("run_2h_100hz.csv");
    for (path, hours) in [(&csv, HOURS), (&short, SHORT_HOURS)] {
        if path.exists() {
            continue;
        }
        let path = path.to_str().context("UTF-8 path")?;
        let status = Command::new(&trainer)
            .args(["simulate", "--profile", "ifog", "--hours", hours, "--rate-hz", RATE_HZ])
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
        .arg(&short)
        .arg(repeat.to_string())
        .status()
        .context("cannot run bench/large-run/run.py")?;
    if !status.success() {
        bail!("the large-run benchmark failed");
    }
    Ok(())
}
