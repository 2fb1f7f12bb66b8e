//! Cross builds of the firmware images: the board's (package
//! [`FIRMWARE`]) and the QEMU test images on the test harnesses (package
//! [`HARNESS`]).

use std::path::PathBuf;
use std::process::Command;

use anyhow::{Context, bail};

use crate::workspace_root;

/// Bare-metal target of the gyro MCU (Cortex-M4F with FPU).
pub const TARGET: &str = "thumbv7em-none-eabihf";

/// The firmware library's package: the board images, `qemu-bench`, `panic-free-check`.
pub const FIRMWARE: &str = "firmware";
/// The test harnesses' package: `qemu-replay`, `qemu-faults` and the board images under QEMU.
pub const HARNESS: &str = "firmware-harness";

/// Target directory of firmware builds made from here. Separate from the
/// workspace's so that a build started inside `cargo test` never waits on
/// the outer cargo's lock.
pub fn target_dir() -> PathBuf {
    crate::target_dir().join("firmware")
}

/// `cargo build --release ARGS` in [`target_dir`], echoed: CI builds the
/// images there, so that the panic checks, the benchmarks and the QEMU tests
/// after it ([`build`]) find them built instead of compiling the HAL and
/// the firmware again in a folder of their own.
pub fn build_release(args: &[&str]) -> anyhow::Result<()> {
    ensure_flip_link()?;
    let dir = target_dir();
    crate::run_with_env(
        "cargo",
        &[&["build", "--release"][..], args].concat(),
        &[("CARGO_TARGET_DIR", dir.as_os_str())],
    )
}

/// The linker .cargo/config.toml sets for the firmware target.
const FLIP_LINK: &str = "flip-link";

/// Installs flip-link (`cargo install`) when it is missing.
pub fn ensure_flip_link() -> anyhow::Result<()> {
    // It has no --version: whether it starts at all says it is installed.
    let present = Command::new(FLIP_LINK).output().is_ok();
    if present {
        return Ok(());
    }
    eprintln!("\n==> installing {FLIP_LINK} (cargo install, once): the firmware images link through it");
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["install", "--locked", FLIP_LINK])
        .status()
        .context("cannot start cargo install")?;
    if !status.success() {
        bail!("cargo install {FLIP_LINK} failed");
    }
    Ok(())
}

/// A board image: its package, its binary (one per image over
/// `firmware::board`: `firmware/src/bin/`, the QEMU images in
/// `firmware-harness/src/bin/`) and the feature it requires.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoardImage {
    /// Its package: [`FIRMWARE`] or, for the QEMU images, [`HARNESS`].
    pub package: &'static str,
    /// The binary's name.
    pub bin: &'static str,
    /// The feature that selects its HAL and, for the QEMU images, QEMU's substitutes.
    pub feature: &'static str,
}

impl BoardImage {
    /// A real board's image `bin` in [`FIRMWARE`], built with `feature`.
    const fn board(bin: &'static str, feature: &'static str) -> Self {
        BoardImage {
            package: FIRMWARE,
            bin,
            feature,
        }
    }

    /// A QEMU image `bin` in [`HARNESS`] (feature `board-qemu`).
    const fn qemu(bin: &'static str) -> Self {
        BoardImage {
            package: HARNESS,
            bin,
            feature: "board-qemu",
        }
    }

    /// Builds the image (release) and returns its ELF path.
    pub fn build(self) -> anyhow::Result<PathBuf> {
        build(self.package, self.bin, &[self.feature])
    }

    /// True for the three-axis images.
    pub fn three_axes(self) -> bool {
        self.bin.starts_with("stm32f405-axes")
    }
}

