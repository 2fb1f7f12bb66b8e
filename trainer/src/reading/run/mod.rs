//! Reading recorded runs (`docs/recorded-run-format.md`) from files or
//! standard input (`-`).
//!
//! Row parsing is [`rbf_core::record`] (shared with the firmware replay); this
//! module adds files, line numbers, metadata, the strictly-increasing time
//! check, the sample-rate checks of [`crate::reading::sampling`], the limits of
//! [`crate::reading::limits`] and error messages of the form
//! `run.csv:1042: column rate_dph: "1.2.3" is not a number`.
//!
//! A run is read once, front to back: [`RunReader::open`] reads the
//! metadata, the header and the first [`PERIOD_ESTIMATE_STEPS`] + 1 rows
//! (the nominal period needs them) and hands those rows out again first, so
//! pipes and FIFOs read like files.
//!
//! Three layers, each importing only the ones below: [`rows`] (the lines,
//! the batch row parser and [`RunError`]), this module ([`RunReader`]), and
//! [`samples`] (a whole run in memory, [`samples::Run`], or streamed,
//! [`samples::StreamedRun`]).

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use rbf_core::axis::Axis;
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
use rbf_core::record::{self, Columns, HeaderError, PERIOD_ESTIMATE_STEPS, PeriodEstimator, Row};
use rbf_core::thermometer::ThermometerSet;
use rbf_core::{CompensatorConfig, GyroSample};

use crate::reading::chunked::{self, Batch, Defect};
use crate::reading::limits::{MAX_COLUMNS, MAX_LINE_BYTES, MAX_PREAMBLE_BYTES, bytes};
use crate::reading::sampling::{self, PeriodSource, PeriodWatch};
use crate::{reading::input, text};

pub mod rows;
pub mod samples;

use self::rows::*;

/// Streams the rows of one run file, checking them as it goes.
pub struct RunReader {
    path: PathBuf,
    source: Box<dyn BufRead + Send>,
    /// The current line's text when it is kept or refused (reused: no
    /// allocation per row).
    line: String,
    /// Bytes of a line that did not lie whole in the read buffer (reused).
    line_bytes: Vec<u8>,
    /// Lines read from the source so far.
    line_no: usize,
    /// Line of the last row handed out (the header's before any).
    last_line_out: usize,
    header_line_no: usize,
    header_line: String,
    column_names: Vec<String>,
    columns: Columns,
    /// The header's columns before an axis was selected.
    header_columns: Columns,
    preamble: Vec<String>,
    last_time_s: Option<f64>,
    /// Rows read ahead at opening, handed out first.
    ahead: VecDeque<RawRow>,
    nominal_period_s: f64,
    /// Checks the steps of rows read after the look-ahead.
    watch: Option<PeriodWatch>,
    /// Text per parsing job of [`RunReader::for_each_batch`].
    chunk_bytes: usize,
}

impl std::fmt::Debug for RunReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunReader")
            .field("path", &self.path)
            .field("line", &self.line_no)
            .finish()
    }
}

impl RunReader {
    /// Opens a run (`-`: standard input) and reads its metadata, header and
    /// first rows.
    pub fn open(path: &Path) -> Result<RunReader, RunError> {
        let source = input::open(path).map_err(|error| RunError::Io {
            path: path.to_owned(),
            error,
        })?;
        // 1 MiB reads: a tenth of the system calls of the default on long runs.
        Self::from_reader(path, BufReader::with_capacity(1 << 20, source))
    }

