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
//! The reader is cut by job, each module importing only the ones below it:
//! [`rows`] (the lines, the batch row parser and [`RunError`]); [`header`]
//! (the preamble and the header, [`RunHeader`]) and `columns` (its column
//! mapping: axes, thermometers);
//! `source` (row decoding, one line at a time); `timing` (the time column's
//! checks); this module ([`RunReader`]: the rows read ahead, the axis
//! selected, line by line or in parallel batches); and [`samples`] (a whole
//! run in memory, [`samples::Run`], or streamed, [`samples::StreamedRun`]).

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::Path;

use rbf_core::axis::Axis;
use rbf_core::record::{Columns, PERIOD_ESTIMATE_STEPS, Row};
use rbf_core::thermometer::ThermometerSet;

use self::header::ReadHeader;
use self::source::LineSource;
use self::timing::TimeCheck;
use crate::reading::chunked::{self, Batch, Defect};
use crate::reading::input;

mod columns;
pub mod header;
pub mod rows;
pub mod samples;
mod source;
mod timing;

pub use self::header::RunHeader;
pub use self::rows::{RawRow, RowParser, RunError};
use self::rows::{io_or_utf8, parse_workers, too_long};

/// Streams the rows of one run file, checking them as it goes.
pub struct RunReader {
    header: RunHeader,
    /// The selected axis's columns (the header's for a single-axis run).
    columns: Columns,
    lines: LineSource,
    time: TimeCheck,
    /// Line of the last row handed out (the header's before any).
    last_line_out: usize,
    /// Rows read ahead at opening, handed out first.
    ahead: VecDeque<RawRow>,
    nominal_period_s: f64,
    /// Text per parsing job of [`RunReader::for_each_batch`].
    chunk_bytes: usize,
}

