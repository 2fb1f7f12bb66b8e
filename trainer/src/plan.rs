//! `trainer plan`: designing the chamber run the default model learns from.
//!
//! A plan is a sequence of [`Segment`]s (ramp to a target at a rate, hold)
//! after a power-on soak at its first temperature. Candidates are drawn from
//! a family that contains what the lag bank needs to see (a cold start whose
//! self-heating transient is recorded, levels across the range, full-rate
//! steps, bursts of swings, slow ramps, holds as long as the slowest coil
//! mode) and the one whose lag-bank regression on a nominal plant has the
//! largest D-criterion ([`d_criterion`]) is kept. On request
//! (`trainer plan --soak-ends`, [`candidate_soaking_ends`]) every candidate
//! also soaks at both ends of the range long enough for a loop
//! [`SLOW_PLANT_FACTOR`] times slower than nominal to settle there
//! ([`end_soak_s`]), so the run reaches the asked range at the loop on plants
//! other than the nominal one, at the cost of dynamic excitation. Either
//! way the plan predicts the loop range on both plants. docs/plan.md argues
//! the choice. Deterministic for a given seed.

use std::fmt::Write as _;

use nalgebra::DMatrix;
use plotters::coord::Shift;
use plotters::prelude::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

use crate::simulate::SimParams;
use crate::simulate::chamber_file::CHAMBER_C;
use crate::simulate::plant::{LOOP_SENSOR, Plant, PlantParams};