/// The single-axis gyro board (what `cargo flash-board` flashes).
pub const BOARD: BoardImage = BoardImage::board("stm32f405", "board-stm32f405");
/// The single-axis board with defmt logging over RTT.
pub const BOARD_DEBUG: BoardImage = BoardImage::board("stm32f405-debug", "board-debug");
/// The three-axis board, a model per axis.
pub const BOARD_AXES: BoardImage = BoardImage::board("stm32f405-axes", "board-stm32f405");
/// The three-axis board for a shared-basis blob.
pub const BOARD_AXES_SHARED: BoardImage = BoardImage::board("stm32f405-axes-shared", "board-stm32f405");
/// [`BOARD`] under QEMU (stack peak measured, exits when done).
pub const BOARD_QEMU: BoardImage = BoardImage::qemu("stm32f405-qemu");
/// [`BOARD_AXES`] under QEMU.
pub const BOARD_AXES_QEMU: BoardImage = BoardImage::qemu("stm32f405-axes-qemu");
/// [`BOARD_AXES_SHARED`] under QEMU.
pub const BOARD_AXES_SHARED_QEMU: BoardImage = BoardImage::qemu("stm32f405-axes-shared-qemu");
/// [`BOARD_QEMU`] serving until stopped (`cargo xtask qemu-board --pty`).
pub const BOARD_QEMU_SERVE: BoardImage = BoardImage::qemu("stm32f405-qemu-serve");
/// [`BOARD_AXES_QEMU`] serving until stopped (`cargo xtask qemu-board --axes 3 --pty`).
pub const BOARD_AXES_QEMU_SERVE: BoardImage = BoardImage::qemu("stm32f405-axes-qemu-serve");

/// Every board image, as CI builds and lints them.
pub const BOARD_IMAGES: [BoardImage; 9] = [
    BOARD,
    BOARD_DEBUG,
    BOARD_AXES,
    BOARD_AXES_SHARED,
    BOARD_QEMU,
    BOARD_AXES_QEMU,
    BOARD_AXES_SHARED_QEMU,
    BOARD_QEMU_SERVE,
    BOARD_AXES_QEMU_SERVE,
];

/// Builds binary `bin` of firmware package `package` ([`FIRMWARE`] or
/// [`HARNESS`]) (release) and returns the ELF path: with `features`, a copy
/// of its own (`bin+feature+…` beside it), because every feature set of one
/// binary is built to the same path and tests build several of them at once.
pub fn build(package: &str, bin: &str, features: &[&str]) -> anyhow::Result<PathBuf> {
    static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());
    ensure_flip_link()?;
    let _building = ONE_AT_A_TIME.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // cargo runs quietly: say what the wait is for (a first build takes minutes).
    eprintln!("==> building firmware binary {bin} for {TARGET} (release; minutes the first time, a no-op once built)");
    let status = build_command(package, bin, features)
        .status()
        .context("cannot start cargo")?;
    if !status.success() {
        bail!("building firmware binary {bin} for {TARGET} failed");
    }
    let built = target_dir().join(TARGET).join("release").join(bin);
    if features.is_empty() {
        return Ok(built);
    }
    let kept = built.with_file_name(format!("{bin}+{}", features.join("+")));
    std::fs::copy(&built, &kept).with_context(|| format!("{}: cannot copy", built.display()))?;
    Ok(kept)
}

/// The `trainer` CLI exactly as `cargo test --workspace` builds it (host,
/// the dev profile) in the workspace's own target directory: its path.
///
/// Built through `cargo test --workspace --no-run`, not `cargo build
/// --package trainer`: the workspace's tests turn on features of shared
/// crates that a build of the trainer alone does not, so that build would compile the firmware, the
/// trainer and its binary a second time, inside the QEMU and device tests'
/// time. After `cargo xtask ci`'s host tests every target is fresh and this
/// costs a no-op; run alone it builds the workspace's tests once.
pub fn trainer_cli() -> anyhow::Result<PathBuf> {
    eprintln!(
        "==> building the trainer CLI with the workspace's tests (cargo test --workspace --no-run; minutes the first time, \
         a no-op once built)"
    );
    let status = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["test", "--quiet", "--workspace", "--no-run"])
        .env("CARGO_TARGET_DIR", crate::target_dir())
        .current_dir(workspace_root())
        .status()
        .context("cannot start cargo")?;
    if !status.success() {
        bail!("building the trainer CLI failed");
    }
    Ok(crate::target_dir().join("debug").join("trainer"))
}

/// The symbol the panic handler of the `panic-free-check` build calls and
/// nothing defines (firmware/src/board.rs).
pub const PANIC_SYMBOL: &str = "hot_path_can_panic";

