//! Air temperature histories (docs/simulator.md, "Profiles"): chamber
//! set-point schedules, and the histories a gyro meets in use. Every
//! history is piecewise linear; every run starts at power-on with the gyro
//! soaked at the first temperature.

use std::f64::consts::PI;

use rand::Rng;

/// The temperature histories.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Profile {
    /// Chamber, IFOG paper: 25 °C, down to 10 °C, hold, up to 40 °C, hold, back to 25 °C.
    Ifog,
    /// Chamber, RLG paper: 20 → −40 → 60 → −40 → 60 → 20 °C with holds.
    Cycle,
    /// Chamber or in use: random set points (within a range, default −40 … 60 °C), ramp
    /// rates (default 0.5 … 5 °C/min) and holds (20 … 90 min).
    Random,
    /// Chamber: a designed multi-rate run, cold start at −20 °C, 5 °C/min ramps between
    /// levels across −40 … 60 °C, holds of 15 … 50 min (about 10.9 h).
    Designed,
    /// In use: powered on soaked cold, warms up on its own heat, then reaches ambient.
    ColdStart,
    /// In use: carried between a hangar and outside (near-instant air steps).
    AmbientSteps,
    /// In use: fast swings at 3 … 8 °C/min.
    Swings,
    /// In use: a 24-h day cycle.
    DayCycle,
    /// In use: a cold start followed by a seeded mix of steps, swings and slow drifts.
    Field,
    /// A chamber profile read from a file (`trainer simulate --chamber-profile PLAN.csv`).
    Planned,
    /// Chamber, a soak test (IEEE Std 952 style): holds at set levels until the
    /// gyro settles (default: 3 h at 25, 0, 40, −20, 60, 20, −40, 10 °C), 1 °C/min
    /// ramps between ([`SOAK_LEVELS_C`], [`SOAK_HOLD_S`]).
    Soak,
}

impl Profile {
    /// Name as written in the metadata.
    pub fn name(self) -> &'static str {
        match self {
            Profile::Ifog => "ifog",
            Profile::Cycle => "cycle",
            Profile::Random => "random",
            Profile::Designed => "designed",
            Profile::ColdStart => "cold-start",
            Profile::AmbientSteps => "ambient-steps",
            Profile::Swings => "swings",
            Profile::DayCycle => "day-cycle",
            Profile::Field => "field",
            Profile::Planned => "chamber-profile",
            Profile::Soak => "soak",
        }
    }

    /// Whether this is an in-use history (no chamber: the run starts at power-on
    /// with no settling hold).
    pub fn in_use(self) -> bool {
        matches!(
            self,
            Profile::ColdStart | Profile::AmbientSteps | Profile::Swings | Profile::DayCycle | Profile::Field
        )
    }

    /// Length of the profile when `--hours` is not given, s (`None`: as long as its set points).
    pub fn default_duration_s(self) -> Option<f64> {
        let hours = match self {
            Profile::Random | Profile::Field => 8.0,
            Profile::ColdStart | Profile::Swings => 4.0,
            Profile::AmbientSteps => 6.0,
            Profile::DayCycle => 24.0,
            Profile::Ifog | Profile::Cycle | Profile::Designed | Profile::Planned | Profile::Soak => return None,
        };
        Some(hours * 3600.0)
    }
}

/// Hold at the start of the chamber protocols ifog, cycle and random
/// (power-on self-heating settles), s.
const START_HOLD_S: f64 = 3600.0;

