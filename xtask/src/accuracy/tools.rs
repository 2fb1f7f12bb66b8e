//! Running the trainer and naming files, for the accuracy benches.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};

/// Runs `exe` with `args`; its standard output, or an error with its standard error.
pub(crate) fn run_tool(exe: &Path, args: &[&str]) -> anyhow::Result<String> {
    let out = Command::new(exe)
        .args(args)
        .output()
        .with_context(|| format!("cannot run {}", exe.display()))?;
    if !out.status.success() {
        bail!(
            "{} {} failed: {}",
            exe.display(),
            args.join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// `p` as text (the benches write under target/, always UTF-8).
pub(crate) fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 paths under target/")
}
