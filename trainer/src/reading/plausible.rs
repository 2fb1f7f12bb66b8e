//! Is a run a plausible gyro recording? Facts a fiber-optic gyro's physics
//! bounds, checked row by row in a few numbers of state: the loop
//! temperature within −60 … 100 °C and changing slower than
//! [`MAX_LOOP_RATE_C_PER_MIN`] by the time column. A run outside them is
//! most often one in other units (°F, time in hours); the commands refuse
//! it with the reason and accept it with `--allow-implausible`. (A time
//! column in milliseconds the run reader refuses already: samples too far
//! apart for a gyro.)

use std::path::Path;

use crate::reading::sampling::sig;
use crate::text;

/// Coldest loop temperature a gyro in use or in a chamber sees, °C.
pub const LOOP_MIN_C: f64 = -60.0;
/// Hottest loop temperature a gyro in use or in a chamber sees, °C.
pub const LOOP_MAX_C: f64 = 100.0;
/// Fastest plausible change of the loop temperature, °C/min, over a minute:
/// a chamber at full rate moves its air at 5 … 15 °C/min and the coil,
/// inside its housing, follows slower.
pub const MAX_LOOP_RATE_C_PER_MIN: f64 = 30.0;
/// The loop temperature's rate is taken between means over this long, s.
const RATE_BIN_S: f64 = 60.0;

/// Row-by-row facts for [`Plausibility::findings`].
#[derive(Clone, Debug)]
pub struct Plausibility {
    temp_name: String,
    min_c: f64,
    max_c: f64,
    first_outside_line: Option<usize>,
    outside: usize,
    readings: usize,
    first_time_s: Option<f64>,
    last_time_s: f64,
    /// The current rate bin: its index, sum and count.
    bin: Option<(i64, f64, usize)>,
    /// The previous bin's index and mean.
    previous: Option<(i64, f64)>,
    fastest_c_per_min: f64,
}

impl Plausibility {
    /// Nothing seen yet of a run whose loop thermometer's column is named `temp_name`.
    pub fn new(temp_name: &str) -> Self {
        Plausibility {
            temp_name: temp_name.to_owned(),
            min_c: f64::INFINITY,
            max_c: f64::NEG_INFINITY,
            first_outside_line: None,
            outside: 0,
            readings: 0,
            first_time_s: None,
            last_time_s: 0.0,
            bin: None,
            previous: None,
            fastest_c_per_min: 0.0,
        }
    }

    /// Names the loop thermometer's column `name` in the findings.
    pub fn set_temp_name(&mut self, name: &str) {
        name.clone_into(&mut self.temp_name);
    }

    /// Takes the row at `line`: its time and loop temperature (if read).
    pub fn push(&mut self, line: usize, time_s: f64, loop_c: Option<f64>) {
        self.first_time_s.get_or_insert(time_s);
        self.last_time_s = time_s;
        let Some(t) = loop_c else { return };
        self.readings += 1;
        self.min_c = self.min_c.min(t);
        self.max_c = self.max_c.max(t);
        if !(LOOP_MIN_C..=LOOP_MAX_C).contains(&t) {
            self.outside += 1;
            self.first_outside_line.get_or_insert(line);
        }
        let index = (time_s / RATE_BIN_S).floor() as i64;
        match &mut self.bin {
            Some((i, sum, n)) if *i == index => {
                *sum += t;
                *n += 1;
            }
            _ => {
                if let Some((i, sum, n)) = self.bin.take() {
                    self.close_bin(i, sum / n as f64);
                }
                self.bin = Some((index, t, 1));
            }
        }
    }

    fn close_bin(&mut self, index: i64, mean_c: f64) {
        if let Some((previous, previous_c)) = self.previous
            && index == previous + 1
        {
            self.fastest_c_per_min = self
                .fastest_c_per_min
                .max((mean_c - previous_c).abs() * 60.0 / RATE_BIN_S);
        }
        self.previous = Some((index, mean_c));
    }

