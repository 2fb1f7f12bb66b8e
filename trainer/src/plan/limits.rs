//! What bounds a plan and what it is made of, below the rest of planning: the
//! chamber's and the run's limits ([`PlanLimits`]), the [`Segment`]s, the
//! constants of the candidate family and the criterion, and the time and
//! set-point arithmetic (whole minutes, ramp times, set points, knots) the
//! candidates and the criterion share.

use crate::simulate::chamber_file::CHAMBER_C;

/// Time constants of the derivative filters whose regression the criterion
/// scores, s: the default lag bank's 15-s ladder (`fit::lag_bank::LADDERS_S[0]`).
pub const CRITERION_TAUS_S: [f64; 6] = [15.0, 60.0, 240.0, 960.0, 3840.0, 15360.0];
/// Parameters of the scored regression: a cubic in T (4) and, per filter,
/// ΔT_k times 1, T and T².
pub const CRITERION_PARAMS: usize = 4 + 3 * CRITERION_TAUS_S.len();
/// Length of the means the information matrix is built from, s (the
/// cluster-STD window: the bias instability decorrelates on this scale).
pub(super) const MEAN_S: usize = 100;
/// A hold at least this long lets the coil's slowest radial mode settle
/// (the slowest lag-bank filter that the runs resolve at full weight), s.
pub const LONG_HOLD_S: f64 = 3840.0;
/// Power-on soak at the start, s: the electronics' self-heating settles
/// with a time constant of up to 30 min on the simulator's unit range.
pub(super) const WARM_UP_S: (f64, f64) = (2700.0, 4500.0);
/// Levels of the grid the set points are drawn from (both limits included).
pub(super) const LEVELS: usize = 11;
/// Smallest move between two levels, as a fraction of the range.
pub(super) const MIN_MOVE: f64 = 0.2;
/// Swing amplitude, fraction of the range.
pub(super) const SWING_AMPLITUDE: (f64, f64) = (0.08, 0.2);
/// The end soaks are sized for a plant whose every time constant (housing,
/// electronics, coil, hub, thermometers) is this many times the nominal
/// plant's: a plan must serve designs slower than the one it is scored on.
pub const SLOW_PLANT_FACTOR: f64 = 1.5;
/// The loop reaches an end of the asked range when it comes within this
/// share of the range of it: the share within which `trainer fit` counts a
/// range of use as covered (the slow coil modes would need hours more to
/// close the rest).
pub const REACH_SHARE: f64 = crate::fit::coverage::USE_REACH_SHARE;
/// Longest plan, h.
pub const MAX_HOURS: f64 = 168.0;
/// Candidates drawn unless `--candidates` says otherwise.
pub const DEFAULT_CANDIDATES: usize = 96;

/// The limits the plan's tests design within: the chamber, −40 …
/// 60 °C at 5 °C/min, for 12 h.
#[cfg(test)]
pub(super) const TEST_LIMITS: PlanLimits = PlanLimits {
    min_c: -40.0,
    max_c: 60.0,
    max_rate_c_per_min: 5.0,
    hours: 12.0,
};

/// What the chamber allows and how long the run may take.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanLimits {
    /// Lowest set point, °C.
    pub min_c: f64,
    /// Highest set point, °C.
    pub max_c: f64,
    /// Fastest ramp, °C/min.
    pub max_rate_c_per_min: f64,
    /// Longest run, h.
    pub hours: f64,
}

impl PlanLimits {
    /// The shortest run a plan within these limits needs, h: the power-on
    /// soak, a full-range ramp up and down at the fastest rate and a long
    /// hold at each end.
    pub fn shortest_hours(&self) -> f64 {
        let ramps_s = 2.0 * (self.max_c - self.min_c) / self.max_rate_c_per_min * 60.0;
        (WARM_UP_S.0 + ramps_s + 2.0 * LONG_HOLD_S) / 3600.0
    }

    /// How close to an end of the range the loop must come to reach it, °C.
    pub fn reach_c(&self) -> f64 {
        REACH_SHARE * (self.max_c - self.min_c)
    }

