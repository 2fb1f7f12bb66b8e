//! `cargo xtask board-faults`: the stm32f405 board's own driver and loop
//! code against scripted faulty peripherals on the host
//! (the test target `firmware-harness/tests/board_faults/`, which `cargo
//! test` runs too; docs/firmware.md, "Faults the board survives").

use std::process::Command;

use anyhow::{Context, bail};

use crate::workspace_root;

/// Scenarios the run must have at least (the list).
pub const MIN_SCENARIOS: u32 = 10;

/// The scenario and failure counts of the summary line
/// `board faults: N scenarios, M failed`.
pub fn parse_summary(line: &str) -> Option<(u32, u32)> {
    let rest = line.strip_prefix("board faults: ")?;
    let (n, rest) = rest.split_once(" scenarios, ")?;
    let m = rest.strip_suffix(" failed")?;
    Some((n.parse().ok()?, m.parse().ok()?))
}

/// Runs the scenarios, echoing one line per scenario and the summary;
/// fails when any scenario failed, fewer than [`MIN_SCENARIOS`] ran, or the
/// summary is missing.
pub fn board_faults() -> anyhow::Result<()> {
    let output = Command::new("cargo")
        // `--workspace` rather than `--package firmware-harness`: the workspace's feature
        // resolution, so that the test builds from (and leaves for) the crates `cargo test
        // --workspace` builds; the package alone resolved other features and compiled
        // rbf-core, gyro-wire, firmware and the harness a second time.
        .args(["test", "--quiet", "--workspace", "--test", "board_faults"])
        .current_dir(workspace_root())
        .output()
        .context("cannot start cargo test")?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    print!("{stdout}");
    let summary = stdout.lines().last().and_then(parse_summary);
    match summary {
        Some((n, 0)) if n >= MIN_SCENARIOS && output.status.success() => Ok(()),
        Some((n, m)) => bail!("board faults: {m} of {n} scenarios failed (at least {MIN_SCENARIOS} must pass)"),
        None => bail!(
            "the board-fault scenarios did not finish:\n{}",
            String::from_utf8_lossy(&output.stderr)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_line_is_read_exactly() {
        assert_eq!(parse_summary("board faults: 11 scenarios, 0 failed"), Some((11, 0)));
        assert_eq!(parse_summary("board faults: 11 scenarios, 2 failed"), Some((11, 2)));
        assert_eq!(parse_summary("board faults: 11 scenarios"), None);
        assert_eq!(parse_summary("noise on RX: ok: ..."), None);
    }
}
