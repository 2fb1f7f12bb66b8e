//! `cargo xtask qemu-replay`: a recorded run through the real firmware image
//! under QEMU, output byte-identical to `trainer compensate`.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use trainer::axes::shared_axes_for_run;
use trainer::blobfile::{ModelFile, read_model_file};
use trainer::evaluate::require_shared_thermometer;
use trainer::run::Run;
use trainer::run::RunReader;

use crate::{firmware, qemu};

/// Flash address of model slot MODEL_A (memory.x).
pub const MODEL_SLOT_A: u32 = 0x080C_0000;

/// What a replay produced besides the output file.
#[derive(Debug)]
pub struct ReplaySummary {
    /// Samples the firmware processed.
    pub samples: usize,
    /// The firmware's closing line (counters, stack use).
    pub report: String,
}

/// Replays `run` with `model` through the `qemu-replay` image; writes the
/// compensated run to `output` and, if asked, the UART frames to `frames`.
pub fn qemu_replay(model: &Path, run: &Path, output: &Path, frames: Option<&Path>) -> anyhow::Result<ReplaySummary> {
    // Refuse what `trainer compensate` refuses, with its messages: a
    // single-axis blob (format 2) or a multi-axis one (format 3); a
    // shared-basis one on a run that lacks its axes or gives each axis
    // its own thermometer.
    let (file, _) = read_model_file(model)?;
    if let ModelFile::Shared(models) = &file {
        let reader = RunReader::open(run)?;
        let axes = shared_axes_for_run(&file, model, &reader)?;
        let columns: Vec<_> = axes.iter().map(|(_, c)| *c).collect();
        require_shared_thermometer(&reader, &columns, models.features().set.thermometer_mask())?;
    }
    let rows = Run::load(run)?.len();
    let elf = firmware::build("qemu-replay", &["test-harness"])?;
    let dir = tempfile::TempDir::new().context("cannot create a working directory")?;
    std::fs::copy(run, dir.path().join("input.csv")).with_context(|| format!("{}: cannot copy", run.display()))?;
    std::fs::copy(model, dir.path().join("model.bin")).with_context(|| format!("{}: cannot copy", model.display()))?;
    let loader = format!("loader,file=model.bin,addr={MODEL_SLOT_A:#x}");
    let deadline = Duration::from_secs(120 + rows as u64 / 5_000);
    let result = qemu::run(&elf, dir.path(), &["-device".into(), loader], deadline)?;
    let report = result
        .log
        .lines()
        .find(|l| l.starts_with("replay: samples"))
        .unwrap_or("")
        .to_owned();
    if !result.success {
        bail!("the firmware replay failed:\n{}", result.log);
    }
    let samples: usize = report
        .split_whitespace()
        .nth(2)
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    if samples != rows {
        bail!("the firmware processed {samples} samples of {rows}:\n{}", result.log);
    }
    std::fs::copy(dir.path().join("output.csv"), output)
        .with_context(|| format!("{}: cannot write", output.display()))?;
    if let Some(frames) = frames {
        std::fs::copy(dir.path().join("frames.bin"), frames)
            .with_context(|| format!("{}: cannot write", frames.display()))?;
    }
    Ok(ReplaySummary { samples, report })
}
