//! `cargo xtask ci`: the whole test suite, as CI runs it.

use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, bail};

use crate::firmware::TARGET;
use crate::{output, qemu, run, workspace_root};

/// Seconds CI fuzzes each target.
const CI_FUZZ_SECONDS: u32 = 20;

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

/// Wall time per CI step, printed at the end: where CI's minutes go.
struct StepClock {
    last: Instant,
    laps: Vec<(String, f64)>,
}

impl StepClock {
    fn new() -> Self {
        StepClock {
            last: Instant::now(),
            laps: Vec::new(),
        }
    }

    /// Ends the step `name`, begun when the last one ended.
    fn lap(&mut self, name: impl Into<String>) {
        let now = Instant::now();
        self.laps.push((name.into(), (now - self.last).as_secs_f64()));
        self.last = now;
    }

    /// The steps and their wall times, s, one per line.
    fn print(&self) {
        eprintln!(
            "
ci: wall time per step"
        );
        for (name, seconds) in &self.laps {
            eprintln!("  {seconds:>6.0} s  {name}");
        }
    }
}

/// Runs `cargo test` with `args`, echoing its output; returns (passed, failed).
fn run_tests(args: &[&str]) -> anyhow::Result<(u64, u64)> {
    eprintln!("\n==> cargo {}", args.join(" "));
    let output = Command::new("cargo")
        .args(args)
        // Tests that need an installed server (PostgreSQL) fail here instead of skipping.
        .env("CI", "true")
        .current_dir(workspace_root())
        .stderr(Stdio::inherit())
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

/// Clippy with `-D warnings`: the host workspace (every target), then the firmware's
/// feature sets for the target, with the no_std check of rbf-core and gyro-wire.
fn clippy(
    qemu_boards: &[&str],
    panic_check: &[&str],
    image_args: impl Fn(&crate::firmware::BoardImage) -> [&'static str; 8],
) -> anyhow::Result<()> {
    run(
        "cargo",
        &["clippy", "--workspace", "--all-targets", "--", "-D", "warnings"],
    )?;
    // The no_std check of rbf-core and gyro-wire (without their default `std`, for the
    // target) in the same run as the QEMU test images: one feature resolution, so the proc
    // macros both use compile once.
    run(
        "cargo",
        &[
            &[
                "clippy",
                "--package",
                "rbf-core",
                "--package",
                "gyro-wire",
                "--no-default-features",
                "--package",
                crate::c_library::PACKAGE,
                "--lib",
            ][..],
            qemu_boards,
            &["--", "-D", "warnings"],
        ]
        .concat(),
    )?;
    for args in crate::firmware::BOARD_IMAGES.iter().map(image_args) {
        run(
            "cargo",
            &[&["clippy"][..], &args[..], &["--", "-D", "warnings"]].concat(),
        )?;
    }
    run(
        "cargo",
        &[&["clippy"][..], panic_check, &["--", "-D", "warnings"]].concat(),
    )
}

/// The workspace's documentation built with rustdoc's warnings denied: a broken
/// link, or a public item's docs linking a private one, fails like a clippy warning.
fn rustdoc() -> anyhow::Result<()> {
    crate::run_with_env(
        "cargo",
        &["doc", "--workspace", "--no-deps"],
        &[("RUSTDOCFLAGS", std::ffi::OsStr::new("-D warnings"))],
    )
}

/// fmt, the import circles and the C header's drift, clippy (host and firmware) with the no_std
/// check, rustdoc and the board faults beside the firmware builds and the panic-free checks (firmware and
/// C library), host tests beside the fuzz build, the tests needing QEMU (and the C library's replays), then 20 s of fuzzing (the targets
/// side by side) beside the test needing PyPI; ends with `N passed, N failed`.
pub fn ci() -> anyhow::Result<()> {
    let started = Instant::now();
    let mut clock = StepClock::new();
    ensure_toolchain()?;
    crate::firmware::ensure_flip_link()?;
    qemu::ensure_installed()?;
    crate::c_library::ensure_arm_toolchain()?;
    crate::postgres::ensure_installed()?;
    clock.lap("toolchain, flip-link, QEMU, the ARM C toolchain and PostgreSQL present");
    run("cargo", &["fmt", "--all", "--check"])?;
    run("cargo", &["fmt", "--manifest-path", "fuzz/Cargo.toml", "--check"])?;
    crate::import_circles::import_circles()?;
    crate::c_library::check_header()?;
    clock.lap("fmt, import circles and the C header");
    // The QEMU test images (qemu-bench, and qemu-replay and qemu-faults on
    // the test harnesses), then each board image on its own: its HAL
    // switches cortex-m-rt to device mode, whose vector table the QEMU test
    // images lack.
    let qemu_boards = [
        "--package",
        crate::firmware::FIRMWARE,
        "--package",
        crate::firmware::HARNESS,
        "--target",
        TARGET,
        "--bins",
    ];
    let panic_check = [
        "--package",
        crate::firmware::FIRMWARE,
        "--target",
        TARGET,
        "--features",
        "panic-free-check-canary",
        "--bin",
        "panic-free-check",
    ];
    // Every board image: one binary each, with the feature it requires.
    let image_args = |image: &crate::firmware::BoardImage| {
        [
            "--package",
            image.package,
            "--target",
            TARGET,
            "--features",
            image.feature,
            "--bin",
            image.bin,
        ]
    };
    // Two sides at once, each in a target folder of its own (so neither waits on the
    // other's cargo lock, and the core one side's single-threaded stretches leave
    // idle, such as the images' LTO, works for the other): clippy and the board-fault
    // scenarios in `target/`, the release builds in `target/firmware/`.
    let (clippy, firmware) = std::thread::scope(|scope| {
        let firmware = scope.spawn(|| {
            let started = Instant::now();
            // The QEMU test images, then every board image (the QEMU ones too, which
            // the QEMU tests would otherwise build then, alone), then the panic-free
            // checks of the firmware and of the C library, then the C library builds
            // the C library tests link (host, and the Cortex-M4F under QEMU).
            crate::firmware::build_release(&qemu_boards)?;
            for image in &crate::firmware::BOARD_IMAGES {
                crate::firmware::build_release(&image_args(image))?;
            }
            crate::firmware::check_panic_free()?;
            crate::c_library::check_panic_free()?;
            for target in [crate::c_library::CTarget::Host, crate::c_library::CTarget::Qemu] {
                crate::c_library::build_library(target, &[])?;
            }
            anyhow::Ok(started.elapsed().as_secs_f64())
        });
        let started = Instant::now();
        let clippy = clippy(&qemu_boards, &panic_check, image_args)
            .and_then(|()| rustdoc())
            .and_then(|()| crate::board_faults::board_faults())
            .map(|()| started.elapsed().as_secs_f64());
        let firmware = firmware
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the firmware builds' thread panicked")));
        (clippy, firmware)
    });
    let (clippy, firmware) = (clippy?, firmware?);
    clock.lap(format!(
        "clippy (host, firmware feature sets, no_std check), rustdoc and board faults ({clippy:.0} s) \
         beside the firmware images, panic-free checks and C library builds ({firmware:.0} s)"
    ));
    // Beside the host tests, the fuzz targets' instrumented build (its own target
    // folder). Not beside the QEMU tests: their boards run in real time, and on a
    // loaded machine a board that falls behind drops samples, which its recordings
    // then show. At the normal CPU priority: it builds the run reader alone, and at
    // the lowest one a machine others load starves it past the host tests' end.
    let (mut passed, mut failed) = std::thread::scope(|scope| {
        let fuzz_build = scope.spawn(crate::fuzz::build_targets);
        let host = run_tests(&["test", "--workspace"]);
        let fuzz_build = fuzz_build
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the fuzz build's thread panicked")));
        host.and_then(|counts| fuzz_build.map(|()| counts))
    })?;
    clock.lap("host tests (build and run), beside them the fuzz build");
    // The tests that need QEMU or the cross build (ignored in a plain `cargo test`).
    // Named with `--workspace`, so that they build with the workspace's features and reuse
    // the step above (`--package e2e-tests` resolved other features and rebuilt trainer and
    // xtask).
    let (p, f) = run_tests(&[
        "test",
        "--workspace",
        "--test",
        "qemu",
        "--test",
        "device",
        "--test",
        "c_library",
        "--",
        "--ignored",
    ])?;
    (passed, failed) = (passed + p, failed + f);
    clock.lap("QEMU, device and C library tests");
    // Each fuzz target for 20 s (longer runs: `cargo xtask fuzz --seconds N`); a finding
    // fails CI (and becomes a regression file). Beside it the test against allantools,
    // which mostly waits on PyPI.
    let allantools = std::thread::scope(|scope| {
        let reference = scope.spawn(|| run_tests(&["test", "--workspace", "--test", "allantools", "--", "--ignored"]));
        let fuzzed = crate::fuzz::run_targets(CI_FUZZ_SECONDS);
        let reference = reference
            .join()
            .unwrap_or_else(|_| Err(anyhow::anyhow!("the allantools test's thread panicked")));
        fuzzed.and(reference)
    })?;
    (passed, failed) = (passed + allantools.0, failed + allantools.1);
    clock.lap("fuzzing beside the allantools test");
    clock.print();
    eprintln!("\nci: all steps passed in {:.0} s", started.elapsed().as_secs_f64());
    println!("{passed} passed, {failed} failed");
    Ok(())
}
