//! Row-level parsing of the recorded-run CSV (`docs/recorded-run-format.md`).
//!
//! `no_std` so that the trainer and the firmware's replay board parse runs with
//! the same code. File handling, line numbering and error messages with file
//! names live with the callers; this module maps header names to columns and
//! turns one data line into numbers, never panicking.

use crate::thermometer::{LOOP_THERMOMETER, THERMOMETERS, ThermometerSet};

/// Column names the format defines.
pub mod column {
    /// Sample time, s.
    pub const TIME_S: &str = "time_s";
    /// Gyro output, °/h.
    pub const RATE_DPH: &str = "rate_dph";
    /// Fiber-loop temperature, °C (thermometer c of a multi-point run).
    pub const TEMP_C: &str = "temp_c";
    /// Thermometers of multi-point runs, °C, in index order; `temp_c` is the fiber loop's.
    pub const THERMOMETERS: [&str; crate::thermometer::THERMOMETERS] = [
        "temp_a", "temp_b", TEMP_C, "temp_d", "temp_e", "temp_f", "temp_g", "temp_h",
    ];
    /// Known true rate, °/h.
    pub const REF_DPH: &str = "ref_dph";
    /// Replay-only: 1 = the temperature sensor fails on this sample.
    pub const TEMP_FAULT: &str = "temp_fault";
    /// Per-axis gyro outputs of a multi-axis run, °/h, in [`crate::axis::Axis`] order.
    pub const AXIS_RATES_DPH: [&str; 3] = [
        crate::axis::Axis::X.rate_column(),
        crate::axis::Axis::Y.rate_column(),
        crate::axis::Axis::Z.rate_column(),
    ];
    /// Per-axis fiber-loop thermometers, °C (absent: `temp_c` serves the axis).
    pub const AXIS_TEMPS_C: [&str; 3] = ["temp_x_c", "temp_y_c", "temp_z_c"];
    /// Per-axis known true rates, °/h.
    pub const AXIS_REFS_DPH: [&str; 3] = ["ref_x_dph", "ref_y_dph", "ref_z_dph"];
}

pub use crate::axis::{Axis, MAX_AXES};

/// Where one axis's columns sit in a multi-axis header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AxisColumns {
    /// Index of `rate_<axis>_dph`.
    pub rate_dph: usize,
    /// Index of the axis's loop thermometer: `temp_<axis>_c`, else `temp_c`, if either exists.
    pub temp_c: Option<usize>,
    /// Index of `ref_<axis>_dph`, if present.
    pub ref_dph: Option<usize>,
}

/// Where the known columns sit in a header.
///
/// A multi-axis header is read one axis at a time: [`Columns::for_axis`]
/// maps the axis's rate, loop thermometer and reference onto `rate_dph`,
/// `temps[2]` (`temp_c`) and `ref_dph`, so every single-axis path (row
/// parsing, features, compensation) serves each axis unchanged.
/// [`Columns::from_header`] gives the first axis present.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Columns {
    /// Index of `time_s`.
    pub time_s: usize,
    /// Index of `rate_dph` (multi-axis: of the selected axis's rate).
    pub rate_dph: usize,
    /// Indices of `temp_a` … `temp_h`, where present (index 2 is `temp_c`;
    /// multi-axis: the selected axis's loop thermometer).
    pub temps: [Option<usize>; THERMOMETERS],
    /// Index of `ref_dph` (multi-axis: of `ref_<axis>_dph`), if present.
    pub ref_dph: Option<usize>,
    /// The axes of a multi-axis run (all `None` in a single-axis run).
    pub axes: [Option<AxisColumns>; MAX_AXES],
    /// The axis these columns read (`None` in a single-axis run).
    pub axis: Option<Axis>,
    /// Index of `temp_fault`, if present.
    pub temp_fault: Option<usize>,
    /// Number of columns every data row must have.
    pub count: usize,
}

/// What is wrong with a header line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum HeaderError {
    /// A required column is absent.
    MissingColumn(&'static str),
    /// A known column appears twice (at this index the second time).
    DuplicateColumn(usize),
    /// The header has both `rate_dph` and the per-axis rate at this index.
    MixedAxes(usize),
}

/// What is wrong with a data row.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum RowErrorKind {
    /// The row has a different number of fields than the header.
    FieldCount {
        /// Fields in the header.
        expected: usize,
        /// Fields in this row.
        found: usize,
    },
    /// The field is not a number.
    NotANumber,
    /// The field is NaN or infinite.
    NonFinite,
    /// `temp_fault` is neither 0 nor 1.
    NotAFlag,
    /// A rate (`rate_dph`, `ref_dph`) beyond [`MAX_ABS_RATE_DPH`].
    OverRange,
}

/// Largest |rate| a run may hold in `rate_dph` or `ref_dph`, °/h: the
/// compensator's plausible-rate limit, one number for both.
pub use crate::compensator::MAX_ABS_RATE_DPH;

