//! The lines of a run's text, below the reader: bounded line reading, each line
//! classified as a row, a comment or a blank line, the batch [`RowParser`], the
//! [`RawRow`] the reader hands out, and a defect's [`RunError`] with its
//! position (`run.csv:1042: ...`).

use std::io::{BufRead, Read};
use std::path::{Path, PathBuf};

use rbf_core::record::{self, Columns, Row, RowErrorKind};

use crate::reading::limits::{MAX_LINE_BYTES, bytes};
use crate::text;

/// A defect in a run file, with its position.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The file could not be opened or read.
    #[error("{}: {error}", text::path(.path))]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying error (in the message, so not chained again).
        error: std::io::Error,
    },
    /// The content breaks the format.
    #[error("{}:{line}: {message}", text::path(.path))]
    Format {
        /// File concerned.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong, naming the column where there is one.
        message: String,
    },
}

/// One data row with its raw text (passed through by `compensate`).
#[derive(Clone, Debug)]
pub struct RawRow {
    /// 1-based line number in the file.
    pub line: usize,
    /// The parsed known columns.
    pub row: Row,
    /// The line as read, without its line end.
    pub text: String,
}

/// One line read through the line-length limit.
pub(super) enum Bounded {
    /// The line's bytes are in the buffer (its `\n`, if any, removed).
    Line,
    /// The end of the input.
    End,
    /// The line exceeds [`MAX_LINE_BYTES`].
    TooLong,
}

/// Reads one line of at most [`MAX_LINE_BYTES`] (plus its `\n`) into `buf`,
/// reading no further than one byte past the limit.
pub(super) fn read_line_bounded(source: &mut (dyn BufRead + Send), buf: &mut Vec<u8>) -> std::io::Result<Bounded> {
    buf.clear();
    let read = source.take(MAX_LINE_BYTES as u64 + 1).read_until(b'\n', buf)?;
    if read == 0 {
        return Ok(Bounded::End);
    }
    if buf.last() == Some(&b'\n') {
        buf.pop();
    } else if buf.len() > MAX_LINE_BYTES {
        return Ok(Bounded::TooLong);
    }
    Ok(Bounded::Line)
}

/// True when `line` (without its `\n`) holds a carriage return before its
/// end: the file's lines end in CR alone.
pub(super) fn has_inner_cr(line: &[u8]) -> bool {
    let body = line.strip_suffix(b"\r").unwrap_or(line);
    memchr::memchr(b'\r', body).is_some()
}

/// The message for a file whose lines end in CR alone.
pub(super) const CR_ONLY: &str = "the file uses CR-only line endings (a carriage return, \\r, ends its lines, as on classic Mac OS); \
     recorded runs end lines with \\n or \\r\\n: convert it, e.g. tr '\\r' '\\n' < in.csv > out.csv";

/// The message for a row where CR-only line ends begin after rows that end in `\n`.
pub(super) const CR_ONLY_FROM_HERE: &str = "from this line on the file uses CR-only line endings (a carriage return, \\r, ends its lines, \
     as on classic Mac OS), after lines ending in \\n: the rows from here read as one line; recorded runs end lines with \\n or \\r\\n: \
     convert it, e.g. tr '\\r' '\\n' < in.csv > out.csv";

/// The message for a line past [`MAX_LINE_BYTES`].
pub(super) fn too_long() -> String {
    format!(
        "line is longer than {} (the limit for one line; a recorded-run row is a few dozen bytes)",
        bytes(MAX_LINE_BYTES as u64)
    )
}

/// Parses a run's data lines by given columns, with the reader's error messages.
#[derive(Clone, Debug)]
pub struct RowParser {
    pub(super) path: PathBuf,
    pub(super) column_names: Vec<String>,
}

impl RowParser {
    /// A parser for the rows under `header` (a run's header line), its
    /// errors naming `path`.
    pub fn new(path: &Path, header: &str) -> Self {
        RowParser {
            path: path.to_owned(),
            column_names: header.split(',').map(|n| record::trim_field(n).to_owned()).collect(),
        }
    }

