//! Cross builds of the firmware board binaries.

use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, bail};

use crate::workspace_root;

/// Bare-metal target of the gyro MCU (Cortex-M4F with FPU).
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// Target directory of firmware builds made from here. Separate from the
/// workspace's so that a build started inside `cargo test` never waits on
/// the outer cargo's lock.
pub fn target_dir() -> PathBuf {
    workspace_root().join("target").join("firmware")
}

/// Builds board binary `bin` (release) and returns the ELF path.
pub fn build(bin: &str, features: &[&str]) -> anyhow::Result<PathBuf> {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.args([
        "build",
        "--quiet",
        "--release",
        "--package",
        "firmware",
        "--target",
        TARGET,
        "--bin",
        bin,
    ])
    .env("CARGO_TARGET_DIR", target_dir())
    .current_dir(workspace_root());
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    let status = cmd.status().context("cannot start cargo")?;
    if !status.success() {
        bail!("building firmware binary {bin} for {TARGET} failed");
    }
    Ok(target_dir().join(TARGET).join("release").join(bin))
}

/// Flash and RAM a firmware image uses, from its ELF sections, bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageSize {
    /// Flash: vector table, code, read-only data and the initial values of .data.
    pub flash: u64,
    /// Static RAM: .data, .bss and .uninit (the stack comes on top).
    pub static_ram: u64,
}

/// Reads the section sizes of an ELF image.
pub fn image_size(elf: &std::path::Path) -> anyhow::Result<ImageSize> {
    use object::{Object, ObjectSection};
    let data = std::fs::read(elf).with_context(|| format!("{}: cannot read", elf.display()))?;
    let file = object::File::parse(&*data).with_context(|| format!("{}: not an ELF image", elf.display()))?;
    let size = |name: &str| file.section_by_name(name).map_or(0, |s| s.size());
    Ok(ImageSize {
        flash: size(".vector_table") + size(".text") + size(".rodata") + size(".data"),
        static_ram: size(".data") + size(".bss") + size(".uninit"),
    })
}
