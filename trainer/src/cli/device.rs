//! `trainer device status|update|record`: talk to a running unit over its UART.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use clap::Subcommand;
use trainer::device::install::{self, read_blob, status_words};
use trainer::device::link::Link;
use trainer::device::port::{self, DEFAULT_BAUD};
use trainer::device::record::{self, End, RecordOptions};
use trainer::device::status;
use trainer::output::{self, Output, Transaction};
use trainer::reading::limits::{
    MAX_PROGRESS_S, MAX_RECORD_HOURS, MAX_SAMPLE_RATE_HZ, MIN_PROGRESS_S, MIN_SAMPLE_RATE_HZ,
};
use trainer::text;

use super::common::{ForceArg, JsonArg, print_and_commit, print_json_and_commit, print_text, stderr};
use super::model_arg::ModelArg;

/// Talk to a running unit over its serial port: health, model update, recording.
///
/// The unit's UART (921,600 Bd, 8N1) through a USB serial adapter, or the
/// pseudo-terminal of `cargo xtask qemu-board --pty` without hardware. Every
/// wait is bounded: a unit that does not answer fails the command with the
/// port's name. The protocol is in docs/firmware.md.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Example (no hardware: `cargo xtask qemu-board --pty` prints the pty):\n  \
                        trainer device status --port /dev/pts/3\n  \
                        trainer device update --port /dev/pts/3 --model model.bin\n  \
                        trainer device record --port /dev/pts/3 --seconds 20 -o run.csv"
)]
pub struct Args {
    #[command(subcommand)]
    command: DeviceCommand,
}

/// The `device` subcommands.
#[derive(Subcommand, Debug)]
enum DeviceCommand {
    Status(StatusArgs),
    Update(UpdateArgs),
    Record(RecordArgs),
}

/// The serial port and how long to wait for the unit, every subcommand's.
#[derive(clap::Args, Debug)]
struct PortArgs {
    /// Serial port of the unit (/dev/ttyUSB0, or the pty qemu-board printed).
    #[arg(long, value_name = "PORT", help_heading = "Unit")]
    port: String,
    /// Line rate, Bd.
    ///
    /// The board's UART runs at 921,600 Bd; a pty ignores the rate.
    #[arg(long, value_name = "B", default_value_t = DEFAULT_BAUD, help_heading = "Unit")]
    baud: u32,
    /// Seconds to wait for an answer.
    ///
    /// For the health report (status, and before and after an update) and
    /// for output frames while recording. The install itself may take up to
    /// 15 s (a flash sector erase).
    #[arg(long, value_name = "S", default_value_t = 3.0, help_heading = "Unit")]
    timeout_s: f64,
}

impl PortArgs {
    fn timeout(&self) -> anyhow::Result<Duration> {
        anyhow::ensure!(
            self.timeout_s.is_finite() && (0.1..=3600.0).contains(&self.timeout_s),
            "--timeout-s {}: seconds, 0.1 … 3600",
            self.timeout_s
        );
        Ok(Duration::from_secs_f64(self.timeout_s))
    }

    fn open(&self) -> anyhow::Result<Link<Box<dyn serialport::SerialPort>>> {
        let port = port::open(&self.port, self.baud)?;
        Ok(Link::new(port, &self.port))
    }
}

/// Show the unit's health report: reset cause, counters, the model it runs.
///
/// Sends the firmware's health command and prints the report in words: the
/// unit's kind (from its output frames), why it last reset (a fault's PC and
/// LR), the running model (its blob's CRC-32, which `trainer inspect` also
/// prints, and the commit sequence of the slot it runs from) and the counters
/// since the reset (samples, missed samples, sensor faults, overruns,
/// dropped frames, flash errors).
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer device status --port /dev/ttyUSB0 --json health.json")]
struct StatusArgs {
    #[command(flatten)]
    port: PortArgs,
    #[command(flatten)]
    json: JsonArg,
    #[command(flatten)]
    force: ForceArg,
}