/// Time constants of the derivative filters whose regression the criterion
/// scores, s: the default lag bank's 15-s ladder (`fit::lag_bank::LADDERS_S[0]`).
pub const CRITERION_TAUS_S: [f64; 6] = [15.0, 60.0, 240.0, 960.0, 3840.0, 15360.0];
/// Parameters of the scored regression: a cubic in T (4) and, per filter,
/// ΔT_k times 1, T and T².
pub const CRITERION_PARAMS: usize = 4 + 3 * CRITERION_TAUS_S.len();
/// Length of the means the information matrix is built from, s (the
/// cluster-STD window: the bias instability decorrelates on this scale).
const MEAN_S: usize = 100;
/// A hold at least this long lets the coil's slowest radial mode settle
/// (the slowest lag-bank filter that the runs resolve at full weight), s.
pub const LONG_HOLD_S: f64 = 3840.0;
/// Power-on soak at the start, s: the electronics' self-heating settles
/// with a time constant of up to 30 min on the simulator's unit range.
const WARM_UP_S: (f64, f64) = (2700.0, 4500.0);
/// Levels of the grid the set points are drawn from (both limits included).
const LEVELS: usize = 11;
/// Smallest move between two levels, as a fraction of the range.
const MIN_MOVE: f64 = 0.2;
/// Swing amplitude, fraction of the range.
const SWING_AMPLITUDE: (f64, f64) = (0.08, 0.2);
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

    /// The shortest run a plan that soaks at the ends needs, h: the
    /// power-on soak at the cold end (the unit is soaked there before it),
    /// a full-range ramp at the fastest rate and a soak at the hot end
    /// ([`end_soak_s`]) long enough for the loop to reach it.
    pub fn shortest_hours_soaking_ends(&self) -> f64 {
        let ramp_s = ramp_seconds(self.max_c - self.min_c, self.max_rate_c_per_min);
        (WARM_UP_S.0 + ramp_s + end_soak_s(self)) / 3600.0
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

    /// [`Self::check`], and refuses hours too short for the end soaks
    /// (`--soak-ends`), saying how long they need.
    pub fn check_soaking_ends(&self) -> Result<(), String> {
        self.check()?;
        let shortest = self.shortest_hours_soaking_ends();
        if self.hours < shortest {
            return Err(format!(
                "--hours {} --soak-ends: too short for the loop to reach {} … {} °C; these limits need at least {:.2} h (a {:.0}-min power-on soak at {} °C, a ramp to {} °C at {} °C/min and a {:.0}-min soak there: what a loop {SLOW_PLANT_FACTOR}× slower than the nominal plant's needs to come within {:.1} °C of where it settles)",
                self.hours,
                self.min_c,
                self.max_c,
                shortest,
                WARM_UP_S.0 / 60.0,
                self.min_c,
                self.max_c,
                self.max_rate_c_per_min,
                end_soak_s(self) / 60.0,
                self.reach_c()
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

/// A designed profile: the segments, the score of the criterion and what it was chosen among.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The limits it meets.
    pub limits: PlanLimits,
    /// The first segment is the power-on soak (no ramp).
    pub segments: Vec<Segment>,
    /// D-criterion of the plan ([`d_criterion`]).
    pub criterion: f64,
    /// Median criterion of the candidates.
    pub median_criterion: f64,
    /// Candidates drawn.
    pub candidates: usize,
    /// Seed of the draw.
    pub seed: u64,
    /// Lowest and highest loop temperature the nominal plant reads under the plan, °C.
    pub loop_range_c: (f64, f64),
    /// The same on a plant [`SLOW_PLANT_FACTOR`] times slower than nominal, °C.
    pub slow_loop_range_c: (f64, f64),
    /// With `--soak-ends`, each end soak lasts at least this, s
    /// ([`end_soak_s`]); `None` without (the plan as before the end soaks).
    pub end_soak_s: Option<f64>,
}

impl Plan {
    /// Set points (time s, temperature °C), time from 0 strictly increasing.
    pub fn knots(&self) -> Vec<(f64, f64)> {
        knots(&self.segments)
    }

    /// How long the gyro must soak unpowered at the first set point before
    /// power-on, s ([`pre_soak_s`] on the documented gyro's plant).
    pub fn pre_soak_s(&self) -> f64 {
        pre_soak_s(&SimParams::default().plant, self.segments[0].target_c)
    }

    /// Length of the run, s.
    pub fn duration_s(&self) -> f64 {
        self.knots().last().map_or(0.0, |k| k.0)
    }

    /// The `#` metadata lines every output format starts with.
    fn metadata(&self) -> String {
        let l = &self.limits;
        let mut s = String::new();
        let _ = writeln!(s, "# source: trainer plan (D-optimal chamber profile, docs/plan.md)");
        let _ = writeln!(s, "# min_c: {}", l.min_c);
        let _ = writeln!(s, "# max_c: {}", l.max_c);
        let _ = writeln!(s, "# max_rate_c_per_min: {}", l.max_rate_c_per_min);
        let _ = writeln!(s, "# hours: {}", l.hours);
        let _ = writeln!(s, "# seed: {}", self.seed);
        let _ = writeln!(
            s,
            "# criterion: D-optimal, (1/p)·ln det of the information matrix per 100-s mean of the lag-bank regression (p = {CRITERION_PARAMS}: a cubic in T; ΔT at τ {} s, each times 1, T, T²) on the nominal plant (trainer simulate's documented gyro)",
            CRITERION_TAUS_S.map(|t| format!("{t:.0}")).join("/")
        );
        let _ = writeln!(
            s,
            "# criterion_value: {:.4} (best of {} candidates; median {:.4})",
            self.criterion, self.candidates, self.median_criterion
        );
        let first = self.segments[0];
        let _ = writeln!(
            s,
            "# pre_soak: before 0 s, the gyro unpowered at {} °C for at least {:.0} min (the nominal plant's every node within {PRE_SOAK_WITHIN_C} °C of the air after {ROOM_C} °C)",
            first.target_c,
            self.pre_soak_s() / 60.0
        );
        let _ = writeln!(
            s,
            "# power_on: at 0 s, soaked at {} °C; held {:.0} min (cold start: the self-heating transient)",
            first.target_c,
            first.hold_s / 60.0
        );
        let _ = writeln!(s, "# duration_h: {:.3}", self.duration_s() / 3600.0);
        if let Some(end_soak_s) = self.end_soak_s {
            let _ = writeln!(
                s,
                "# end_soak_min: {:.1} (at each end of the range: a loop {SLOW_PLANT_FACTOR}× slower than nominal comes within {:.1} °C of where it settles)",
                end_soak_s / 60.0,
                self.limits.reach_c()
            );
        }
        let _ = writeln!(
            s,
            "# predicted_loop_c: {:.1},{:.1} (nominal plant; {:.1},{:.1} with every time constant {SLOW_PLANT_FACTOR}× nominal)",
            self.loop_range_c.0, self.loop_range_c.1, self.slow_loop_range_c.0, self.slow_loop_range_c.1
        );
        s
    }

    /// Whether a loop of this range reaches both ends of the asked range
    /// (within [`PlanLimits::reach_c`]).
    pub fn reaches(&self, loop_range_c: (f64, f64)) -> bool {
        let reach_c = self.limits.reach_c();
        loop_range_c.0 <= self.limits.min_c + reach_c && loop_range_c.1 >= self.limits.max_c - reach_c
    }

    /// What the plan predicts at the loop, in a line or more: the range on
    /// the nominal plant and on the slow one, and a warning for each that
    /// stays short of an end of the asked range by more than
    /// [`PlanLimits::reach_c`], saying by how much and what closes the gap.
    pub fn loop_range_lines(&self) -> Vec<String> {
        let (min_c, max_c) = (self.limits.min_c, self.limits.max_c);
        let (lo, hi) = self.loop_range_c;
        let (slo, shi) = self.slow_loop_range_c;
        let soaks = match self.end_soak_s {
            Some(s) => format!("soaks of {:.1} min or more at each end", s / 60.0),
            None => "no end soaks: --soak-ends adds them".to_owned(),
        };
        let mut out = vec![format!(
            "predicted loop range: {lo:.1} … {hi:.1} °C on the nominal plant, {slo:.1} … {shi:.1} °C with every time constant {SLOW_PLANT_FACTOR}× nominal (asked {min_c} … {max_c} °C; {soaks})"
        )];
        for (name, range) in [
            ("the nominal plant", self.loop_range_c),
            ("the slow plant", self.slow_loop_range_c),
        ] {
            if self.reaches(range) {
                continue;
            }
            let short: Vec<String> = [(range.0 - min_c, min_c), (max_c - range.1, max_c)]
                .into_iter()
                .filter(|&(gap, _)| gap > self.limits.reach_c())
                .map(|(gap, end)| format!("{gap:.1} °C short of {end} °C"))
                .collect();
            let remedy = match self.end_soak_s {
                None => "--soak-ends closes the gap (more --hours may)",
                Some(_) => "its self-heating or lags keep it from the ends; more --hours may close the gap",
            };
            out.push(format!(
                "warning: on {name} the loop is predicted to reach only {:.1} … {:.1} °C, {} (more than the {:.1} °C a fit counts as reached): {remedy}",
                range.0,
                range.1,
                short.join(" and "),
                self.limits.reach_c()
            ));
        }
        out
    }

    /// The set-point CSV `trainer simulate --chamber-profile` reads.
    pub fn set_points_csv(&self) -> String {
        let mut s = self.metadata();
        s.push_str("time_s,chamber_c\n");
        for (t, c) in self.knots() {
            let _ = writeln!(s, "{t:.0},{c}");
        }
        s
    }

    /// The segment table chamber controllers take: set point, ramp and hold minutes.
    pub fn segments_csv(&self) -> String {
        let mut s = self.metadata();
        let _ = writeln!(
            s,
            "# segment 1 is the power-on soak: no ramp; before it, the pre-soak above (unpowered, {:.0} min)",
            self.pre_soak_s() / 60.0
        );
        s.push_str("segment,target_c,ramp_min,hold_min\n");
        for (i, g) in self.segments.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{},{},{}",
                i + 1,
                g.target_c,
                ramp_minutes(g.ramp_s),
                minutes(g.hold_s)
            );
        }
        s
    }
}

/// A hold in minutes: every hold of a plan is a whole number of minutes.
fn minutes(s: f64) -> String {
    format!("{:.0}", s / 60.0)
}

/// A ramp in minutes: every ramp is a whole number of tenths of a minute,
/// so one decimal is exact.
fn ramp_minutes(s: f64) -> String {
    format!("{:.1}", s / 60.0)
}

/// Where the gyro waits before a plan, °C: the lab.
const ROOM_C: f64 = 23.0;
/// The pre-soak ends when every node of the plant is this close to the air, °C.
const PRE_SOAK_WITHIN_C: f64 = 0.1;

/// How long the unpowered gyro must soak at `start_c` after the lab
/// (`ROOM_C`) before a plan's power-on, s, in whole minutes: until every
/// node of `plant` (housing, electronics, coil layers, hub) lies within
/// `PRE_SOAK_WITHIN_C` of the air, as the plan's first state assumes.
pub fn pre_soak_s(plant: &PlantParams, start_c: f64) -> f64 {
    let unpowered = PlantParams {
        self_heating_c: 0.0,
        ..plant.clone()
    };
    let mut node = Plant::soaked(&unpowered, ROOM_C);
    let settled = |n: &Plant| {
        [n.base_c, n.top_c, n.electronics_c]
            .iter()
            .chain(n.layers_c())
            .chain(n.hub_c.as_ref())
            .all(|c| (c - start_c).abs() <= PRE_SOAK_WITHIN_C)
    };
    let mut t_s = 0.0;
    // Bounded: a day covers any plant `PlantParams::check` accepts many times over.
    while !settled(&node) && t_s < 86_400.0 {
        node.step(&unpowered, start_c, 1.0);
        t_s += 1.0;
    }
    (t_s / MINUTE_S).ceil() * MINUTE_S
}

/// Set points of `segments`: the start, then each ramp's end and hold's end.
fn knots(segments: &[Segment]) -> Vec<(f64, f64)> {
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
fn ramp_seconds(delta_c: f64, rate_c_per_min: f64) -> f64 {
    let s = delta_c.abs() / rate_c_per_min * 60.0;
    let up = (s / TENTH_MIN_S).ceil() * TENTH_MIN_S;
    if up - s < 1e-6 { up + TENTH_MIN_S } else { up }
}

/// Ramps are whole multiples of this, s (a tenth of a minute).
const TENTH_MIN_S: f64 = 6.0;

/// Holds and soaks are whole multiples of this, s.
const MINUTE_S: f64 = 60.0;

/// `s` rounded down to whole minutes.
fn floor_minutes(s: f64) -> f64 {
    (s / MINUTE_S).floor().max(0.0) * MINUTE_S
}

/// `s` rounded to whole minutes.
fn whole_minutes(s: f64) -> f64 {
    (s / MINUTE_S).round().max(0.0) * MINUTE_S
}

/// A temperature on a whole-degree grid (what a chamber operator types),
/// kept within the limits.
fn set_point(c: f64, l: &PlanLimits) -> f64 {
    c.round().clamp(l.min_c, l.max_c)
}

/// Builds a segment list up to a time budget.
#[derive(Clone)]
struct Builder<'a> {
    limits: &'a PlanLimits,
    segments: Vec<Segment>,
    now_c: f64,
    t_s: f64,
}

impl Builder<'_> {
    /// Draws one move of the design family with `rng` and appends it: a
    /// burst of swings at the full rate about a centre near the current
    /// level, legs alternating sides, or a move to another level, slow or
    /// fast. With `end_soak_s` (`--soak-ends`), a move to an end of the
    /// range holds there at least that long, for the loop to settle.
    fn draw_move(&mut self, rng: &mut impl Rng, end_soak_s: Option<f64>) {
        let l = self.limits;
        let span = l.max_c - l.min_c;
        let level = |k: usize| l.min_c + span * k as f64 / (LEVELS - 1) as f64;
        let r = l.max_rate_c_per_min;
        let kind = rng.random_range(0..10u32);
        let hold_s = match rng.random_range(0..10u32) {
            0..=3 => rng.random_range(600.0..=1500.0),
            4..=6 => rng.random_range(1500.0..=2700.0),
            _ => rng.random_range(LONG_HOLD_S..=1.4 * LONG_HOLD_S),
        };
        if kind <= 1 {
            let legs = rng.random_range(2..=4);
            let reach = span * SWING_AMPLITUDE.1;
            let centre = self.now_c.clamp(l.min_c + reach, l.max_c - reach);
            let mut side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            for _ in 0..legs {
                let amp = span * rng.random_range(SWING_AMPLITUDE.0..=SWING_AMPLITUDE.1);
                self.ramp_hold(centre + side * amp, r, rng.random_range(0.0..=300.0));
                side = -side;
            }
            self.ramp_hold(centre, r, hold_s);
            return;
        }
        let target = loop {
            let t = level(rng.random_range(0..LEVELS));
            if (t - self.now_c).abs() >= MIN_MOVE * span {
                break t;
            }
        };
        let rate = match kind {
            2..=5 => r,
            6..=7 => r * rng.random_range(0.3..=0.7),
            _ => r * rng.random_range(0.1..=0.3),
        };
        let hold_s = match end_soak_s {
            Some(soak_s) if is_end(set_point(target, l), l) => hold_s.max(soak_s),
            _ => hold_s,
        };
        self.ramp_hold(target, rate, hold_s);
    }

    fn ramp_hold(&mut self, target_c: f64, rate: f64, hold_s: f64) {
        let target_c = set_point(target_c, self.limits);
        if (target_c - self.now_c).abs() < 0.5 {
            self.hold(hold_s);
            return;
        }
        let ramp_s = ramp_seconds(target_c - self.now_c, rate);
        let hold_s = whole_minutes(hold_s);
        self.segments.push(Segment {
            target_c,
            ramp_s,
            hold_s,
        });
        self.t_s += ramp_s + hold_s;
        self.now_c = target_c;
    }

    fn hold(&mut self, hold_s: f64) {
        let hold_s = whole_minutes(hold_s);
        if let Some(last) = self.segments.last_mut() {
            last.hold_s += hold_s;
        }
        self.t_s += hold_s;
    }
}

/// Whether `c` is an end of the range (a set point rounds to 0.01 °C).
fn is_end(c: f64, l: &PlanLimits) -> bool {
    (c - l.min_c).abs() < 0.006 || (c - l.max_c).abs() < 0.006
}

/// The ends of the range still to visit from `now_c`, nearest first.
fn ends_left(l: &PlanLimits, now_c: f64, low_left: bool, high_left: bool) -> Vec<f64> {
    let mut ends: Vec<f64> = [(l.min_c, low_left), (l.max_c, high_left)]
        .into_iter()
        .filter(|e| e.1)
        .map(|e| e.0)
        .collect();
    ends.sort_by(|a, b| (a - now_c).abs().total_cmp(&(b - now_c).abs()));
    ends
}

/// Seconds to visit `ends` from `now_c` in turn at the full rate with an
/// `end_soak_s` soak at each.
fn visits_s(l: &PlanLimits, now_c: f64, ends: &[f64], end_soak_s: f64) -> f64 {
    let mut at = now_c;
    let mut s = 0.0;
    for &e in ends {
        let target = set_point(e, l);
        if (target - at).abs() >= 0.01 {
            s += ramp_seconds(target - at, l.max_rate_c_per_min);
        }
        s += whole_minutes(end_soak_s);
        at = target;
    }
    s
}

/// One candidate of the design family, drawn with `rng`, cut to the time budget.
pub fn candidate(limits: &PlanLimits, rng: &mut impl Rng) -> Vec<Segment> {
    let l = limits;
    let span = l.max_c - l.min_c;
    let level = |k: usize| l.min_c + span * k as f64 / (LEVELS - 1) as f64;
    let end_s = (l.hours * 3600.0 / TENTH_MIN_S).floor() * TENTH_MIN_S;
    // Cold start: soaked in the lowest fifth of the range.
    let start = set_point(level(rng.random_range(0..=2)), l);
    let mut b = Builder {
        limits: l,
        segments: vec![Segment {
            target_c: start,
            ramp_s: 0.0,
            hold_s: whole_minutes(rng.random_range(WARM_UP_S.0..=WARM_UP_S.1)),
        }],
        now_c: start,
        t_s: 0.0,
    };
    b.t_s = b.segments[0].hold_s;
    while b.t_s < end_s {
        b.draw_move(rng, None);
    }
    cut(b.segments, end_s)
}

/// One candidate of the design family, drawn with `rng`, cut to the time
/// budget, with a soak of at least `end_soak_s` at each end of the range
/// (`trainer plan --soak-ends`; without it, [`candidate`]). The power-on
/// soak counts for the cold end when it starts there: the unit is soaked
/// before it. A move is drawn only while the ends not yet
/// visited still fit in the budget after it; then they are visited, nearest
/// first, at the full rate.
pub fn candidate_soaking_ends(limits: &PlanLimits, end_soak_s: f64, rng: &mut impl Rng) -> Vec<Segment> {
    let l = limits;
    let span = l.max_c - l.min_c;
    let level = |k: usize| l.min_c + span * k as f64 / (LEVELS - 1) as f64;
    let is_end = |c: f64| is_end(c, l);
    let r = l.max_rate_c_per_min;
    let end_s = (l.hours * 3600.0 / TENTH_MIN_S).floor() * TENTH_MIN_S;
    // Cold start: soaked in the lowest fifth of the range; at its bottom
    // when the budget has no room for a soak there later.
    let drawn = set_point(level(rng.random_range(0..=2)), l);
    let fits = |start: f64| {
        let ends = ends_left(l, start, (start - l.min_c).abs() >= 0.006, true);
        WARM_UP_S.0 + visits_s(l, start, &ends, end_soak_s) <= end_s
    };
    let start = if fits(drawn) { drawn } else { set_point(l.min_c, l) };
    let mut low_left = (start - l.min_c).abs() >= 0.006;
    let mut high_left = true;
    let ends_need_s = visits_s(l, start, &ends_left(l, start, low_left, high_left), end_soak_s);
    let warm_up_s =
        whole_minutes(rng.random_range(WARM_UP_S.0..=WARM_UP_S.1)).min(floor_minutes(end_s - ends_need_s).max(0.0));
    let mut b = Builder {
        limits: l,
        segments: vec![Segment {
            target_c: start,
            ramp_s: 0.0,
            hold_s: warm_up_s,
        }],
        now_c: start,
        t_s: 0.0,
    };
    b.t_s = b.segments[0].hold_s;
    while b.t_s < end_s {
        let before = b.clone();
        b.draw_move(rng, Some(end_soak_s));
        let at_end = is_end(b.now_c);
        let (low, high) = (
            low_left && !(at_end && b.now_c < l.min_c + 0.5 * span),
            high_left && !(at_end && b.now_c > l.min_c + 0.5 * span),
        );
        let need_s = visits_s(l, b.now_c, &ends_left(l, b.now_c, low, high), end_soak_s);
        let visited_now = (low, high) != (low_left, high_left);
        if b.t_s + need_s > end_s && (need_s > 0.0 || visited_now) {
            // This move leaves no room for the ends (or its own end soak
            // runs past the budget): drop it and visit the ends instead.
            b = before;
            break;
        }
        (low_left, high_left) = (low, high);
    }
    for e in ends_left(l, b.now_c, low_left, high_left) {
        b.ramp_hold(e, r, end_soak_s);
    }
    cut(b.segments, end_s)
}

/// `segments` cut to end at or before `end_s`: a hold is shortened, a ramp
/// that would run past the end is dropped and the hold before it extended.
fn cut(mut segments: Vec<Segment>, end_s: f64) -> Vec<Segment> {
    let mut t = 0.0;
    let mut keep = Vec::with_capacity(segments.len());
    for g in segments.drain(..) {
        if t + g.ramp_s > end_s {
            break;
        }
        let hold_s = g.hold_s.min(floor_minutes(end_s - t - g.ramp_s));
        t += g.ramp_s + hold_s;
        keep.push(Segment { hold_s, ..g });
        if t >= end_s {
            break;
        }
    }
    if let Some(last) = keep.last_mut() {
        last.hold_s += floor_minutes(end_s - t);
    }
    // A segment left with neither ramp nor hold adds no set point.
    let first = keep.first().copied();
    let mut out: Vec<Segment> = first.into_iter().collect();
    out.extend(keep.into_iter().skip(1).filter(|g| g.ramp_s > 0.0 || g.hold_s > 0.0));
    out
}

/// The loop sensor's reading on the noise-free `plant` at 1 s under the
/// set points of `segments`, °C; the unit soaked at the first set point
/// and switched on at 0 s.
pub fn loop_temps(segments: &[Segment], plant: &PlantParams) -> Vec<f64> {
    let k = knots(segments);
    let end = k.last().map_or(0.0, |k| k.0) as usize;
    let start_c = k.first().map_or(20.0, |k| k.1);
    let mut node = Plant::soaked(plant, start_c);
    let mut sensor = start_c;
    let lag_s = plant.thermometer_lags_s[LOOP_SENSOR];
    let mut out = Vec::with_capacity(end);
    let mut j = 0;
    for i in 0..end {
        let t = i as f64;
        while j + 1 < k.len() && k[j + 1].0 <= t {
            j += 1;
        }
        let air = match k.get(j + 1) {
            Some(b) => k[j].1 + (b.1 - k[j].1) * (t - k[j].0) / (b.0 - k[j].0),
            None => k[j].1,
        };
        node.step(plant, air, 1.0);
        sensor += (plant.loop_sensor.node_c(&node) - sensor) / lag_s;
        out.push(sensor);
    }
    out
}

/// The D-criterion of a loop-temperature history at 1 s within `limits`:
/// (1/p)·ln det(XᵀX / n), X the lag-bank regression's inputs (a cubic in
/// T; each filter's ΔT times 1, T, T²) averaged over 100-s means, T scaled
/// to ±1 over the limits and ΔT by the fastest rate, n the number of 100-s
/// means the time budget holds (so a shorter plan scores its lost hours).
/// The filters start settled, as the firmware's do at power-on.
pub fn d_criterion(temps_c: &[f64], limits: &PlanLimits) -> f64 {
    let mid = 0.5 * (limits.min_c + limits.max_c);
    let half = 0.5 * (limits.max_c - limits.min_c);
    let p = CRITERION_PARAMS;
    let n_taus = CRITERION_TAUS_S.len();
    let mut filt = [0.0f64; 6];
    if let Some(&t0) = temps_c.first() {
        filt = [t0; 6];
    }
    let mut info = DMatrix::<f64>::zeros(p, p);
    let mut sum = vec![0.0; p];
    let mut x = vec![0.0; p];
    let mut count = 0;
    for &t in temps_c {
        let u = (t - mid) / half;
        x[0] = 1.0;
        x[1] = u;
        x[2] = u * u;
        x[3] = u * u * u;
        for (k, tau) in CRITERION_TAUS_S.iter().enumerate() {
            let rate = (t - filt[k]) / (tau + 1.0);
            filt[k] += rate;
            let r = rate * 60.0 / limits.max_rate_c_per_min;
            x[4 + k] = r;
            x[4 + n_taus + k] = u * r;
            x[4 + 2 * n_taus + k] = u * u * r;
        }
        for (s, v) in sum.iter_mut().zip(&x) {
            *s += v;
        }
        count += 1;
        if count == MEAN_S {
            let m = nalgebra::DVector::from_iterator(p, sum.iter().map(|s| s / MEAN_S as f64));
            info.syger(1.0, &m, &m, 1.0);
            sum.iter_mut().for_each(|s| *s = 0.0);
            count = 0;
        }
    }
    info.fill_upper_triangle_with_lower_triangle();
    let budget = (limits.hours * 3600.0 / MEAN_S as f64).max(1.0);
    info /= budget;
    match info.cholesky() {
        Some(c) => 2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>() / p as f64,
        None => f64::NEG_INFINITY,
    }
}

/// `plant` with every time constant (housing, electronics, coil, hub,
/// thermometers) `factor` times as long.
pub fn slowed(plant: &PlantParams, factor: f64) -> PlantParams {
    let mut p = plant.clone();
    for tau in [
        &mut p.tau_base_s,
        &mut p.tau_top_s,
        &mut p.tau_electronics_s,
        &mut p.tau_coil_outer_s,
        &mut p.tau_coil_layer_s,
    ] {
        *tau *= factor;
    }
    if let Some(hub) = p.hub.as_mut() {
        hub.tau_base_s *= factor;
        hub.tau_coil_s *= factor;
    }
    for lag in &mut p.thermometer_lags_s {
        *lag *= factor;
    }
    p
}

/// The soak at an end of the range a plan holds, s (whole tenths of a
/// minute): after a ramp across the whole range at the full rate, the time
/// the loop of the nominal plant slowed [`SLOW_PLANT_FACTOR`] times takes
/// to come and stay within [`PlanLimits::reach_c`] of where it settles at
/// that end, the longer of the two directions, and never shorter than a
/// long hold.
pub fn end_soak_s(limits: &PlanLimits) -> f64 {
    let slow = slowed(&SimParams::default().plant, SLOW_PLANT_FACTOR);
    let ramp_s = ramp_seconds(limits.max_c - limits.min_c, limits.max_rate_c_per_min);
    // Powered long before the ramp, so the self-heating transient is over;
    // held long after it, so the loop has settled by the end.
    let (before_s, after_s) = (12.0 * 3600.0, 24.0 * 3600.0);
    let settle_s = |from_c: f64, to_c: f64| {
        let segments = [
            Segment {
                target_c: from_c,
                ramp_s: 0.0,
                hold_s: before_s,
            },
            Segment {
                target_c: to_c,
                ramp_s,
                hold_s: after_s,
            },
        ];
        let temps = loop_temps(&segments, &slow);
        // Where it settles: the set point plus what self-heating adds, which no plan removes.
        let settled_c = temps.last().copied().unwrap_or(to_c);
        let last_out = temps
            .iter()
            .rposition(|t| (t - settled_c).abs() > limits.reach_c())
            .map_or(0, |i| i + 1);
        (last_out as f64 - before_s - ramp_s).max(0.0)
    };
    let s = settle_s(limits.min_c, limits.max_c)
        .max(settle_s(limits.max_c, limits.min_c))
        .max(LONG_HOLD_S);
    (s / TENTH_MIN_S).ceil() * TENTH_MIN_S
}

/// Lowest and highest of `temps_c`, °C.
fn range_of(temps_c: &[f64]) -> (f64, f64) {
    temps_c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
        (lo.min(t), hi.max(t))
    })
}