    /// Reads a run from any buffered source; `path` names it in messages.
    pub fn from_reader(path: &Path, source: impl BufRead + Send + 'static) -> Result<RunReader, RunError> {
        let mut source: Box<dyn BufRead + Send> = Box::new(source);
        let mut buf = Vec::new();
        let mut line_no = 0;
        let mut preamble = Vec::new();
        let mut preamble_bytes = 0usize;
        let mut metadata_rates: Vec<(usize, f64)> = Vec::new();
        let mut counted_time_base = false;
        let format_error = |line: usize, message: String| RunError::Format {
            path: path.to_owned(),
            line,
            message,
        };
        let header_line = loop {
            line_no += 1;
            let read = read_line_bounded(source.as_mut(), &mut buf).map_err(|e| io_or_utf8(path, line_no, e))?;
            // A compressed file holds any bytes, a carriage return among them:
            // named for what it is before the line ends are judged.
            if line_no == 1
                && let Some((format, tool)) = compressed_format(&buf)
            {
                return Err(format_error(
                    line_no,
                    format!("the file is {format}-compressed, not CSV text; decompress it first ({tool})"),
                ));
            }
            // A file with CR-only line ends reads as one line: it would
            // otherwise be "no header", "too long" or thousands of columns.
            if has_inner_cr(&buf) {
                return Err(format_error(line_no, CR_ONLY.into()));
            }
            match read {
                Bounded::End => {
                    return Err(format_error(line_no, "no header line: the file has no columns".into()));
                }
                Bounded::TooLong => return Err(format_error(line_no, too_long())),
                Bounded::Line => {}
            }
            let Ok(line) = std::str::from_utf8(&buf) else {
                return Err(format_error(line_no, "line is not valid UTF-8 text".into()));
            };
            let line = if line_no == 1 {
                line.trim_start_matches('\u{feff}')
            } else {
                line
            };
            let line = line.trim_end_matches('\r');
            if !record::is_comment_or_blank(line) {
                break line.to_owned();
            }
            preamble_bytes += line.len() + 1;
            if preamble_bytes > MAX_PREAMBLE_BYTES {
                return Err(format_error(
                    line_no,
                    format!(
                        "more than {} of metadata, comment and blank lines before the header (the limit)",
                        bytes(MAX_PREAMBLE_BYTES as u64)
                    ),
                ));
            }
            counted_time_base |= record::metadata(line).is_some_and(|(k, v)| sampling::is_counted_time_base(k, v));
            if let Some(value) = record::metadata(line)
                .filter(|(key, _)| *key == "sample_rate_hz")
                .map(|(_, value)| value)
                && let Some(hz) = sampling::metadata_rate_hz(value).map_err(|m| format_error(line_no, m))?
            {
                metadata_rates.push((line_no, hz));
            }
            preamble.push(line.to_owned());
        };
        let columns_count = memchr::memchr_iter(b',', header_line.as_bytes()).count() + 1;
        if columns_count > MAX_COLUMNS {
            return Err(format_error(
                line_no,
                format!("header has {columns_count} columns; at most {MAX_COLUMNS} are read (the limit)"),
            ));
        }
        let column_names: Vec<String> = header_line
            .split(',')
            .map(|s| record::trim_field(s).to_owned())
            .collect();
        let columns = Columns::from_header(&header_line).map_err(|e| match e {
            HeaderError::MissingColumn(_) => format_error(line_no, missing_columns(&header_line, &column_names)),
            HeaderError::DuplicateColumn(i) => format_error(
                line_no,
                format!(
                    "column {} appears twice in the header",
                    text::escape_controls(&column_names[i])
                ),
            ),
            HeaderError::MixedAxes(i) => format_error(
                line_no,
                format!(
                    "column {} (field {}): a run has rate_dph (one axis) or rate_x_dph, rate_y_dph, \
                     rate_z_dph (one to three axes), not both",
                    text::escape_controls(&column_names[i]),
                    i + 1
                ),
            ),
            _ => format_error(line_no, "unusable header".into()),
        })?;
        let mut reader = RunReader {
            path: path.to_owned(),
            source,
            line: String::new(),
            line_bytes: buf,
            line_no,
            last_line_out: line_no,
            header_line_no: line_no,
            header_line,
            column_names,
            columns,
            header_columns: columns,
            preamble,
            last_time_s: None,
            ahead: VecDeque::new(),
            nominal_period_s: 1.0,
            watch: None,
            chunk_bytes: chunked::CHUNK_BYTES,
        };
        reader.read_ahead(&metadata_rates, counted_time_base)?;
        Ok(reader)
    }

