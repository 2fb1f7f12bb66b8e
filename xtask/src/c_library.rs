//! rbf-core from C: the header `rbf-core-c/include/rbf_core.h` generated
//! from the crate by cbindgen (`cargo xtask c-header`, and CI's check that
//! the checked-in one has not drifted), and the static library built for
//! the host and for the MCU target.

use std::path::PathBuf;

use anyhow::{Context, bail};

use crate::workspace_root;

/// The crate of the C library.
pub const PACKAGE: &str = "rbf-core-c";

/// The crate's folder.
pub fn crate_dir() -> PathBuf {
    workspace_root().join(PACKAGE)
}

/// The checked-in header.
pub fn header_path() -> PathBuf {
    crate_dir().join("include").join("rbf_core.h")
}

/// The header cbindgen writes for the crate's source today.
pub fn generate_header() -> anyhow::Result<Vec<u8>> {
    let dir = crate_dir();
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml"))
        .map_err(|e| anyhow::anyhow!("{}: {e}", dir.join("cbindgen.toml").display()))?;
    let bindings = cbindgen::Builder::new()
        .with_crate(&dir)
        .with_config(config)
        .generate()
        .with_context(|| format!("cbindgen cannot read {}", dir.display()))?;
    let mut out = Vec::new();
    bindings.write(&mut out);
    Ok(out)
}

/// `cargo xtask c-header`: writes the header; returns its path.
pub fn write_header() -> anyhow::Result<PathBuf> {
    let path = header_path();
    std::fs::write(&path, generate_header()?).with_context(|| format!("{}: cannot write", path.display()))?;
    Ok(path)
}

/// Fails when the checked-in header is not what cbindgen writes for the
/// crate's source (CI's check: a changed interface needs its header).
pub fn check_header() -> anyhow::Result<()> {
    let path = header_path();
    let checked_in = std::fs::read(&path).with_context(|| format!("{}: cannot read", path.display()))?;
    if checked_in != generate_header()? {
        bail!(
            "{} differs from what rbf-core-c's source generates: run `cargo xtask c-header` and commit it",
            path.display()
        );
    }
    Ok(())
}

/// Where the C program and the library are built for: the host (`cc`) or
/// the STM32F405 (`arm-none-eabi-gcc` and newlib, run under QEMU).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CTarget {
    /// The host's `cc` and the library built for the host.
    Host,
    /// The Cortex-M4F under QEMU's netduinoplus2: the library for
    /// [`crate::firmware::TARGET`], newlib with semihosting (librdimon).
    Qemu,
}

/// The C compiler of the Cortex-M4F build.
pub const ARM_GCC: &str = "arm-none-eabi-gcc";

/// Flags of every C compile: C11, warnings are errors.
const C_FLAGS: [&str; 5] = ["-std=c11", "-O2", "-Wall", "-Wextra", "-Werror"];

/// Cortex-M4F with its FPU, hard-float ABI: what the library is built for.
pub const ARM_FLAGS: [&str; 4] = ["-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"];

/// The cargo profile the library is built with (the workspace's
/// Cargo.toml: the release profile at opt-level 2, fewer instructions per
/// step for a C caller; docs/decisions.md).
pub const PROFILE: &str = "c-library";

