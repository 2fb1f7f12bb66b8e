//! Project automation behind `cargo xtask`, as a library so that end-to-end
//! tests run QEMU through exactly the code the commands use.
//!
//! - [`firmware`]: cross builds of the board binaries;
//! - [`qemu`]: running an image under `qemu-system-arm` with a hard deadline;
//! - [`replay`]: `cargo xtask qemu-replay`;
//! - [`qemu_board`]: `cargo xtask qemu-board --pty`, the board on a pseudo-terminal;
//! - [`bench`](mod@bench): `cargo xtask bench-fw`; [`board_stack`]: its board stack measurement;
//! - [`accuracy`]: `cargo xtask bench-accuracy`;
//! - [`fuzz`]: `cargo xtask fuzz`;
//! - [`import_circles`]: `cargo xtask import-circles`;
//! - [`faults`]: `cargo xtask qemu-faults`;
//! - [`large_run`]: `cargo xtask bench-large-run`; [`bench_batch`]: `cargo xtask bench-batch`;
//! - [`postgres`]: the PostgreSQL server binaries the records tests start (installed by CI);
//! - [`ci`]: `cargo xtask ci`, the whole test suite; [`build_graph`]: that xtask and the tests build one trainer.
#![forbid(unsafe_code)]

pub mod accuracy;
pub mod bench;
pub mod bench_batch;
pub mod board_faults;
pub mod board_stack;
pub mod build_graph;
pub mod c_library;
pub mod c_replay;
pub mod ci;
pub mod faults;
pub mod firmware;
pub mod fuzz;
pub mod import_circles;
pub mod large_run;
pub mod panic_paths;
pub mod postgres;
pub mod qemu;
pub mod qemu_board;
pub mod replay;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, bail};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask sits in the workspace")
        .to_owned()
}

/// The workspace's target directory, where cargo puts what it builds:
/// `CARGO_TARGET_DIR` when set (relative to the current directory, as cargo
/// reads it), else `cargo metadata`'s `target_directory` (which follows
/// `build.target-dir` in a cargo config), else `<workspace>/target`. Every
/// path to a built binary or image starts here; resolved once per process.
pub fn target_dir() -> PathBuf {
    static DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    DIR.get_or_init(|| {
        target_dir_from(
            std::env::var_os("CARGO_TARGET_DIR"),
            std::env::current_dir().ok(),
            metadata_target_dir,
        )
    })
    .clone()
}

/// [`target_dir`] from the variable's value, the current directory and `cargo metadata`.
fn target_dir_from(
    variable: Option<std::ffi::OsString>,
    cwd: Option<PathBuf>,
    metadata: impl FnOnce() -> Option<PathBuf>,
) -> PathBuf {
    match variable.filter(|d| !d.is_empty()).map(PathBuf::from) {
        Some(dir) => match cwd {
            Some(cwd) if dir.is_relative() => cwd.join(dir),
            _ => dir,
        },
        None => metadata().unwrap_or_else(|| workspace_root().join("target")),
    }
}

/// `target_directory` as `cargo metadata` reports it for the workspace.
fn metadata_target_dir() -> Option<PathBuf> {
    let out = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
        .args(["metadata", "--format-version", "1", "--no-deps", "--offline"])
        .current_dir(workspace_root())
        .output()
        .ok()
        .filter(|o| o.status.success())?;
    let metadata: serde_json::Value = serde_json::from_slice(&out.stdout).ok()?;
    Some(PathBuf::from(metadata["target_directory"].as_str()?))
}

/// The release trainer binary in [`target_dir`] (what the benches run).
pub fn release_trainer() -> PathBuf {
    target_dir().join("release").join("trainer")
}

/// Runs a command in the workspace root, echoing it, failing if it fails.
pub fn run(program: &str, args: &[&str]) -> anyhow::Result<()> {
    run_with_env(program, args, &[])
}

/// [`run`] with the environment variables `env` set for the command.
pub fn run_with_env(program: &str, args: &[&str], env: &[(&str, &std::ffi::OsStr)]) -> anyhow::Result<()> {
    eprintln!("\n==> {program} {}", args.join(" "));
    let started = Instant::now();
    let status = Command::new(program)
        .args(args)
        .envs(env.iter().copied())
        .current_dir(workspace_root())
        .status()
        .with_context(|| format!("cannot start {program}"))?;
    if !status.success() {
        bail!("`{program} {}` failed ({status})", args.join(" "));
    }
    eprintln!("    ok in {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// Standard output of a command, empty if it cannot run.
pub fn output(program: &str, args: &[&str]) -> String {
    Command::new(program)
        .args(args)
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default()
}

/// The python of a venv under `dir` holding `packages` (made once; remade
/// when `modules`, a comma list, does not import).
pub fn python_venv(dir: &Path, packages: &[&str], modules: &str) -> anyhow::Result<PathBuf> {
    let python = dir.join("venv/bin/python");
    let ready = || {
        Command::new(&python)
            .args(["-c", &format!("import {modules}")])
            .status()
            .is_ok_and(|s| s.success())
    };
    if python.exists() && ready() {
        return Ok(python);
    }
    eprintln!("==> making a venv with {} (once)", packages.join(", "));
    let made = Command::new("python3")
        .args(["-m", "venv"])
        .arg(dir.join("venv"))
        .status()
        .with_context(|| "cannot start python3")?
        .success();
    let installed = made
        && Command::new(&python)
            .args(["-m", "pip", "install", "--quiet"])
            .args(packages)
            .status()?
            .success();
    if !installed || !ready() {
        bail!("could not make the venv with {}", packages.join(", "));
    }
    Ok(python)
}

#[cfg(test)]
mod tests {
    use std::path::{Path, PathBuf};

    use super::{metadata_target_dir, target_dir_from, workspace_root};

    #[test]
    fn the_target_dir_is_cargo_target_dir_else_what_cargo_metadata_says() {
        let cwd = || Some(PathBuf::from("/work/here"));
        let unused = || -> Option<PathBuf> { panic!("cargo metadata asked although CARGO_TARGET_DIR is set") };
        assert_eq!(
            target_dir_from(Some("/tmp/t".into()), cwd(), unused),
            Path::new("/tmp/t")
        );
        assert_eq!(
            target_dir_from(Some("rel/t".into()), cwd(), unused),
            Path::new("/work/here/rel/t")
        );
        let from_metadata = || Some(PathBuf::from("/elsewhere/target"));
        assert_eq!(
            target_dir_from(None, cwd(), from_metadata),
            Path::new("/elsewhere/target")
        );
        assert_eq!(
            target_dir_from(Some("".into()), cwd(), from_metadata),
            Path::new("/elsewhere/target"),
            "an empty variable is unset, as cargo reads it"
        );
        assert_eq!(target_dir_from(None, cwd(), || None), workspace_root().join("target"));
        // cargo itself answers for this workspace with an absolute directory.
        assert!(metadata_target_dir().is_some_and(|d| d.is_absolute()));
    }
}