    /// Reads the first [`PERIOD_ESTIMATE_STEPS`] + 1 rows, settles the
    /// nominal period, checks every stated rate (line, Hz) against the time
    /// column and the rows against the period.
    fn read_ahead(&mut self, metadata_rates: &[(usize, f64)], counted_time_base: bool) -> Result<(), RunError> {
        while self.ahead.len() <= PERIOD_ESTIMATE_STEPS {
            match self.read_source_row(true)? {
                Some((line, row)) => self.ahead.push_back(RawRow {
                    line,
                    row,
                    text: self.line.clone(),
                }),
                None => break,
            }
        }
        let mut estimator = self.period_estimator();
        let mut steps: Vec<f64> = Vec::with_capacity(self.ahead.len());
        let mut prev: Option<f64> = None;
        for raw in &self.ahead {
            if !estimator.is_complete() {
                estimator.push_time(raw.row.time_s);
            }
            if let Some(p) = prev {
                steps.push(raw.row.time_s - p);
            }
            prev = Some(raw.row.time_s);
        }
        self.nominal_period_s = estimator.period_s();
        let count = steps.len();
        let median = record::nominal_period_s(None, &mut steps);
        let lines = (
            self.ahead.front().map_or(0, |r| r.line),
            self.ahead.back().map_or(0, |r| r.line),
        );
        // A counted time base steps long only where samples were missed:
        // its stated rate is the unit's, whatever was lost at the start.
        for &(line, hz) in metadata_rates.iter().filter(|_| !counted_time_base) {
            sampling::check_agreement(hz, median, count, lines).map_err(|m| self.error_at(line, m))?;
        }
        if metadata_rates.is_empty() {
            sampling::check_unstated_period(median, count, lines).map_err(|m| self.error_at(lines.0, m))?;
        }
        let source = if metadata_rates.is_empty() {
            PeriodSource::Median
        } else {
            PeriodSource::Metadata
        };
        let mut watch = PeriodWatch::new(self.nominal_period_s, source);
        if counted_time_base {
            watch = watch.counted();
        }
        let mut prev: Option<f64> = None;
        for raw in &self.ahead {
            if let Some(p) = prev {
                watch
                    .push(raw.row.time_s - p, raw.line)
                    .map_err(|(line, m)| self.error_at(line, m))?;
            }
            prev = Some(raw.row.time_s);
        }
        self.watch = Some(watch);
        Ok(())
    }

    /// Sets the text per parsing job of [`RunReader::for_each_batch`] (at
    /// least 1 byte; the tests cut small runs into many chunks with it).
    pub fn set_chunk_bytes(&mut self, bytes: usize) {
        self.chunk_bytes = bytes.max(1);
    }

    /// The file being read (`-`: standard input).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header line as read (without line end).
    pub fn header_line(&self) -> &str {
        &self.header_line
    }

    /// Line number of the header, 1-based.
    pub fn header_line_number(&self) -> usize {
        self.header_line_no
    }

    /// Number of the last row handed out, 1-based: the header's until a row is.
    pub fn line_number(&self) -> usize {
        self.last_line_out
    }

    /// Where the known columns are (of the selected axis in a multi-axis run).
    pub fn columns(&self) -> &Columns {
        &self.columns
    }

    /// The axes of a multi-axis run, in x, y, z order; empty for a single-axis run.
    pub fn axes(&self) -> Vec<Axis> {
        self.header_columns.axes_present().collect()
    }

    /// The columns that read `axis` ([`Columns::for_axis`]), or an error at
    /// the header naming the missing rate column.
    pub fn axis_columns(&self, axis: Axis) -> Result<Columns, RunError> {
        self.header_columns.for_axis(axis).ok_or_else(|| {
            self.error_at(
                self.header_line_no,
                format!(
                    "header has no column {} (header: {})",
                    axis.rate_column(),
                    short(&self.header_line)
                ),
            )
        })
    }

    /// Fails on a multi-axis run, for commands that read one axis
    /// (`rate_dph`): the message names the axes and the commands that read them.
    pub fn require_single_axis(&self) -> Result<(), RunError> {
        let axes = self.axes();
        if axes.is_empty() {
            return Ok(());
        }
        let names: Vec<&str> = axes.iter().map(|a| a.name()).collect();
        Err(self.error_at(
            self.header_line_no,
            format!(
                "a multi-axis run (axes {}): this reads single-axis runs (rate_dph); fit, compensate, \
                 eval and inspect read each axis",
                names.join(", ")
            ),
        ))
    }

    /// Reads `axis` of a multi-axis run from here on, as a single-axis run
    /// (its rate as `rate_dph`, its loop thermometer as `temp_c`, its
    /// reference as `ref_dph`); the rows already read ahead are parsed again.
    pub fn select_axis(&mut self, axis: Axis) -> Result<(), RunError> {
        let columns = self.axis_columns(axis)?;
        let mut ahead = std::mem::take(&mut self.ahead);
        for raw in &mut ahead {
            raw.row = self.parse_with(&columns, raw.line, &raw.text)?;
        }
        self.ahead = ahead;
        self.columns = columns;
        Ok(())
    }

    /// Parses the text of data line `line` with `columns` (another axis's
    /// columns of this run, see [`RunReader::axis_columns`]); a refused
    /// row's error names this file, the line and the column.
    pub fn parse_with(&self, columns: &Columns, line: usize, text: &str) -> Result<Row, RunError> {
        self.row_parser().parse(columns, line, text)
    }

    /// The lines before the header (metadata, blank lines) as read, without line ends.
    pub fn preamble(&self) -> &[String] {
        &self.preamble
    }

