//! `cargo xtask`: project commands that are more than one cargo call.
//!
//! - `cargo xtask ci`: the whole test suite, as CI runs it, installing what it
//!   needs (the thumbv7em target, rustfmt, clippy) when missing.
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::{Parser, Subcommand};

/// Bare-metal target of the gyro MCU (Cortex-M4F).
const TARGET: &str = "thumbv7em-none-eabihf";

/// Project automation.
#[derive(Parser)]
#[command(about, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Run the whole test suite as CI does: fmt check, clippy -D warnings (host
    /// and firmware), host tests, the no_std check of rbf-core, the firmware build.
    /// Installs the thumbv7em target, rustfmt and clippy when missing.
    Ci,
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Cmd::Ci => ci(),
    }
}

fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask sits in the workspace")
        .to_owned()
}

/// Runs a command in the workspace root, failing with its name if it fails.
fn run(program: &str, args: &[&str]) -> anyhow::Result<()> {
    eprintln!("\n==> {program} {}", args.join(" "));
    let started = Instant::now();
    let status = Command::new(program)
        .args(args)
        .current_dir(workspace_root())
        .status()
        .with_context(|| format!("cannot start {program}"))?;
    if !status.success() {
        bail!("`{program} {}` failed ({status})", args.join(" "));
    }
    eprintln!("    ok in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

fn output(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default()
}

/// Installs the cross target and the rustup components CI needs, if missing.
fn ensure_toolchain() -> anyhow::Result<()> {
    if !output("rustup", &["target", "list", "--installed"])
        .lines()
        .any(|l| l.trim() == TARGET)
    {
        run("rustup", &["target", "add", TARGET])?;
    }
    let components = output("rustup", &["component", "list", "--installed"]);
    for component in ["rustfmt", "clippy"] {
        if !components.lines().any(|l| l.starts_with(component)) {
            run("rustup", &["component", "add", component])?;
        }
    }
    Ok(())
}

fn ci() -> anyhow::Result<()> {
    let started = Instant::now();
    ensure_toolchain()?;
    run("cargo", &["fmt", "--all", "--check"])?;
    run(
        "cargo",
        &["clippy", "--workspace", "--all-targets", "--", "-D", "warnings"],
    )?;
    run(
        "cargo",
        &[
            "clippy",
            "--package",
            "firmware",
            "--target",
            TARGET,
            "--",
            "-D",
            "warnings",
        ],
    )?;
    run(
        "cargo",
        &[
            "check",
            "--package",
            "rbf-core",
            "--target",
            TARGET,
            "--no-default-features",
        ],
    )?;
    run(
        "cargo",
        &["build", "--package", "firmware", "--target", TARGET, "--release"],
    )?;
    let (passed, failed) = run_tests(&["test", "--workspace"])?;
    eprintln!("\nci: all steps passed in {:.0} s", started.elapsed().as_secs_f64());
    println!("{passed} passed, {failed} failed");
    Ok(())
}

/// Runs `cargo test`, echoing its output, and sums its `test result:` lines.
fn run_tests(args: &[&str]) -> anyhow::Result<(u64, u64)> {
    eprintln!("\n==> cargo {}", args.join(" "));
    let output = Command::new("cargo")
        .args(args)
        .current_dir(workspace_root())
        .stderr(std::process::Stdio::inherit())
        .output()
        .context("cannot start cargo test")?;
    let stdout = String::from_utf8_lossy(&output.stdout);
    print!("{stdout}");
    let (mut passed, mut failed) = (0, 0);
    for line in stdout.lines().filter_map(|l| l.trim().strip_prefix("test result: ")) {
        let count = |word: &str| {
            line.split(';')
                .find_map(|part| {
                    part.trim()
                        .trim_start_matches("ok. ")
                        .trim_start_matches("FAILED. ")
                        .strip_suffix(word)
                })
                .and_then(|n| n.trim().parse::<u64>().ok())
                .unwrap_or(0)
        };
        passed += count("passed");
        failed += count("failed");
    }
    if !output.status.success() {
        bail!("`cargo {}` failed: {passed} passed, {failed} failed", args.join(" "));
    }
    Ok((passed, failed))
}