/// Limits of the in-use histories (docs/simulator.md, "In-use histories"); the
/// tests check every generated history against them.
pub mod limits {
    /// Every in-use history stays within this, °C.
    pub const AMBIENT_C: (f64, f64) = (-40.0, 55.0);
    /// A near-instant air step takes this long, s.
    pub const STEP_S: (f64, f64) = (30.0, 120.0);
    /// Rate of a fast swing, °C/min.
    pub const SWING_C_PER_MIN: (f64, f64) = (3.0, 8.0);
    /// Amplitude of a swing about its centre, °C.
    pub const SWING_AMPLITUDE_C: (f64, f64) = (5.0, 15.0);
    /// Soak temperature of a cold start, °C.
    pub const COLD_SOAK_C: (f64, f64) = (-40.0, 0.0);
    /// Warm-up at the soak temperature after power-on, min.
    pub const WARM_UP_MIN: (f64, f64) = (20.0, 60.0);
    /// Ambient a cold start ends in, °C.
    pub const COLD_START_AMBIENT_C: (f64, f64) = (10.0, 30.0);
    /// Rate of a cold start's heated warm-up (when not a step), °C/min.
    pub const HEATER_C_PER_MIN: (f64, f64) = (0.5, 3.0);
    /// Hangar temperature, °C.
    pub const HANGAR_C: (f64, f64) = (15.0, 25.0);
    /// Outside temperature, °C.
    pub const OUTSIDE_C: (f64, f64) = (-30.0, 45.0);
    /// Dwell after a step, min.
    pub const DWELL_MIN: (f64, f64) = (20.0, 90.0);
    /// Dwell at a swing's extreme, min.
    pub const SWING_DWELL_MIN: (f64, f64) = (0.0, 10.0);
    /// Mean of a day cycle or of the swings, °C.
    pub const MEAN_C: (f64, f64) = (-10.0, 30.0);
    /// Amplitude of a day cycle, °C.
    pub const DAY_AMPLITUDE_C: (f64, f64) = (4.0, 12.0);
    /// Period of a day cycle, s.
    pub const DAY_S: f64 = 86_400.0;
    /// A slow drift of a field history moves this far, °C, over this long, h.
    pub const DRIFT_TO_C: (f64, f64) = (-20.0, 40.0);
    /// Length of a slow drift of a field history, h.
    pub const DRIFT_H: (f64, f64) = (2.0, 6.0);
    /// Smallest change of an air step, °C.
    pub const MIN_STEP_C: f64 = 10.0;
    /// Knot spacing of the smooth (sinusoidal) pieces, s.
    pub const SMOOTH_KNOT_S: f64 = 300.0;
}

/// Levels of the designed chamber run after its cold start at the first, °C.
pub const DESIGNED_LEVELS_C: [f64; 15] = [
    -20.0, 60.0, -40.0, 30.0, -10.0, 50.0, 0.0, 40.0, -30.0, 20.0, -40.0, 60.0, 10.0, -20.0, 25.0,
];
/// Holds of the designed run, min.
pub const DESIGNED_HOLD_MIN: (f64, f64) = (15.0, 50.0);
/// Ramp rate of the designed run unless `--ramp` says otherwise, °C/min.
pub const DESIGNED_RAMP_C_PER_MIN: f64 = 5.0;

/// Chamber levels of the soak profile, in order, °C (the soak test of issue 48).
pub const SOAK_LEVELS_C: [f64; 8] = [25.0, 0.0, 40.0, -20.0, 60.0, 20.0, -40.0, 10.0];
/// Hold at each level of the soak profile, s (3 h).
pub const SOAK_HOLD_S: f64 = 3.0 * 3600.0;

/// A piecewise-linear air temperature.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    knots: Vec<(f64, f64)>,
}

impl Schedule {
    /// The schedule through `knots` (time s, temperature °C), times non-decreasing.
    pub fn from_knots(knots: Vec<(f64, f64)>) -> Self {
        Schedule { knots }
    }

    /// The knots (time s, temperature °C).
    pub fn knots(&self) -> &[(f64, f64)] {
        &self.knots
    }

    /// Air at time `t`, °C (the last value holds after the end).
    pub fn air_c(&self, t: f64) -> f64 {
        let i = self.knots.partition_point(|k| k.0 <= t);
        match (self.knots.get(i.wrapping_sub(1)), self.knots.get(i)) {
            (Some(a), Some(b)) if b.0 > a.0 => a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0),
            (Some(a), _) => a.1,
            (None, Some(b)) => b.1,
            (None, None) => 20.0,
        }
    }

    /// Time of the last knot, s.
    pub fn duration_s(&self) -> f64 {
        self.knots.last().map_or(0.0, |k| k.0)
    }
}

/// Builds a history knot by knot from its start.
struct Knots {
    knots: Vec<(f64, f64)>,
}

impl Knots {
    fn start(temp_c: f64) -> Self {
        Knots {
            knots: vec![(0.0, temp_c)],
        }
    }

    fn now(&self) -> (f64, f64) {
        *self.knots.last().expect("a history has a start")
    }

    fn hold(&mut self, duration_s: f64) {
        let (t, temp) = self.now();
        self.knots.push((t + duration_s, temp));
    }

    fn ramp_to(&mut self, temp_c: f64, c_per_min: f64) {
        let (t, temp) = self.now();
        self.knots.push((t + (temp_c - temp).abs() / c_per_min * 60.0, temp_c));
    }