/// Proves at link time that model validation and the per-sample path cannot
/// panic: `panic-free-check` must link, and its canary (the same image with
/// one deliberate out-of-bounds index) must fail to link on [`PANIC_SYMBOL`],
/// which shows the check can fail.
pub fn check_panic_free() -> anyhow::Result<()> {
    let bin = "panic-free-check";
    eprintln!("\n==> panic-free check: {bin} must link");
    let out = build_command(FIRMWARE, bin, &["panic-free-check"])
        .output()
        .context("cannot start cargo")?;
    if !out.status.success() {
        let log = String::from_utf8_lossy(&out.stderr);
        if log.contains(PANIC_SYMBOL) {
            bail!(
                "a panic path survives in the firmware's per-sample path or model validation \
                 (undefined {PANIC_SYMBOL}); see docs/panic-free.md to find it:\n{log}"
            );
        }
        bail!("building {bin} failed:\n{log}");
    }
    eprintln!("==> panic-free check: its canary must not link");
    let out = build_command(FIRMWARE, bin, &["panic-free-check-canary"])
        .output()
        .context("cannot start cargo")?;
    let log = String::from_utf8_lossy(&out.stderr);
    if out.status.success() || !log.contains(PANIC_SYMBOL) {
        bail!("the panic-free canary linked (or failed otherwise): the check proves nothing\n{log}");
    }
    eprintln!("    ok: no panic path; the canary's panic path fails the link as it must");
    check_board_panics()
}

/// Builds the board images (what is flashed), single-axis (`stm32f405`),
/// three-axis (`stm32f405-axes`) and shared-basis three-axis
/// (`stm32f405-axes-shared`), and
/// proves from their machine code that they hold no panic call site, and
/// that nothing after init reaches one ([`crate::panic_paths`]).
pub fn check_board_panics() -> anyhow::Result<()> {
    for image in [BOARD, BOARD_AXES, BOARD_AXES_SHARED] {
        eprintln!(
            "\n==> board image {}: no panic call site, none reachable from its loop and handlers",
            image.bin
        );
        let reach = crate::panic_paths::check_board_image(&image.build()?)?;
        eprintln!(
            "    ok: no panic call site in the image; {} functions reachable from run_forever and the handlers",
            reach.functions
        );
    }
    Ok(())
}

fn build_command(package: &str, bin: &str, features: &[&str]) -> Command {
    let mut cmd = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.args([
        "build",
        "--quiet",
        "--release",
        "--package",
        package,
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
    cmd
}

/// Flash and RAM a firmware image uses, from its ELF sections, bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImageSize {
    /// Flash: vector table, code, read-only data and the initial values of
    /// .data and of the tables memory.x copies to RAM (.ram_tables).
    pub flash: u64,
    /// Static RAM: .ram_tables, .data, .bss and .uninit (the stack comes on top).
    pub static_ram: u64,
    /// The largest object in flash's read-only data (name, bytes).
    pub largest_rodata: (String, u64),
    /// Whether rbf-core's exp2 table lies in RAM (memory.x's .ram_tables).
    pub exp2_table_in_ram: bool,
}

/// Reads the section sizes of an ELF image.
pub fn image_size(elf: &std::path::Path) -> anyhow::Result<ImageSize> {
    use object::{Object, ObjectSection};
    let data = std::fs::read(elf).with_context(|| format!("{}: cannot read", elf.display()))?;
    let file = object::File::parse(&*data).with_context(|| format!("{}: not an ELF image", elf.display()))?;
    use object::{ObjectSymbol, SectionIndex};
    let size = |name: &str| file.section_by_name(name).map_or(0, |s| s.size());
    let index = |name: &str| file.section_by_name(name).map(|s| s.index());
    let in_section = |sym: &object::Symbol<'_, '_>, section: Option<SectionIndex>| {
        section.is_some() && sym.section_index() == section
    };
    let (rodata, ram_tables) = (index(".rodata"), index(".ram_tables"));
    let mut largest_rodata = (String::new(), 0);
    let mut exp2_table_in_ram = false;
    for sym in file.symbols() {
        let name = sym.name().unwrap_or("");
        if in_section(&sym, rodata) && sym.size() > largest_rodata.1 {
            largest_rodata = (name.to_owned(), sym.size());
        }
        if in_section(&sym, ram_tables) && name.contains("EXP2_OCTAVE_BITS") {
            exp2_table_in_ram = true;
        }
    }
    let ram_tables_len = size(".ram_tables");
    Ok(ImageSize {
        flash: size(".vector_table") + size(".text") + size(".rodata") + size(".data") + ram_tables_len,
        static_ram: ram_tables_len + size(".data") + size(".bss") + size(".uninit"),
        largest_rodata,
        exp2_table_in_ram,
    })
}