/// True when `rate_dph` lies within ±[`MAX_ABS_RATE_DPH`].
fn rate_in_range(rate_dph: f64) -> bool {
    rate_dph.abs() <= MAX_ABS_RATE_DPH
}

/// A row error and the 0-based column index it concerns (None: the whole row).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowError {
    /// Column index the error concerns, if one.
    pub column: Option<usize>,
    /// What is wrong.
    pub kind: RowErrorKind,
}

/// The known values of one data row.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Row {
    /// Sample time, s.
    pub time_s: f64,
    /// Gyro output, °/h.
    pub rate_dph: f64,
    /// Thermometers `temp_a` … `temp_h`, °C, where the columns exist.
    pub temps_c: [Option<f64>; THERMOMETERS],
    /// Known true rate, °/h, if the column exists.
    pub ref_dph: Option<f64>,
    /// The sensor is to fail on this sample (replay).
    pub temp_fault: bool,
}

impl Row {
    /// Loop temperature (`temp_c`), °C, if the column exists.
    pub fn temp_c(&self) -> Option<f64> {
        self.temps_c[LOOP_THERMOMETER]
    }

    /// The thermometer readings the sensors give for this row: the values,
    /// or none at all where `temp_fault` says they fail (replay).
    pub fn readings_c(&self) -> [Option<f64>; THERMOMETERS] {
        if self.temp_fault {
            [None; THERMOMETERS]
        } else {
            self.temps_c
        }
    }
}

/// Trims spaces, tabs and a trailing carriage return.
pub fn trim_field(s: &str) -> &str {
    let (start, end) = trimmed_bounds(s.as_bytes());
    // The bounds sit next to ASCII bytes, so they are char boundaries.
    s.get(start..end).unwrap_or("")
}

/// [`trim_field`] on bytes.
pub fn trim_field_bytes(s: &[u8]) -> &[u8] {
    let (start, end) = trimmed_bounds(s);
    s.get(start..end).unwrap_or(&[])
}

/// Start and end of `s` without leading and trailing spaces, tabs and CRs.
fn trimmed_bounds(s: &[u8]) -> (usize, usize) {
    let blank = |b: &u8| *b == b' ' || *b == b'\t' || *b == b'\r';
    let start = s.iter().position(|b| !blank(b)).unwrap_or(s.len());
    let end = s.iter().rposition(|b| !blank(b)).map_or(start, |e| e + 1);
    (start, end)
}

/// Powers of ten exactly representable in f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20,
    1e21, 1e22,
];

/// Parses a number exactly as `str::parse::<f64>` does (the same value for
/// every input, errors included), faster for the form recorded runs use:
/// `[+-]digits[.digits]` whose digits make an integer m ≤ 2^53 with at most
/// 22 after the point is m / 10^k, both exact in f64, so the one IEEE
/// division is the correctly rounded value (Clinger's fast path). Anything
/// else goes to core's parser.
pub fn parse_f64(text: &str) -> Result<f64, core::num::ParseFloatError> {
    match fast_decimal(text.as_bytes()) {
        Some(v) => Ok(v),
        None => text.parse(),
    }
}

/// [`parse_f64`] of a field's bytes; `None` for anything that is not a
/// number (including bytes that are not UTF-8).
pub fn parse_f64_bytes(bytes: &[u8]) -> Option<f64> {
    fast_decimal(bytes).or_else(|| core::str::from_utf8(bytes).ok()?.parse().ok())
}

/// The leading `[+-]digits[.digits]` of `bytes`, with the number of bytes
/// it spans: the one decimal parser of recorded runs (a whole field by
/// [`parse_f64`], a field where it lies in a row by the one-pass row
/// parser). `None` where the rule does not give the exact value (no digit,
/// more than 15 digits). At most 15 digits:
/// 10^15 < 2^53, so the mantissa needs no overflow check.
fn fast_decimal_prefix(bytes: &[u8]) -> Option<(f64, usize)> {
    let (negative, sign_len) = match bytes.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    };
    const MAX_DIGITS: usize = 15;
    let mut mantissa: u64 = 0;
    let (mut digit_count, mut fraction_digits, mut seen_point) = (0usize, 0usize, false);
    let mut len = sign_len;
    for &b in bytes.get(sign_len..).unwrap_or(&[]) {
        let d = b.wrapping_sub(b'0');
        if d < 10 {
            mantissa = mantissa * 10 + u64::from(d);
            digit_count += 1;
            fraction_digits += usize::from(seen_point);
            if digit_count > MAX_DIGITS {
                return None;
            }
        } else if b == b'.' && !seen_point {
            seen_point = true;
        } else {
            break;
        }
        len += 1;
    }
    if digit_count == 0 {
        return None;
    }
    let &scale = POW10.get(fraction_digits)?;
    let value = mantissa as f64 / scale;
    Some((if negative { -value } else { value }, len))
}

