//! The data section of a run parsed on every core: the text is read in
//! chunks that end at a line end, each chunk's rows are parsed on a worker
//! thread by [`rbf_core::record`]'s row parser (the one the firmware replay
//! uses, so the values and the refusals are the same), and the chunks are
//! handed back in file order. Line numbers come from counting the line ends
//! of each chunk before it is parsed, so a defect names the same line as
//! the line-by-line reader. At most [`IN_FLIGHT`] chunks are read and not
//! yet consumed: memory stays flat whatever the run's length.

use std::collections::BTreeMap;
use std::io::BufRead;
use std::ops::Range;
use std::sync::mpsc::{Receiver, sync_channel};
use std::sync::{Arc, Mutex};

use rbf_core::GyroSample;
use rbf_core::features::THERMOMETERS;
use rbf_core::record::{self, Columns, Row, RowError};
use rbf_core::thermometer::ThermometerSet;

use crate::reading::limits::MAX_LINE_BYTES;

/// Bytes of text one parsing job takes (a little more: the chunk runs to
/// the next line end).
pub const CHUNK_BYTES: usize = 256 * 1024;
/// Chunks read ahead of the consumer, at most: the bound on memory.
pub const IN_FLIGHT: usize = 8;

/// One data row of a chunk, compact: its thermometer readings lie in
/// [`Batch`]'s `temps` (a whole [`Row`] is four times the size, and a pass
/// moves every row).
#[derive(Clone, Copy, Debug, PartialEq)]
struct ChunkRow {
    line: usize,
    start: u32,
    end: u32,
    time_s: f64,
    rate_dph: f64,
    /// NaN where the run has no `ref_dph` (a parsed value is finite).
    ref_dph: f64,
    temp_fault: bool,
}

/// Why parsing stopped inside a chunk.
#[derive(Clone, Debug, PartialEq)]
pub enum Defect {
    /// The line is longer than [`MAX_LINE_BYTES`].
    TooLong,
    /// The line is not UTF-8 text.
    NotUtf8,
    /// The row parser refused the line.
    Refused(RowError),
}

/// Consecutive rows of a run, in file order, with the text they were parsed from.
#[derive(Debug, Default)]
pub struct Batch {
    /// The chunk's text (lines and their line ends).
    text: Vec<u8>,
    rows: Vec<ChunkRow>,
    /// The thermometer readings of the rows, `stride` per row, in the order
    /// of `temp_a` … `temp_h` among the columns of `thermometers`.
    temps: Vec<f64>,
    thermometers: ThermometerSet,
    stride: usize,
    /// Each row's gyro sample as the firmware receives it ([`GyroSample::from_recorded`]).
    samples: Vec<GyroSample>,
    /// The first defect in the chunk, after the rows: its line, what it is,
    /// and where the line's text lies in `text`.
    defect: Option<(usize, Defect, Range<usize>)>,
    /// Where the batch's buffers go when it is dropped ([`for_each_batch`]'s batches).
    recycler: Option<Arc<Recycler>>,
}

impl Batch {
    /// An empty batch for rows of a run with `columns`.
    pub fn new(columns: &Columns) -> Batch {
        Batch::with_buffers(columns, Vec::new(), Buffers::default())
    }

    /// An empty batch for rows of a run with `columns` in `text` and `buffers`
    /// (emptied, their capacity kept).
    fn with_buffers(columns: &Columns, mut text: Vec<u8>, mut buffers: Buffers) -> Batch {
        let thermometers = columns.thermometers();
        text.clear();
        buffers.rows.clear();
        buffers.temps.clear();
        buffers.samples.clear();
        Batch {
            text,
            rows: buffers.rows,
            temps: buffers.temps,
            thermometers,
            stride: thermometers.len(),
            samples: buffers.samples,
            defect: None,
            recycler: None,
        }
    }

    /// Appends a row read from line `line` whose text (without line end) is `text`.
    pub fn push(&mut self, line: usize, row: &Row, text: &[u8]) {
        let start = self.text.len();
        self.text.extend_from_slice(text);
        self.push_parsed(line, row, start..self.text.len());
        self.text.push(b'\n');
    }

