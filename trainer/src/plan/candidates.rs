//! The candidate plans: segments drawn from the family the lag bank needs to see
//! ([`candidate`]), or the same soaking at both ends of the range
//! ([`candidate_soaking_ends`]), on whole minutes and reachable set points, cut to the
//! longest run the limits allow.

use rand::Rng;

use super::limits::*;

/// Builds a segment list up to a time budget.
#[derive(Clone)]
pub(super) struct Builder<'a> {
    pub(super) limits: &'a PlanLimits,
    pub(super) segments: Vec<Segment>,
    pub(super) now_c: f64,
    pub(super) t_s: f64,
}

impl Builder<'_> {
    /// Draws one move of the design family with `rng` and appends it: a
    /// burst of swings at the full rate about a centre near the current
    /// level, legs alternating sides, or a move to another level, slow or
    /// fast. With `end_soak_s` (`--soak-ends`), a move to an end of the
    /// range holds there at least that long, for the loop to settle.
    pub(super) fn draw_move(&mut self, rng: &mut impl Rng, end_soak_s: Option<f64>) {
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
        let hold_s = match end_soak_s {
            Some(soak_s) if is_end(set_point(target, l), l) => hold_s.max(soak_s),
            _ => hold_s,
        };
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

/// Whether `c` is an end of the range (a set point rounds to 0.01 °C).
pub(super) fn is_end(c: f64, l: &PlanLimits) -> bool {
    (c - l.min_c).abs() < 0.006 || (c - l.max_c).abs() < 0.006
}

/// The ends of the range still to visit from `now_c`, nearest first.
pub(super) fn ends_left(l: &PlanLimits, now_c: f64, low_left: bool, high_left: bool) -> Vec<f64> {
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
pub(super) fn visits_s(l: &PlanLimits, now_c: f64, ends: &[f64], end_soak_s: f64) -> f64 {
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
