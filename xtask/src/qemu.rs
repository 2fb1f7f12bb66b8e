//! Running firmware images under `qemu-system-arm` (netduinoplus2 = STM32F405).
//!
//! QEMU runs in a working directory that semihosting file calls reach, with
//! its output in a file there (never a pipe that could close), and is killed
//! at a deadline: without `enable=on` the first semihosting call would hang it.

use std::fs::File;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

/// The emulated machine: an STM32F405 like the real board.
pub const MACHINE: &str = "netduinoplus2";
/// QEMU binary.
pub const QEMU: &str = "qemu-system-arm";

/// True when `qemu-system-arm` can be started.
pub fn available() -> bool {
    Command::new(QEMU)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Installs Debian's `qemu-system-arm` when it is missing.
pub fn ensure_installed() -> anyhow::Result<()> {
    if available() {
        return Ok(());
    }
    apt_install(&[QEMU])?;
    if !available() {
        bail!("{QEMU} still not available after installing it");
    }
    Ok(())
}

/// Installs Debian `packages` (apt-get, --no-install-recommends).
pub fn apt_install(packages: &[&str]) -> anyhow::Result<()> {
    eprintln!(
        "\n==> installing {} (apt-get, --no-install-recommends)",
        packages.join(" ")
    );
    let install = [&["install", "-y", "-qq", "--no-install-recommends"][..], packages].concat();
    for args in [&["update", "-qq"][..], &install] {
        let status = Command::new("apt-get")
            .args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .context("cannot run apt-get")?;
        if !status.success() {
            bail!("apt-get {} failed", args.join(" "));
        }
    }
    Ok(())
}

/// What a QEMU run printed and how it ended.
#[derive(Debug)]
pub struct QemuRun {
    /// Semihosting console output (and QEMU's own messages).
    pub log: String,
    /// The guest exited with success through semihosting.
    pub success: bool,
}

/// Runs `elf` in `dir` with `extra` arguments; kills it after `deadline`.
pub fn run(elf: &Path, dir: &Path, extra: &[String], deadline: Duration) -> anyhow::Result<QemuRun> {
    run_with_args(elf, dir, &[], extra, deadline)
}

/// [`run`] with `argv` as the program's command line over semihosting
/// (what newlib's `main` gets as `argc`/`argv`).
pub fn run_with_args(
    elf: &Path,
    dir: &Path,
    argv: &[&str],
    extra: &[String],
    deadline: Duration,
) -> anyhow::Result<QemuRun> {
    let child = spawn_command(elf, dir, "none", argv, extra, None)?;
    wait(child, dir, deadline)
}

/// Starts `elf` in `dir` with USART1 on the chardev spec `serial` (`none`,
/// `chardev:ID` with a `-chardev` among `extra`); its log goes to
/// `dir/qemu.log`. [`wait`] for it.
pub fn spawn(elf: &Path, dir: &Path, serial: &str, extra: &[String]) -> anyhow::Result<Child> {
    spawn_limited(elf, dir, serial, extra, None)
}

/// [`spawn`], with QEMU killed by `timeout` (coreutils) after `limit` if it
/// is given: a QEMU whose parent died without stopping it ends all the same.
pub fn spawn_limited(
    elf: &Path,
    dir: &Path,
    serial: &str,
    extra: &[String],
    limit: Option<Duration>,
) -> anyhow::Result<Child> {
    spawn_command(elf, dir, serial, &[], extra, limit)
}

/// [`spawn_limited`] with `argv` as the guest's semihosting command line.
fn spawn_command(
    elf: &Path,
    dir: &Path,
    serial: &str,
    argv: &[&str],
    extra: &[String],
    limit: Option<Duration>,
) -> anyhow::Result<Child> {
    let log = File::create(dir.join(LOG)).context("cannot create qemu.log")?;
    let mut semihosting = String::from("enable=on,target=native");
    for arg in argv {
        semihosting.push_str(",arg=");
        semihosting.push_str(arg);
    }
    let mut command = match limit {
        Some(limit) => {
            let mut c = Command::new("timeout");
            c.args(["--signal=KILL", &format!("{}s", limit.as_secs().max(1)), QEMU]);
            c
        }
        None => Command::new(QEMU),
    };
    command
        .args(["-machine", MACHINE, "-nographic", "-monitor", "none", "-serial", serial])
        .args(["-semihosting-config", &semihosting])
        .args(extra)
        .arg("-kernel")
        .arg(elf)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("cannot start {QEMU}"))
}

/// File in the run directory that holds QEMU's output.
pub const LOG: &str = "qemu.log";

/// Waits for a [`spawn`]ed QEMU to end; kills it after `deadline`.
pub fn wait(mut child: Child, dir: &Path, deadline: Duration) -> anyhow::Result<QemuRun> {
    let log_path = dir.join(LOG);
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if started.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            let log = std::fs::read_to_string(&log_path).unwrap_or_default();
            bail!(
                "QEMU did not finish within {} s; its output:\n{log}",
                deadline.as_secs()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ok(QemuRun {
        log: std::fs::read_to_string(&log_path).unwrap_or_default(),
        success: status.success(),
    })
}