    fn step_to(&mut self, temp_c: f64, transition_s: f64) {
        let (t, _) = self.now();
        self.knots.push((t + transition_s, temp_c));
    }

    /// A half-cosine from the current temperature to `temp_c` over `duration_s`.
    fn drift_to(&mut self, temp_c: f64, duration_s: f64) {
        let (t0, from) = self.now();
        let pieces = (duration_s / limits::SMOOTH_KNOT_S).ceil().max(1.0) as usize;
        for k in 1..=pieces {
            let x = k as f64 / pieces as f64;
            self.knots.push((
                t0 + x * duration_s,
                from + (temp_c - from) * 0.5 * (1.0 - (PI * x).cos()),
            ));
        }
    }

    fn done(self) -> Vec<(f64, f64)> {
        self.knots
    }
}

fn uniform(rng: &mut impl Rng, (lo, hi): (f64, f64)) -> f64 {
    rng.random_range(lo..=hi)
}

/// A draw from `range` at least [`limits::MIN_STEP_C`] away from `from`.
fn step_target(rng: &mut impl Rng, range: (f64, f64), from: f64) -> f64 {
    loop {
        let target = uniform(rng, range);
        if (target - from).abs() >= limits::MIN_STEP_C {
            return target;
        }
    }
}

fn through(set_points: &[f64], ramp_c_per_min: f64, hold_s: f64) -> Vec<(f64, f64)> {
    let mut knots = vec![(0.0, set_points[0]), (START_HOLD_S, set_points[0])];
    let mut t = START_HOLD_S;
    for w in set_points.windows(2) {
        t += (w[1] - w[0]).abs() / ramp_c_per_min * 60.0;
        knots.push((t, w[1]));
        t += hold_s;
        knots.push((t, w[1]));
    }
    knots
}

fn random(run: &ScheduleSpec, end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let (lo, hi) = run.random_range_c;
    let (slowest, fastest) = run.ramp_range_c_per_min;
    let start = 0.5 * (lo + hi);
    let mut knots = vec![(0.0, start), (START_HOLD_S, start)];
    let (mut t, mut temp) = (START_HOLD_S, start);
    // Steps of at least a fifth of the range (10 °C over −40 … 60 °C).
    let min_step = 0.2 * (hi - lo);
    while t < end_s {
        let next = loop {
            let candidate = rng.random_range(lo..=hi);
            if (candidate - temp).abs() >= min_step {
                break candidate;
            }
        };
        let ramp: f64 = rng.random_range(slowest..=fastest);
        t += (next - temp).abs() / ramp * 60.0;
        knots.push((t, next));
        t += rng.random_range(20.0..=90.0) * 60.0;
        knots.push((t, next));
        temp = next;
    }
    knots
}

/// A hold of `hold_s` at each of `levels_c` from power-on, ramps of `ramp_c_per_min` between.
fn soak(levels_c: &[f64], hold_s: f64, ramp_c_per_min: f64) -> Vec<(f64, f64)> {
    let Some((&first, rest)) = levels_c.split_first() else {
        return Vec::new();
    };
    let mut k = Knots::start(first);
    k.hold(hold_s);
    for &level in rest {
        k.ramp_to(level, ramp_c_per_min);
        k.hold(hold_s);
    }
    k.done()
}

fn designed(ramp_c_per_min: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let mut k = Knots::start(DESIGNED_LEVELS_C[0]);
    k.hold(uniform(rng, DESIGNED_HOLD_MIN) * 60.0);
    for &level in &DESIGNED_LEVELS_C[1..] {
        k.ramp_to(level, ramp_c_per_min);
        k.hold(uniform(rng, DESIGNED_HOLD_MIN) * 60.0);
    }
    k.done()
}

/// Power-on soaked cold; a warm-up there, then a step or a heated ramp to ambient.
fn cold_start(k: &mut Knots, rng: &mut impl Rng) {
    k.hold(uniform(rng, limits::WARM_UP_MIN) * 60.0);
    let ambient = uniform(rng, limits::COLD_START_AMBIENT_C);
    if rng.random_bool(0.5) {
        k.step_to(ambient, uniform(rng, limits::STEP_S));
    } else {
        k.ramp_to(ambient, uniform(rng, limits::HEATER_C_PER_MIN));
    }
}