impl std::fmt::Debug for RunReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunReader")
            .field("path", &self.header.path())
            .field("line", &self.lines.line_number())
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
        let ReadHeader {
            header,
            metadata_rates,
            counted_time_base,
        } = RunHeader::read(path, source.as_mut(), &mut buf)?;
        let line_no = header.line_number();
        let columns = *header.columns();
        let mut reader = RunReader {
            header,
            columns,
            lines: LineSource::new(source, line_no, buf),
            time: TimeCheck::default(),
            last_line_out: line_no,
            ahead: VecDeque::new(),
            nominal_period_s: 1.0,
            chunk_bytes: chunked::CHUNK_BYTES,
        };
        reader.read_ahead(&metadata_rates, counted_time_base)?;
        Ok(reader)
    }

    /// Reads the first [`PERIOD_ESTIMATE_STEPS`] + 1 rows and settles the
    /// nominal period on them ([`TimeCheck::settle`]).
    fn read_ahead(&mut self, metadata_rates: &[(usize, f64)], counted_time_base: bool) -> Result<(), RunError> {
        while self.ahead.len() <= PERIOD_ESTIMATE_STEPS {
            match self.read_checked(true)? {
                Some((line, row)) => self.ahead.push_back(RawRow {
                    line,
                    row,
                    text: self.lines.text().to_owned(),
                }),
                None => break,
            }
        }
        self.nominal_period_s = self
            .time
            .settle(
                &self.ahead,
                metadata_rates,
                counted_time_base,
                self.header.period_estimator(),
            )
            .map_err(|(line, m)| self.header.error_at(line, m))?;
        Ok(())
    }

    /// Sets the text per parsing job of [`RunReader::for_each_batch`] (at
    /// least 1 byte; the tests cut small runs into many chunks with it).
    pub fn set_chunk_bytes(&mut self, bytes: usize) {
        self.chunk_bytes = bytes.max(1);
    }

    /// What the run says before its data: preamble, header, column mapping.
    pub fn header(&self) -> &RunHeader {
        &self.header
    }

    /// The file being read (`-`: standard input).
    pub fn path(&self) -> &Path {
        self.header.path()
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
        self.header.axes()
    }

    /// The columns that read `axis` ([`RunHeader::axis_columns`]).
    pub fn axis_columns(&self, axis: Axis) -> Result<Columns, RunError> {
        self.header.axis_columns(axis)
    }

    /// Reads `axis` of a multi-axis run from here on, as a single-axis run
    /// (its rate as `rate_dph`, its loop thermometer as `temp_c`, its
    /// reference as `ref_dph`); the rows already read ahead are parsed again.
    pub fn select_axis(&mut self, axis: Axis) -> Result<(), RunError> {
        let columns = self.axis_columns(axis)?;
        let parser = self.header.row_parser();
        for raw in &mut self.ahead {
            raw.row = parser.parse(&columns, raw.line, &raw.text)?;
        }
        self.columns = columns;
        Ok(())
    }

    /// The run's nominal sample period, s: `# sample_rate_hz`, else the
    /// median of the first steps ([`rbf_core::record::nominal_period_s`], the rule the
    /// firmware replay follows too).
    pub fn nominal_period_s(&self) -> f64 {
        self.nominal_period_s
    }

    /// Fails unless the run has a `temp_c` column (single-point models need it).
    pub fn require_temp(&self) -> Result<(), RunError> {
        self.require_thermometers(ThermometerSet::LOOP)
    }

    /// Fails unless the selected axis's columns include `thermometers`,
    /// naming the missing ones ([`RunHeader::require_thermometers`]).
    pub fn require_thermometers(&self, thermometers: ThermometerSet) -> Result<(), RunError> {
        self.header.require_thermometers(&self.columns, thermometers)
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
            text: self.lines.text().to_owned(),
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

    /// The next row from the source, handed out ([`Self::line_number`] moves to it).
    fn read_row(&mut self, keep_text: bool) -> Result<Option<(usize, Row)>, RunError> {
        let read = self.read_checked(keep_text)?;
        if let Some((line, _)) = read {
            self.last_line_out = line;
        }
        Ok(read)
    }

    /// The next row from the source, its time checked ([`TimeCheck::step`]).
    fn read_checked(&mut self, keep_text: bool) -> Result<Option<(usize, Row)>, RunError> {
        let Some((line, row)) = self.lines.next_row(&self.header, &self.columns, keep_text)? else {
            return Ok(None);
        };
        self.time
            .step(row.time_s, line, self.columns.time_s)
            .map_err(|(start, m)| self.header.error_at(start, m))?;
        Ok(Some((line, row)))
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
        let mut source = self.lines.take_source();
        let first_line = self.lines.line_number() + 1;
        let columns = self.columns;
        let path = self.header.path().to_owned();
        chunked::for_each_batch(
            source.as_mut(),
            &columns,
            first_line,
            self.chunk_bytes,
            parse_workers(),
            |mut batch| {
                batch.set_previous_time(self.time.last_time_s());
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
                    Some((line, defect, text)) => Err(match defect {
                        Defect::TooLong => self.header.error_at(line, too_long()),
                        Defect::NotUtf8 => self.header.error_at(line, "line is not valid UTF-8 text".into()),
                        Defect::Refused(e) => self.header.row_parser().error(line, &text, e),
                    }),
                }
            },
            |line, error| io_or_utf8(&path, line, error),
        )?;
        Ok(rows)
    }

    /// The first row of `batch` that breaks the time checks, with its
    /// error; the time of the last good row is kept for the next batch.
    fn check_batch(&mut self, batch: &Batch) -> Option<(usize, RunError)> {
        for k in 0..batch.len() {
            if let Err((line, m)) = self.time.step(batch.time_s(k), batch.line(k), self.columns.time_s) {
                return Some((k, self.header.error_at(line, m)));
            }
        }
        None
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::reading::limits::MAX_LINE_BYTES;

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
            .header()
            .require_single_axis()
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("run.csv:1: a multi-axis run (axes x): this reads single-axis runs"),
            "{err}"
        );
        assert!(
            open_axis(TEXT.as_bytes(), None)
                .unwrap()
                .header()
                .require_single_axis()
                .is_ok()
        );
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