    fn push_parsed(&mut self, line: usize, row: &Row, text: Range<usize>) {
        self.rows.push(ChunkRow {
            line,
            start: text.start as u32,
            end: text.end as u32,
            time_s: row.time_s,
            rate_dph: row.rate_dph,
            ref_dph: row.ref_dph.unwrap_or(f64::NAN),
            temp_fault: row.temp_fault,
        });
        for (i, t) in row.temps_c.iter().enumerate() {
            if self.thermometers.contains(i) {
                self.temps.push(t.unwrap_or(f64::NAN));
            }
        }
    }

    /// Computes the rows' gyro samples, the first one's time step from
    /// `prev_time_s` (the time of the row before the batch).
    fn make_samples(&mut self, prev_time_s: Option<f64>) {
        self.samples.clear();
        self.samples.reserve(self.rows.len());
        let mut prev = prev_time_s;
        for i in 0..self.rows.len() {
            let row = self.row(i);
            self.samples.push(GyroSample::from_recorded(
                prev,
                row.time_s,
                row.rate_dph,
                &row.readings_c(),
            ));
            prev = Some(row.time_s);
        }
    }

    /// Sets the time of the row before the batch (the first row's time step
    /// depends on it; the samples are made without it on the workers).
    pub fn set_previous_time(&mut self, prev_time_s: Option<f64>) {
        if self.samples.len() != self.rows.len() {
            self.make_samples(prev_time_s);
        } else if let (Some(sample), Some(first)) = (self.samples.first_mut(), self.rows.first()) {
            sample.dt_s = rbf_core::compensator::time_step_s(prev_time_s, first.time_s);
        }
    }

    /// The gyro sample of row `i` as the firmware receives it
    /// ([`GyroSample::from_recorded`], the time step from the row before).
    pub fn sample(&self, i: usize) -> GyroSample {
        self.samples.get(i).copied().unwrap_or(GyroSample {
            dt_s: 0.0,
            rate_dph: f32::NAN,
            temps_c: [None; THERMOMETERS],
        })
    }

    /// The rate of row `i`, °/h.
    pub fn rate_dph(&self, i: usize) -> f64 {
        self.rows.get(i).map_or(f64::NAN, |r| r.rate_dph)
    }

    /// The known true rate of row `i`, °/h, where the run has `ref_dph`.
    pub fn ref_dph(&self, i: usize) -> Option<f64> {
        self.rows.get(i).map(|r| r.ref_dph).filter(|r| !r.is_nan())
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when the batch holds no row.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Keeps the first `len` rows.
    pub fn truncate(&mut self, len: usize) {
        self.rows.truncate(len);
        self.samples.truncate(len);
        self.temps.truncate(len * self.stride);
    }

    /// The line number of row `i`, 1-based.
    pub fn line(&self, i: usize) -> usize {
        self.rows.get(i).map_or(0, |r| r.line)
    }

    /// The sample time of row `i`, s.
    pub fn time_s(&self, i: usize) -> f64 {
        self.rows.get(i).map_or(f64::NAN, |r| r.time_s)
    }

    /// Row `i` as the row parser gave it.
    pub fn row(&self, i: usize) -> Row {
        let Some(r) = self.rows.get(i) else {
            return Row {
                time_s: f64::NAN,
                rate_dph: f64::NAN,
                temps_c: [None; THERMOMETERS],
                ref_dph: None,
                temp_fault: false,
            };
        };
        let mut temps_c = [None; THERMOMETERS];
        let mut k = i * self.stride;
        for (j, t) in temps_c.iter_mut().enumerate() {
            if self.thermometers.contains(j) {
                *t = self.temps.get(k).copied();
                k += 1;
            }
        }
        Row {
            time_s: r.time_s,
            rate_dph: r.rate_dph,
            temps_c,
            ref_dph: (!r.ref_dph.is_nan()).then_some(r.ref_dph),
            temp_fault: r.temp_fault,
        }
    }

    /// The text of row `i`'s line, without its line end.
    pub fn line_text(&self, i: usize) -> &[u8] {
        self.rows
            .get(i)
            .and_then(|r| self.text.get(r.start as usize..r.end as usize))
            .unwrap_or(&[])
    }

    /// Takes the defect that stopped parsing in this chunk: its line, what
    /// it is, and the line's text.
    pub fn take_defect(&mut self) -> Option<(usize, Defect, String)> {
        let (line, defect, range) = self.defect.take()?;
        let text = String::from_utf8_lossy(self.text.get(range).unwrap_or(&[])).into_owned();
        Some((line, defect, text))
    }
}

/// A batch's row buffers, kept for the next batch.
#[derive(Debug, Default)]
struct Buffers {
    rows: Vec<ChunkRow>,
    temps: Vec<f64>,
    samples: Vec<GyroSample>,
}

/// The buffers of consumed batches, handed back to the reader (texts) and
/// the parsers (rows): a run's batches reuse a few allocations instead of
/// taking fresh pages for every chunk. Without it the system allocator gave
/// the megabytes of each batch back to the kernel as the consumers freed
/// them on other threads, and faulted them in again for the next.
#[derive(Debug)]
struct Recycler {
    texts: Mutex<Vec<Vec<u8>>>,
    buffers: Mutex<Vec<Buffers>>,
    /// Buffers kept of each kind, at most (the batches alive at once).
    keep: usize,
}

impl Recycler {
    fn new(keep: usize) -> Self {
        Recycler {
            texts: Mutex::new(Vec::new()),
            buffers: Mutex::new(Vec::new()),
            keep,
        }
    }

