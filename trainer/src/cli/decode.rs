//! `trainer decode`: firmware output frames (a UART capture) to CSV.

use std::io::Write;
use std::path::PathBuf;

use anyhow::Context;
use trainer::output::{self, Output, Transaction};
use trainer::{reading::input, text};

use super::common::{ForceArg, print_and_commit, stderr};

/// Decode firmware output frames (a UART capture) into CSV.
///
/// Frames are postcard + COBS, each ended by 0x00, CRC-checked (format 2;
/// format 1 of older firmware, without a check, is read too). Writes
/// seq, rate_dph [°/h], bias_dph [°/h], rate_comp_dph [°/h], temp_c [°C], flags; a
/// three-axis firmware's frames give those per axis (rate_x_dph … flags_x, then y, z).
/// A damaged frame (its CRC does not match, or it is of another kind) is
/// skipped and reported (the seq gap shows where); a capture that starts
/// mid-frame loses only that first partial frame. A capture without one
/// valid frame, an empty one included, is an error and writes nothing.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer decode uart.bin -o frames.csv")]
pub struct Args {
    /// Captured frame bytes (- reads standard input).
    #[arg(value_name = "FRAMES.bin", help_heading = "Data")]
    frames: PathBuf,
    /// CSV to write.
    #[arg(short, long, value_name = "OUT.csv", help_heading = "Output")]
    output: PathBuf,
    #[command(flatten)]
    force: ForceArg,
}

/// Runs `trainer decode`.
pub fn run(a: Args) -> anyhow::Result<()> {
    let target = output::check_target(&a.output, &[&a.frames], a.force.existing())?;
    let capture = input::open(&a.frames).with_context(|| format!("{}: cannot read", text::path(&a.frames)))?;
    let mut out = Output::open(target)?;
    let decoded = trainer::reading::frames::decode_capture(capture, &mut out).with_context(|| text::path(&a.frames))?;
    if decoded.damaged > 0 {
        // A warning that cannot be written (stderr closed or full) is lost, never a panic.
        let _ = writeln!(
            stderr(),
            "warning: {}: {} damaged frame(s) skipped, at byte offsets {:?}",
            text::path(&a.frames),
            decoded.damaged,
            decoded.damaged_at
        );
    }
    let printed = format!("wrote {} ({} frames)\n", text::path(&a.output), decoded.frames);
    print_and_commit(printed.as_bytes(), false, Transaction::of(out))
}
