//! Argument groups and output helpers every subcommand shares.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use clap::builder::RangedU64ValueParser;
use trainer::dataset::gradients::Selection;
use trainer::output::{Existing, Output, Transaction};
use trainer::text::{self, SafeWriter};

/// Standard output, control characters from outside escaped on the way.
pub fn stdout() -> SafeWriter<std::io::StdoutLock<'static>> {
    SafeWriter::new(std::io::stdout().lock())
}

/// Standard error, control characters from outside escaped on the way.
pub fn stderr() -> SafeWriter<std::io::StderrLock<'static>> {
    SafeWriter::new(std::io::stderr().lock())
}

pub use trainer::refusals::flag_hint;

/// `--force`: whether an existing output may be replaced.
#[derive(Args, Debug)]
pub struct ForceArg {
    /// Replace outputs that exist.
    ///
    /// By default an existing file is never replaced; even with --force a link, a
    /// device, a read-only file or an input is not.
    #[arg(long, help_heading = "Output")]
    pub force: bool,
}

impl ForceArg {
    /// The replacement policy asked for.
    pub fn existing(&self) -> Existing {
        Existing::from_force(self.force)
    }
}

/// `--allow-uncompensated`: what to do with a run where no row could be compensated.
#[derive(Args, Debug)]
pub struct AllowUncompensated {
    /// Accept a run where no row could be compensated.
    ///
    /// A run where every row carries flag 4 is by default an error naming the cause
    /// (temperatures out of range, sensor faults).
    #[arg(long, help_heading = "Data")]
    pub allow_uncompensated: bool,
    /// Accept a run implausible as a gyro recording.
    ///
    /// By default a run is refused, naming the reason, when its loop temperature leaves
    /// −60 … 100 °C (°F?) or changes faster than 20 °C/min by its time column (time_s
    /// in hours?).
    #[arg(long, help_heading = "Data")]
    pub allow_implausible: bool,
}

impl AllowUncompensated {
    /// The runs the command accepts that it would otherwise refuse.
    pub fn acceptance(&self) -> trainer::evaluation::axes::Acceptance {
        trainer::evaluation::axes::Acceptance {
            uncompensated: self.allow_uncompensated,
            implausible: self.allow_implausible,
        }
    }
}

/// `--json FILE`: the figures as JSON, `-` for standard output.
#[derive(Args, Debug)]
pub struct JsonArg {
    /// Also write the figures as JSON (- = standard output).
    ///
    /// With `-` the JSON is standard output and the human-readable text goes to
    /// standard error.
    #[arg(long, value_name = "FILE", help_heading = "Output")]
    pub json: Option<PathBuf>,
}

/// Where `--json` sends its document.
pub enum JsonSink {
    /// No JSON asked for.
    None,
    /// Standard output (`--json -`).
    Stdout,
    /// A file, written in full or not at all.
    File(Output),
}

impl JsonArg {
    /// Checks the JSON target against `inputs` before any work.
    pub fn sink(&self, inputs: &[&Path], existing: Existing) -> anyhow::Result<JsonSink> {
        Ok(match &self.json {
            None => JsonSink::None,
            Some(p) if trainer::reading::input::is_stdin(p) => JsonSink::Stdout,
            Some(p) => JsonSink::File(Output::create(p, inputs, existing)?),
        })
    }
}

impl JsonSink {
    /// Whether the JSON goes to standard output (and the text to standard error).
    pub fn is_stdout(&self) -> bool {
        matches!(self, JsonSink::Stdout)
    }

    /// Writes `value` pretty-printed: into its file, staged in
    /// `transaction` with the command's other outputs; for standard output,
    /// returns the text, which [`print_json_and_commit`] prints after the
    /// human-readable text (on standard error), so a reader that stops
    /// early (`| head -c 100`) cannot cost the table.
    pub fn write(self, value: &serde_json::Value, transaction: &mut Transaction) -> anyhow::Result<Option<String>> {
        let json = serde_json::to_string_pretty(value)?;
        match self {
            JsonSink::None => Ok(None),
            JsonSink::Stdout => Ok(Some(json)),
            JsonSink::File(mut out) => {
                out.write_all(json.as_bytes())
                    .with_context(|| format!("{}: write failed", text::path(out.path())))?;
                transaction.add(out);
                Ok(None)
            }
        }
    }
}

/// Writes the human-readable `text` where it belongs: standard output, or
/// standard error when the JSON took standard output; flushed.
pub fn print_text(text: &[u8], json_on_stdout: bool) -> std::io::Result<()> {
    if json_on_stdout {
        let mut err = stderr();
        err.write_all(text)?;
        err.flush()
    } else {
        let mut out = stdout();
        out.write_all(text)?;
        out.flush()
    }
}

/// Prints each of `notices` on standard error as a `note:` line, before
/// the command's own output. A note that cannot be written (standard
/// error closed) is dropped: it is no reason to fail the command.
pub fn print_notes(notices: &[String]) {
    let mut err = stderr();
    for notice in notices {
        if writeln!(err, "note: {notice}").is_err() {
            return;
        }
    }
    let _ = err.flush();
}

