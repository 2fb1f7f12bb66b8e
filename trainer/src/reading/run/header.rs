//! What a run says before its data: the metadata, comment and blank lines
//! (the preamble) and the header, read and checked; the column mapping read
//! from the header is in the sibling module `columns`.

use std::io::BufRead;
use std::path::{Path, PathBuf};

use rbf_core::record::{self, Columns, HeaderError, PeriodEstimator};

use super::rows::{
    Bounded, CR_ONLY, RowParser, RunError, has_inner_cr, io_or_utf8, missing_columns, read_line_bounded, too_long,
};
use crate::reading::limits::{MAX_COLUMNS, MAX_PREAMBLE_BYTES, bytes};
use crate::reading::sampling;
use crate::text;

/// A run's lines before its data, read and checked.
#[derive(Clone, Debug)]
pub struct RunHeader {
    pub(super) path: PathBuf,
    /// Line number of the header, 1-based.
    pub(super) line_no: usize,
    /// The header line as read (without line end).
    pub(super) line: String,
    pub(super) column_names: Vec<String>,
    /// The header's columns (every axis's).
    pub(super) columns: Columns,
    pub(super) preamble: Vec<String>,
}

/// The header and what its preamble states besides: `# sample_rate_hz`
/// lines (line, Hz), checked against the rows later.
pub(super) struct ReadHeader {
    /// The header.
    pub header: RunHeader,
    /// The stated sample rates.
    pub metadata_rates: Vec<(usize, f64)>,
    /// Whether the preamble says the time column counts samples
    /// (`trainer device record`'s `# time_base`): a long step there is a gap.
    pub counted_time_base: bool,
}

impl RunHeader {
    /// Reads the lines of `source` up to and including the header; `buf`
    /// is left for the data lines' reuse.
    pub(super) fn read(
        path: &Path,
        source: &mut (dyn BufRead + Send),
        buf: &mut Vec<u8>,
    ) -> Result<ReadHeader, RunError> {
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
            let read = read_line_bounded(source, buf).map_err(|e| io_or_utf8(path, line_no, e))?;
            // A compressed file holds any bytes, a carriage return among them:
            // named for what it is before the line ends are judged.
            if line_no == 1
                && let Some((format, tool)) = compressed_format(buf)
            {
                return Err(format_error(
                    line_no,
                    format!("the file is {format}-compressed, not CSV text; decompress it first ({tool})"),
                ));
            }
            // A file with CR-only line ends reads as one line: it would
            // otherwise be "no header", "too long" or thousands of columns.
            if has_inner_cr(buf) {
                return Err(format_error(line_no, CR_ONLY.into()));
            }
            match read {
                Bounded::End => {
                    return Err(format_error(line_no, "no header line: the file has no columns".into()));
                }
                Bounded::TooLong => return Err(format_error(line_no, too_long())),
                Bounded::Line => {}
            }
            let Ok(line) = std::str::from_utf8(buf) else {
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
            let metadata = record::metadata(line);
            counted_time_base |= metadata.is_some_and(|(k, v)| sampling::is_counted_time_base(k, v));
            if let Some(value) = metadata
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
        Ok(ReadHeader {
            header: RunHeader {
                path: path.to_owned(),
                line_no,
                line: header_line,
                column_names,
                columns,
                preamble,
            },
            metadata_rates,
            counted_time_base,
        })
    }

    /// The file being read (`-`: standard input).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The header line as read (without line end).
    pub fn line(&self) -> &str {
        &self.line
    }

    /// Line number of the header, 1-based.
    pub fn line_number(&self) -> usize {
        self.line_no
    }

    /// The lines before the header (metadata, blank lines) as read, without line ends.
    pub fn preamble(&self) -> &[String] {
        &self.preamble
    }

    /// A period estimator primed with this run's metadata (see [`PeriodEstimator`]).
    pub fn period_estimator(&self) -> PeriodEstimator {
        let mut estimator = PeriodEstimator::new();
        self.preamble.iter().for_each(|line| estimator.note_preamble_line(line));
        estimator
    }

    /// A parser of this run's lines by given columns (another axis's, see
    /// [`RunHeader::axis_columns`]): its errors name this file, the line
    /// and the column.
    pub fn row_parser(&self) -> RowParser {
        RowParser {
            path: self.path.clone(),
            column_names: self.column_names.clone(),
        }
    }

    /// An error of this file at `line`.
    pub(super) fn error_at(&self, line: usize, message: String) -> RunError {
        RunError::Format {
            path: self.path.clone(),
            line,
            message,
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
