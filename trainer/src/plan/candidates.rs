//! The candidate plans: segments drawn from the family the lag bank needs to see
//! ([`candidate`]), or the same soaking at both ends of the range and in
//! its interior bands ([`candidate_soaking`]), on whole minutes and reachable set points, cut to the
//! longest run the limits allow.

use rand::Rng;

use super::limits::*;
use crate::fit::coverage::{BAND_C, band_count};

/// Builds a segment list up to a time budget.
#[derive(Clone)]
pub(super) struct Builder<'a> {
    pub(super) limits: &'a PlanLimits,
    pub(super) segments: Vec<Segment>,
    pub(super) now_c: f64,
    pub(super) t_s: f64,
    /// Each end's soak: every drawn move to an end holds there at least this long.
    pub(super) end_soak_s: Option<f64>,
    /// The soaks still to hold ([`Station`]); a drawn move into one holds its soak.
    pub(super) stations_left: Vec<Station>,
}

impl Builder<'_> {
    /// Draws one move of the design family with `rng` and appends it: a
    /// burst of swings at the full rate about a centre near the current
    /// level, legs alternating sides, or a move to another level, slow or
    /// fast. A move to a level a station still to hold covers
    /// ([`Self::stations_left`]) holds there at least the station's soak, for
    /// the loop to settle, and the station is held.
    pub(super) fn draw_move(&mut self, rng: &mut impl Rng) {
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
            let center = self.now_c.clamp(l.min_c + reach, l.max_c - reach);
            let mut side = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            for _ in 0..legs {
                let amp = span * rng.random_range(SWING_AMPLITUDE.0..=SWING_AMPLITUDE.1);
                self.ramp_hold(center + side * amp, r, rng.random_range(0.0..=300.0));
                side = -side;
            }
            self.ramp_hold(center, r, hold_s);
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
        let at = set_point(target, l);
        let mut hold_s = match self.end_soak_s {
            Some(soak_s) if is_end(at, l) => hold_s.max(soak_s),
            _ => hold_s,
        };
        if let Some(i) = self.stations_left.iter().position(|s| s.covers(at)) {
            hold_s = hold_s.max(self.stations_left.remove(i).soak_s);
        }
        self.ramp_hold(target, rate, hold_s);
    }

    pub(super) fn ramp_hold(&mut self, target_c: f64, rate: f64, hold_s: f64) {
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

    pub(super) fn hold(&mut self, hold_s: f64) {
        let hold_s = whole_minutes(hold_s);
        if let Some(last) = self.segments.last_mut() {
            last.hold_s += hold_s;
        }
        self.t_s += hold_s;
    }
}

/// Whether set point `c` is `level_c` (a set point rounds to 0.01 °C).
fn is_at(c: f64, level_c: f64) -> bool {
    (c - level_c).abs() < 0.006
}

/// Whether `c` is an end of the range (a set point rounds to 0.01 °C).
pub(super) fn is_end(c: f64, l: &PlanLimits) -> bool {
    is_at(c, l.min_c) || is_at(c, l.max_c)
}

/// A soak a candidate holds once besides its drawn moves: at an end of the
/// range, or in the middle of an interior [`BAND_C`] band (the bands `trainer
/// fit` asks a settled level in, `fit::coverage::bands_without_level_c`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Station {
    /// Lowest set point that holds it, °C.
    pub(super) lo_c: f64,
    /// Highest set point that holds it, °C: excluded for a band; an end's
    /// is its `lo_c`.
    pub(super) hi_c: f64,
    /// Whether it is an end of the range (held only there).
    pub(super) is_end: bool,
    /// Where the candidate goes when it has not held it by the end, °C.
    pub(super) target_c: f64,
    /// How long it holds there, s.
    pub(super) soak_s: f64,
}

impl Station {
    /// An end of the range, soaked `soak_s`.
    fn end(c: f64, soak_s: f64) -> Station {
        Station {
            lo_c: c,
            hi_c: c,
            is_end: true,
            target_c: c,
            soak_s,
        }
    }

    /// Whether a hold at set point `c` holds this station.
    pub(super) fn covers(&self, c: f64) -> bool {
        if self.is_end {
            is_at(c, self.lo_c)
        } else {
            c >= self.lo_c && c < self.hi_c
        }
    }
}

/// How far from a band's centre a set point holds the band's soak, °C: the
/// middle half of the band. A soak at a band's edge can settle the loop in
/// the band beside it (self-heating lifts the loop above the air; measured on
/// the 24-h plan of seed 1, docs/decisions.md "Band soaks (issue 48)").
pub(super) const BAND_MIDDLE_C: f64 = 0.25 * BAND_C;

/// The stations of a soaking candidate under `l`: the cold end soaked
/// `end_soak_s`, the hot end `hot_end_soak_s`, and with `band_soak_s` each
/// interior [`BAND_C`] band of the range (all but the two that hold the
/// ends) in its middle half ([`BAND_MIDDLE_C`]), visited at its centre.
pub(super) fn stations(l: &PlanLimits, end_soak_s: f64, hot_end_soak_s: f64, band_soak_s: Option<f64>) -> Vec<Station> {
    let mut out = vec![Station::end(l.min_c, end_soak_s), Station::end(l.max_c, hot_end_soak_s)];
    if let Some(soak_s) = band_soak_s {
        out.extend((1..interior_bands(l) + 1).map(|b| {
            let centre_c = l.min_c + (b as f64 + 0.5) * BAND_C;
            Station {
                lo_c: centre_c - BAND_MIDDLE_C,
                hi_c: centre_c + BAND_MIDDLE_C,
                is_end: false,
                target_c: set_point(centre_c, l),
                soak_s,
            }
        }));
    }
    out
}

