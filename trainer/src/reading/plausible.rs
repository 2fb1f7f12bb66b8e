//! Is a run a plausible gyro recording? Facts a fiber-optic gyro's physics
//! bounds, checked row by row in a few numbers of state: the loop
//! temperature within −60 … 100 °C and changing slower than
//! [`MAX_LOOP_RATE_C_PER_MIN`] by the time column, a run no longer than
//! [`MAX_RUN_HOURS`], a rate in °/h that sees its reference and varies as
//! a gyro's noise does. A run outside them is most often one in other units
//! (°F, time in hours, minutes or milliseconds, rate in rad/s or °/s); every
//! command that reads a run refuses it with the reason and accepts it with
//! `--allow-implausible`. (A time column in milliseconds at a gyro's rates
//! below 200 Hz the run reader refuses already: samples too far apart.)

use std::path::Path;

use crate::reading::sampling::sig;
use crate::text;

/// Coldest loop temperature a gyro in use or in a chamber sees, °C.
pub const LOOP_MIN_C: f64 = -60.0;
/// Hottest loop temperature a gyro in use or in a chamber sees, °C.
pub const LOOP_MAX_C: f64 = 100.0;
/// Fastest plausible change of the loop temperature, °C/min, between 10-s means:
/// a chamber at full rate moves its air at 5 … 15 °C/min and the coil,
/// inside its housing, follows slower.
pub const MAX_LOOP_RATE_C_PER_MIN: f64 = 20.0;
/// The loop temperature's rate is taken between means over this long, s:
/// long enough that a thermometer's noise and quantisation do not count, short
/// enough that a run whose time column is in minutes shows its ramps 60 times
/// too fast.
const RATE_BIN_S: f64 = 10.0;
/// Longest run, h: what `trainer device record` records at most; a longer
/// span is a time column in milliseconds far more often than a six-week run.
pub const MAX_RUN_HOURS: f64 = crate::reading::limits::MAX_RECORD_HOURS;
/// A reference this large, °/h, is one a gyro in °/h reads (Earth rate is up
/// to 15 °/h): a rate whose mean stays under 1/[`REFERENCE_RATIO`] of it
/// does not see the reference, and is in other units.
const MIN_SEEN_REF_DPH: f64 = 1.0;
/// See [`MIN_SEEN_REF_DPH`].
const REFERENCE_RATIO: f64 = 100.0;
/// Narrowest spread of a varying rate column, °/h: the finest gyros' noise
/// alone spreads 1-s samples over more than 1e-2 °/h; rad/s or °/s readings
/// of any gyro spread less than this.
pub const MIN_RATE_SPREAD_DPH: f64 = 1e-4;
/// Room temperature written in °F, the start of a chamber run logged in °F:
/// 15 … 30 °C is 59 … 86 °F.
const ROOM_IN_FAHRENHEIT: (f64, f64) = (59.0, 86.0);
/// 0 °C in °F: a run logged in °F whose loop never froze never reads below it.
const FREEZING_IN_FAHRENHEIT: f64 = 32.0;
/// Least span of a run read for the °F hint, degrees: a chamber run's ramps,
/// not a soak at one temperature.
const FAHRENHEIT_MIN_SPAN: f64 = 10.0;

/// Units a rate column is often in, with their size in °/h.
const RATE_UNITS: [(&str, f64); 3] = [
    ("rad/s", 3600.0 * 180.0 / std::f64::consts::PI),
    ("°/s", 3600.0),
    ("rad/h", 180.0 / std::f64::consts::PI),
];

/// Row-by-row facts for [`Plausibility::findings`].
#[derive(Clone, Debug)]
pub struct Plausibility {
    temp_name: String,
    min_c: f64,
    max_c: f64,
    /// The first reading, °C (as read).
    first_c: Option<f64>,
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
    rate_name: String,
    ref_name: String,
    /// Least and greatest rate, °/h, and the sum of the rates.
    rate_dph: (f64, f64, f64),
    /// Rows with a reference, and the sums of their rates and references, °/h.
    with_ref: (usize, f64, f64),
}

impl Plausibility {
    /// Nothing seen yet of a run whose loop thermometer's column is named `temp_name`.
    pub fn new(temp_name: &str) -> Self {
        Plausibility {
            temp_name: temp_name.to_owned(),
            min_c: f64::INFINITY,
            max_c: f64::NEG_INFINITY,
            first_c: None,
            first_outside_line: None,
            outside: 0,
            readings: 0,
            first_time_s: None,
            last_time_s: 0.0,
            bin: None,
            previous: None,
            fastest_c_per_min: 0.0,
            rate_name: "rate_dph".to_owned(),
            ref_name: "ref_dph".to_owned(),
            rate_dph: (f64::INFINITY, f64::NEG_INFINITY, 0.0),
            with_ref: (0, 0.0, 0.0),
        }
    }

    /// Names the rate and reference columns `rate` and `reference` in the findings.
    pub fn set_rate_names(&mut self, rate: &str, reference: &str) {
        rate.clone_into(&mut self.rate_name);
        reference.clone_into(&mut self.ref_name);
    }