    /// The fastest change of the loop temperature seen, °C/min: between
    /// consecutive 1-min means, and at least the whole run's range over its
    /// span (which catches a run whose span is under two minutes).
    pub fn fastest_c_per_min(&self) -> f64 {
        let mut probe = self.clone();
        if let Some((i, sum, n)) = probe.bin.take() {
            probe.close_bin(i, sum / n as f64);
        }
        let span_min = (self.last_time_s - self.first_time_s.unwrap_or(self.last_time_s)) / 60.0;
        let whole = if span_min > 0.0 && self.readings > 1 {
            (self.max_c - self.min_c) / span_min
        } else {
            0.0
        };
        probe.fastest_c_per_min.max(whole)
    }

    /// What is implausible about the run at `path`, one sentence each with
    /// the likely cause; empty for a plausible run.
    pub fn findings(&self, path: &Path) -> Vec<String> {
        let name = text::path(path);
        let mut found = Vec::new();
        if let Some(line) = self.first_outside_line {
            let fahrenheit = if self.max_c > LOOP_MAX_C && self.max_c <= 250.0 {
                "; °F? temperatures are °C ((F − 32)/1.8)"
            } else {
                ""
            };
            found.push(format!(
                "{name}: {}: {} of {} readings lie outside {LOOP_MIN_C} … {LOOP_MAX_C} °C, the range a gyro's fiber \
                 loop works in (first at line {line}; read {} … {} °C){fahrenheit}",
                self.temp_name,
                self.outside,
                self.readings,
                sig(self.min_c),
                sig(self.max_c),
            ));
        }
        let fastest = self.fastest_c_per_min();
        if fastest > MAX_LOOP_RATE_C_PER_MIN {
            found.push(format!(
                "{name}: {} changes by {} °C/min by time_s; a fiber loop's temperature changes slower than \
                 {MAX_LOOP_RATE_C_PER_MIN} °C/min (is time_s in hours or minutes? it must be in seconds)",
                self.temp_name,
                sig(fastest)
            ));
        }
        found
    }
}

/// The finding for training runs whose loop temperature (`what`, e.g. `the
/// training runs' loop temperature`) spans `lo_c` … `hi_c`, when that leaves
/// [`LOOP_MIN_C`] … [`LOOP_MAX_C`].
pub fn range_finding(what: &str, lo_c: f64, hi_c: f64) -> Option<String> {
    let fahrenheit = if hi_c > LOOP_MAX_C && hi_c <= 250.0 {
        "; °F? temperatures are °C ((F − 32)/1.8)"
    } else {
        ""
    };
    (lo_c < LOOP_MIN_C || hi_c > LOOP_MAX_C).then(|| {
        format!(
            "{what} spans {} … {} °C, outside {LOOP_MIN_C} … {LOOP_MAX_C} °C, the range a gyro's fiber loop works in{fahrenheit}",
            sig(lo_c),
            sig(hi_c)
        )
    })
}

/// Refuses a run listed twice: a training run that holds the same data as
/// an earlier training run (it would count twice and pull the model towards
/// it), or a run of `others` (role and paths, e.g. `--holdout`) that holds
/// the same data as a training run (its figures would be the training
/// run's, presented as an independent check). The same data: the same
/// file, a byte copy, or the same rows whatever the `#` lines and line ends
/// ([`same_data`]).
pub fn require_distinct_runs(
    train: &[std::path::PathBuf],
    others: &[(&str, &[std::path::PathBuf])],
) -> anyhow::Result<()> {
    for (i, path) in train.iter().enumerate() {
        for earlier in &train[..i] {
            if let Some(how) = same_data(earlier, path)? {
                anyhow::bail!(
                    "{}: the training run is {how} training run {}: it would count twice and pull the model \
                     towards it; list each run once",
                    text::path(path),
                    text::path(earlier)
                );
            }
        }
    }
    for (role, paths) in others {
        for path in *paths {
            for trained in train {
                if let Some(how) = same_data(trained, path)? {
                    anyhow::bail!(
                        "{}: the {role} run is {how} training run {}: its figures would be the training run's, not an \
                         independent check; drop it from {role}, or record another run to hold out",
                        text::path(path),
                        text::path(trained)
                    );
                }
            }
        }
    }
    Ok(())
}