/// Interior [`BAND_C`] bands of the range: those between the two that hold its ends.
pub fn interior_bands(l: &PlanLimits) -> usize {
    band_count(l.min_c, l.max_c).saturating_sub(2)
}

/// `left` in the order the candidate visits them from `now_c`: each time the
/// nearest still left.
pub(super) fn route(now_c: f64, left: &[Station]) -> Vec<Station> {
    let mut left = left.to_vec();
    let mut at = now_c;
    let mut out = Vec::with_capacity(left.len());
    while let Some(i) =
        (0..left.len()).min_by(|&a, &b| (left[a].target_c - at).abs().total_cmp(&(left[b].target_c - at).abs()))
    {
        let s = left.remove(i);
        at = s.target_c;
        out.push(s);
    }
    out
}

/// Seconds to hold `left` from `now_c` in [`route`]'s order at the full rate.
pub(super) fn visits_s(l: &PlanLimits, now_c: f64, left: &[Station]) -> f64 {
    let mut at = now_c;
    let mut s = 0.0;
    for st in route(now_c, left) {
        if (st.target_c - at).abs() >= 0.01 {
            s += ramp_seconds(st.target_c - at, l.max_rate_c_per_min);
        }
        s += whole_minutes(st.soak_s);
        at = st.target_c;
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
        end_soak_s: None,
        stations_left: Vec::new(),
    };
    b.t_s = b.segments[0].hold_s;
    while b.t_s < end_s {
        b.draw_move(rng);
    }
    cut(b.segments, end_s)
}

/// One candidate of the design family, drawn with `rng`, cut to the time
/// budget, with a soak of at least `end_soak_s` at each end of the range
/// and, with `band_soak_s`, one of at least that in each interior
/// [`BAND_C`] band (`trainer plan`'s default, `--band-soaks` and
/// `--soak-ends`; without end soaks, [`candidate`]). The power-on soak counts for
/// the cold end when it starts there: the unit is soaked before it. With
/// `pooled_hot_end_soak_s` (the ends pooled, [`super::ends::Ends::pools_ends`])
/// it always starts there and the hot end soaks that long instead. A move is
/// drawn only while the stations not yet held still fit in the budget after
/// it; then they are visited, nearest first, at the full rate.
pub fn candidate_soaking(
    limits: &PlanLimits,
    end_soak_s: f64,
    pooled_hot_end_soak_s: Option<f64>,
    band_soak_s: Option<f64>,
    rng: &mut impl Rng,
) -> Vec<Segment> {
    let l = limits;
    let span = l.max_c - l.min_c;
    let level = |k: usize| l.min_c + span * k as f64 / (LEVELS - 1) as f64;
    let r = l.max_rate_c_per_min;
    let end_s = (l.hours * 3600.0 / TENTH_MIN_S).floor() * TENTH_MIN_S;
    let pooled_ends = pooled_hot_end_soak_s.is_some();
    let all = stations(l, end_soak_s, pooled_hot_end_soak_s.unwrap_or(end_soak_s), band_soak_s);
    // Held by the power-on soak at `start`: the cold end, when it starts there.
    let left_after_start =
        |start: f64| -> Vec<Station> { all.iter().copied().filter(|s| !(s.is_end && s.covers(start))).collect() };
    // Cold start: soaked in the lowest fifth of the range; at its bottom
    // with pooled ends, or when the budget has no room for a soak there later.
    let drawn = set_point(level(rng.random_range(0..=2)), l);
    let fits = |start: f64| WARM_UP_S.0 + visits_s(l, start, &left_after_start(start)) <= end_s;
    let start = if fits(drawn) && !pooled_ends {
        drawn
    } else {
        set_point(l.min_c, l)
    };
    let stations_left = left_after_start(start);
    let need_s = visits_s(l, start, &stations_left);
    let warm_up_s =
        whole_minutes(rng.random_range(WARM_UP_S.0..=WARM_UP_S.1)).min(floor_minutes(end_s - need_s).max(0.0));
    let mut b = Builder {
        limits: l,
        segments: vec![Segment {
            target_c: start,
            ramp_s: 0.0,
            hold_s: warm_up_s,
        }],
        now_c: start,
        t_s: 0.0,
        end_soak_s: Some(end_soak_s),
        stations_left,
    };
    b.t_s = b.segments[0].hold_s;
    while b.t_s < end_s {
        let before = b.clone();
        b.draw_move(rng);
        let need_s = visits_s(l, b.now_c, &b.stations_left);
        let held_now = b.stations_left.len() != before.stations_left.len();
        if b.t_s + need_s > end_s && (need_s > 0.0 || held_now) {
            // This move leaves no room for the stations (or its own soak
            // runs past the budget): drop it and visit them instead.
            b = before;
            break;
        }
    }
    for s in route(b.now_c, &b.stations_left) {
        b.ramp_hold(s.target_c, r, s.soak_s);
    }
    cut(b.segments, end_s)
}

/// `segments` cut to end at or before `end_s`: a hold is shortened, a ramp
/// that would run past the end is dropped and the hold before it extended.
pub(super) fn cut(mut segments: Vec<Segment>, end_s: f64) -> Vec<Segment> {
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