/// Install a model on a running unit over its UART, checked first.
///
/// The blob is checked as the unit's firmware checks it (CRC, shape,
/// parameters, the unit's kind and capacity): a blob the unit would refuse
/// is refused here, with the reason, before anything is sent. Then it is
/// sent, the unit's reply is put in words, and a new health report must name
/// the new blob as the running model. The unit keeps sampling throughout and
/// switches between two samples; a reset at any point leaves the old model or
/// the new one running.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer device update --port /dev/ttyUSB0 --model model.bin")]
struct UpdateArgs {
    #[command(flatten)]
    port: PortArgs,
    #[command(flatten)]
    model: ModelArg,
    /// Install a blob for other axes, or another serial, than the unit's.
    ///
    /// A three-axis unit takes a single-axis blob (as axis x) or a blob for
    /// some of its axes, and runs the others uncompensated (flag 4); a blob whose
    /// provenance names another serial than the unit's running model is another
    /// gyro's calibration. Without --force either is refused, naming both, before
    /// anything is sent.
    #[arg(long, help_heading = "Model")]
    force: bool,
}

/// Record the unit's output live into a recorded-run CSV (a chamber run).
///
/// One row per output frame: time_s (from the frame's sequence number at
/// --sample-rate-hz; lost frames leave gaps), seq, rate_dph, unit_bias_dph,
/// unit_rate_comp_dph, temp_c and unit_flags (per axis for a three-axis unit), after
/// `#` lines naming the unit, its model and the sample rate. The file is a
/// recorded run `trainer fit` reads as it is. A progress line shows the
/// elapsed time, temperature, rate, rows, missed and damaged frames and the
/// flags seen. It stops after --seconds/--hours, or at Ctrl-C: either way the
/// run written so far is committed whole. If the line fails (the unit goes
/// silent or the adapter is unplugged) the rows before are committed too
/// and the command exits 1 with the cause. Every frame is written: one the
/// reader of runs would refuse as a row (a rate or temperature that is not
/// a number, a rate beyond ±3,600,000 °/h: flags 16, 2) becomes a `#` line
/// with the reader's reason, which readers skip. The unit's bias,
/// compensated rate and flags are unit_bias_dph, unit_rate_comp_dph and
/// unit_flags, so `trainer compensate` adds its own beside them.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  trainer device record --port /dev/ttyUSB0 --hours 12 --plan plan.csv -o chamber1.csv\n  \
                        trainer device record --port /dev/pts/3 --seconds 20 -o run.csv"
)]
struct RecordArgs {
    #[command(flatten)]
    port: PortArgs,
    /// Record for S seconds.
    #[arg(long, value_name = "S", conflicts_with = "hours", help_heading = "Duration")]
    seconds: Option<f64>,
    /// Record for H hours.
    #[arg(long, value_name = "H", help_heading = "Duration")]
    hours: Option<f64>,
    /// The unit's sample rate, Hz (the board samples at 1,000 Hz).
    #[arg(long, value_name = "HZ", default_value_t = 1000.0, help_heading = "Unit")]
    sample_rate_hz: f64,
    /// The planned chamber profile (trainer plan's time_s,chamber_c).
    ///
    /// The progress line then shows how far the run is in it and the set point now.
    #[arg(long, value_name = "PLAN.csv", help_heading = "Data")]
    plan: Option<PathBuf>,
    /// Seconds between progress lines.
    #[arg(long, value_name = "S", default_value_t = 1.0, help_heading = "Output")]
    progress_s: f64,
    /// Recorded run to write.
    #[arg(short, long, value_name = "RUN.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Runs `trainer device`.
pub fn run(a: Args) -> anyhow::Result<()> {
    match a.command {
        DeviceCommand::Status(a) => status_command(a),
        DeviceCommand::Update(a) => update_command(a),
        DeviceCommand::Record(a) => record_command(a),
    }
}

fn status_command(a: StatusArgs) -> anyhow::Result<()> {
    let timeout = a.port.timeout()?;
    let sink = a.json.sink(&[], a.force.existing())?;
    let mut link = a.port.open()?;
    let unit = status::query(&mut link, timeout)?;
    let on_stdout = sink.is_stdout();
    let mut transaction = Transaction::new();
    let json = sink.write(&status::to_json(&a.port.port, &unit), &mut transaction)?;
    print_json_and_commit(
        status::describe(&text::terminal_safe(&a.port.port), &unit).as_bytes(),
        on_stdout,
        json,
        transaction,
    )
}

fn update_command(a: UpdateArgs) -> anyhow::Result<()> {
    let timeout = a.port.timeout()?;
    // Checked before the port is even opened: a blob no unit takes is never sent.
    let blob = read_blob(&a.model.path)?;
    let mut link = a.port.open()?;
    let done = install::install(&mut link, &blob, timeout, a.force)?;
    let text = format!(
        "{}: {} in {:.2} s\nrunning model: {} (was: {})\n",
        link.name(),
        status_words(0),
        done.reply_s,
        status::model_words(&done.after.report),
        status::model_words(&done.before.report),
    );
    print_text(text.as_bytes(), false).context("standard output: write failed")
}

/// A number as a message quotes it: `1e300`, not its 301 digits.
fn shown(x: f64) -> String {
    if x.is_finite() && x.abs() >= 1e9 {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

fn record_command(a: RecordArgs) -> anyhow::Result<()> {
    let timeout = a.port.timeout()?;
    // Every figure is checked before the port is opened, against the limits
    // the reader of the run holds (the sample rate goes into its `#` line).
    let max_s = MAX_RECORD_HOURS * 3600.0;
    let duration = match (a.seconds, a.hours) {
        (Some(s), _) => Some(("--seconds", s, s)),
        (None, Some(h)) => Some(("--hours", h, h * 3600.0)),
        (None, None) => None,
    };
    if let Some((flag, given, s)) = duration {
        anyhow::ensure!(
            s.is_finite() && s > 0.0 && s <= max_s,
            "{flag} {}: the duration must be positive and at most {MAX_RECORD_HOURS} h ({max_s} s)",
            shown(given)
        );
    }
    anyhow::ensure!(
        a.sample_rate_hz.is_finite() && (MIN_SAMPLE_RATE_HZ..=MAX_SAMPLE_RATE_HZ).contains(&a.sample_rate_hz),
        "--sample-rate-hz {}: must be {MIN_SAMPLE_RATE_HZ} … {MAX_SAMPLE_RATE_HZ} Hz (what a recorded run may state)",
        shown(a.sample_rate_hz)
    );
    anyhow::ensure!(
        a.progress_s.is_finite() && (MIN_PROGRESS_S..=MAX_PROGRESS_S).contains(&a.progress_s),
        "--progress-s {}: must be {MIN_PROGRESS_S} … {MAX_PROGRESS_S} s",
        shown(a.progress_s)
    );
    let duration = duration.map(|(_, _, s)| s);
    let plan = a
        .plan
        .as_deref()
        .map(trainer::simulate::chamber_file::read_chamber_profile)
        .transpose()?;
    let inputs: Vec<&std::path::Path> = a.plan.as_deref().into_iter().collect();
    let target = output::check_target(&a.output, &inputs, a.force.existing())?;
    let stop = output::stop_gracefully();
    let mut link = a.port.open()?;
    let unit = status::query(&mut link, timeout)?;
    let mut out = Output::open(target)?;
    let options = RecordOptions {
        duration: duration.map(Duration::from_secs_f64),
        sample_rate_hz: a.sample_rate_hz,
        silence_timeout: timeout,
        progress_every: Duration::from_secs_f64(a.progress_s),
    };
    let on_terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut report = |p: &record::Progress| {
        let line = record::progress_line(p, plan.as_ref());
        let mut err = stderr();
        let _ = if on_terminal {
            write!(err, "\r{line}\x1b[K")
        } else {
            writeln!(err, "{line}")
        };
        let _ = err.flush();
    };
    let (progress, end) = record::record(&mut link, &mut out, &unit, &options, &|| stop.requested(), &mut report)
        .with_context(|| format!("{}: write failed", text::path(&a.output)))?;
    if on_terminal {
        let _ = writeln!(stderr());
    }
    let how = match &end {
        End::Duration => "the duration reached".to_owned(),
        End::Stopped => "stopped".to_owned(),
        End::Failed(_) => "the line failed".to_owned(),
    };
    let summary = format!(
        "wrote {} ({} rows in {:.1} s, {how}; {} frames missed, {} damaged, {} unusable kept as # lines)\n",
        text::path(&a.output),
        progress.rows,
        progress.elapsed_s,
        progress.missed,
        progress.damaged,
        progress.unusable
    );
    print_and_commit(summary.as_bytes(), false, Transaction::of(out))?;
    match end {
        End::Failed(e) => Err(e.context(format!(
            "{}: recording ended early; the rows before the failure are written",
            text::path(&a.output)
        ))),
        _ => Ok(()),
    }
}