/// How the files at `a` and `b` hold the same data (`the same file as`,
/// `a copy of`, `the same rows as`), or `None`. The same rows: equal once
/// `#` lines, blank lines and `\r` line ends are left out, so a copy with
/// its metadata stripped or its line ends converted is still found.
fn same_data(a: &Path, b: &Path) -> anyhow::Result<Option<&'static str>> {
    let (Ok(ca), Ok(cb)) = (a.canonicalize(), b.canonicalize()) else {
        return Ok(None);
    };
    if ca == cb {
        return Ok(Some("the same file as"));
    }
    let (ma, mb) = (std::fs::metadata(&ca)?, std::fs::metadata(&cb)?);
    if !ma.is_file() || !mb.is_file() {
        return Ok(None);
    }
    let (ra, rb) = (data_rows(&ca)?, data_rows(&cb)?);
    if ra.digest != rb.digest || ra.rows != rb.rows {
        return Ok(None);
    }
    Ok(Some(if ma.len() == mb.len() && ra.raw_digest == rb.raw_digest {
        "a copy of"
    } else {
        "the same rows as"
    }))
}

/// Digests of a file's data rows and of its bytes.
struct RowDigest {
    /// Over the lines that are not `#` lines nor blank, without their line ends.
    digest: u64,
    /// Over every byte.
    raw_digest: u64,
    /// Lines the row digest took.
    rows: u64,
}

/// [`RowDigest`] of the file at `path`, streamed.
fn data_rows(path: &Path) -> anyhow::Result<RowDigest> {
    use std::hash::Hasher;
    use std::io::BufRead;
    let file = std::fs::File::open(path).map_err(|e| anyhow::anyhow!("{}: {e}", text::path(path)))?;
    let mut reader = std::io::BufReader::with_capacity(1 << 20, file);
    let (mut digest, mut raw_digest) = (std::hash::DefaultHasher::new(), std::hash::DefaultHasher::new());
    let mut rows = 0u64;
    let mut line = Vec::new();
    loop {
        line.clear();
        if reader
            .read_until(b'\n', &mut line)
            .map_err(|e| anyhow::anyhow!("{}: {e}", text::path(path)))?
            == 0
        {
            break;
        }
        raw_digest.write(&line);
        let mut row = line.as_slice();
        while let [head @ .., b'\n' | b'\r'] = row {
            row = head;
        }
        if row.is_empty() || row.starts_with(b"#") {
            continue;
        }
        digest.write(row);
        digest.write_u8(b'\n');
        rows += 1;
    }
    Ok(RowDigest {
        digest: digest.finish(),
        raw_digest: raw_digest.finish(),
        rows,
    })
}

/// Refuses a run with `findings` ([`Plausibility::findings`]) unless `allow`.
pub fn require_plausible(findings: &[String], allow: bool) -> anyhow::Result<()> {
    if findings.is_empty() || allow {
        return Ok(());
    }
    Err(Implausible(findings.join("; ")).into())
}

/// A run refused as implausible; the message says why.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Implausible(pub String);

#[cfg(test)]
mod tests {
    use super::*;

    fn findings(rows: impl Iterator<Item = (f64, f64)>) -> Vec<String> {
        let mut p = Plausibility::new("temp_c");
        for (i, (t, c)) in rows.enumerate() {
            p.push(i + 2, t, Some(c));
        }
        p.findings(Path::new("run.csv"))
    }

    #[test]
    fn a_chamber_run_in_seconds_and_celsius_is_plausible() {
        // 12 h at 1 Hz, −40 … 60 °C at 1 °C/min.
        let ramp = (0..43_200).map(|i| {
            let x = (f64::from(i) / 60.0) % 200.0;
            (f64::from(i), -40.0 + if x < 100.0 { x } else { 200.0 - x })
        });
        assert_eq!(findings(ramp), Vec::<String>::new());
    }

    #[test]
    fn fahrenheit_and_a_time_column_in_hours_are_named() {
        let fahrenheit = findings((0..3600).map(|i| (f64::from(i), 50.0 + f64::from(i) / 40.0)));
        assert!(
            fahrenheit.len() == 1 && fahrenheit[0].contains("°F?") && fahrenheit[0].contains("first at line 2003"),
            "{fahrenheit:?}"
        );
        // 1 °C/min written with time in hours: 3600 °C/min by time_s.
        let hours = findings((0..7200).map(|i| (f64::from(i) / 3600.0, 20.0 + f64::from(i) / 600.0)));
        assert!(hours.len() == 1 && hours[0].contains("time_s in hours"), "{hours:?}");
    }
}