    /// Parses the text of data line `line` with `columns`.
    pub fn parse(&self, columns: &Columns, line: usize, text: &str) -> Result<Row, RunError> {
        columns.parse_row(text).map_err(|e| self.error(line, text, e))
    }

    /// Why the reader refuses row `text` under `columns`, in its words
    /// (`None`: it takes it); what a recorder asks before it writes a row.
    pub fn refusal(&self, columns: &Columns, text: &str) -> Option<String> {
        columns.parse_row(text).err().map(|e| self.message(text, e))
    }

    /// The error for row `text` of line `line`, naming its column and quoting its field.
    pub(super) fn error(&self, line: usize, text: &str, e: record::RowError) -> RunError {
        RunError::Format {
            path: self.path.clone(),
            line,
            message: self.message(text, e),
        }
    }

    /// What is wrong with row `text`, naming its column and quoting its field.
    fn message(&self, text: &str, e: record::RowError) -> String {
        let column = e.column.and_then(|i| self.column_names.get(i).map(|n| (i, n)));
        let field = e
            .column
            .and_then(|i| text.split(',').nth(i))
            .map(record::trim_field)
            .unwrap_or("");
        // CR-only line ends after rows ending in \n: the fields of many
        // rows on one line, whatever the parser tripped on first.
        if has_inner_cr(text.as_bytes()) {
            return CR_ONLY_FROM_HERE.to_owned();
        }
        let message = match e.kind {
            RowErrorKind::FieldCount { expected, found } => {
                format!("row has {found} fields, the header has {expected}")
            }
            RowErrorKind::NotANumber if field.is_empty() => "field is empty, a number is required".to_owned(),
            RowErrorKind::NotANumber => format!("\"{}\" is not a number", short(field)),
            RowErrorKind::NonFinite => format!("\"{}\" is not a finite number", short(field)),
            RowErrorKind::NotAFlag => format!("\"{}\" is not 0 or 1", short(field)),
            RowErrorKind::OverRange => format!(
                "\"{}\" is beyond ±{} °/h (1000 °/s), the range a recorded run may hold; is the column in °/h?",
                short(field),
                record::MAX_ABS_RATE_DPH
            ),
            _ => "unreadable row".to_owned(),
        };
        match column {
            Some((i, name)) => format!("column {} (field {}): {message}", text::escape_controls(name), i + 1),
            None => message,
        }
    }
}

/// Threads that parse a run's chunks: one per core.
pub(super) fn parse_workers() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// What one line of the data section is.
pub(super) enum Line {
    /// Blank or a comment.
    Skip,
    /// A data row.
    Row(Row),
    /// A data row the format refuses.
    Refused(record::RowError),
    /// Bytes that are not UTF-8 text.
    NotUtf8,
}

/// Classifies `line` (without its `\n`), copying its text (without a
/// trailing `\r`) into `text` when `keep_text` or when it is refused.
pub(super) fn classify(columns: &Columns, line: &[u8], text: &mut String, keep_text: bool) -> Line {
    let Ok(line) = std::str::from_utf8(line) else {
        return Line::NotUtf8;
    };
    let line = line.strip_suffix('\r').unwrap_or(line);
    if record::is_comment_or_blank(line) {
        return Line::Skip;
    }
    let parsed = columns.parse_row_bytes(line.as_bytes());
    if keep_text || parsed.is_err() {
        text.clear();
        text.push_str(line);
    }
    match parsed {
        Ok(row) => Line::Row(row),
        Err(e) => Line::Refused(e),
    }
}

pub(super) fn io_or_utf8(path: &Path, line: usize, e: std::io::Error) -> RunError {
    if e.kind() == std::io::ErrorKind::InvalidData {
        RunError::Format {
            path: path.to_owned(),
            line,
            message: "line is not valid UTF-8 text".into(),
        }
    } else {
        RunError::Io {
            path: path.to_owned(),
            error: e,
        }
    }
}