/// Designs a plan within `limits`: the best of `candidates` draws from
/// `seed` by the D-criterion on the documented gyro's plant; with
/// `soak_ends`, drawn by [`candidate_soaking_ends`], else by [`candidate`]
/// (the draws are then the same as before end soaks existed).
pub fn design(limits: &PlanLimits, seed: u64, candidates: usize, soak_ends: bool) -> Result<Plan, String> {
    let end_soak_s = if soak_ends {
        limits.check_soaking_ends()?;
        Some(end_soak_s(limits))
    } else {
        limits.check()?;
        None
    };
    let plant = SimParams::default().plant;
    let indices: Vec<u64> = (0..candidates.max(1) as u64).collect();
    let scored = crate::parallel::parallel_map(&indices, |&i| {
        let mut rng = Pcg64::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(i));
        let segments = match end_soak_s {
            Some(s) => candidate_soaking_ends(limits, s, &mut rng),
            None => candidate(limits, &mut rng),
        };
        let score = d_criterion(&loop_temps(&segments, &plant), limits);
        (segments, score)
    });
    let mut scores: Vec<f64> = scored.iter().map(|s| s.1).collect();
    scores.sort_by(f64::total_cmp);
    let median_criterion = scores[scores.len() / 2];
    let (segments, criterion) = scored
        .into_iter()
        .filter(|s| s.1.is_finite())
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .ok_or_else(|| "no candidate plan has an invertible information matrix".to_owned())?;
    let loop_range_c = range_of(&loop_temps(&segments, &plant));
    let slow_loop_range_c = range_of(&loop_temps(&segments, &slowed(&plant, SLOW_PLANT_FACTOR)));
    Ok(Plan {
        limits: *limits,
        segments,
        criterion,
        median_criterion,
        candidates: candidates.max(1),
        seed,
        loop_range_c,
        slow_loop_range_c,
        end_soak_s,
    })
}