    /// Refuses limits no plan can meet, saying which and why.
    pub fn check(&self) -> Result<(), String> {
        let (lo, hi) = CHAMBER_C;
        for (flag, v) in [
            ("--min-c", self.min_c),
            ("--max-c", self.max_c),
            ("--max-rate-c-per-min", self.max_rate_c_per_min),
            ("--hours", self.hours),
        ] {
            if !v.is_finite() {
                return Err(format!("{flag} {v}: not a finite number"));
            }
        }
        if self.min_c < lo || self.max_c > hi {
            return Err(format!(
                "--min-c {} --max-c {}: set points must lie within {lo} … {hi} °C (the loop sensor's range)",
                self.min_c, self.max_c
            ));
        }
        if self.max_c - self.min_c < 10.0 {
            return Err(format!(
                "--min-c {} must lie at least 10 °C below --max-c {} (a plan needs levels to tell the static curve from the rates)",
                self.min_c, self.max_c
            ));
        }
        if !(self.max_rate_c_per_min > 0.0 && self.max_rate_c_per_min <= 20.0) {
            return Err(format!(
                "--max-rate-c-per-min {}: must be above 0 and at most 20 °C/min",
                self.max_rate_c_per_min
            ));
        }
        if self.hours > MAX_HOURS {
            return Err(format!("--hours {}: at most {MAX_HOURS} h", self.hours));
        }
        let shortest = self.shortest_hours();
        if self.hours < shortest {
            return Err(format!(
                "--hours {}: too short; these limits need at least {:.2} h (a {:.0}-min power-on soak, {:.0} … {:.0} °C up and down at {} °C/min, a {:.0}-min hold at each end)",
                self.hours,
                shortest,
                WARM_UP_S.0 / 60.0,
                self.min_c,
                self.max_c,
                self.max_rate_c_per_min,
                LONG_HOLD_S / 60.0
            ));
        }
        Ok(())
    }
}

/// One step of a chamber program: ramp to `target_c` at `rate_c_per_min`, then hold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Set point, °C.
    pub target_c: f64,
    /// Ramp duration, s (whole tenths of a minute; 0 for the first segment, the soak).
    pub ramp_s: f64,
    /// Hold at the set point after the ramp, s (whole minutes, may be 0).
    pub hold_s: f64,
}

/// Set points of `segments`: the start, then each ramp's end and hold's end.
pub(super) fn knots(segments: &[Segment]) -> Vec<(f64, f64)> {
    let Some(first) = segments.first() else {
        return Vec::new();
    };
    let mut k = vec![(0.0, first.target_c)];
    let mut t = 0.0;
    for (i, g) in segments.iter().enumerate() {
        if i > 0 && g.ramp_s > 0.0 {
            t += g.ramp_s;
            k.push((t, g.target_c));
        }
        if g.hold_s > 0.0 {
            t += g.hold_s;
            k.push((t, g.target_c));
        }
    }
    k
}

/// Seconds a ramp of `delta_c` takes at no more than `rate` °C/min, in
/// whole tenths of a minute (whole minutes would slow a short swing at
/// the full rate by up to half): rounded up, a tenth more when exact, so
/// no rounding of the written values can make a segment faster than the limit.
pub(super) fn ramp_seconds(delta_c: f64, rate_c_per_min: f64) -> f64 {
    let s = delta_c.abs() / rate_c_per_min * 60.0;
    let up = (s / TENTH_MIN_S).ceil() * TENTH_MIN_S;
    if up - s < 1e-6 { up + TENTH_MIN_S } else { up }
}

/// Ramps are whole multiples of this, s (a tenth of a minute).
pub(super) const TENTH_MIN_S: f64 = 6.0;

/// Holds and soaks are whole multiples of this, s.
pub(super) const MINUTE_S: f64 = 60.0;

/// `s` rounded down to whole minutes.
pub(super) fn floor_minutes(s: f64) -> f64 {
    (s / MINUTE_S).floor().max(0.0) * MINUTE_S
}

/// `s` rounded to whole minutes.
pub(super) fn whole_minutes(s: f64) -> f64 {
    (s / MINUTE_S).round().max(0.0) * MINUTE_S
}

/// A temperature on a whole-degree grid (what a chamber operator types),
/// kept within the limits.
pub(super) fn set_point(c: f64, l: &PlanLimits) -> f64 {
    c.round().clamp(l.min_c, l.max_c)
}