    /// A text buffer, one used before where there is one (`next_chunk` empties it).
    fn text(&self) -> Vec<u8> {
        self.texts.lock().ok().and_then(|mut t| t.pop()).unwrap_or_default()
    }

    /// Row buffers, one set used before where there is one.
    fn buffers(&self) -> Buffers {
        self.buffers.lock().ok().and_then(|mut b| b.pop()).unwrap_or_default()
    }

    /// Keeps `batch`'s buffers for the batches to come.
    fn give(&self, batch: &mut Batch) {
        if let Ok(mut texts) = self.texts.lock()
            && texts.len() < self.keep
        {
            texts.push(std::mem::take(&mut batch.text));
        }
        if let Ok(mut buffers) = self.buffers.lock()
            && buffers.len() < self.keep
        {
            buffers.push(Buffers {
                rows: std::mem::take(&mut batch.rows),
                temps: std::mem::take(&mut batch.temps),
                samples: std::mem::take(&mut batch.samples),
            });
        }
    }
}

impl Drop for Batch {
    fn drop(&mut self) {
        if let Some(recycler) = self.recycler.take() {
            recycler.give(self);
        }
    }
}

/// A chunk of text ending at a line end (or at the end of the input), and
/// the number of its first line.
struct Chunk {
    seq: usize,
    first_line: usize,
    text: Vec<u8>,
}

/// True for a line the data section skips: blank, or a `#` comment.
fn is_comment_or_blank(line: &[u8]) -> bool {
    let t = record::trim_field_bytes(line);
    t.first().is_none_or(|&b| b == b'#')
}

/// Skips the blanks a field may have around it (those [`record::trim_field_bytes`] trims).
fn skip_blanks(bytes: &[u8]) -> &[u8] {
    match bytes.first() {
        Some(b' ' | b'\t' | b'\r') => skip_blanks(&bytes[1..]),
        _ => bytes,
    }
}

/// One data line by [`Columns::parse_row_bytes`]'s rules, faster: fields
/// that are plain numbers (`fast_float2`, correctly rounded like core's
/// parser) are read where they lie; a line of any other form, or one that
/// breaks a rule, goes to [`Columns::parse_row_bytes`], which gives the
/// value or the error.
pub fn parse_row(columns: &Columns, line: &[u8]) -> Result<Row, RowError> {
    match parse_row_fast(columns, line) {
        Some(row) => Ok(row),
        None => columns.parse_row_bytes(line),
    }
}

/// The fast path of [`parse_row`]: `None` for anything but finite numbers
/// in every field, the right count of fields, and rates in range.
fn parse_row_fast(columns: &Columns, line: &[u8]) -> Option<Row> {
    const FIELDS: usize = 16;
    let mut values = [0.0f64; FIELDS];
    let mut rest = line;
    let mut found = 0;
    loop {
        rest = skip_blanks(rest);
        let (value, len) = fast_float2::parse_partial::<f64, _>(rest).ok()?;
        if !value.is_finite() {
            return None;
        }
        *values.get_mut(found)? = value;
        found += 1;
        rest = skip_blanks(rest.get(len..)?);
        match rest.split_first() {
            None => break,
            Some((b',', tail)) => rest = tail,
            Some(_) => return None,
        }
    }
    if found != columns.count {
        return None;
    }
    columns.row_from_fields(values.get(..found)?)
}

/// Parses the lines of `text` (line `first_line` first) with `columns`,
/// stopping at the first defect; the rules of the line-by-line reader.
pub fn parse_chunk(columns: &Columns, text: Vec<u8>, first_line: usize) -> Batch {
    parse_chunk_into(columns, text, first_line, Buffers::default())
}

/// [`parse_chunk`] into `buffers`.
fn parse_chunk_into(columns: &Columns, text: Vec<u8>, first_line: usize, buffers: Buffers) -> Batch {
    // Lines split at `\n` of valid UTF-8 are valid UTF-8: one check for the
    // chunk, and one per line only when it fails.
    let all_utf8 = std::str::from_utf8(&text).is_ok();
    let mut batch = Batch::with_buffers(columns, Vec::new(), buffers);
    // Room for every line without a reallocation, and no more: capacity
    // the rows never fill still ends up resident as the allocator reuses
    // it at other offsets, so that a long run's resident memory would grow.
    let most_rows = memchr::memchr_iter(b'\n', &text).count() + 1;
    batch.rows.reserve(most_rows);
    batch.temps.reserve(most_rows * batch.stride);
    let mut defect = None;
    let mut pos = 0;
    let mut line = first_line;
    while pos < text.len() {
        let end = memchr::memchr(b'\n', &text[pos..]).map_or(text.len(), |e| pos + e);
        let raw = &text[pos..end];
        if raw.len() > MAX_LINE_BYTES {
            defect = Some((line, Defect::TooLong, pos..end));
            break;
        }
        if !all_utf8 && std::str::from_utf8(raw).is_err() {
            defect = Some((line, Defect::NotUtf8, pos..end));
            break;
        }
        let body = raw.strip_suffix(b"\r").unwrap_or(raw);
        if !is_comment_or_blank(body) {
            let range = pos..pos + body.len();
            match parse_row(columns, body) {
                Ok(row) => batch.push_parsed(line, &row, range),
                Err(e) => {
                    defect = Some((line, Defect::Refused(e), range));
                    break;
                }
            }
        }
        pos = end + 1;
        line += 1;
    }
    batch.text = text;
    batch.defect = defect;
    batch.make_samples(None);
    batch
}

/// Reads the next chunk from `source`: about `chunk_bytes`, cut after the
/// last line end, the rest kept in `carry` for the next; a line without an
/// end past [`MAX_LINE_BYTES`] is handed out whole (the parser refuses it).
/// `None` at the end of the input.
fn next_chunk(
    source: &mut dyn BufRead,
    carry: &mut Vec<u8>,
    chunk_bytes: usize,
    mut buf: Vec<u8>,
) -> std::io::Result<Option<Vec<u8>>> {
    buf.clear();
    buf.reserve(chunk_bytes + carry.len());
    buf.append(carry);
    let mut target = chunk_bytes.max(buf.len() + 1);
    loop {
        let mut at_end = false;
        while buf.len() < target {
            let available = source.fill_buf()?;
            if available.is_empty() {
                at_end = true;
                break;
            }
            let take = available.len().min(target - buf.len());
            buf.extend_from_slice(&available[..take]);
            source.consume(take);
        }
        if at_end {
            return Ok((!buf.is_empty()).then_some(buf));
        }
        match memchr::memrchr(b'\n', &buf) {
            Some(i) => {
                carry.extend_from_slice(&buf[i + 1..]);
                buf.truncate(i + 1);
                return Ok(Some(buf));
            }
            None if buf.len() > MAX_LINE_BYTES => return Ok(Some(buf)),
            None => target += chunk_bytes,
        }
    }
}

/// Parses the rest of `source` (its next line is `first_line`) in chunks
/// of about `chunk_bytes` ([`CHUNK_BYTES`] serves) on `workers` threads and hands the batches to `consume` in file order on
/// this thread; stops at the first error `consume` returns. Read errors
/// come back as `(line, error)`: the line the failed read would have begun.
pub fn for_each_batch<E>(
    source: &mut (dyn BufRead + Send),
    columns: &Columns,
    first_line: usize,
    chunk_bytes: usize,
    workers: usize,
    mut consume: impl FnMut(Batch) -> Result<(), E>,
    io_error: impl FnOnce(usize, std::io::Error) -> E,
) -> Result<(), E> {
    let workers = workers.max(1);
    let (chunk_tx, chunk_rx) = sync_channel::<Chunk>(workers);
    let chunk_rx = Arc::new(Mutex::new(chunk_rx));
    let (parsed_tx, parsed_rx) = sync_channel::<(usize, Batch)>(IN_FLIGHT);
    // One token per chunk in flight: the reader takes one before reading,
    // the consumer gives it back after consuming.
    let (token_tx, token_rx) = sync_channel::<()>(IN_FLIGHT);
    let recycler = Arc::new(Recycler::new(IN_FLIGHT + 2 * workers));
    std::thread::scope(|scope| {
        let reader_recycler = Arc::clone(&recycler);
        let reader = scope.spawn(move || -> Result<(), (usize, std::io::Error)> {
            let mut carry = Vec::new();
            let mut line = first_line;
            for seq in 0.. {
                if token_tx.send(()).is_err() {
                    return Ok(());
                }
                let text = match next_chunk(source, &mut carry, chunk_bytes, reader_recycler.text()) {
                    Ok(Some(text)) => text,
                    Ok(None) => return Ok(()),
                    Err(e) => return Err((line, e)),
                };
                let lines = memchr::memchr_iter(b'\n', &text).count();
                let chunk = Chunk {
                    seq,
                    first_line: line,
                    text,
                };
                line += lines;
                if chunk_tx.send(chunk).is_err() {
                    return Ok(());
                }
            }
            Ok(())
        });
        for _ in 0..workers {
            let chunk_rx = Arc::clone(&chunk_rx);
            let parsed_tx = parsed_tx.clone();
            let recycler = Arc::clone(&recycler);
            scope.spawn(move || {
                loop {
                    let next = chunk_rx.lock().ok().and_then(|rx| rx.recv().ok());
                    let Some(chunk) = next else { return };
                    let mut batch = parse_chunk_into(columns, chunk.text, chunk.first_line, recycler.buffers());
                    batch.recycler = Some(Arc::clone(&recycler));
                    if parsed_tx.send((chunk.seq, batch)).is_err() {
                        return;
                    }
                }
            });
        }
        // Only the workers hold the chunk receiver: when they stop, the reader's sends fail.
        drop(chunk_rx);
        drop(parsed_tx);
        let result = consume_in_order(&parsed_rx, &token_rx, &mut consume);
        // Unblock and stop the reader and the workers whatever happened.
        drop(token_rx);
        drop(parsed_rx);
        let read = reader.join().unwrap_or(Ok(()));
        result?;
        read.map_err(|(line, e)| io_error(line, e))
    })
}

/// Hands the parsed batches to `consume` in sequence order.
fn consume_in_order<E>(
    parsed: &Receiver<(usize, Batch)>,
    tokens: &Receiver<()>,
    consume: &mut impl FnMut(Batch) -> Result<(), E>,
) -> Result<(), E> {
    let mut waiting: BTreeMap<usize, Batch> = BTreeMap::new();
    let mut next = 0;
    loop {
        while let Some(batch) = waiting.remove(&next) {
            let stop = batch.defect.is_some();
            consume(batch)?;
            next += 1;
            let _ = tokens.recv();
            if stop {
                return Ok(());
            }
        }
        match parsed.recv() {
            Ok((seq, batch)) => {
                waiting.insert(seq, batch);
            }
            Err(_) => return Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn columns() -> Columns {
        Columns::from_header("time_s,rate_dph,temp_c").unwrap()
    }

    #[test]
    fn chunks_end_at_line_ends_and_carry_the_rest() {
        let mut text = Vec::new();
        let mut n = 0;
        while text.len() < 3 * CHUNK_BYTES {
            text.extend_from_slice(format!("{n}.5,1.25,20\n").as_bytes());
            n += 1;
        }
        text.extend_from_slice(b"9e9,1,2");
        let mut source: &[u8] = &text;
        let mut carry = Vec::new();
        let mut joined = Vec::new();
        while let Some(chunk) = next_chunk(&mut source, &mut carry, CHUNK_BYTES, Vec::new()).unwrap() {
            assert!(chunk.ends_with(b"\n") || chunk.ends_with(b"9e9,1,2"));
            joined.extend_from_slice(&chunk);
        }
        assert_eq!(joined, text);
    }

    #[test]
    fn a_line_past_the_limit_is_refused_at_its_line() {
        let mut text = b"0,1,2\n\n".to_vec();
        text.extend(std::iter::repeat_n(b'1', MAX_LINE_BYTES + 1));
        let batch = parse_chunk(&columns(), text, 10);
        assert_eq!(batch.len(), 1);
        assert_eq!(
            batch.defect.clone().map(|(line, d, _)| (line, d)),
            Some((12, Defect::TooLong))
        );
    }

    #[test]
    fn rows_keep_their_text_without_line_ends() {
        let batch = parse_chunk(&columns(), b"# c\r\n0, 1 ,2\r\n\n1,2,3".to_vec(), 4);
        let lines: Vec<(usize, &[u8])> = (0..batch.len()).map(|i| (batch.line(i), batch.line_text(i))).collect();
        assert_eq!(lines, [(5, &b"0, 1 ,2"[..]), (7, &b"1,2,3"[..])]);
        assert!(batch.defect.is_none());
    }

    #[test]
    fn the_fast_row_parser_agrees_with_the_shared_one_on_every_form() {
        let columns = Columns::from_header("time_s,rate_dph,temp_c,ref_dph").unwrap();
        let forms = [
            "1",
            "1.",
            ".5",
            "+3",
            "-0",
            "1e5",
            "1E-3",
            "2.5e+2",
            "0x1",
            "1_0",
            "inf",
            "NaN",
            " 2 ",
            "\t7\t",
            "1e",
            "e1",
            "..",
            "-",
            "",
            "4e6",
            "3600000",
            "-3600000.0000001",
            "0.1000000000000000055511151231257827",
            "123456789012345678901234567890",
            "1e-400",
            "1e400",
            "١",
        ];
        for a in forms {
            for b in forms {
                let line = format!("{a},{b},20.5,{b}");
                assert_eq!(
                    parse_row(&columns, line.as_bytes()),
                    columns.parse_row_bytes(line.as_bytes()),
                    "{line}"
                );
            }
        }
    }

    /// A field as recorders write it, or one of the forms around it.
    fn field() -> impl proptest::strategy::Strategy<Value = String> {
        use proptest::prelude::*;
        let number = prop_oneof![
            4 => "[+-]?[0-9]{0,20}(\\.[0-9]{0,25})?",
            2 => "[+-]?[0-9]{1,3}(\\.[0-9]{1,8})?[eE][+-]?[0-9]{1,3}",
            1 => "[0-9a-zA-Z.+\\-_]{0,8}",
            1 => prop::sample::select(vec!["inf", "-infinity", "NaN", "9007199254740993", "1e400", ".", "+.5", "5."])
                .prop_map(str::to_owned),
        ];
        ("[ \t]{0,2}", number, "[ \t\r]{0,2}").prop_map(|(before, n, after)| format!("{before}{n}{after}"))
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 20_000,
            failure_persistence: None,
            ..proptest::test_runner::Config::default()
        })]

        /// The host reader's fast path (`fast_float2`, numbers read where they
        /// lie) gives every row, value and error that rbf-core's one decimal
        /// parser and row parser give, the path the firmware's replay runs.
        #[test]
        fn the_host_fast_path_reads_every_line_as_rbf_core_does(
            fields in proptest::collection::vec(field(), 4),
        ) {
            let columns = Columns::from_header("time_s,rate_dph,temp_c,ref_dph").unwrap();
            let line = fields.join(",");
            proptest::prop_assert_eq!(
                parse_row(&columns, line.as_bytes()),
                columns.parse_row_bytes(line.as_bytes()),
                "{:?}", line
            );
            // Field by field: where the fast path reads a whole field as a
            // finite number, it is rbf-core's value to the bit.
            for f in &fields {
                let trimmed = skip_blanks(f.as_bytes());
                if let Ok((value, len)) = fast_float2::parse_partial::<f64, _>(trimmed)
                    && value.is_finite()
                    && skip_blanks(&trimmed[len..]).is_empty()
                {
                    let shared = rbf_core::record::parse_f64_bytes(rbf_core::record::trim_field_bytes(f.as_bytes()));
                    proptest::prop_assert_eq!(shared.map(f64::to_bits), Some(value.to_bits()), "{:?}", f);
                }
            }
        }
    }
}
