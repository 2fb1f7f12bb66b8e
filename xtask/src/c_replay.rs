//! `cargo xtask c-replay`: a recorded run through rbf-core's C library, by
//! the C program `rbf-core-c/c/replay.c` built from the header and the
//! static library as a maker would build it, on the host (`cc`) or on the
//! STM32F405 under QEMU (`arm-none-eabi-gcc`, newlib, semihosting); the
//! output byte-identical to `trainer compensate`.

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use anyhow::{Context, bail};
use rbf_core::CompensatorConfig;
use trainer::evaluation::axes::{Acceptance, compensate_command};
use trainer::output::{Existing, Output, Transaction};
use trainer::reading::run::RunReader;

use crate::c_library::{self, CTarget};
use crate::qemu;

/// What a C replay printed besides the output file (its closing line:
/// rows, the model's CRC-32, axes and provenance id).
#[derive(Debug)]
pub struct CReplaySummary {
    /// The program's closing line.
    pub report: String,
}

/// Files the C program reads and writes in its working directory.
const MODEL: &str = "model.bin";
const RUN: &str = "input.csv";
const OUTPUT: &str = "output.csv";

/// Exit status of replay.c when the library refused the blob.
const REFUSED_EXIT: i32 = 2;

/// Replays `run` with `model` through the C program on `target` into
/// `output` (see the module documentation). The library loads the blob
/// first: a blob it refuses ends the replay with its words. Then what
/// `trainer compensate` refuses is refused with its messages (it is run,
/// its output discarded), and the output appears whole (compensate's
/// provenance lines, then the C program's rows) or not at all.
pub fn c_replay(
    target: CTarget,
    model: &Path,
    run: &Path,
    output: &Path,
    existing: Existing,
    accept: Acceptance,
) -> anyhow::Result<CReplaySummary> {
    let inputs = [model, run];
    trainer::output::check_target(output, &inputs, existing)?;
    let blob = std::fs::read(model).with_context(|| format!("{}: cannot read", model.display()))?;
    let period_s = RunReader::open(run)?.nominal_period_s();
    let sample_rate_hz = CompensatorConfig::sample_rate_hz_for_period_s(period_s);
    let dir = tempfile::TempDir::new().context("cannot create a working directory")?;
    std::fs::write(dir.path().join(MODEL), &blob).with_context(|| format!("{}: cannot copy", model.display()))?;
    std::fs::copy(run, dir.path().join(RUN)).with_context(|| format!("{}: cannot copy", run.display()))?;
    // Shortest round-trip decimal: the program's strtof gives the same f32.
    let rate = format!("{sample_rate_hz}");
    let argv = ["replay", MODEL, rate.as_str(), RUN, OUTPUT];
    let ran = match target {
        CTarget::Host => run_on_host(dir.path(), &argv)?,
        CTarget::Qemu => run_under_qemu(dir.path(), &argv)?,
    };
    if let Some(words) = refusal(&ran) {
        bail!("{}: the C library refuses the blob: {words}", model.display());
    }
    // compensate's checks and refusals, with its messages (a malformed run
    // is named with its line and column there).
    drop(compensate_command(model, run, output, existing, accept)?);
    if !ran.success {
        bail!("the C replay failed:\n{}", ran.log);
    }
    let rows = std::fs::read(dir.path().join(OUTPUT)).with_context(|| format!("the C replay wrote no {OUTPUT}"))?;
    let mut out = Output::create(output, &inputs, existing)?;
    let write = |e| anyhow::Error::new(e).context(format!("{}: cannot write", output.display()));
    out.write_all(trainer::blobfile::provenance_lines(model, &blob).as_bytes())
        .map_err(write)?;
    out.write_all(&rows).map_err(write)?;
    let mut transaction = Transaction::new();
    transaction.add(out);
    transaction.commit()?;
    let report = ran
        .log
        .lines()
        .find(|l| l.starts_with("replay: "))
        .unwrap_or("")
        .to_owned();
    Ok(CReplaySummary { report })
}

/// How the C program ended: its output (stdout and stderr, or QEMU's log)
/// and exit status.
struct Ran {
    log: String,
    success: bool,
    refused: bool,
}

/// The library's words for a refused blob, if the program says it refused one.
fn refusal(ran: &Ran) -> Option<&str> {
    if !ran.refused && ran.success {
        return None;
    }
    ran.log
        .lines()
        .find_map(|l| l.split_once(": refused: ").map(|(_, words)| words))
}

/// Builds the library and the program for the host; runs it in `dir`.
fn run_on_host(dir: &Path, argv: &[&str]) -> anyhow::Result<Ran> {
    let library = c_library::build_library(CTarget::Host, &[])?;
    let program = dir.join("replay");
    c_library::compile_c(
        CTarget::Host,
        &[c_library::c_dir().join("replay.c")],
        &library,
        &program,
        &[],
    )?;
    let out = Command::new(&program)
        .args(&argv[1..])
        .current_dir(dir)
        .output()
        .with_context(|| format!("cannot start {}", program.display()))?;
    Ok(Ran {
        log: format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        ),
        success: out.status.success(),
        refused: out.status.code() == Some(REFUSED_EXIT),
    })
}

/// Builds the library and the program for the Cortex-M4F; runs it under
/// QEMU in `dir` (files and arguments over semihosting).
fn run_under_qemu(dir: &Path, argv: &[&str]) -> anyhow::Result<Ran> {
    qemu::ensure_installed()?;
    c_library::ensure_arm_toolchain()?;
    let library = c_library::build_library(CTarget::Qemu, &[])?;
    let elf = dir.join("replay.elf");
    c_library::compile_c(
        CTarget::Qemu,
        &[c_library::c_dir().join("replay.c")],
        &library,
        &elf,
        &[],
    )?;
    let run_len = std::fs::metadata(dir.join(RUN)).map_or(0, |m| m.len() as usize);
    let deadline = Duration::from_secs(120 + run_len as u64 / 20_000);
    let result = qemu::run_with_args(&elf, dir, argv, &[], deadline)?;
    let refused = result.log.contains(": refused: ");
    Ok(Ran {
        log: result.log,
        success: result.success,
        refused,
    })
}
