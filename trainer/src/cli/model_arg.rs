//! `--model MODEL.bin`, the model blob every command that reads one names the same way.

use std::path::{Path, PathBuf};

use trainer::reading::{distinct, input};

/// `--model MODEL.bin`: the model blob to read (- reads standard input).
#[derive(clap::Args, Debug)]
pub struct ModelArg {
    /// Model blob written by `trainer fit`.
    #[arg(long = "model", value_name = "MODEL.bin", help_heading = "Model")]
    pub path: PathBuf,
}

impl ModelArg {
    /// The inputs of a command that evaluates this model on `runs`: the runs,
    /// then the model; refused if standard input is named twice or a run
    /// is named twice.
    pub fn with_evaluated_runs<'a>(&'a self, runs: &'a [PathBuf]) -> anyhow::Result<Vec<&'a Path>> {
        let inputs: Vec<&Path> = runs.iter().map(|p| p.as_path()).chain([self.path.as_path()]).collect();
        input::check_stdin_once(inputs.iter().copied())?;
        distinct::require_distinct_runs(&[("evaluated", runs)])?;
        Ok(inputs)
    }
}
