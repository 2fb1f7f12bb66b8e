//! `cargo xtask qemu-faults`: the fault-injection campaigns on the firmware
//! image under QEMU (sensor and bus faults, model-region bit flips, resets
//! during model updates, UART commands).

use std::path::Path;
use std::time::Duration;

use anyhow::{Context, bail};
use trainer::blobfile::read_model;

use crate::replay::MODEL_SLOT_A;
use crate::{firmware, qemu};

/// Flash address of model slot MODEL_B (memory.x).
pub const MODEL_SLOT_B: u32 = 0x080E_0000;

/// Runs the `qemu-faults` image with `model` in MODEL_A (the model running)
/// and `update` in MODEL_B (the update installed); returns its report lines,
/// the last being `faults injected N, samples lost 0, panics 0, ...`.
pub fn qemu_faults(model: &Path, update: &Path) -> anyhow::Result<Vec<String>> {
    read_model(model)?;
    read_model(update)?;
    let elf = firmware::build(firmware::HARNESS, "qemu-faults", &[])?;
    let dir = tempfile::TempDir::new().context("cannot create a working directory")?;
    std::fs::copy(model, dir.path().join("a.bin")).with_context(|| format!("{}: cannot copy", model.display()))?;
    std::fs::copy(update, dir.path().join("b.bin")).with_context(|| format!("{}: cannot copy", update.display()))?;
    let extra = [
        "-device".to_owned(),
        format!("loader,file=a.bin,addr={MODEL_SLOT_A:#x}"),
        "-device".to_owned(),
        format!("loader,file=b.bin,addr={MODEL_SLOT_B:#x}"),
    ];
    let result = qemu::run(&elf, dir.path(), &extra, Duration::from_secs(300))?;
    let lines: Vec<String> = result
        .log
        .lines()
        .filter(|l| l.starts_with("faults"))
        .map(str::to_owned)
        .collect();
    if !result.success || !lines.last().is_some_and(|l| l.starts_with("faults injected")) {
        bail!(
            "the fault campaign failed or did not finish (a panic stops the image):\n{}",
            result.log
        );
    }
    Ok(lines)
}