    /// The run's nominal sample period, s: `# sample_rate_hz`, else the
    /// median of the first steps ([`record::nominal_period_s`], the rule the
    /// firmware replay follows too).
    pub fn nominal_period_s(&self) -> f64 {
        self.nominal_period_s
    }

    /// A period estimator primed with this run's metadata (see [`PeriodEstimator`]).
    pub fn period_estimator(&self) -> PeriodEstimator {
        let mut estimator = PeriodEstimator::new();
        self.preamble.iter().for_each(|line| estimator.note_preamble_line(line));
        estimator
    }

    /// Fails unless the run has a `temp_c` column (single-point models need it).
    pub fn require_temp(&self) -> Result<(), RunError> {
        self.require_thermometers(ThermometerSet::LOOP)
    }

    /// Fails unless the run has the columns of `thermometers`, naming the
    /// missing ones.
    pub fn require_thermometers(&self, thermometers: ThermometerSet) -> Result<(), RunError> {
        self.require_thermometers_of(&self.columns, thermometers)
    }

    /// [`RunReader::require_thermometers`] for `columns` (another axis's).
    pub fn require_thermometers_of(&self, columns: &Columns, thermometers: ThermometerSet) -> Result<(), RunError> {
        let absent = thermometers.difference(columns.thermometers());
        let missing: Vec<&str> = record::column::THERMOMETERS
            .iter()
            .enumerate()
            .filter(|(i, _)| absent.contains(*i))
            .map(|(_, name)| *name)
            .collect();
        if missing.is_empty() {
            return Ok(());
        }
        let what = if thermometers == ThermometerSet::LOOP {
            "which single-point models need"
        } else {
            "which the model's inputs need"
        };
        Err(self.error_at(
            self.header_line_no,
            format!(
                "header has no column {}, {what} (header: {})",
                missing.join(", "),
                short(&self.header_line)
            ),
        ))
    }

    fn error_at(&self, line: usize, message: String) -> RunError {
        RunError::Format {
            path: self.path.clone(),
            line,
            message,
        }
    }

    /// Reads the next data row; `Ok(None)` at the end of the file.
    pub fn next_row(&mut self) -> Result<Option<RawRow>, RunError> {
        if let Some(raw) = self.ahead.pop_front() {
            self.last_line_out = raw.line;
            return Ok(Some(raw));
        }
        Ok(self.read_row(true)?.map(|(line, row)| RawRow {
            line,
            row,
            text: self.line.clone(),
        }))
    }

    /// Reads the next data row without keeping its text (the fast path of
    /// streaming passes: the line is parsed where it lies in the read
    /// buffer, no copy, no allocation); (line number, row).
    pub fn next_parsed(&mut self) -> Result<Option<(usize, Row)>, RunError> {
        if let Some(raw) = self.ahead.pop_front() {
            self.last_line_out = raw.line;
            return Ok(Some((raw.line, raw.row)));
        }
        self.read_row(false)
    }

    /// The next row from the source, its time step watched for a change of rate.
    fn read_row(&mut self, keep_text: bool) -> Result<Option<(usize, Row)>, RunError> {
        let previous_s = self.last_time_s;
        let Some((line, row)) = self.read_source_row(keep_text)? else {
            return Ok(None);
        };
        if let (Some(watch), Some(p)) = (&mut self.watch, previous_s) {
            let checked = watch.push(row.time_s - p, line);
            checked.map_err(|(start, m)| self.error_at(start, m))?;
        }
        self.last_line_out = line;
        Ok(Some((line, row)))
    }