/// The fast path of [`parse_f64`]: `Some` only where the whole of `bytes`
/// is one decimal [`fast_decimal_prefix`] reads exactly.
fn fast_decimal(bytes: &[u8]) -> Option<f64> {
    match fast_decimal_prefix(bytes)? {
        (value, len) if len == bytes.len() => Some(value),
        _ => None,
    }
}

/// A metadata line (`# ...`), blank line, or data/header line.
pub fn is_comment_or_blank(line: &str) -> bool {
    let t = trim_field(line);
    t.is_empty() || t.starts_with('#')
}

/// Parses a `# key: value` metadata line into (key, value).
pub fn metadata(line: &str) -> Option<(&str, &str)> {
    let rest = trim_field(line).strip_prefix('#')?;
    let (key, value) = rest.split_once(':')?;
    Some((trim_field(key), trim_field(value)))
}

/// Time steps used to estimate the nominal sample period without metadata.
pub const PERIOD_ESTIMATE_STEPS: usize = 1000;

/// The nominal sample period of a run, s: `1 / sample_rate_hz` when the
/// metadata gives a positive rate, else the median (upper median for an even
/// count) of the first [`PERIOD_ESTIMATE_STEPS`] time steps, else 1 s.
///
/// `steps` is sorted in place. Trainer and firmware replay both call this, so
/// they draw segment gaps at the same places.
pub fn nominal_period_s(metadata_rate_hz: Option<f64>, steps: &mut [f64]) -> f64 {
    if let Some(rate) = metadata_rate_hz.filter(|r| r.is_finite() && *r > 0.0) {
        return 1.0 / rate;
    }
    if steps.is_empty() {
        return 1.0;
    }
    steps.sort_unstable_by(f64::total_cmp);
    steps[steps.len() / 2]
}

/// Collects what the nominal-period rule needs while a run is read: the first
/// positive `# sample_rate_hz` before the header and the first
/// [`PERIOD_ESTIMATE_STEPS`] time steps. The trainer and the firmware replay
/// both use it, so they agree on segment gaps for any file.
#[derive(Clone, Debug, Default)]
pub struct PeriodEstimator {
    metadata_rate_hz: Option<f64>,
    prev_time_s: Option<f64>,
    steps: heapless::Vec<f64, PERIOD_ESTIMATE_STEPS>,
}

impl PeriodEstimator {
    /// Nothing seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A line before the header; the first positive `sample_rate_hz` counts.
    pub fn note_preamble_line(&mut self, line: &str) {
        if self.metadata_rate_hz.is_none() {
            self.metadata_rate_hz = metadata_sample_rate_hz(line).filter(|r| r.is_finite() && *r > 0.0);
        }
    }

    /// A data row's time; `true` once no further rows are needed.
    pub fn push_time(&mut self, time_s: f64) -> bool {
        if let Some(prev) = self.prev_time_s {
            let _ = self.steps.push(time_s - prev);
        }
        self.prev_time_s = Some(time_s);
        self.is_complete()
    }

    /// True when the rows read so far settle the period.
    pub fn is_complete(&self) -> bool {
        self.metadata_rate_hz.is_some() || self.steps.is_full()
    }

    /// The nominal period by [`nominal_period_s`], s.
    pub fn period_s(&mut self) -> f64 {
        nominal_period_s(self.metadata_rate_hz, &mut self.steps)
    }
}

/// The `sample_rate_hz` metadata value of a `# key: value` line, if it is one.
pub fn metadata_sample_rate_hz(line: &str) -> Option<f64> {
    metadata(line)
        .filter(|(k, _)| *k == "sample_rate_hz")
        .and_then(|(_, v)| v.parse().ok())
}

/// Names of the columns `compensate` appends, with their leading comma.
pub const COMPENSATED_COLUMNS: &str = ",bias_dph,rate_comp_dph,flags";

/// Writes the header of a compensated output: the input header as read,
/// then per axis present `bias_<axis>_dph`, `rate_comp_<axis>_dph`,
/// `flags_<axis>` (a single-axis run: [`COMPENSATED_COLUMNS`]), and a `\n`.
pub fn write_compensated_header<W: core::fmt::Write>(
    out: &mut W,
    input_header: &str,
    columns: &Columns,
) -> core::fmt::Result {
    out.write_str(input_header)?;
    if !columns.is_multi_axis() {
        out.write_str(COMPENSATED_COLUMNS)?;
    }
    for axis in columns.axes_present() {
        let a = axis.name();
        write!(out, ",bias_{a}_dph,rate_comp_{a}_dph,flags_{a}")?;
    }
    out.write_char('\n')
}