/// Builds the static library (profile [`PROFILE`]) for `target` with `features`;
/// returns the path of `librbf_core_c.a`. In the firmware's target
/// directory ([`crate::firmware::target_dir`]), so that a build started
/// inside `cargo test` never waits on the outer cargo's lock.
pub fn build_library(target: CTarget, features: &[&str]) -> anyhow::Result<PathBuf> {
    let dir = crate::firmware::target_dir();
    let mut cmd = std::process::Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.args(["build", "--quiet", "--profile", PROFILE, "--package", PACKAGE])
        .env("CARGO_TARGET_DIR", &dir)
        .current_dir(workspace_root());
    if !features.is_empty() {
        cmd.args(["--features", &features.join(",")]);
    }
    let out = match target {
        CTarget::Host => dir.join(PROFILE),
        CTarget::Qemu => {
            cmd.args(["--target", crate::firmware::TARGET]);
            dir.join(crate::firmware::TARGET).join(PROFILE)
        }
    };
    let status = cmd.status().context("cannot start cargo")?;
    if !status.success() {
        bail!("building {PACKAGE} for {target:?} failed");
    }
    let lib = out.join("librbf_core_c.a");
    if features.is_empty() {
        return Ok(lib);
    }
    // Each feature set its own copy: they are built to the same path.
    let kept = out.join(format!("librbf_core_c+{}.a", features.join("+")));
    std::fs::copy(&lib, &kept).with_context(|| format!("{}: cannot copy", lib.display()))?;
    Ok(kept)
}

/// The C sources of the replay program and its QEMU startup.
pub fn c_dir() -> PathBuf {
    crate_dir().join("c")
}