    /// The next data row read from the source; its text (without line end)
    /// in `self.line` when `keep_text` or when it is refused (the error
    /// message quotes it).
    fn read_source_row(&mut self, keep_text: bool) -> Result<Option<(usize, Row)>, RunError> {
        loop {
            self.line_no += 1;
            let buf = self
                .source
                .fill_buf()
                .map_err(|e| io_or_utf8(&self.path, self.line_no, e))?;
            let outcome = match memchr::memchr(b'\n', buf) {
                Some(end) if end <= MAX_LINE_BYTES => {
                    let outcome = classify(&self.columns, buf.get(..end).unwrap_or(&[]), &mut self.line, keep_text);
                    self.source.consume(end + 1);
                    outcome
                }
                Some(_) => {
                    let message = if has_inner_cr(buf.get(..MAX_LINE_BYTES).unwrap_or(buf)) {
                        CR_ONLY.into()
                    } else {
                        too_long()
                    };
                    return Err(self.error_at(self.line_no, message));
                }
                None => {
                    // The line runs past the buffer or ends the file without
                    // a line end: the copying path.
                    let mut bytes = std::mem::take(&mut self.line_bytes);
                    let read = read_line_bounded(self.source.as_mut(), &mut bytes)
                        .map_err(|e| io_or_utf8(&self.path, self.line_no, e));
                    let outcome = match read {
                        Ok(Bounded::End) => {
                            self.line_no -= 1;
                            self.line_bytes = bytes;
                            return Ok(None);
                        }
                        Ok(_) if has_inner_cr(&bytes) => Err(self.error_at(self.line_no, CR_ONLY.into())),
                        Ok(Bounded::TooLong) => Err(self.error_at(self.line_no, too_long())),
                        Ok(Bounded::Line) => Ok(classify(&self.columns, &bytes, &mut self.line, keep_text)),
                        Err(e) => Err(e),
                    };
                    self.line_bytes = bytes;
                    outcome?
                }
            };
            let row = match outcome {
                Line::Skip => continue,
                Line::NotUtf8 => {
                    return Err(self.error_at(self.line_no, "line is not valid UTF-8 text".into()));
                }
                Line::Refused(_) if has_inner_cr(self.line.as_bytes()) => {
                    return Err(self.error_at(self.line_no, CR_ONLY.into()));
                }
                Line::Refused(e) => return Err(self.row_error(e)),
                Line::Row(row) => row,
            };
            if let Some(last) = self.last_time_s
                && row.time_s <= last
            {
                return Err(self.error_at(
                    self.line_no,
                    format!(
                        "column time_s (field {}): {} does not increase (previous row {last})",
                        self.columns.time_s + 1,
                        row.time_s
                    ),
                ));
            }
            self.last_time_s = Some(row.time_s);
            return Ok(Some((self.line_no, row)));
        }
    }

    /// Hands every remaining data row to `consume` in batches, in file
    /// order, parsed on every core ([`crate::reading::chunked`]) with the checks and
    /// the error messages of [`RunReader::next_row`]: a batch holds only rows
    /// that passed, and the error of the first that did not follows it.
    /// Returns the number of rows handed out.
    pub fn for_each_batch(mut self, mut consume: impl FnMut(Batch)) -> Result<usize, RunError> {
        let mut rows = 0;
        if !self.ahead.is_empty() {
            let mut first = Batch::new(&self.columns);
            for raw in std::mem::take(&mut self.ahead) {
                first.push(raw.line, &raw.row, raw.text.as_bytes());
                self.last_line_out = raw.line;
            }
            first.set_previous_time(None);
            rows += first.len();
            consume(first);
        }
        let mut source: Box<dyn BufRead + Send> = Box::new(std::io::empty());
        std::mem::swap(&mut source, &mut self.source);
        let first_line = self.line_no + 1;
        let columns = self.columns;
        let path = self.path.clone();
        chunked::for_each_batch(
            source.as_mut(),
            &columns,
            first_line,
            self.chunk_bytes,
            parse_workers(),
            |mut batch| {
                batch.set_previous_time(self.last_time_s);
                let failed = self.check_batch(&batch);
                let defect = batch.take_defect();
                if let Some((k, _)) = failed {
                    batch.truncate(k);
                }
                rows += batch.len();
                if !batch.is_empty() {
                    self.last_line_out = batch.line(batch.len() - 1);
                }
                consume(batch);
                if let Some((_, e)) = failed {
                    return Err(e);
                }
                match defect {
                    None => Ok(()),
                    Some((line, defect, text)) => {
                        self.line_no = line;
                        self.line = text;
                        Err(match defect {
                            Defect::TooLong => self.error_at(line, too_long()),
                            Defect::NotUtf8 => self.error_at(line, "line is not valid UTF-8 text".into()),
                            Defect::Refused(e) => self.row_error(e),
                        })
                    }
                }
            },
            |line, error| io_or_utf8(&path, line, error),
        )?;
        Ok(rows)
    }

    /// The first row of `batch` that breaks the strictly increasing time or
    /// the sample-rate watch, with its error; the time of the last good row
    /// is kept for the next batch.
    fn check_batch(&mut self, batch: &Batch) -> Option<(usize, RunError)> {
        for k in 0..batch.len() {
            let time_s = batch.time_s(k);
            let line = batch.line(k);
            if let Some(last) = self.last_time_s {
                if time_s <= last {
                    let message = format!(
                        "column time_s (field {}): {} does not increase (previous row {last})",
                        self.columns.time_s + 1,
                        time_s
                    );
                    return Some((k, self.error_at(line, message)));
                }
                if let Some(watch) = &mut self.watch
                    && let Err((start, m)) = watch.push(time_s - last, line)
                {
                    return Some((k, self.error_at(start, m)));
                }
            }
            self.last_time_s = Some(time_s);
        }
        None
    }

