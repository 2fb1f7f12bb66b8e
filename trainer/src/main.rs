//! `trainer`: fit, apply and evaluate IFOG temperature-drift models.
//!
//! This file parses the command line and dispatches; each subcommand lives in
//! its own module under `cli/`.

use std::io::Write;
use std::process::ExitCode;

use clap::Parser;
use trainer::text;

mod cli;

/// Removes temperature drift from fiber-optic gyros.
///
/// Typical session: record chamber runs (recorded-run CSV: time_s, rate_dph,
/// temp_c, optionally ref_dph), `trainer fit` them into MODEL.bin, check the
/// result on other runs with `trainer eval`, flash MODEL.bin into the
/// firmware's model region. `trainer compensate` applies a model to a run
/// exactly as the firmware would.
#[derive(Parser, Debug)]
#[command(version, about, long_about, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: cli::Command,
}

fn main() -> ExitCode {
    // First, before any other thread: every terminating signal cleans up,
    // and SIGXFSZ makes a write fail instead of killing a command mid-print.
    trainer::output::catch_signals();
    // A command line clap refuses exits 1 like every other error (--help and
    // --version print to stdout and exit 0).
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help or --version that cannot be printed (stdout full) fails too.
            let printed = e.print();
            return if e.use_stderr() || printed.is_err() {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match cli.command.run() {
        Ok(()) => ExitCode::SUCCESS,
        // A unit that missed its acceptance spec: every output is written; exit 3.
        Err(e) if e.is::<trainer::acceptance::Rejected>() => {
            let _ = writeln!(std::io::stderr(), "{}", text::terminal_safe(&format!("{e:#}")));
            ExitCode::from(3)
        }
        Err(e) => {
            // File names, fields and serials from outside may hold control characters.
            let message = format!("{e:#}{}", cli::flag_hint(&e));
            // Exit 1 even when the message cannot be written (stderr closed
            // or full): `eprintln!` would panic (exit 101).
            let _ = writeln!(std::io::stderr(), "error: {}", text::terminal_safe(&message));
            ExitCode::FAILURE
        }
    }
}