/// Compiles the C `sources` with the header against `library` into
/// `output` for `target` (the QEMU image with startup.c, link.ld and
/// newlib's semihosting library); `extra` goes to the compiler last. The
/// compiler's messages on failure.
pub fn compile_c(
    target: CTarget,
    sources: &[PathBuf],
    library: &std::path::Path,
    output: &std::path::Path,
    extra: &[&str],
) -> anyhow::Result<()> {
    let include = crate_dir().join("include");
    let mut cmd = match target {
        CTarget::Host => std::process::Command::new("cc"),
        CTarget::Qemu => {
            let mut c = std::process::Command::new(ARM_GCC);
            c.args(ARM_FLAGS)
                .args(["--specs=rdimon.specs", "-Wl,--gc-sections", "-T"])
                .arg(c_dir().join("qemu").join("link.ld"))
                .arg(c_dir().join("qemu").join("startup.c"));
            c
        }
    };
    cmd.args(C_FLAGS).arg("-I").arg(include).args(sources).arg(library);
    cmd.args(["-lm"]);
    if target == CTarget::Host {
        // The host library is built with Rust's std.
        cmd.args(["-lpthread", "-ldl"]);
    }
    cmd.args(extra).arg("-o").arg(output);
    let compiler = if target == CTarget::Host { "cc" } else { ARM_GCC };
    let out = cmd.output().with_context(|| format!("cannot start {compiler}"))?;
    if !out.status.success() {
        bail!(
            "{compiler} failed on {}:\n{}",
            sources
                .iter()
                .map(|s| s.display().to_string())
                .collect::<Vec<_>>()
                .join(" "),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

/// True when `arm-none-eabi-gcc` and newlib's semihosting library are there.
pub fn arm_toolchain_available() -> bool {
    std::process::Command::new(ARM_GCC)
        .args(["-print-file-name=librdimon.a"])
        .args(ARM_FLAGS)
        .output()
        .is_ok_and(|o| o.status.success() && String::from_utf8_lossy(&o.stdout).trim() != "librdimon.a")
}

/// Installs Debian's `gcc-arm-none-eabi` and `libnewlib-arm-none-eabi` when missing.
pub fn ensure_arm_toolchain() -> anyhow::Result<()> {
    if arm_toolchain_available() {
        return Ok(());
    }
    crate::qemu::apt_install(&["gcc-arm-none-eabi", "libnewlib-arm-none-eabi"])?;
    if !arm_toolchain_available() {
        bail!("{ARM_GCC} with newlib still not available after installing it");
    }
    Ok(())
}

/// The functions the header declares (`rbf_…(`), as a C program may call them.
pub fn exported_functions() -> anyhow::Result<Vec<String>> {
    let path = header_path();
    let header = std::fs::read_to_string(&path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut names: Vec<String> = header
        .lines()
        .filter(|l| !l.starts_with(' ') && !l.starts_with('#'))
        .filter_map(|l| {
            let open = l.find('(')?;
            let name = l[..open].rsplit([' ', '*']).next()?;
            name.starts_with("rbf_").then(|| name.to_owned())
        })
        .collect();
    names.dedup();
    if names.len() < 7 {
        bail!(
            "{}: found {} functions, expected every export: {names:?}",
            path.display(),
            names.len()
        );
    }
    Ok(names)
}

/// The symbol the panic handler of the `panic-free-check` build calls and
/// nothing defines (rbf-core-c/src/panic.rs), as the firmware's check has it.
pub use crate::firmware::PANIC_SYMBOL;

/// Links `program` for the Cortex-M4F against the library built with
/// `feature`, every exported function kept (`--require-defined`), so that a
/// panic path reachable from any of them leaves [`PANIC_SYMBOL`] undefined.
/// The linker's messages when it fails.
fn link_with_every_export(feature: &str, extra_symbols: &[&str]) -> anyhow::Result<Result<(), String>> {
    let library = build_library(CTarget::Qemu, &[feature])?;
    let dir = tempfile::TempDir::new().context("cannot create a working directory")?;
    let mut keep: Vec<String> = exported_functions()?
        .iter()
        .map(|f| format!("-Wl,--require-defined={f}"))
        .collect();
    keep.extend(extra_symbols.iter().map(|f| format!("-Wl,--require-defined={f}")));
    let keep: Vec<&str> = keep.iter().map(String::as_str).collect();
    let elf = dir.path().join("check.elf");
    Ok(compile_c(CTarget::Qemu, &[c_dir().join("replay.c")], &library, &elf, &keep).map_err(|e| format!("{e:#}")))
}

/// Proves at link time that no panic is reachable from any function of the
/// C library on the target: the library built with `panic-free-check` links
/// into a C program that keeps every export, and its canary (one deliberate
/// bounds check in an extra export) fails to link on [`PANIC_SYMBOL`].
pub fn check_panic_free() -> anyhow::Result<()> {
    ensure_arm_toolchain()?;
    eprintln!("\n==> C library panic-free check: every export linked, no {PANIC_SYMBOL}");
    if let Err(log) = link_with_every_export("panic-free-check", &[])? {
        if log.contains(PANIC_SYMBOL) {
            bail!(
                "a panic path is reachable from a function of the C library (undefined {PANIC_SYMBOL}); \
                 see docs/panic-free.md to find it:\n{log}"
            );
        }
        bail!("linking the C library's panic-free check failed:\n{log}");
    }
    eprintln!("==> C library panic-free check: its canary must not link");
    match link_with_every_export("panic-free-check-canary", &["rbf_panic_canary"])? {
        Err(log) if log.contains(PANIC_SYMBOL) => {
            eprintln!("    ok: no panic path from any export; the canary's fails the link as it must");
            Ok(())
        }
        Err(log) => bail!("the C library's canary failed to link for another reason:\n{log}"),
        Ok(()) => bail!("the C library's panic-free canary linked: the check proves nothing"),
    }
}

/// What the C library costs in one C loop on the Cortex-M4F (`bench.c`
/// under QEMU, `-icount shift=0`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CLibraryCost {
    /// 1 (rbf_gyro_*) or 3 (rbf_imu_*).
    pub axes: u8,
    /// Instructions per sample of the step (the C loop's call included).
    pub instructions_per_sample: u64,
    /// Flash the library's code and constants take in the linked image, bytes.
    pub flash_bytes: u64,
    /// The library's own statics in the image, bytes (the state is the caller's).
    pub static_ram_bytes: u64,
    /// The state the caller provides, bytes (`RBF_*_STATE_SIZE`).
    pub state_bytes: u64,
    /// Stack the load and the steps took, bytes (the C loop's frame included).
    pub stack_bytes: u64,
}

/// The bytes the library's objects (`librbf_core_c`) take in flash and in
/// static RAM, from a GNU ld map file's input sections.
pub fn library_sizes_from_map(map: &str) -> (u64, u64) {
    let (mut flash, mut ram) = (0, 0);
    let mut output_section = String::new();
    let mut pending: Option<()> = None;
    for line in map.lines() {
        if let Some(name) = line.split_whitespace().next().filter(|_| !line.starts_with(' ')) {
            output_section = name.to_owned();
        }
        // An input section: " .name  0xADDR  0xSIZE  FILE", the name alone on
        // its line when long.
        let fields: Vec<&str> = line.split_whitespace().collect();
        let rest = match fields.as_slice() {
            [name, addr, ..] if line.starts_with(' ') && name.starts_with('.') && addr.starts_with("0x") => {
                &fields[1..]
            }
            [addr, ..] if addr.starts_with("0x") && pending.is_some() => &fields[..],
            [name] if line.starts_with(' ') && name.starts_with('.') => {
                pending = Some(());
                continue;
            }
            _ => {
                pending = None;
                continue;
            }
        };
        pending = None;
        let [_, size, file, ..] = rest else { continue };
        if !file.contains("librbf_core_c") {
            continue;
        }
        let Ok(size) = u64::from_str_radix(size.trim_start_matches("0x"), 16) else {
            continue;
        };
        match output_section.as_str() {
            ".bss" => ram += size,
            ".data" => {
                ram += size;
                flash += size;
            }
            ".text" | ".ARM.exidx" | ".ARM.extab" | ".init_array" => flash += size,
            // Debug information, attributes, comments: not in the image.
            _ => {}
        }
    }
    (flash, ram)
}

/// Builds `bench.c` for `axes` against the target library, runs it under
/// QEMU in `dir` on the blob `blob` there (written by qemu-bench: the very
/// model the Rust loop is timed on) and reads its costs.
pub fn bench(dir: &std::path::Path, axes: u8, blob: &str) -> anyhow::Result<CLibraryCost> {
    ensure_arm_toolchain()?;
    let library = build_library(CTarget::Qemu, &[])?;
    let elf = dir.join(format!("c-bench-{axes}.elf"));
    let map = dir.join(format!("c-bench-{axes}.map"));
    let define = format!("-DBENCH_AXES={axes}");
    let map_arg = format!("-Wl,-Map={}", map.display());
    compile_c(
        CTarget::Qemu,
        &[c_dir().join("bench.c")],
        &library,
        &elf,
        &[&define, &map_arg],
    )?;
    let icount = ["-icount".to_owned(), "shift=0".to_owned()];
    let run = crate::qemu::run_with_args(
        &elf,
        dir,
        &["bench", blob],
        &icount,
        std::time::Duration::from_secs(120),
    )?;
    let prefix = format!("c_library axes={axes} instructions_per_sample ");
    let Some(line) = run.log.lines().find_map(|l| l.strip_prefix(&prefix)) else {
        bail!("the C library bench (axes {axes}) printed no figure:\n{}", run.log);
    };
    let mut words = line.split_whitespace();
    let instructions_per_sample = words.next().and_then(|n| n.parse().ok());
    let stack_bytes = words.nth(1).and_then(|n| n.parse().ok());
    let (Some(instructions_per_sample), Some(stack_bytes)) = (instructions_per_sample, stack_bytes) else {
        bail!("the C library bench (axes {axes}) printed an unreadable line: {line}");
    };
    let map_text = std::fs::read_to_string(&map).with_context(|| format!("{}: cannot read", map.display()))?;
    let (flash_bytes, static_ram_bytes) = library_sizes_from_map(&map_text);
    let state_bytes = if axes == 1 {
        rbf_core_c::RBF_GYRO_STATE_SIZE
    } else {
        rbf_core_c::RBF_IMU_STATE_SIZE
    } as u64;
    Ok(CLibraryCost {
        axes,
        instructions_per_sample,
        flash_bytes,
        static_ram_bytes,
        state_bytes,
        stack_bytes,
    })
}