/// Writes one compensated output row of a run with one or more axes: the input line as
/// read, then `bias`, `rate_comp` and `flags` of each sample in axis order (f32 shortest
/// round-trip decimal), and a `\n`. The firmware replay writes rows with this; the trainer's
/// byte-buffer twin (`trainer::evaluation::compensate::push_compensated_row`) is tested against it.
pub fn write_compensated_row<W: core::fmt::Write>(
    out: &mut W,
    input_line: &str,
    samples: &[crate::CompensatedSample],
) -> core::fmt::Result {
    out.write_str(input_line)?;
    for s in samples {
        write!(out, ",{},{},{}", s.bias_dph, s.rate_comp_dph, s.flags.bits())?;
    }
    out.write_char('\n')
}

impl Columns {
    /// Maps a header line (a leading UTF-8 BOM is allowed) to column indices.
    ///
    /// A run has `rate_dph` (one axis) or one to three of `rate_x_dph`,
    /// `rate_y_dph`, `rate_z_dph`, never both; a multi-axis header maps to
    /// its first axis present (see [`Columns::for_axis`]).
    pub fn from_header(line: &str) -> Result<Columns, HeaderError> {
        let line = line.strip_prefix('\u{feff}').unwrap_or(line);
        let (mut time_s, mut rate_dph, mut ref_dph, mut temp_fault) = (None, None, None, None);
        let mut temps = [None; THERMOMETERS];
        let (mut axis_rates, mut axis_temps, mut axis_refs) = ([None; MAX_AXES], [None; MAX_AXES], [None; MAX_AXES]);
        let mut count = 0;
        for (i, name) in line.split(',').enumerate() {
            count = i + 1;
            let name = trim_field(name);
            let in_list = |list: &[&str; MAX_AXES]| list.iter().position(|t| *t == name);
            let slot = match name {
                column::TIME_S => &mut time_s,
                column::RATE_DPH => &mut rate_dph,
                column::REF_DPH => &mut ref_dph,
                column::TEMP_FAULT => &mut temp_fault,
                _ => match column::THERMOMETERS.iter().position(|t| *t == name) {
                    Some(k) => &mut temps[k],
                    None => match (
                        in_list(&column::AXIS_RATES_DPH),
                        in_list(&column::AXIS_TEMPS_C),
                        in_list(&column::AXIS_REFS_DPH),
                    ) {
                        (Some(k), _, _) => &mut axis_rates[k],
                        (_, Some(k), _) => &mut axis_temps[k],
                        (_, _, Some(k)) => &mut axis_refs[k],
                        _ => continue,
                    },
                },
            };
            if slot.replace(i).is_some() {
                return Err(HeaderError::DuplicateColumn(i));
            }
        }
        let time_s = time_s.ok_or(HeaderError::MissingColumn(column::TIME_S))?;
        let mut axes = [None; MAX_AXES];
        for (k, axis) in axes.iter_mut().enumerate() {
            *axis = axis_rates[k].map(|rate_dph| AxisColumns {
                rate_dph,
                temp_c: axis_temps[k].or(temps[LOOP_THERMOMETER]),
                ref_dph: axis_refs[k],
            });
        }
        let single = Columns {
            time_s,
            rate_dph: 0,
            temps,
            ref_dph,
            axes: [None; MAX_AXES],
            axis: None,
            temp_fault,
            count,
        };
        match (rate_dph, axis_rates.iter().flatten().min()) {
            (Some(_), Some(&per_axis)) => Err(HeaderError::MixedAxes(per_axis)),
            (Some(rate_dph), None) => Ok(Columns { rate_dph, ..single }),
            (None, Some(_)) => {
                let multi = Columns { axes, ..single };
                let first = multi.axes_present().next();
                first
                    .and_then(|a| multi.for_axis(a))
                    .ok_or(HeaderError::MissingColumn(column::RATE_DPH))
            }
            (None, None) => Err(HeaderError::MissingColumn(column::RATE_DPH)),
        }
    }

    /// True when the run carries per-axis rates (`rate_x_dph` …) rather than `rate_dph`.
    pub fn is_multi_axis(&self) -> bool {
        self.axes.iter().any(Option::is_some)
    }

