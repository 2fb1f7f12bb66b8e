//! `cargo xtask qemu-board --pty`: the gyro board without hardware. The
//! `stm32f405-qemu-serve` board image (the `stm32f405-qemu` image that
//! never exits, its front ends and thermometers emulated;
//! `stm32f405-axes-qemu-serve` for a three-axis IMU) runs under QEMU with USART1 on a
//! pseudo-terminal, at its real sample rate (1 kHz, no `-icount`), until it
//! is stopped: `trainer device` talks to the pty as to a USB serial adapter.
//! The sensors answer from a built-in temperature ramp, or (single-axis)
//! from a recorded run the image reads over semihosting (`run.csv`).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

use crate::replay::MODEL_SLOT_A;
use crate::{firmware, qemu};

/// How long QEMU may take to open its pseudo-terminal.
const PTY_WAIT: Duration = Duration::from_secs(10);

/// What `qemu-board` runs.
#[derive(Clone, Debug, Default)]
pub struct BoardOptions {
    /// The three-axis image (`stm32f405-axes-qemu-serve`) instead of the single-axis one.
    pub three_axes: bool,
    /// A model blob placed in flash slot A before boot (none: the board
    /// starts without a model, flag 4 on every frame).
    pub model: Option<PathBuf>,
    /// A recorded run the emulated front ends and thermometers answer from,
    /// row after row (from its start again at its end): single-axis for the
    /// single-axis image, three-axis for the three-axis one; `None`: the
    /// built-in temperature ramp.
    pub run: Option<PathBuf>,
    /// QEMU is killed after this long whatever happens (tests); `None`: it
    /// runs until stopped.
    pub limit: Option<Duration>,
}

/// A running board: QEMU with USART1 on [`QemuBoard::pty`]. Dropping it kills QEMU.
#[derive(Debug)]
pub struct QemuBoard {
    child: Child,
    pty: PathBuf,
    dir: tempfile::TempDir,
}

/// Builds the serving image for `options` and returns its ELF path.
pub fn build_image(three_axes: bool) -> anyhow::Result<PathBuf> {
    if three_axes {
        firmware::BOARD_AXES_QEMU_SERVE.build()
    } else {
        firmware::BOARD_QEMU_SERVE.build()
    }
}

impl QemuBoard {
    /// Builds the image and starts it; returns once QEMU has opened its pty.
    pub fn start(options: &BoardOptions) -> anyhow::Result<QemuBoard> {
        let built = build_image(options.three_axes)?;
        Self::start_image(&built, options)
    }

    /// Starts the already built image `elf` (see [`build_image`]).
    pub fn start_image(elf: &Path, options: &BoardOptions) -> anyhow::Result<QemuBoard> {
        let dir = tempfile::TempDir::new()?;
        let image = dir.path().join("stm32f405-serve");
        std::fs::copy(elf, &image).with_context(|| format!("{}: cannot copy", elf.display()))?;
        if let Some(run) = &options.run {
            // Checked here with the trainer's reader, so that the image reads
            // a valid run with the image's axes.
            let run_axes = trainer::reading::run::RunReader::open(run)?.axes();
            match (options.three_axes, run_axes.is_empty()) {
                (true, true) => anyhow::bail!(
                    "{}: a single-axis run; the three-axis board (--axes 3) answers from a three-axis run \
                     (rate_x_dph, temp_x_c, …)",
                    run.display()
                ),
                (false, false) => anyhow::bail!(
                    "{}: a three-axis run; give --axes 3 for the three-axis board",
                    run.display()
                ),
                _ => {}
            }
            trainer::reading::run::samples::Run::load(run)?;
            std::fs::copy(run, dir.path().join("run.csv"))
                .with_context(|| format!("{}: cannot read", run.display()))?;
        }
        let mut extra = Vec::new();
        if let Some(model) = &options.model {
            std::fs::copy(model, dir.path().join("model.bin"))
                .with_context(|| format!("{}: cannot read", model.display()))?;
            extra.push("-device".to_owned());
            extra.push(format!("loader,file=model.bin,addr={MODEL_SLOT_A:#x}"));
        }
        let child = qemu::spawn_limited(&image, dir.path(), "pty", &extra, options.limit)?;
        let mut board = QemuBoard {
            child,
            pty: PathBuf::new(),
            dir,
        };
        board.pty = board.wait_for_pty()?;
        Ok(board)
    }

    /// Reads the pty's path from QEMU's log ("char device redirected to /dev/pts/N").
    fn wait_for_pty(&mut self) -> anyhow::Result<PathBuf> {
        let started = Instant::now();
        loop {
            let log = self.log();
            if let Some(path) = pty_of(&log) {
                return Ok(path);
            }
            if let Some(status) = self.child.try_wait()? {
                bail!("QEMU ended ({status}) before it opened a pty; its output:\n{log}");
            }
            if started.elapsed() > PTY_WAIT {
                bail!("QEMU opened no pty within {} s; its output:\n{log}", PTY_WAIT.as_secs());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The pseudo-terminal USART1 is on.
    pub fn pty(&self) -> &Path {
        &self.pty
    }

    /// What QEMU printed so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.path().join(qemu::LOG)).unwrap_or_default()
    }

    /// An error with QEMU's output if it has ended.
    pub fn check_running(&mut self) -> anyhow::Result<()> {
        match self.child.try_wait()? {
            None => Ok(()),
            Some(status) => bail!("QEMU ended ({status}); its output:\n{}", self.log()),
        }
    }
}

impl QemuBoard {
    /// Stops QEMU: SIGTERM first, which `timeout` (when QEMU runs under
    /// one) passes on to QEMU (a SIGKILL would end `timeout` alone and
    /// leave QEMU running), then SIGKILL if it has not ended within 2 s.
    pub fn stop(&mut self) {
        if matches!(self.child.try_wait(), Ok(Some(_))) {
            return;
        }
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let deadline = Instant::now() + Duration::from_secs(2);
        while Instant::now() < deadline {
            if matches!(self.child.try_wait(), Ok(Some(_))) {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        self.stop();
    }
}

/// The pty path in QEMU's log line `char device redirected to PATH (label …)`.
fn pty_of(log: &str) -> Option<PathBuf> {
    log.lines().find_map(|line| {
        let rest = line.split("char device redirected to ").nth(1)?;
        rest.split_whitespace().next().map(PathBuf::from)
    })
}

/// `cargo xtask qemu-board --pty`: starts the board, prints `pty: PATH` on
/// a line of its own and serves until SIGINT, SIGTERM or SIGHUP (or the
/// limit), then stops QEMU. An error if QEMU ends by itself.
pub fn serve(options: &BoardOptions) -> anyhow::Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ] {
        signal_hook::flag::register(signal, stop.clone()).context("cannot install the signal handlers")?;
    }
    let mut board = QemuBoard::start(options)?;
    let mut out = std::io::stdout().lock();
    writeln!(out, "pty: {}", board.pty().display())?;
    out.flush()?;
    drop(out);
    eprintln!(
        "qemu-board: the {} board runs under QEMU; Ctrl-C stops it",
        if options.three_axes {
            "three-axis"
        } else {
            "single-axis"
        }
    );
    while !stop.load(Ordering::Relaxed) {
        board.check_running()?;
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pty_is_read_from_qemu_s_redirection_line() {
        let log = "qemu-system-arm: warning: x\nchar device redirected to /dev/pts/7 (label serial0)\n";
        assert_eq!(pty_of(log), Some(PathBuf::from("/dev/pts/7")));
        assert_eq!(pty_of("char device redirected"), None);
        assert_eq!(pty_of(""), None);
    }
}
