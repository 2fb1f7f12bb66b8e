//! Reading a chamber profile (`trainer simulate --chamber-profile PLAN.csv`),
//! as `trainer plan` writes one: `#` metadata lines, a header naming
//! `time_s` and `chamber_c` (other columns ignored), then piecewise-linear
//! set points, time strictly increasing from 0 or later. Errors name the
//! file, line and column: `plan.csv:7:8: chamber_c: "x" is not a number`.

use std::path::{Path, PathBuf};

use super::profile::Schedule;

/// Set points a chamber can hold, °C (the TMP117's range).
pub const CHAMBER_C: (f64, f64) = (-55.0, 150.0);

/// A defect in a chamber profile, with its place.
#[derive(Debug, thiserror::Error)]
pub enum ChamberProfileError {
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// File concerned.
        path: PathBuf,
        /// Underlying error.
        error: std::io::Error,
    },
    /// The content breaks the format.
    #[error("{path}:{line}:{column}: {message}")]
    Format {
        /// File concerned.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based column (character) where the defect starts.
        column: usize,
        /// What is wrong, naming the column where there is one.
        message: String,
    },
}

/// Reads the chamber profile in `path`, refused past
/// [`crate::reading::limits::MAX_PROFILE_BYTES`] without reading further.
pub fn read_chamber_profile(path: &Path) -> Result<Schedule, ChamberProfileError> {
    use std::io::Read;
    let limit = crate::reading::limits::MAX_PROFILE_BYTES;
    let io = |error| ChamberProfileError::Io {
        path: path.to_owned(),
        error,
    };
    let mut text = String::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(limit + 1).read_to_string(&mut text))
        .map_err(io)?;
    if text.len() as u64 > limit {
        return Err(io(std::io::Error::other(format!(
            "more than {limit} bytes; a chamber profile is at most {} (the limit)",
            crate::reading::limits::bytes(limit)
        ))));
    }
    parse_chamber_profile(path, &text)
}