/// Image formats `--plot` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlotFormat {
    /// Scalable vector graphics.
    Svg,
    /// Portable network graphics.
    Png,
}

/// Plot size, pixels.
const PLOT_SIZE: (u32, u32) = (1000, 480);

/// The plan drawn: chamber set points and the nominal loop temperature over hours.
pub fn plot(plan: &Plan, format: PlotFormat) -> anyhow::Result<Vec<u8>> {
    let temps = loop_temps(&plan.segments, &SimParams::default().plant);
    match format {
        PlotFormat::Svg => {
            let mut svg = String::new();
            draw_plan(
                SVGBackend::with_string(&mut svg, PLOT_SIZE).into_drawing_area(),
                plan,
                &temps,
            )
            .map_err(|e| anyhow::anyhow!("drawing the SVG: {e}"))?;
            Ok(svg.into_bytes())
        }
        PlotFormat::Png => {
            let mut rgb = vec![0u8; PLOT_SIZE.0 as usize * PLOT_SIZE.1 as usize * 3];
            draw_plan(
                BitMapBackend::with_buffer(&mut rgb, PLOT_SIZE).into_drawing_area(),
                plan,
                &temps,
            )
            .map_err(|e| anyhow::anyhow!("drawing the PNG: {e}"))?;
            crate::plotting::png::encode_png(&rgb, PLOT_SIZE)
        }
    }
}