/// The one line a failed print becomes: a reader that stopped early (a
/// broken pipe, `| head`) is named as such, not as an I/O error.
fn print_failed(stream: &str, e: std::io::Error) -> anyhow::Error {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        anyhow::anyhow!("{stream}: closed by its reader before the output was whole (broken pipe); nothing written")
    } else {
        anyhow::anyhow!("{stream}: write failed ({e}); nothing written")
    }
}

/// How every command that writes files ends: `text` printed ([`print_text`]),
/// then every output staged in `transaction` committed together. A print
/// that fails (a closed pipe, a full disk behind a redirection) fails the
/// command before anything is committed; `text` may say "wrote": a commit
/// that fails after it makes the command exit 1 with the cause.
pub fn print_and_commit(text: &[u8], json_on_stdout: bool, transaction: Transaction) -> anyhow::Result<()> {
    print_json_and_commit(text, json_on_stdout, None, transaction)
}

/// [`print_and_commit`], with the JSON document for standard output
/// (`--json -`, [`JsonSink::write`]) printed after `text`: the text is
/// whole on standard error whatever becomes of standard output.
pub fn print_json_and_commit(
    text: &[u8],
    text_to_stderr: bool,
    stdout_json: Option<String>,
    transaction: Transaction,
) -> anyhow::Result<()> {
    let stream = if text_to_stderr {
        "standard error"
    } else {
        "standard output"
    };
    print_text(text, text_to_stderr).map_err(|e| print_failed(stream, e))?;
    if let Some(json) = stdout_json {
        let mut out = stdout();
        writeln!(out, "{json}")
            .and_then(|()| out.flush())
            .map_err(|e| print_failed("standard output", e))?;
    }
    transaction.commit()
}

/// How multi-point inputs are selected from their correlations with the bias.
#[derive(Args, Debug)]
pub struct SelectArgs {
    /// Select inputs with |r| ≥ R.
    ///
    /// Every temperature and gradient whose correlation with the bias has magnitude at
    /// least R (the RLG paper's rule: `--select-threshold 0.9`). `correlate` uses 0.9 when
    /// neither this nor --select-top is given; `fit --method svr-pso` then chooses the
    /// thermometers by validation instead.
    #[arg(long, value_name = "R", conflicts_with = "select_top", help_heading = "Multi-point")]
    pub select_threshold: Option<f64>,
    /// Select the N inputs of largest |r|.
    ///
    /// 8 temperatures and 28 gradients at most.
    #[arg(long, value_name = "N", help_heading = "Multi-point",
          value_parser = RangedU64ValueParser::<usize>::new().range(1..=36))]
    pub select_top: Option<usize>,
}

/// The RLG paper's correlation threshold.
pub const PAPER_THRESHOLD: f64 = 0.9;

impl SelectArgs {
    /// The correlation rule asked for, if any.
    pub fn selection(&self) -> anyhow::Result<Option<Selection>> {
        if let Some(r) = self.select_threshold {
            anyhow::ensure!(
                (0.0..=1.0).contains(&r),
                "--select-threshold {r}: a correlation magnitude, 0 … 1"
            );
        }
        Ok(match (self.select_top, self.select_threshold) {
            (Some(n), _) => Some(Selection::Top(n)),
            (None, Some(r)) => Some(Selection::Threshold(r)),
            (None, None) => None,
        })
    }
}

/// A correlation rule as the selection line names it.
pub fn rule_name(selection: Selection) -> String {
    match selection {
        Selection::Top(n) => format!("top {n} by |r|"),
        Selection::Threshold(t) => format!("|r| ≥ {t}"),
    }
}

/// The correlation matrix and the selection's line (chosen by `rule`), as
/// `correlate` and `fit` print them.
pub fn describe_selection(
    table: &trainer::dataset::gradients::CorrelationTable,
    selected: &[trainer::dataset::gradients::Candidate],
    rule: &str,
) -> String {
    use trainer::dataset::gradients::{candidate_name, format_table};
    let names: Vec<String> = selected
        .iter()
        .map(|&c| format!("{} (r = {:.3})", candidate_name(table, c), table.r[c.i][c.j]))
        .collect();
    format!(
        "{}selected ({rule}): {}\n",
        format_table(table, selected),
        if names.is_empty() {
            "none".to_owned()
        } else {
            names.join(", ")
        }
    )
}

/// The names of a feature set's inputs with units, for printing.
pub fn input_names(set: rbf_core::FeatureSet) -> Vec<String> {
    set.names().map(|n| n.to_string()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_are_named_as_the_selection_line_prints_them() {
        assert_eq!(rule_name(Selection::Top(3)), "top 3 by |r|");
        assert_eq!(rule_name(Selection::Threshold(0.9)), "|r| ≥ 0.9");
    }

    #[test]
    fn a_threshold_outside_0_to_1_is_refused() {
        let select = SelectArgs {
            select_threshold: Some(1.5),
            select_top: None,
        };
        let err = select.selection().unwrap_err().to_string();
        assert!(err.contains("--select-threshold 1.5"), "{err}");
        let select = SelectArgs {
            select_threshold: None,
            select_top: Some(4),
        };
        assert!(matches!(select.selection().unwrap(), Some(Selection::Top(4))));
    }
}