    /// Takes the row's rate and reference (if read), °/h.
    pub fn push_rate(&mut self, rate_dph: f64, ref_dph: Option<f64>) {
        let (lo, hi, sum) = &mut self.rate_dph;
        *lo = lo.min(rate_dph);
        *hi = hi.max(rate_dph);
        *sum += rate_dph;
        if let Some(r) = ref_dph {
            let (n, rates, refs) = &mut self.with_ref;
            *n += 1;
            *rates += rate_dph;
            *refs += r;
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
        self.first_c.get_or_insert(t);
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

    /// A loop temperature in °F that stays inside the °C range: the run
    /// starts at room temperature written in °F ([`ROOM_IN_FAHRENHEIT`]: in
    /// °C that is a loop starting at 59 … 86 °C, above any room), never reads
    /// below [`FREEZING_IN_FAHRENHEIT`], and spans at least
    /// [`FAHRENHEIT_MIN_SPAN`] (a chamber run's ramps). A run in °C that
    /// starts hot and stays above 32 °C (a slice of a hot test) is the one
    /// false alarm, and `--allow-implausible` takes it.
    fn looks_fahrenheit(&self) -> bool {
        self.first_c
            .is_some_and(|first| (ROOM_IN_FAHRENHEIT.0..=ROOM_IN_FAHRENHEIT.1).contains(&first))
            && self.min_c >= FREEZING_IN_FAHRENHEIT
            && self.max_c - self.min_c >= FAHRENHEIT_MIN_SPAN
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
        if self.first_outside_line.is_none() && self.looks_fahrenheit() {
            found.push(format!(
                "{name}: {}: starts at {} and reads {} … {}: °F? A chamber run starts at room temperature (15 … 30 °C); \
                 this one starts where room temperature lies in °F ({} … {} °F) and never reads below {} (0 °C in °F); \
                 temperatures are °C ((F − 32)/1.8)",
                self.temp_name,
                sig(self.first_c.unwrap_or(f64::NAN)),
                sig(self.min_c),
                sig(self.max_c),
                ROOM_IN_FAHRENHEIT.0,
                ROOM_IN_FAHRENHEIT.1,
                FREEZING_IN_FAHRENHEIT
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
        let span_h = (self.last_time_s - self.first_time_s.unwrap_or(self.last_time_s)) / 3600.0;
        if span_h > MAX_RUN_HOURS {
            found.push(format!(
                "{name}: time_s spans {} h, longer than a recording lasts ({MAX_RUN_HOURS} h at most): is time_s in \
                 milliseconds? it must be in seconds",
                sig(span_h)
            ));
        }
        found.extend(self.rate_finding(&name));
        found
    }

    /// The finding for a rate column in other units than °/h: one that does
    /// not see a reference of [`MIN_SEEN_REF_DPH`] or more, or whose spread is
    /// under [`MIN_RATE_SPREAD_DPH`] although it varies.
    fn rate_finding(&self, name: &str) -> Option<String> {
        let (lo, hi, _) = self.rate_dph;
        let (n, rates, refs) = self.with_ref;
        let unit_hint = |ratio: f64| {
            RATE_UNITS
                .iter()
                .find(|(_, dph)| (ratio * dph - 1.0).abs() < 0.5)
                .map_or(String::new(), |(unit, _)| format!("{unit}? "))
        };
        if n > 0 {
            let (mean_rate, mean_ref) = (rates / n as f64, refs / n as f64);
            if mean_ref.abs() >= MIN_SEEN_REF_DPH && mean_rate.abs() < mean_ref.abs() / REFERENCE_RATIO {
                return Some(format!(
                    "{name}: {} averages {} while {} averages {} °/h: the gyro does not see the rate it turned at \
                     ({}the rate and the reference must both be in °/h)",
                    self.rate_name,
                    sig(mean_rate),
                    self.ref_name,
                    sig(mean_ref),
                    unit_hint(mean_rate / mean_ref)
                ));
            }
        }
        let spread = hi - lo;
        (spread > 0.0 && spread < MIN_RATE_SPREAD_DPH).then(|| {
            format!(
                "{name}: {} varies only within {} … {}, a spread of {}; a gyro's noise alone in °/h spreads its \
                 readings wider than {MIN_RATE_SPREAD_DPH} °/h (rad/s or °/s? the rate must be in °/h)",
                self.rate_name,
                sig(lo),
                sig(hi),
                sig(spread)
            )
        })
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
    fn fahrenheit_inside_the_celsius_range_is_named_and_no_shipped_run_is_taken_for_it() {
        // A chamber run 25 → 10 → 35 °C at 1 °C/min logged in °F: 77 → 50 → 95 °F,
        // inside the range a loop may read in °C.
        let protocol_c = |i: u32| {
            let m = f64::from(i) / 60.0;
            if m < 15.0 {
                25.0 - m
            } else if m < 40.0 {
                10.0 + (m - 15.0)
            } else {
                35.0
            }
        };
        let in_f = findings((0..4 * 3600).map(|i| (f64::from(i), 32.0 + 1.8 * protocol_c(i))));
        assert!(
            in_f.len() == 1 && in_f[0].contains("°F?") && in_f[0].contains("starts at 77"),
            "{in_f:?}"
        );
        // The same run in °C, and every run shipped or shared: no hint.
        assert!(findings((0..4 * 3600).map(|i| (f64::from(i), protocol_c(i)))).is_empty());
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let shared = root.join("../shared/data");
        let dirs = [
            root.join("examples/data"),
            shared.join("other-designs"),
            shared.join("bmi270"),
        ];
        let mut read = 0;
        for entry in dirs.iter().filter_map(|d| std::fs::read_dir(d).ok()).flatten() {
            let path = entry.unwrap().path();
            let Ok(mut reader) = crate::reading::run::RunReader::open(&path) else {
                continue;
            };
            let mut p = Plausibility::new("temp_c");
            while let Some(row) = reader.next_row().unwrap() {
                p.push(row.line, row.row.time_s, row.row.temps_c[0]);
            }
            let found = p.findings(&path);
            assert!(found.iter().all(|f| !f.contains("°F?")), "{found:?}");
            read += 1;
        }
        assert!(read >= 6, "the shipped runs were read ({read})");
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