/// `legs` swings about `centre`, alternating sides.
fn swings(k: &mut Knots, rng: &mut impl Rng, center: f64, legs: usize) {
    let mut side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let (lo, hi) = limits::AMBIENT_C;
    for _ in 0..legs {
        let target = (center + side * uniform(rng, limits::SWING_AMPLITUDE_C)).clamp(lo, hi);
        k.ramp_to(target, uniform(rng, limits::SWING_C_PER_MIN));
        k.hold(uniform(rng, limits::SWING_DWELL_MIN) * 60.0);
        side = -side;
    }
}

fn cold_start_history(end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let mut k = Knots::start(uniform(rng, limits::COLD_SOAK_C));
    cold_start(&mut k, rng);
    k.hold((end_s - k.now().0).max(0.0));
    k.done()
}

fn ambient_steps(end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let hangar = uniform(rng, limits::HANGAR_C);
    let mut k = Knots::start(hangar);
    k.hold(uniform(rng, limits::WARM_UP_MIN) * 60.0);
    while k.now().0 < end_s {
        let outside = step_target(rng, limits::OUTSIDE_C, hangar);
        k.step_to(outside, uniform(rng, limits::STEP_S));
        k.hold(uniform(rng, limits::DWELL_MIN) * 60.0);
        k.step_to(hangar, uniform(rng, limits::STEP_S));
        k.hold(uniform(rng, limits::DWELL_MIN) * 60.0);
    }
    k.done()
}

fn swings_history(end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let center = uniform(rng, limits::MEAN_C);
    let mut k = Knots::start(center);
    k.hold(uniform(rng, limits::WARM_UP_MIN) * 60.0);
    while k.now().0 < end_s {
        swings(&mut k, rng, center, 2);
    }
    k.done()
}

fn day_cycle(end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let mean = uniform(rng, limits::MEAN_C);
    let amplitude = uniform(rng, limits::DAY_AMPLITUDE_C);
    let phase = rng.random_range(0.0..2.0 * PI);
    let at = |t: f64| mean + amplitude * (2.0 * PI * t / limits::DAY_S + phase).sin();
    let pieces = (end_s / limits::SMOOTH_KNOT_S).ceil().max(1.0) as usize;
    (0..=pieces)
        .map(|i| {
            let t = i as f64 * limits::SMOOTH_KNOT_S;
            (t, at(t))
        })
        .collect()
}

/// A cold start, then steps, swing bursts and slow (day-cycle-like) drifts in random order.
fn field(end_s: f64, rng: &mut impl Rng) -> Vec<(f64, f64)> {
    let mut k = Knots::start(uniform(rng, limits::COLD_SOAK_C));
    cold_start(&mut k, rng);
    while k.now().0 < end_s {
        match rng.random_range(0..3u32) {
            0 => {
                let target = step_target(rng, limits::OUTSIDE_C, k.now().1);
                k.step_to(target, uniform(rng, limits::STEP_S));
                k.hold(uniform(rng, limits::DWELL_MIN) * 60.0);
            }
            1 => {
                let legs = rng.random_range(2..=6);
                let center = k.now().1;
                swings(&mut k, rng, center, legs);
                k.hold(uniform(rng, limits::DWELL_MIN) * 60.0);
            }
            _ => {
                let target = uniform(rng, limits::DRIFT_TO_C);
                k.drift_to(target, uniform(rng, limits::DRIFT_H) * 3600.0);
            }
        }
    }
    k.done()
}

/// What a schedule is drawn from: a simulated run's profile settings
/// (`ChamberRun::schedule_spec`).
#[derive(Clone, Copy, Debug)]
pub struct ScheduleSpec<'a> {
    /// The profile.
    pub profile: Profile,
    /// Total duration, s; `None`: the profile's own.
    pub duration_s: Option<f64>,
    /// Chamber ramp rate between set points, °C/min.
    pub ramp_c_per_min: f64,
    /// Hold at each set point, s (ifog and cycle profiles).
    pub hold_s: f64,
    /// Set-point range of random profiles, °C (min, max).
    pub random_range_c: (f64, f64),
    /// Ramp-rate range of random profiles, °C/min (slowest, fastest).
    pub ramp_range_c_per_min: (f64, f64),
    /// Chamber levels of soak runs, in order, °C.
    pub soak_levels_c: &'a [f64],
    /// Hold at each soak level, s.
    pub soak_hold_s: f64,
    /// The chamber profile of planned runs.
    pub planned: Option<&'a Schedule>,
}