/// `s` for a message: at most 60 characters, control characters escaped.
/// The message for a header without a required column: every required
/// column it lacks, and the delimiter it uses when that is not a comma.
pub(super) fn missing_columns(header_line: &str, names: &[String]) -> String {
    use rbf_core::record::column;
    let has = |name: &str| names.iter().any(|n| n == name);
    let mut missing = Vec::new();
    if !has(column::TIME_S) {
        missing.push(column::TIME_S.to_owned());
    }
    if !has(column::RATE_DPH) && !column::AXIS_RATES_DPH.iter().any(|r| has(r)) {
        missing.push(format!(
            "{} (or {})",
            column::RATE_DPH,
            column::AXIS_RATES_DPH.join(", ")
        ));
    }
    let list = match missing.len() {
        1 => format!("column {}", missing[0]),
        _ => format!("columns {}", missing.join(" and ")),
    };
    // Every column of the format that is missing, not only the required
    // two: a single-point model needs temp_c too.
    let no_temp = !has(column::TEMP_C) && !names.iter().any(|n| n.starts_with("temp_") && n.len() == 6);
    let list = if no_temp {
        format!(
            "{list}, nor {} (the loop temperature a single-point model needs)",
            column::TEMP_C
        )
    } else {
        list
    };
    let hints = near_names(names);
    let list = if hints.is_empty() {
        list
    } else {
        format!(
            "{list}; did you mean {}? (the format's names carry their units)",
            hints
                .iter()
                .map(|(found, known)| format!("{known} for {}", short(found)))
                .collect::<Vec<_>>()
                .join(", ")
        )
    };
    let delimiter = [(';', "';'"), ('\t', "a tab"), ('|', "'|'")]
        .into_iter()
        .find(|(c, _)| !header_line.contains(',') && header_line.contains(*c));
    match delimiter {
        Some((c, name)) => format!(
            "header has no required {list}: its fields are separated by {name}, not by commas (header: {}); \
             the recorded-run format is comma-separated: convert the file, e.g. tr '{}' ',' (with decimal commas, \
             turn them into points first)",
            short(header_line),
            c.escape_default()
        ),
        None => format!("header has no required {list} (header: {})", short(header_line)),
    }
}

/// Header names that are not the format's but look like one of its
/// columns (`time` → `time_s`, `temperature` → `temp_c`, `Rate_DPH` →
/// `rate_dph`): the name and the format's name. Near: the same letters
/// but for case, the format's stem (`time`, `rate`, `temp`, `ref`) leading
/// either, or at most two edits apart.
pub(super) fn near_names(names: &[String]) -> Vec<(String, &'static str)> {
    use rbf_core::record::column;
    const KNOWN: [&str; 4] = [column::TIME_S, column::RATE_DPH, column::TEMP_C, column::REF_DPH];
    let mut hints: Vec<(String, &'static str)> = Vec::new();
    for name in names {
        // The format's own multi-axis and multi-point names are not typos.
        if KNOWN.contains(&name.as_str()) || ["rate_", "temp_", "ref_"].iter().any(|p| name.starts_with(p)) {
            continue;
        }
        let lower = name.to_lowercase();
        let near = KNOWN.iter().copied().find(|known| {
            let stem = known.split('_').next().unwrap_or(known);
            lower == *known
                || (!lower.is_empty() && (lower.starts_with(stem) || stem.starts_with(lower.as_str())))
                || edits(&lower, known) <= 2
        });
        if let Some(known) = near.filter(|k| !names.iter().any(|n| n == k) && !hints.iter().any(|(_, h)| h == k)) {
            hints.push((name.clone(), known));
        }
    }
    hints
}

/// The Levenshtein distance of two short names.
fn edits(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (above + 1).min(row[j] + 1).min(diagonal + usize::from(ca != cb));
            diagonal = above;
        }
    }
    row[b.len()]
}

pub(super) fn short(s: &str) -> String {
    const MAX: usize = 60;
    let s = if s.chars().count() <= MAX {
        s.to_owned()
    } else {
        format!("{}…", s.chars().take(MAX).collect::<String>())
    };
    text::escape_controls(&s).into_owned()
}
