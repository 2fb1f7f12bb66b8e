//! Row decoding: the data lines of a run taken from its source one at a
//! time, each parsed where it lies in the read buffer (no copy) unless it
//! runs past the buffer's end, blank and comment lines skipped, a refused
//! line's error naming its line and column.

use std::io::BufRead;

use rbf_core::record::{Columns, Row};

use super::header::RunHeader;
use super::rows::{Bounded, CR_ONLY, Line, RunError, classify, has_inner_cr, io_or_utf8, read_line_bounded, too_long};
use crate::reading::limits::MAX_LINE_BYTES;

/// The data lines of a run after its header.
pub(super) struct LineSource {
    source: Box<dyn BufRead + Send>,
    /// The current line's text when it is kept or refused (reused: no
    /// allocation per row).
    line: String,
    /// Bytes of a line that did not lie whole in the read buffer (reused).
    line_bytes: Vec<u8>,
    /// Lines read from the source so far.
    line_no: usize,
}

impl LineSource {
    /// The lines of `source` after line `line_no` (the header's); `line_bytes`
    /// a buffer to reuse.
    pub(super) fn new(source: Box<dyn BufRead + Send>, line_no: usize, line_bytes: Vec<u8>) -> LineSource {
        LineSource {
            source,
            line: String::new(),
            line_bytes,
            line_no,
        }
    }

    /// Lines read from the source so far.
    pub(super) fn line_number(&self) -> usize {
        self.line_no
    }

    /// The text of the last row read with `keep_text` (without line end).
    pub(super) fn text(&self) -> &str {
        &self.line
    }

    /// The source from here on, leaving an empty one (the batch reader takes it).
    pub(super) fn take_source(&mut self) -> Box<dyn BufRead + Send> {
        std::mem::replace(&mut self.source, Box::new(std::io::empty()))
    }

    /// The next data row by `columns`, (line number, row); its text in
    /// [`Self::text`] when `keep_text`. Errors name `header`'s file.
    pub(super) fn next_row(
        &mut self,
        header: &RunHeader,
        columns: &Columns,
        keep_text: bool,
    ) -> Result<Option<(usize, Row)>, RunError> {
        loop {
            self.line_no += 1;
            let buf = self
                .source
                .fill_buf()
                .map_err(|e| io_or_utf8(header.path(), self.line_no, e))?;
            let outcome = match memchr::memchr(b'\n', buf) {
                Some(end) if end <= MAX_LINE_BYTES => {
                    let outcome = classify(columns, buf.get(..end).unwrap_or(&[]), &mut self.line, keep_text);
                    self.source.consume(end + 1);
                    outcome
                }
                Some(_) => {
                    let message = if has_inner_cr(buf.get(..MAX_LINE_BYTES).unwrap_or(buf)) {
                        CR_ONLY.into()
                    } else {
                        too_long()
                    };
                    return Err(header.error_at(self.line_no, message));
                }
                None => {
                    // The line runs past the buffer or ends the file without
                    // a line end: the copying path.
                    let mut bytes = std::mem::take(&mut self.line_bytes);
                    let read = read_line_bounded(self.source.as_mut(), &mut bytes)
                        .map_err(|e| io_or_utf8(header.path(), self.line_no, e));
                    let outcome = match read {
                        Ok(Bounded::End) => {
                            self.line_no -= 1;
                            self.line_bytes = bytes;
                            return Ok(None);
                        }
                        Ok(_) if has_inner_cr(&bytes) => Err(header.error_at(self.line_no, CR_ONLY.into())),
                        Ok(Bounded::TooLong) => Err(header.error_at(self.line_no, too_long())),
                        Ok(Bounded::Line) => Ok(classify(columns, &bytes, &mut self.line, keep_text)),
                        Err(e) => Err(e),
                    };
                    self.line_bytes = bytes;
                    outcome?
                }
            };
            return match outcome {
                Line::Skip => continue,
                Line::NotUtf8 => Err(header.error_at(self.line_no, "line is not valid UTF-8 text".into())),
                Line::Refused(_) if has_inner_cr(self.line.as_bytes()) => {
                    Err(header.error_at(self.line_no, CR_ONLY.into()))
                }
                Line::Refused(e) => Err(header.row_parser().error(self.line_no, &self.line, e)),
                Line::Row(row) => Ok(Some((self.line_no, row))),
            };
        }
    }
}
