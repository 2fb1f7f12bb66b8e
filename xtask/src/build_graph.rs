//! Whether `cargo xtask` and `cargo test --workspace` build the same crates.
//!
//! Cargo compiles a crate again for every set of features it is asked for, and
//! everything that depends on it with it. CI builds xtask first (`cargo xtask
//! ci`), then the workspace's tests: when the tests turn on a feature of a
//! crate the trainer is built from (a test's `rustix` with `pty`, proptest's
//! `getrandom` with `std`), the trainer, the firmware library and rbf-core are
//! compiled twice. xtask/Cargo.toml asks for those features itself;
//! [`feature_mismatches`] finds the ones it misses.

use std::collections::{BTreeMap, BTreeSet};
use std::process::Command;

use anyhow::{Context, bail};

use crate::workspace_root;

/// Each package of a `cargo tree` resolution ("name vX.Y.Z") and the feature
/// sets it is built with (two when proc-macros use it with other features
/// than a normal dependency does: cargo builds it once for each).
fn resolved_features(selection: &[&str], edges: &str) -> anyhow::Result<BTreeMap<String, BTreeSet<String>>> {
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args([
            "tree", "--quiet", "--prefix", "none", "--format", "{p}|{f}", "--edges", edges,
        ])
        .args(selection)
        .current_dir(workspace_root())
        .output()
        .context("cannot start cargo tree")?;
    if !out.status.success() {
        bail!("cargo tree failed: {}", String::from_utf8_lossy(&out.stderr));
    }
    let mut resolved: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        // A package seen before ends in " (*)", after its features.
        let Some((package, features)) = line.trim_end_matches(" (*)").split_once('|') else {
            continue;
        };
        let package = package.trim_end_matches(" (proc-macro)");
        resolved
            .entry(package.to_owned())
            .or_default()
            .insert(features.to_owned());
    }
    Ok(resolved)
}

/// The packages `cargo xtask` builds with other features than `cargo test
/// --workspace` does: "package: xtask's features / the tests' features", one
/// per package; empty when every crate xtask builds is reused by the tests.
pub fn feature_mismatches() -> anyhow::Result<Vec<String>> {
    let xtask = resolved_features(&["--package", "xtask"], "normal,build")?;
    let tests = resolved_features(&["--workspace"], "normal,build,dev")?;
    Ok(xtask
        .iter()
        .filter_map(|(package, sets)| {
            let theirs = tests.get(package)?;
            let missing: Vec<&String> = sets.difference(theirs).collect();
            let listed =
                |sets: &mut dyn Iterator<Item = &String>| sets.map(|f| format!("[{f}]")).collect::<Vec<_>>().join(" ");
            (!missing.is_empty()).then(|| {
                format!(
                    "{package}: {} / {}",
                    listed(&mut missing.into_iter()),
                    listed(&mut theirs.iter())
                )
            })
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xtask_builds_every_crate_with_the_features_the_workspace_tests_build_it_with() {
        let mismatches = feature_mismatches().unwrap();
        assert!(
            mismatches.is_empty(),
            "ask for these features in xtask/Cargo.toml, or CI compiles them and what depends on \
             them twice:\n{}",
            mismatches.join("\n")
        );
    }
}