fn draw_plan<DB: DrawingBackend>(
    root: DrawingArea<DB, Shift>,
    plan: &Plan,
    temps: &[f64],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let l = &plan.limits;
    let hours = (plan.duration_s() / 3600.0).max(1e-3);
    let (x_lo, x_hi) = crate::plotting::axes::padded(0.0, hours);
    let (c_lo, c_hi) =
        crate::plotting::axes::with_legend_room(l.min_c, l.max_c, 2, root.dim_in_pixel().1.saturating_sub(100));
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "chamber plan {} … {} °C, ≤ {} °C/min, {:.2} h (D-criterion {:.3})",
                l.min_c, l.max_c, l.max_rate_c_per_min, hours, plan.criterion
            ),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(crate::plotting::axes::y_label_area_px(
            &root,
            crate::plotting::axes::linear_tick_labels(c_lo, c_hi),
            crate::plotting::axes::TICK_LABEL_PX,
            60,
        ))
        .build_cartesian_2d(x_lo..x_hi, c_lo..c_hi)?;
    let (x_light, y_light) = crate::plotting::axes::light_lines_of(chart.plotting_area());
    chart
        .configure_mesh()
        .x_max_light_lines(x_light)
        .y_max_light_lines(y_light)
        .x_label_formatter(&crate::plotting::axes::tick_label)
        .y_label_formatter(&crate::plotting::axes::tick_label)
        .x_desc("time [h]")
        .y_desc("temperature [°C]")
        .draw()?;
    let set_points: Vec<(f64, f64)> = plan.knots().iter().map(|&(t, c)| (t / 3600.0, c)).collect();
    chart
        .draw_series(LineSeries::new(set_points, RGBColor(200, 60, 40).stroke_width(2)))?
        .label("chamber set point")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(200, 60, 40)));
    let sensed: Vec<(f64, f64)> = temps
        .iter()
        .enumerate()
        .step_by(10)
        .map(|(i, &c)| (i as f64 / 3600.0, c))
        .collect();
    chart
        .draw_series(LineSeries::new(sensed, RGBColor(30, 90, 200)))?
        .label("loop sensor, nominal plant")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RGBColor(30, 90, 200)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: PlanLimits = PlanLimits {
        min_c: -40.0,
        max_c: 60.0,
        max_rate_c_per_min: 5.0,
        hours: 12.0,
    };

    #[test]
    fn candidates_keep_every_limit_and_end_within_the_budget() {
        let soak_s = end_soak_s(&LIMITS);
        for (seed, soak_ends) in (0..40).flat_map(|seed| [(seed, false), (seed, true)]) {
            let mut rng = Pcg64::seed_from_u64(seed);
            let segments = if soak_ends {
                candidate_soaking_ends(&LIMITS, soak_s, &mut rng)
            } else {
                candidate(&LIMITS, &mut rng)
            };
            let k = knots(&segments);
            assert_eq!(k[0].0.to_bits(), 0.0f64.to_bits(), "seed {seed}: starts at 0");
            assert!(k.last().unwrap().0 <= 12.0 * 3600.0, "seed {seed}: {:?}", k.last());
            for w in k.windows(2) {
                assert!(w[1].0 > w[0].0, "seed {seed}: time not increasing {w:?}");
                let rate = (w[1].1 - w[0].1).abs() / (w[1].0 - w[0].0) * 60.0;
                assert!(rate < 5.0, "seed {seed}: {rate} °C/min");
            }
            assert!(k.iter().all(|&(_, c)| (-40.0..=60.0).contains(&c)));
        }
    }

    #[test]
    fn the_criterion_prefers_a_rich_profile_to_a_slow_cycle() {
        let plant = SimParams::default().plant;
        let cycle = vec![
            Segment {
                target_c: 20.0,
                ramp_s: 0.0,
                hold_s: 3600.0,
            },
            Segment {
                target_c: -40.0,
                ramp_s: 3601.0,
                hold_s: 7200.0,
            },
            Segment {
                target_c: 60.0,
                ramp_s: 6001.0,
                hold_s: 7200.0,
            },
            Segment {
                target_c: 20.0,
                ramp_s: 2401.0,
                hold_s: 10_000.0,
            },
        ];
        let slow = d_criterion(&loop_temps(&cycle, &plant), &LIMITS);
        let plan = design(&LIMITS, 1, 8, false).unwrap();
        assert!(plan.criterion > slow + 1.0, "plan {} vs cycle {slow}", plan.criterion);
        assert!(plan.criterion >= plan.median_criterion);
    }

    #[test]
    fn the_same_seed_gives_the_same_plan() {
        for soak_ends in [false, true] {
            let a = design(&LIMITS, 7, 6, soak_ends).unwrap();
            let b = design(&LIMITS, 7, 6, soak_ends).unwrap();
            assert_eq!(a.set_points_csv(), b.set_points_csv());
            assert_ne!(
                a.set_points_csv(),
                design(&LIMITS, 8, 6, soak_ends).unwrap().set_points_csv()
            );
        }
    }

    #[test]
    fn segment_tables_hold_whole_degrees_and_whole_minutes_of_hold_after_a_stated_pre_soak() {
        for (seed, soak_ends) in [(1, false), (3, false), (7, true)] {
            let plan = design(&LIMITS, seed, 4, soak_ends).unwrap();
            let table = plan.segments_csv();
            for row in table.lines().filter(|l| !l.starts_with('#')).skip(1) {
                let f: Vec<&str> = row.split(',').collect();
                for v in [f[1], f[3]] {
                    assert!(!v.contains('.'), "seed {seed}: {row}: not a whole number");
                }
            }
            let pre = table
                .lines()
                .find(|l| l.starts_with("# pre_soak: "))
                .expect("a pre-soak line");
            assert!(pre.contains(" min "), "{pre}");
        }
        // The nominal plant, from the lab to -40 °C: hours, not minutes; a
        // start at the lab's temperature needs none.
        let plant = SimParams::default().plant;
        let cold = pre_soak_s(&plant, -40.0);
        assert!((3600.0..86_400.0).contains(&cold) && cold % 60.0 == 0.0, "{cold}");
        assert!(pre_soak_s(&plant, ROOM_C) < 60.0 + 1e-9);
    }

    #[test]
    fn the_designed_segments_themselves_hold_whole_degrees_and_minutes_within_the_checks() {
        // The plan's values, not only their printing: a hold of 1.3 min
        // printed as 1 would put the table and the set points at odds.
        for (seed, soak_ends) in [(1, false), (2, false), (5, false), (7, true), (9, true)] {
            let plan = design(&LIMITS, seed, 4, soak_ends).unwrap();
            for g in &plan.segments {
                assert!(g.target_c.fract() == 0.0, "seed {seed}: set point {}", g.target_c);
                assert!(g.hold_s % 60.0 == 0.0, "seed {seed}: hold {} s", g.hold_s);
                assert!(g.ramp_s % 6.0 == 0.0, "seed {seed}: ramp {} s", g.ramp_s);
            }
            // The limits still hold after the rounding.
            for w in plan.segments.windows(2) {
                let rate_c_per_min = (w[1].target_c - w[0].target_c).abs() / (w[1].ramp_s / 60.0);
                assert!(rate_c_per_min <= LIMITS.max_rate_c_per_min, "seed {seed}: {w:?}");
            }
            assert!(
                plan.segments
                    .iter()
                    .all(|g| (LIMITS.min_c..=LIMITS.max_c).contains(&g.target_c))
            );
            assert!(plan.duration_s() <= LIMITS.hours * 3600.0, "seed {seed}");
            assert!(plan.pre_soak_s() % 60.0 == 0.0 && plan.pre_soak_s() > 0.0);
        }
    }

    #[test]
    fn ramps_are_rounded_up_to_stay_under_the_limit() {
        // Whole minutes: exact in f64.
        let secs = |delta: f64, rate: f64| ramp_seconds(delta, rate).to_bits();
        assert_eq!(secs(100.0, 5.0), 1206.0f64.to_bits());
        assert_eq!(secs(10.0, 3.0), 204.0f64.to_bits());
        assert_eq!(secs(7.0, 3.0), 144.0f64.to_bits());
        assert_eq!(ramp_minutes(90.0), "1.5");
        assert_eq!(minutes(3600.0), "60");
    }
}