/// Parses chamber-profile `text` read from `path` (named in errors).
pub fn parse_chamber_profile(path: &Path, text: &str) -> Result<Schedule, ChamberProfileError> {
    let fail = |line: usize, column: usize, message: String| ChamberProfileError::Format {
        path: path.to_owned(),
        line,
        column,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
        .skip_while(|(_, l)| l.starts_with('#'));
    let (header_line, header) = lines
        .next()
        .ok_or_else(|| fail(1, 1, "no header line (expected time_s,chamber_c)".into()))?;
    let names: Vec<&str> = header.split(',').map(str::trim).collect();
    // A segment table (`trainer plan --format segments`) is for the chamber
    // controller; the simulator follows the set points of the default format.
    let segments = ["segment", "target_c", "ramp_min", "hold_min"]
        .iter()
        .all(|c| names.contains(c));
    let position = |name: &str| {
        names.iter().position(|n| *n == name).ok_or_else(|| {
            let why = if segments {
                ": this is a segment table (trainer plan --format segments), which a chamber controller takes; \
                 --chamber-profile reads the set points: write them with trainer plan --format set-points"
            } else {
                ""
            };
            fail(
                header_line,
                1,
                format!("no column {name} in the header \"{header}\"{why}"),
            )
        })
    };
    let (time_col, temp_col) = (position("time_s")?, position("chamber_c")?);
    let mut knots: Vec<(f64, f64)> = Vec::new();
    for (line, row) in lines {
        if row.trim().is_empty() {
            continue;
        }
        // Each field with the 1-based character column it starts at.
        let mut fields = Vec::with_capacity(names.len());
        let mut start = 0;
        for field in row.split(',') {
            fields.push((row[..start].chars().count() + 1, field));
            start += field.len() + 1;
        }
        let value = |col: usize, name: &str| -> Result<f64, ChamberProfileError> {
            let &(column, field) = fields.get(col).ok_or_else(|| {
                fail(
                    line,
                    row.chars().count() + 1,
                    format!(
                        "{name}: missing ({} fields, the header has {})",
                        fields.len(),
                        names.len()
                    ),
                )
            })?;
            let v: f64 = field
                .trim()
                .parse()
                .map_err(|_| fail(line, column, format!("{name}: \"{}\" is not a number", field.trim())))?;
            if !v.is_finite() {
                return Err(fail(line, column, format!("{name}: {v} is not finite")));
            }
            Ok(v)
        };
        let (t, temp) = (value(time_col, "time_s")?, value(temp_col, "chamber_c")?);
        let time_column = fields[time_col].0;
        if t < 0.0 {
            return Err(fail(line, time_column, format!("time_s: {t} is before 0")));
        }
        if let Some(&(last, _)) = knots.last()
            && t <= last
        {
            return Err(fail(
                line,
                time_column,
                format!("time_s: {t} does not increase (the row before is at {last})"),
            ));
        }
        if !(CHAMBER_C.0..=CHAMBER_C.1).contains(&temp) {
            return Err(fail(
                line,
                fields[temp_col].0,
                format!("chamber_c: {temp} °C lies outside {} … {} °C", CHAMBER_C.0, CHAMBER_C.1),
            ));
        }
        knots.push((t, temp));
    }
    if knots.is_empty() {
        return Err(fail(header_line + 1, 1, "no set points after the header".into()));
    }
    Ok(Schedule::from_knots(knots))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Schedule, String> {
        parse_chamber_profile(Path::new("plan.csv"), text).map_err(|e| e.to_string())
    }

    #[test]
    fn a_plan_with_metadata_gives_its_set_points_and_interpolates_between_them() {
        let schedule =
            parse("# criterion: D-optimal\n# max_rate_c_per_min: 5\ntime_s,chamber_c\r\n0,-20\n600,-20\n1800,40\n")
                .unwrap();
        assert_eq!(schedule.knots(), &[(0.0, -20.0), (600.0, -20.0), (1800.0, 40.0)]);
        // Half-way up the ramp: exact in binary floating point.
        assert_eq!(schedule.air_c(1200.0).to_bits(), 10.0f64.to_bits());
        // Columns in any order, unknown ones ignored.
        let segments = parse("segment,target_c,ramp_min,hold_min\n1,20,0,60\n")
            .unwrap_err()
            .to_string();
        assert!(
            segments.contains("this is a segment table") && segments.contains("--format set-points"),
            "{segments}"
        );
        let swapped = parse("chamber_c,note,time_s\n25,a,0\n30,b,60\n").unwrap();
        assert_eq!(swapped.knots(), &[(0.0, 25.0), (60.0, 30.0)]);
    }

    #[test]
    fn defects_are_refused_with_file_line_and_column() {
        for (text, expected) in [
            (
                "time_s,chamber_c\n0,20\n60,2O\n",
                "plan.csv:3:4: chamber_c: \"2O\" is not a number",
            ),
            (
                "# a\ntime_s,chamber_c\n0,20\n0,25\n",
                "plan.csv:4:1: time_s: 0 does not increase",
            ),
            (
                "time_s,chamber_c\n0,20\n60,200\n",
                "plan.csv:3:4: chamber_c: 200 °C lies outside",
            ),
            ("time_s,chamber_c\n-5,20\n", "plan.csv:2:1: time_s: -5 is before 0"),
            ("time_s,chamber_c\n0,20\n60\n", "plan.csv:3:3: chamber_c: missing"),
            (
                "time_s,chamber_c\n0,NaN\n",
                "plan.csv:2:3: chamber_c: NaN is not finite",
            ),
            ("time_s,temp\n0,20\n", "plan.csv:1:1: no column chamber_c"),
            ("# only metadata\n", "plan.csv:1:1: no header line"),
            ("time_s,chamber_c\n", "plan.csv:2:1: no set points"),
        ] {
            let error = parse(text).expect_err(text);
            assert!(error.starts_with(expected), "{text:?}: {error}");
        }
    }
}