    /// The error for a refused row, naming its column and quoting its field
    /// (the row's text is in `self.line`).
    fn row_error(&self, e: record::RowError) -> RunError {
        self.row_error_in(self.line_no, &self.line, e)
    }

    /// The error for row `text` of line `line`, refused by the row parser.
    fn row_error_in(&self, line: usize, text: &str, e: record::RowError) -> RunError {
        self.row_parser().error(line, text, e)
    }

    /// A parser of this run's lines by other columns (another axis's, see
    /// [`RunReader::axis_columns`]) that outlives the reader: its errors
    /// name this file, the line and the column.
    pub fn row_parser(&self) -> RowParser {
        RowParser {
            path: self.path.clone(),
            column_names: self.column_names.clone(),
        }
    }
}

/// The compression format whose magic bytes `head` (a file's first bytes)
/// starts with, and the command that undoes it.
fn compressed_format(head: &[u8]) -> Option<(&'static str, &'static str)> {
    const MAGIC: [(&[u8], &str, &str); 5] = [
        (&[0x1f, 0x8b], "gzip", "gunzip FILE"),
        (&[0x28, 0xb5, 0x2f, 0xfd], "zstd", "unzstd FILE"),
        (&[0xfd, b'7', b'z', b'X', b'Z', 0x00], "xz", "unxz FILE"),
        (b"BZh", "bzip2", "bunzip2 FILE"),
        (b"PK\x03\x04", "zip", "unzip FILE"),
    ];
    MAGIC
        .iter()
        .find(|(magic, _, _)| head.starts_with(magic))
        .map(|&(_, format, tool)| (format, tool))
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    const TEXT: &str = "# sample_rate_hz: 100\r\ntime_s,rate_dph,temp_c\r\n0.00,1.5,20.0\r\n# a comment\n\n0.01, 2.5 ,20.25\n0.02,3.5,20.5";

    fn rows(capacity: usize, text: &'static str) -> Result<Vec<(usize, Row)>, RunError> {
        let source = BufReader::with_capacity(capacity, text.as_bytes());
        let mut reader = RunReader::from_reader(Path::new("run.csv"), source)?;
        let mut out = Vec::new();
        while let Some(row) = reader.next_parsed()? {
            out.push(row);
        }
        Ok(out)
    }

    #[test]
    fn rows_read_alike_in_place_and_across_buffer_ends() {
        let whole = rows(1 << 16, TEXT).unwrap();
        assert_eq!(whole.len(), 3);
        assert_eq!(whole.iter().map(|(line, _)| *line).collect::<Vec<_>>(), [3, 6, 7]);
        assert_eq!(whole[1].1.rate_dph, 2.5);
        assert_eq!(whole[2].1.temp_c(), Some(20.5), "last line without a line end");
        for capacity in [1, 5, 7, 16] {
            assert_eq!(rows(capacity, TEXT).unwrap(), whole, "buffer of {capacity} bytes");
        }
    }

    #[test]
    fn refused_rows_name_line_and_column_on_either_path() {
        let text = "time_s,rate_dph,temp_c\n0.00,1.5,20.0\n0.01,x1,20.0\n";
        for capacity in [1 << 16, 5] {
            let err = rows(capacity, text).unwrap_err().to_string();
            assert_eq!(
                err, "run.csv:3: column rate_dph (field 2): \"x1\" is not a number",
                "buffer of {capacity} bytes"
            );
        }
        let not_utf8: &'static [u8] = b"time_s,rate_dph\n0.00,1.5\n0.01,\xff\n";
        let err = RunReader::from_reader(Path::new("run.csv"), BufReader::new(not_utf8)).unwrap_err();
        assert_eq!(err.to_string(), "run.csv:3: line is not valid UTF-8 text");
    }

    /// Every row and the error of a run read line by line ([`RunReader::next_parsed`]).
    fn line_by_line(text: &[u8]) -> (Vec<(usize, Row)>, Option<String>) {
        line_by_line_axis(text, None)
    }

    /// A reader of `text` on `axis` (none: the run as it opens).
    fn open_axis(text: &[u8], axis: Option<Axis>) -> Result<RunReader, RunError> {
        let source = BufReader::with_capacity(64, std::io::Cursor::new(text.to_vec()));
        let mut reader = RunReader::from_reader(Path::new("run.csv"), source)?;
        if let Some(axis) = axis {
            reader.select_axis(axis)?;
        }
        Ok(reader)
    }

    /// [`line_by_line`] of one axis.
    fn line_by_line_axis(text: &[u8], axis: Option<Axis>) -> (Vec<(usize, Row)>, Option<String>) {
        let mut reader = match open_axis(text, axis) {
            Ok(r) => r,
            Err(e) => return (Vec::new(), Some(e.to_string())),
        };
        let mut out = Vec::new();
        loop {
            match reader.next_parsed() {
                Ok(Some(row)) => out.push(row),
                Ok(None) => return (out, None),
                Err(e) => return (out, Some(e.to_string())),
            }
        }
    }

    /// The same by [`RunReader::for_each_batch`] in chunks of `chunk_bytes`.
    fn chunked(text: &[u8], chunk_bytes: usize) -> (Vec<(usize, Row)>, Option<String>) {
        chunked_axis(text, chunk_bytes, None)
    }

    /// [`chunked`] of one axis.
    fn chunked_axis(text: &[u8], chunk_bytes: usize, axis: Option<Axis>) -> (Vec<(usize, Row)>, Option<String>) {
        let mut reader = match open_axis(text, axis) {
            Ok(r) => r,
            Err(e) => return (Vec::new(), Some(e.to_string())),
        };
        reader.set_chunk_bytes(chunk_bytes);
        let mut out = Vec::new();
        let result = reader.for_each_batch(|batch| {
            for i in 0..batch.len() {
                out.push((batch.line(i), batch.row(i)));
            }
        });
        (out, result.err().map(|e| e.to_string()))
    }

    /// A run of `rows` rows at 10 Hz with a known set of columns, then `edit` applied to its text.
    fn generated(rows: usize, header: &str, seed: u64) -> Vec<u8> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let mut text = format!("# sample_rate_hz: 10\n{header}\n").into_bytes();
        let columns = header.split(',').count();
        for i in 0..rows {
            let mut fields = vec![format!("{:.2}", i as f64 * 0.1)];
            for c in 1..columns {
                let v: f64 = rng.random_range(-50.0..50.0);
                fields.push(match (c + i) % 5 {
                    0 => format!("{v:.7}"),
                    1 => format!("{v:e}"),
                    2 => format!(" {v:.3}\t"),
                    3 => format!("{}", v as f32),
                    _ => format!("{v}"),
                });
            }
            text.extend_from_slice(fields.join(",").as_bytes());
            text.extend_from_slice(if i % 7 == 0 { b"\r\n" } else { b"\n" });
            if i % 50 == 3 {
                text.extend_from_slice(b"# note\n\n");
            }
        }
        text
    }

    #[test]
    fn the_chunked_reader_gives_the_rows_and_the_errors_of_the_line_reader() {
        use rand::{Rng, SeedableRng};
        let headers = [
            "time_s,rate_dph,temp_c",
            "time_s,rate_dph,temp_c,ref_dph",
            "rate_dph,temp_a,time_s,note,temp_c,temp_h",
        ];
        // Edits that break a file somewhere, each in its own way.
        let damage: [&[u8]; 12] = [
            b"1.2.3",
            b"",
            b"\xff\xfe",
            b"nan",
            b"1e999",
            b"#",
            b"\n",
            b",",
            b"0",
            b"-",
            b"4e6",
            b"\r\r",
        ];
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let mut cases = 0;
        for (h, header) in headers.iter().enumerate() {
            for seed in 0..12u64 {
                let mut text = generated(400, header, seed + 100 * h as u64);
                if seed > 0 {
                    let edits = 1 + seed as usize % 3;
                    for _ in 0..edits {
                        let at = rng.random_range(text.len() / 3..text.len());
                        let len = rng.random_range(0..4).min(text.len() - at);
                        let with = damage[rng.random_range(0..damage.len())];
                        text.splice(at..at + len, with.iter().copied());
                    }
                }
                if seed == 5 {
                    // A line past the limit, mid-file.
                    let at = text.len() / 2;
                    text.splice(at..at, std::iter::repeat_n(b'7', MAX_LINE_BYTES + 3));
                }
                if seed == 6 {
                    text.pop();
                }
                let expected = line_by_line(&text);
                for chunk_bytes in [1, 97, 4096, chunked::CHUNK_BYTES] {
                    assert_eq!(
                        chunked(&text, chunk_bytes),
                        expected,
                        "header {header}, seed {seed}, chunks of {chunk_bytes} bytes"
                    );
                }
                cases += usize::from(expected.1.is_some());
            }
        }
        assert!(
            cases >= 20,
            "only {cases} files were refused: the edits test too little"
        );
    }

    #[test]
    fn the_chunked_reader_gives_each_axis_the_rows_and_errors_of_the_line_reader() {
        use rand::{Rng, SeedableRng};
        let header = "time_s,rate_x_dph,temp_x_c,rate_y_dph,temp_c,ref_y_dph,rate_z_dph,temp_z_c";
        let mut rng = rand_pcg::Pcg64::seed_from_u64(25);
        let mut refused = 0;
        for seed in 0..8u64 {
            let mut text = generated(300, header, seed);
            if seed > 0 {
                let at = rng.random_range(text.len() / 3..text.len());
                text.splice(at..at + 1, b"x".iter().copied());
            }
            for axis in Axis::ALL {
                let expected = line_by_line_axis(&text, Some(axis));
                for chunk_bytes in [1, 97, chunked::CHUNK_BYTES] {
                    assert_eq!(
                        chunked_axis(&text, chunk_bytes, Some(axis)),
                        expected,
                        "axis {axis:?}, seed {seed}, chunks of {chunk_bytes} bytes"
                    );
                }
                refused += usize::from(expected.1.is_some());
            }
            // Each axis reads its own rate, thermometer and reference.
            let clean = generated(3, header, seed);
            let fields: Vec<f64> = String::from_utf8(clean)
                .unwrap()
                .lines()
                .nth(2)
                .unwrap()
                .split(',')
                .map(|f| f.trim().parse().unwrap())
                .collect();
            let text = generated(3, header, seed);
            let (y, _) = line_by_line_axis(&text, Some(Axis::Y));
            assert_eq!(
                (y[0].1.rate_dph, y[0].1.temp_c(), y[0].1.ref_dph),
                (fields[3], Some(fields[4]), Some(fields[5]))
            );
            let (z, _) = line_by_line_axis(&text, Some(Axis::Z));
            assert_eq!(
                (z[0].1.rate_dph, z[0].1.temp_c(), z[0].1.ref_dph),
                (fields[6], Some(fields[7]), None)
            );
        }
        assert!(refused >= 6, "only {refused} axis readings were refused");
    }

    #[test]
    fn a_run_with_rate_dph_and_a_per_axis_rate_is_refused_naming_the_column() {
        let text = b"# sample_rate_hz: 10\ntime_s,rate_dph,temp_c,rate_z_dph\n0,1,20,2\n";
        let err = open_axis(text, None).unwrap_err().to_string();
        assert_eq!(
            err,
            "run.csv:2: column rate_z_dph (field 4): a run has rate_dph (one axis) or rate_x_dph, rate_y_dph, \
             rate_z_dph (one to three axes), not both"
        );
        let text = b"time_s,rate_x_dph,temp_c\n0,1,20\n0.1,2,20\n";
        let err = open_axis(text, Some(Axis::Y)).unwrap_err().to_string();
        assert!(err.starts_with("run.csv:1: header has no column rate_y_dph"), "{err}");
        let err = open_axis(text, None)
            .unwrap()
            .require_single_axis()
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("run.csv:1: a multi-axis run (axes x): this reads single-axis runs"),
            "{err}"
        );
        assert!(open_axis(TEXT.as_bytes(), None).unwrap().require_single_axis().is_ok());
        let text = b"time_s,rate_x_dph,temp_c,rate_y_dph\n0,1,20,2\n0.1,2,20,oops\n";
        let err = open_axis(text, Some(Axis::Y)).unwrap_err().to_string();
        assert_eq!(err, "run.csv:3: column rate_y_dph (field 4): \"oops\" is not a number");
    }

    #[test]
    fn a_non_increasing_time_and_a_rate_change_are_refused_at_their_line_on_both_paths() {
        let mut text = generated(300, "time_s,rate_dph,temp_c", 1);
        text.extend_from_slice(b"29.9,1,2\n");
        let (_, error) = chunked(&text, 128);
        assert_eq!(error, line_by_line(&text).1);
        assert!(error.unwrap().contains("does not increase"));
        let mut text = generated(300, "time_s,rate_dph,temp_c", 2);
        for i in 0..200 {
            text.extend_from_slice(format!("{},1,2\n", 40.0 + i as f64).as_bytes());
        }
        let expected = line_by_line(&text);
        assert!(expected.1.is_some(), "a 1-Hz stretch in a 10-Hz run is refused");
        assert_eq!(chunked(&text, 128), expected);
    }
}
