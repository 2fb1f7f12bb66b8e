//! Chamber set-point schedules (docs/simulator.md, "Profiles").

use rand::Rng;

use super::ChamberRun;

/// The chamber protocols.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Profile {
    /// IFOG paper: 25 °C, down to 10 °C, hold, up to 40 °C, hold, back to 25 °C.
    Ifog,
    /// RLG paper: 20 → −40 → 60 → −40 → 60 → 20 °C with holds.
    Cycle,
    /// Random set points (within a range, default −40 … 60 °C), ramp rates (0.5 … 5 °C/min)
    /// and holds (20 … 90 min).
    Random,
}

impl Profile {
    /// Name as written in the metadata.
    pub fn name(self) -> &'static str {
        match self {
            Profile::Ifog => "ifog",
            Profile::Cycle => "cycle",
            Profile::Random => "random",
        }
    }
}

/// Hold at the start of every profile (power-on self-heating settles), s.
const START_HOLD_S: f64 = 3600.0;
/// Default length of a random profile, s.
const RANDOM_DURATION_S: f64 = 8.0 * 3600.0;

/// A piecewise-linear chamber air temperature.
#[derive(Clone, Debug)]
pub struct Schedule {
    knots: Vec<(f64, f64)>,
}

impl Schedule {
    /// Chamber air at time `t`, °C (the last value holds after the end).
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

/// The schedule of `run` (random profiles draw from `rng`).
pub fn schedule(run: &ChamberRun, rng: &mut impl Rng) -> Schedule {
    let knots = match run.profile {
        Profile::Ifog => through(&[25.0, 10.0, 40.0, 25.0], run.ramp_c_per_min, run.hold_s),
        Profile::Cycle => through(&[20.0, -40.0, 60.0, -40.0, 60.0, 20.0], run.ramp_c_per_min, run.hold_s),
        Profile::Random => {
            let end = run.duration_s.unwrap_or(RANDOM_DURATION_S);
            let (lo, hi) = run.random_range_c;
            let start = 0.5 * (lo + hi);
            let mut knots = vec![(0.0, start), (START_HOLD_S, start)];
            let (mut t, mut temp) = (START_HOLD_S, start);
            // Steps of at least a fifth of the range (10 °C over −40 … 60 °C).
            let min_step = 0.2 * (hi - lo);
            while t < end {
                let next = loop {
                    let candidate = rng.random_range(lo..=hi);
                    if (candidate - temp).abs() >= min_step {
                        break candidate;
                    }
                };
                let ramp: f64 = rng.random_range(0.5..=5.0);
                t += (next - temp).abs() / ramp * 60.0;
                knots.push((t, next));
                t += rng.random_range(20.0..=90.0) * 60.0;
                knots.push((t, next));
                temp = next;
            }
            knots
        }
    };
    Schedule { knots }
}