    /// The axes of a multi-axis run, in x, y, z order (none for a single-axis run).
    pub fn axes_present(&self) -> impl Iterator<Item = Axis> + '_ {
        Axis::ALL.into_iter().filter(|a| self.axes[a.index()].is_some())
    }

    /// The columns that read `axis` of a multi-axis run as a single-axis
    /// run: its rate as `rate_dph`, its loop thermometer as `temp_c`, its
    /// reference as `ref_dph`; `None` when the run has no such axis.
    pub fn for_axis(&self, axis: Axis) -> Option<Columns> {
        let a = self.axes[axis.index()]?;
        let mut temps = self.temps;
        temps[LOOP_THERMOMETER] = a.temp_c;
        Some(Columns {
            rate_dph: a.rate_dph,
            temps,
            ref_dph: a.ref_dph,
            axis: Some(axis),
            ..*self
        })
    }

    /// Index of `temp_c` (the fiber-loop temperature), if present.
    pub fn temp_c(&self) -> Option<usize> {
        self.temps[LOOP_THERMOMETER]
    }

    /// The thermometers present (thermometer i when `temps[i]` exists).
    pub fn thermometers(&self) -> ThermometerSet {
        let mut set = ThermometerSet::EMPTY;
        for (i, t) in self.temps.iter().enumerate() {
            if t.is_some() {
                set.insert(i);
            }
        }
        set
    }

    /// One pass over a row whose fields are all plain decimals (what every
    /// recorder writes): each number parsed where it lies, blanks around it
    /// skipped, the same values as the general path. `None` sends the row to
    /// the general path (other number forms, text columns, errors).
    fn parse_row_fast(&self, line: &[u8]) -> Option<Row> {
        // Up to 16: a multi-point run has 11 (time, rate, ref, temp_a … temp_h).
        const FIELDS: usize = 16;
        let mut values = [0.0f64; FIELDS];
        let blank = |b: &u8| *b == b' ' || *b == b'\t' || *b == b'\r';
        let mut rest = line;
        let mut found = 0;
        loop {
            let start = rest.iter().position(|b| !blank(b)).unwrap_or(rest.len());
            rest = rest.get(start..)?;
            let (value, len) = fast_decimal_prefix(rest)?;
            *values.get_mut(found)? = value;
            found += 1;
            rest = rest.get(len..)?;
            let end = rest.iter().position(|b| !blank(b)).unwrap_or(rest.len());
            rest = rest.get(end..)?;
            match rest.split_first() {
                None => break,
                Some((b',', tail)) => rest = tail,
                Some(_) => return None,
            }
        }
        if found != self.count {
            return None;
        }
        self.row_from_fields(values.get(..found)?)
    }

    /// The row of a line whose fields were all parsed as finite numbers, in
    /// column order: `None` when a rate or reference is out of range or
    /// `temp_fault` is neither 0 nor 1 (the general path says why). The fast
    /// paths of this reader and of the trainer's parallel one share it.
    pub fn row_from_fields(&self, values: &[f64]) -> Option<Row> {
        let at = |i: usize| values.get(i).copied();
        let optional = |i: Option<usize>| match i {
            Some(i) => at(i).map(Some),
            None => Some(None),
        };
        let temp_fault = match optional(self.temp_fault)? {
            None => false,
            Some(0.0) => false,
            Some(1.0) => true,
            Some(_) => return None,
        };
        let mut temps_c = [None; THERMOMETERS];
        for (t, &c) in temps_c.iter_mut().zip(&self.temps) {
            *t = optional(c)?;
        }
        let rate_dph = at(self.rate_dph).filter(|r| rate_in_range(*r))?;
        let ref_dph = optional(self.ref_dph)?;
        if !ref_dph.is_none_or(rate_in_range) {
            return None;
        }
        Some(Row {
            time_s: at(self.time_s)?,
            rate_dph,
            temps_c,
            ref_dph,
            temp_fault,
        })
    }

    /// Parses one data line (trailing `\r` allowed).
    pub fn parse_row(&self, line: &str) -> Result<Row, RowError> {
        self.parse_row_bytes(line.as_bytes())
    }

    /// [`Self::parse_row`] on the line's bytes (the streaming reader's path:
    /// no UTF-8 check, a number is ASCII or an error anyway).
    pub fn parse_row_bytes(&self, line: &[u8]) -> Result<Row, RowError> {
        match self.parse_row_fast(line) {
            Some(row) => Ok(row),
            None => self.parse_row_general(line),
        }
    }

    /// Any row: fields split at commas, trimmed, parsed by [`parse_f64_bytes`];
    /// the errors name the column.
    fn parse_row_general(&self, line: &[u8]) -> Result<Row, RowError> {
        // Fields between commas: the first few kept by index in one scan
        // (every file this project writes has 3 to 5 columns), the wanted
        // ones picked from a wider layout in a second scan.
        const DIRECT: usize = 8;
        let mut direct: [&[u8]; DIRECT] = [b""; DIRECT];
        let mut found = 0;
        for field in line.split(|&b| b == b',') {
            if let Some(slot) = direct.get_mut(found) {
                *slot = field;
            }
            found += 1;
        }
        if found != self.count {
            return Err(RowError {
                column: None,
                kind: RowErrorKind::FieldCount {
                    expected: self.count,
                    found,
                },
            });
        }
        // time, rate, ref, fault, then the thermometers.
        const WANTED: usize = 4 + THERMOMETERS;
        let mut wanted = [None; WANTED];
        wanted[..4].copy_from_slice(&[Some(self.time_s), Some(self.rate_dph), self.ref_dph, self.temp_fault]);
        wanted[4..].copy_from_slice(&self.temps);
        let mut fields: [&[u8]; WANTED] = [b""; WANTED];
        if found <= DIRECT {
            for (slot, want) in fields.iter_mut().zip(wanted) {
                if let Some(field) = want.and_then(|i| direct.get(i)) {
                    *slot = field;
                }
            }
        } else {
            for (i, field) in line.split(|&b| b == b',').enumerate() {
                for (slot, want) in fields.iter_mut().zip(wanted) {
                    if want == Some(i) {
                        *slot = field;
                    }
                }
            }
        }
        let number = |index: usize, text: &[u8]| -> Result<f64, RowError> {
            let v: f64 = parse_f64_bytes(trim_field_bytes(text)).ok_or(RowError {
                column: Some(index),
                kind: RowErrorKind::NotANumber,
            })?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(RowError {
                    column: Some(index),
                    kind: RowErrorKind::NonFinite,
                })
            }
        };
        let optional = |index: Option<usize>, text: &[u8]| index.map(|i| number(i, text)).transpose();
        let in_range = |index: Option<usize>, v: Option<f64>| match v {
            Some(r) if !rate_in_range(r) => Err(RowError {
                column: index,
                kind: RowErrorKind::OverRange,
            }),
            _ => Ok(v),
        };
        let temp_fault = match optional(self.temp_fault, fields[3])? {
            None => false,
            Some(0.0) => false,
            Some(1.0) => true,
            Some(_) => {
                return Err(RowError {
                    column: self.temp_fault,
                    kind: RowErrorKind::NotAFlag,
                });
            }
        };
        let mut temps_c = [None; THERMOMETERS];
        for ((t, &c), text) in temps_c.iter_mut().zip(&self.temps).zip(&fields[4..]) {
            *t = optional(c, text)?;
        }
        let time_s = number(self.time_s, fields[0])?;
        let rate_dph = number(self.rate_dph, fields[1])?;
        in_range(Some(self.rate_dph), Some(rate_dph))?;
        let ref_dph = in_range(self.ref_dph, optional(self.ref_dph, fields[2])?)?;
        Ok(Row {
            time_s,
            rate_dph,
            temps_c,
            ref_dph,
            temp_fault,
        })
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    #[test]
    fn the_one_pass_row_parser_agrees_with_the_general_one_bit_for_bit() {
        let c = Columns::from_header("time_s, rate_dph ,temp_c,ref_dph,temp_fault").unwrap();
        let fields = [
            "0",
            "1",
            "-0",
            "+2.5",
            " 3.25 ",
            "\t-7.125\r",
            "10.04450",
            "0.0000001",
            "123456789012345",
            "1234567890123456",
            ".5",
            "5.",
            "-.5",
            "1e3",
            "1.2.3",
            "",
            " ",
            "x",
            "inf",
            "nan",
            "1,",
        ];
        let (mut fast, mut checked) = (0, 0);
        for (k, a) in fields.iter().enumerate() {
            for b in fields.iter().skip(k % 3).step_by(2) {
                for flag in ["0", "1", "2", " 1.0"] {
                    let line = format!("{a},{b},20.5,{a},{flag}");
                    let general = c.parse_row_general(line.as_bytes());
                    if let Some(row) = c.parse_row_fast(line.as_bytes()) {
                        let Ok(g) = general else {
                            panic!("{line:?}: fast path accepted what the general path refuses");
                        };
                        let bits = |r: Row| {
                            (
                                r.time_s.to_bits(),
                                r.rate_dph.to_bits(),
                                r.ref_dph.map(f64::to_bits),
                                r.temp_fault,
                            )
                        };
                        assert_eq!(bits(row), bits(g), "{line:?}");
                        fast += 1;
                    }
                    // Refused rows are refused the same way, whichever path saw them first.
                    if let Err(e) = general {
                        assert_eq!(c.parse_row(&line), Err(e), "{line:?}");
                    }
                    checked += 1;
                }
            }
        }
        assert!(
            fast > 100 && fast < checked,
            "{fast} of {checked} rows took the fast path"
        );
    }

    #[test]
    fn wide_layouts_pick_the_known_columns_wherever_they_are() {
        let header = "a,b,c,d,e,f,g,h,temp_c,i,time_s,rate_dph";
        let c = Columns::from_header(header).unwrap();
        let row = c.parse_row("x,x,x,x,x,x,x,x,21.5,x,3.25,-7").unwrap();
        assert_eq!((row.time_s, row.rate_dph, row.temp_c()), (3.25, -7.0, Some(21.5)));
        let err = c.parse_row("x,x,x,x,x,x,x,x,21.5,x,3.25").unwrap_err();
        assert_eq!(
            err.kind,
            RowErrorKind::FieldCount {
                expected: 12,
                found: 11
            }
        );
    }

    #[test]
    fn thermometer_columns_parse_alike_on_both_paths_and_name_a_bad_one() {
        let c = Columns::from_header("time_s,rate_dph,ref_dph,temp_a,temp_b,temp_c,temp_d,temp_e,temp_f,temp_g,temp_h")
            .unwrap();
        assert_eq!((c.thermometers(), c.temp_c()), (ThermometerSet::ALL, Some(5)));
        let line = "1,2,3,20.5,21,22,23,24,25,26,27.25";
        let fast = c.parse_row_fast(line.as_bytes()).unwrap();
        assert_eq!(Ok(fast), c.parse_row_general(line.as_bytes()));
        assert_eq!(
            fast.temps_c,
            [20.5, 21.0, 22.0, 23.0, 24.0, 25.0, 26.0, 27.25].map(Some)
        );
        assert_eq!(fast.temp_c(), Some(22.0));
        assert_eq!(
            c.parse_row("1,2,3,20.5,21,22,23,x,25,26,27"),
            Err(RowError {
                column: Some(7),
                kind: RowErrorKind::NotANumber
            })
        );
        let some = Columns::from_header("temp_h,time_s,temp_b,rate_dph").unwrap();
        assert_eq!(some.thermometers().bits(), 0b1000_0010);
        let row = some.parse_row("30,1,20,5").unwrap();
        assert_eq!(
            (row.temps_c[7], row.temps_c[1], row.temp_c()),
            (Some(30.0), Some(20.0), None)
        );
    }

    #[test]
    fn fields_are_trimmed_of_blanks_only_text_and_bytes_alike() {
        for (raw, want) in [
            (" \t1.5 \r", "1.5"),
            ("  é x ", "é x"),
            (" \t\r", ""),
            ("", ""),
            ("a", "a"),
        ] {
            assert_eq!(trim_field(raw), want, "{raw:?}");
            assert_eq!(trim_field_bytes(raw.as_bytes()), want.as_bytes(), "{raw:?}");
        }
    }

    #[test]
    fn header_maps_known_columns_in_any_order_and_ignores_others() {
        let c = Columns::from_header("\u{feff}temp_c, extra ,time_s,rate_dph\r").unwrap();
        assert_eq!(
            (c.time_s, c.rate_dph, c.temp_c(), c.ref_dph, c.count),
            (2, 3, Some(0), None, 4)
        );
        assert_eq!(
            Columns::from_header("time_s,temp_c"),
            Err(HeaderError::MissingColumn("rate_dph"))
        );
        assert_eq!(
            Columns::from_header("time_s,rate_dph,time_s"),
            Err(HeaderError::DuplicateColumn(2))
        );
    }

    #[test]
    fn a_multi_axis_header_reads_each_axis_as_a_single_axis_run() {
        let header = "time_s,rate_x_dph,temp_c,rate_z_dph,temp_z_c,ref_z_dph,note";
        let c = Columns::from_header(header).unwrap();
        assert!(c.is_multi_axis());
        assert_eq!(c.axes_present().collect::<std::vec::Vec<_>>(), [Axis::X, Axis::Z]);
        assert_eq!(
            (c.axis, c.rate_dph, c.temp_c(), c.ref_dph),
            (Some(Axis::X), 1, Some(2), None)
        );
        assert_eq!(c.for_axis(Axis::Y), None);
        let z = c.for_axis(Axis::Z).unwrap();
        assert_eq!(
            (z.axis, z.rate_dph, z.temp_c(), z.ref_dph),
            (Some(Axis::Z), 3, Some(4), Some(5))
        );
        let line = "1.5,10,20.5,-30,21.25,-29.5,x";
        let (rx, rz) = (c.parse_row(line).unwrap(), z.parse_row(line).unwrap());
        assert_eq!((rx.rate_dph, rx.temp_c(), rx.ref_dph), (10.0, Some(20.5), None));
        assert_eq!(
            (rz.rate_dph, rz.temp_c(), rz.ref_dph),
            (-30.0, Some(21.25), Some(-29.5))
        );
        assert_eq!(
            z.parse_row("1.5,10,20.5,x,21.25,-29.5,x"),
            Err(RowError {
                column: Some(3),
                kind: RowErrorKind::NotANumber
            }),
            "the axis's rate column is named"
        );
        assert_eq!(
            Columns::from_header("time_s,rate_dph,temp_c,rate_y_dph"),
            Err(HeaderError::MixedAxes(3))
        );
        assert_eq!(
            Columns::from_header("time_s,temp_x_c,ref_x_dph"),
            Err(HeaderError::MissingColumn("rate_dph"))
        );
        assert_eq!(
            Columns::from_header("time_s,rate_y_dph,rate_y_dph"),
            Err(HeaderError::DuplicateColumn(2))
        );
        let single = Columns::from_header("time_s,rate_dph,temp_c,temp_x_c").unwrap();
        assert!(!single.is_multi_axis() && single.axis.is_none());
        assert_eq!(single.temp_c(), Some(2), "temp_x_c means nothing to a single-axis run");
    }

    #[test]
    fn compensated_output_names_and_writes_every_axis_and_single_axis_output_is_unchanged() {
        use crate::{CompensatedSample, Flags};
        let sample = |bias_dph: f32, bits: u8| CompensatedSample {
            bias_dph,
            rate_comp_dph: 1.0 - bias_dph,
            temp_c: 20.0,
            flags: Flags(bits),
        };
        let mut text = heapless::String::<256>::new();
        let multi = Columns::from_header("time_s,rate_x_dph,rate_y_dph,temp_c").unwrap();
        write_compensated_header(&mut text, "time_s,rate_x_dph,rate_y_dph,temp_c", &multi).unwrap();
        write_compensated_row(&mut text, "0,1,1,20", &[sample(0.25, 0), sample(-0.5, 9)]).unwrap();
        assert_eq!(
            text.as_str(),
            "time_s,rate_x_dph,rate_y_dph,temp_c,bias_x_dph,rate_comp_x_dph,flags_x,bias_y_dph,rate_comp_y_dph,flags_y\n\
             0,1,1,20,0.25,0.75,0,-0.5,1.5,9\n"
        );
        text.clear();
        let single = Columns::from_header("time_s,rate_dph,temp_c").unwrap();
        write_compensated_header(&mut text, "time_s,rate_dph,temp_c", &single).unwrap();
        write_compensated_row(&mut text, "0,1,20", &[sample(0.1, 8)]).unwrap();
        assert_eq!(
            text.as_str(),
            "time_s,rate_dph,temp_c,bias_dph,rate_comp_dph,flags\n0,1,20,0.1,0.9,8\n"
        );
    }

    #[test]
    fn rows_parse_or_name_the_offending_column() {
        let c = Columns::from_header("time_s,rate_dph,temp_c,temp_fault,note").unwrap();
        let row = c.parse_row(" 1.5 ,-2e-3,20,1,x\r").unwrap();
        assert_eq!(
            (row.time_s, row.rate_dph, row.temp_c(), row.temp_fault),
            (1.5, -2e-3, Some(20.0), true)
        );
        let err = |line: &str| c.parse_row(line).unwrap_err();
        assert_eq!(
            err("1,1.2.3,20,0,x"),
            RowError {
                column: Some(1),
                kind: RowErrorKind::NotANumber
            }
        );
        assert_eq!(
            err("1,NaN,20,0,x"),
            RowError {
                column: Some(1),
                kind: RowErrorKind::NonFinite
            }
        );
        assert_eq!(
            err("1,2,inf,0,x"),
            RowError {
                column: Some(2),
                kind: RowErrorKind::NonFinite
            }
        );
        assert_eq!(
            err("1,-3600000.5,20,0,x"),
            RowError {
                column: Some(1),
                kind: RowErrorKind::OverRange
            }
        );
        assert!(c.parse_row("1,-3600000,20,0,x").is_ok(), "1000 °/s itself is a rate");
        let with_ref = Columns::from_header("time_s,rate_dph,ref_dph").unwrap();
        assert_eq!(
            with_ref.parse_row("1,2,1e30"),
            Err(RowError {
                column: Some(2),
                kind: RowErrorKind::OverRange
            })
        );
        assert_eq!(
            err("1,2,20,0.5,x"),
            RowError {
                column: Some(3),
                kind: RowErrorKind::NotAFlag
            }
        );
        assert_eq!(
            err("1,2,20"),
            RowError {
                column: None,
                kind: RowErrorKind::FieldCount { expected: 5, found: 3 }
            }
        );
        assert_eq!(
            err("1,,20,0,x"),
            RowError {
                column: Some(1),
                kind: RowErrorKind::NotANumber
            }
        );
    }

    #[test]
    fn period_estimator_takes_the_first_positive_rate_or_the_median_step() {
        let mut e = PeriodEstimator::new();
        e.note_preamble_line("# sample_rate_hz: abc");
        e.note_preamble_line("# sample_rate_hz: -5");
        e.note_preamble_line("# sample_rate_hz: 4");
        e.note_preamble_line("# sample_rate_hz: 8");
        assert!(e.is_complete());
        assert_eq!(e.period_s(), 0.25);
        let mut e = PeriodEstimator::new();
        for t in [0.0, 1.0, 2.0, 5.0, 6.0] {
            assert!(!e.push_time(t));
        }
        assert_eq!(e.period_s(), 1.0, "median of steps 1, 1, 3, 1");
        assert_eq!(PeriodEstimator::new().period_s(), 1.0, "nothing known: 1 s");
    }

    #[test]
    fn metadata_lines_split_into_key_and_value() {
        assert_eq!(metadata("# sample_rate_hz: 10\r"), Some(("sample_rate_hz", "10")));
        assert_eq!(metadata("#no colon"), None);
        assert!(is_comment_or_blank("  \r"));
    }
}
