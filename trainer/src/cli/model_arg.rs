//! `--model MODEL.bin`, the model blob every command that reads one names the same way.

use std::path::PathBuf;

/// `--model MODEL.bin`: the model blob to read (- reads standard input).
#[derive(clap::Args, Debug)]
pub struct ModelArg {
    /// Model blob written by `trainer fit`.
    #[arg(long = "model", value_name = "MODEL.bin", help_heading = "Model")]
    pub path: PathBuf,
}