/// The schedule `run` asks for (random, designed and in-use profiles draw from `rng`).
pub fn schedule(run: &ScheduleSpec, rng: &mut impl Rng) -> Schedule {
    let end_s = run.duration_s.or(run.profile.default_duration_s()).unwrap_or(0.0);
    let knots = match run.profile {
        Profile::Ifog => through(&[25.0, 10.0, 40.0, 25.0], run.ramp_c_per_min, run.hold_s),
        Profile::Cycle => through(&[20.0, -40.0, 60.0, -40.0, 60.0, 20.0], run.ramp_c_per_min, run.hold_s),
        Profile::Random => random(run, end_s, rng),
        Profile::Designed => designed(run.ramp_c_per_min, rng),
        Profile::ColdStart => cold_start_history(end_s, rng),
        Profile::AmbientSteps => ambient_steps(end_s, rng),
        Profile::Swings => swings_history(end_s, rng),
        Profile::DayCycle => day_cycle(end_s, rng),
        Profile::Field => field(end_s, rng),
        Profile::Planned => run.planned.map_or_else(Vec::new, |s| s.knots.clone()),
        Profile::Soak => soak(run.soak_levels_c, run.soak_hold_s, run.ramp_c_per_min),
    };
    Schedule { knots }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_pcg::Pcg64;

    use super::*;
    use crate::simulate::ChamberRun;

    fn knots_of(run: &ChamberRun) -> Vec<(f64, f64)> {
        schedule(&run.schedule_spec(), &mut Pcg64::seed_from_u64(run.seed)).knots
    }

    /// Each piece as (duration s, change °C), with its rate in °C/min.
    fn pieces(knots: &[(f64, f64)]) -> Vec<(f64, f64, f64)> {
        knots
            .windows(2)
            .map(|w| {
                let (dt, dc) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
                (dt, dc, if dt > 0.0 { dc.abs() / dt * 60.0 } else { 0.0 })
            })
            .collect()
    }

    fn within((lo, hi): (f64, f64), x: f64) -> bool {
        x >= lo - 1e-9 && x <= hi + 1e-9
    }

    #[test]
    fn in_use_histories_keep_their_documented_rates_and_ranges() {
        let in_use = [
            Profile::ColdStart,
            Profile::AmbientSteps,
            Profile::Swings,
            Profile::DayCycle,
            Profile::Field,
        ];
        for profile in in_use {
            let mut swing_legs = 0;
            for seed in 0..40 {
                let run = ChamberRun::with_profile(profile, seed);
                let knots = knots_of(&run);
                let what = format!("{profile:?} seed {seed}");
                assert_eq!(knots[0].0.to_bits(), 0f64.to_bits(), "{what}: starts at power-on");
                assert!(
                    knots.last().unwrap().0 >= profile.default_duration_s().unwrap(),
                    "{what}"
                );
                assert!(
                    knots.iter().all(|k| within(limits::AMBIENT_C, k.1)),
                    "{what}: {knots:?}"
                );
                for (dt, dc, rate) in pieces(&knots) {
                    assert!(dt >= 0.0, "{what}: time goes forward");
                    let step = within(limits::STEP_S, dt) && dc.abs() >= limits::MIN_STEP_C - 1e-9;
                    let held = dc == 0.0;
                    let ramp = rate <= limits::SWING_C_PER_MIN.1 + 1e-9;
                    assert!(held || step || ramp, "{what}: {dc} °C in {dt} s");
                    if !step && within(limits::SWING_C_PER_MIN, rate) {
                        swing_legs += 1;
                    }
                }
                match profile {
                    Profile::ColdStart | Profile::Field => {
                        assert!(within(limits::COLD_SOAK_C, knots[0].1), "{what}: soaked cold");
                        let warm_up_min = (knots[1].0 - knots[0].0) / 60.0;
                        assert!(
                            within(limits::WARM_UP_MIN, warm_up_min),
                            "{what}: warm-up {warm_up_min} min"
                        );
                        assert!(within(limits::COLD_START_AMBIENT_C, knots[2].1), "{what}");
                    }
                    Profile::AmbientSteps => {
                        // Nothing but holds and near-instant steps between hangar and outside.
                        for (dt, dc, _) in pieces(&knots[1..]) {
                            assert!(dc == 0.0 || within(limits::STEP_S, dt), "{what}: {dc} °C in {dt} s");
                        }
                    }
                    Profile::Swings => {
                        for (_, dc, rate) in pieces(&knots) {
                            assert!(
                                dc == 0.0 || within(limits::SWING_C_PER_MIN, rate),
                                "{what}: {rate} °C/min"
                            );
                        }
                        let center = knots[0].1;
                        let amplitude = limits::SWING_AMPLITUDE_C.1;
                        assert!(knots.iter().all(|k| (k.1 - center).abs() <= amplitude + 1e-9));
                    }
                    Profile::DayCycle => {
                        let fastest = 2.0 * PI * limits::DAY_AMPLITUDE_C.1 / limits::DAY_S * 60.0;
                        assert!(pieces(&knots).iter().all(|p| p.2 <= fastest), "{what}");
                    }
                    _ => unreachable!(),
                }
            }
            if matches!(profile, Profile::Swings | Profile::Field) {
                assert!(swing_legs > 40, "{profile:?}: {swing_legs} swing legs at 3 … 8 °C/min");
            }
        }
    }

    #[test]
    fn random_set_points_keep_the_asked_range_and_rates() {
        for seed in 0..40 {
            let run = ChamberRun {
                random_range_c: (-20.0, 50.0),
                ramp_range_c_per_min: (0.2, 3.0),
                duration_s: Some(8.0 * 3600.0),
                ..ChamberRun::with_profile(Profile::Random, seed)
            };
            let knots = knots_of(&run);
            assert!(knots.iter().all(|k| within((-20.0, 50.0), k.1)), "seed {seed}");
            for (_, dc, rate) in pieces(&knots) {
                assert!(dc == 0.0 || within((0.2, 3.0), rate), "seed {seed}: {rate} °C/min");
            }
        }
    }

    #[test]
    fn the_soak_test_holds_3_h_at_each_level_in_order_with_1_c_per_min_ramps() {
        let knots = knots_of(&ChamberRun::with_profile(Profile::Soak, 1));
        let holds: Vec<(f64, f64)> = pieces(&knots)
            .iter()
            .zip(&knots)
            .filter(|(p, _)| p.1 == 0.0)
            .map(|(p, k)| (k.1, p.0))
            .collect();
        assert_eq!(
            holds.iter().map(|h| h.0).collect::<Vec<_>>(),
            SOAK_LEVELS_C.to_vec(),
            "levels in order"
        );
        assert!(holds.iter().all(|h| (h.1 - SOAK_HOLD_S).abs() < 1e-9), "{holds:?}");
        for (_, dc, rate) in pieces(&knots) {
            assert!(dc == 0.0 || (rate - 1.0).abs() < 1e-9, "{rate} °C/min");
        }
        // 8 × 3 h of holds + 355 °C of ramps at 1 °C/min: 29.9 h, as design4/5_soak.csv.
        let hours = knots.last().unwrap().0 / 3600.0;
        assert!((hours - (24.0 + 355.0 / 60.0)).abs() < 1e-9, "{hours} h");
        let other = ChamberRun {
            soak_levels_c: vec![-10.0, 50.0],
            soak_hold_s: 3600.0,
            ..ChamberRun::with_profile(Profile::Soak, 1)
        };
        assert_eq!(
            knots_of(&other),
            vec![(0.0, -10.0), (3600.0, -10.0), (7200.0, 50.0), (10_800.0, 50.0)]
        );
    }

    #[test]
    fn the_designed_run_spans_minus_40_to_60_at_5_c_per_min_in_about_11_hours() {
        for seed in 0..20 {
            let knots = knots_of(&ChamberRun::designed(seed));
            assert_eq!(knots[0].1.to_bits(), (-20f64).to_bits(), "cold start at −20 °C");
            for (dt, dc, rate) in pieces(&knots) {
                if dc == 0.0 {
                    assert!(within(DESIGNED_HOLD_MIN, dt / 60.0), "hold {} min", dt / 60.0);
                } else {
                    assert!((rate - 5.0).abs() < 1e-9, "{rate} °C/min");
                }
            }
            let hours = knots.last().unwrap().0 / 3600.0;
            // 15 holds of 15 … 50 min: 10.9 h on average, σ ≈ 0.65 h.
            assert!((8.5..=13.5).contains(&hours), "{hours} h");
        }
        let levels: Vec<f64> = DESIGNED_LEVELS_C.to_vec();
        assert!(levels.contains(&-40.0) && levels.contains(&60.0));
    }
}
