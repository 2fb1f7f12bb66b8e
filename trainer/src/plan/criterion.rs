//! A plan on the plant: the loop temperatures it drives ([`loop_temps`]), the
//! D-criterion of the lag-bank regression on them ([`d_criterion`]), how
//! loosely the response bank's regression on them pins the static curve
//! ([`static_curve_variance`]), the choice between candidates by both
//! ([`chosen`]), the slow plant ([`slowed`]) and the soaks the ends and the
//! power-on need ([`end_soak_s`], [`pre_soak_s`]).

use nalgebra::DMatrix;

use super::limits::*;
use crate::fit::response::{self, BLOCK_S};
use crate::reading::run::samples::Run;
use crate::simulate::SimParams;
use crate::simulate::plant::{LOOP_SENSOR, Plant, PlantParams};

/// Where the gyro waits before a plan, °C: the lab.
pub(super) const ROOM_C: f64 = 23.0;
/// The pre-soak ends when every node of the plant is this close to the air, °C.
pub(super) const PRE_SOAK_WITHIN_C: f64 = 0.1;

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

/// Settled temperatures [`static_curve_variance`] reads the static curve at:
/// this many, evenly from the lowest to the highest of the limits.
pub const STATIC_CURVE_LEVELS: usize = 8;

/// How loosely a run whose loop reads `temps_c` (1 s, from 0 s) pins the
/// static curve the response bank identifies
/// ([`response::static_curve_variance`], per unit variance of a block's
/// noise) at [`STATIC_CURVE_LEVELS`] levels over `limits`: a soak test's
/// settled spread after the default fit grows with it. Lower is better;
/// `None` where the bank cannot be built on the run.
pub fn static_curve_variance(temps_c: &[f64], limits: &PlanLimits) -> Option<f64> {
    let n = temps_c.len();
    let run = Run {
        path: "plan candidate".into(),
        time_s: (0..n).map(|i| i as f64).collect(),
        rate_dph: vec![0.0; n],
        temp_c: temps_c.iter().map(|&t| Some(t)).collect(),
        temps_c: Vec::new(),
        thermometers: rbf_core::thermometer::ThermometerSet::LOOP,
        ref_dph: Some(vec![0.0; n]),
        nominal_period_s: 1.0,
    };
    let (bank, blocks) = response::plain_bank_and_blocks(std::slice::from_ref(&run), BLOCK_S).ok()?;
    let step = (limits.max_c - limits.min_c) / (STATIC_CURVE_LEVELS - 1) as f64;
    let levels: Vec<f64> = (0..STATIC_CURVE_LEVELS)
        .map(|i| limits.min_c + step * i as f64)
        .collect();
    response::static_curve_variance(&bank, &blocks, &levels)
}

/// The candidate a plan keeps, by index into `scores` (each candidate's
/// D-criterion and static-curve variance): the least sum of its rank by the
/// D-criterion (highest first) and its rank by the variance (lowest first),
/// ties to the higher D-criterion. Candidates without a finite D-criterion
/// are never kept; one without a variance ranks last by it. With
/// `d_alone`, the highest D-criterion (`--plain`: the plans of before).
/// `None` if no candidate has a finite D-criterion.
pub fn chosen(scores: &[(f64, Option<f64>)], d_alone: bool) -> Option<usize> {
    let finite: Vec<usize> = (0..scores.len()).filter(|&i| scores[i].0.is_finite()).collect();
    let by_d = |a: &usize, b: &usize| scores[*b].0.total_cmp(&scores[*a].0);
    if d_alone {
        return finite.iter().copied().min_by(by_d);
    }
    let variance = |i: usize| scores[i].1.unwrap_or(f64::INFINITY);
    let rank_of = |order: &[usize]| {
        let mut rank = vec![0usize; scores.len()];
        for (r, &i) in order.iter().enumerate() {
            rank[i] = r;
        }
        rank
    };
    let mut d_order = finite.clone();
    d_order.sort_by(by_d);
    let mut v_order = finite.clone();
    v_order.sort_by(|&a, &b| variance(a).total_cmp(&variance(b)).then_with(|| by_d(&a, &b)));
    let (d_rank, v_rank) = (rank_of(&d_order), rank_of(&v_order));
    finite.iter().copied().min_by(|&a, &b| {
        (d_rank[a] + v_rank[a])
            .cmp(&(d_rank[b] + v_rank[b]))
            .then_with(|| by_d(&a, &b))
    })
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
pub(super) fn range_of(temps_c: &[f64]) -> (f64, f64) {
    temps_c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
        (lo.min(t), hi.max(t))
    })
}

impl PlanLimits {
    /// The shortest run a plan that soaks at the ends needs, h: the
    /// power-on soak at the cold end (the unit is soaked there before it),
    /// a full-range ramp at the fastest rate and a soak at the hot end
    /// ([`end_soak_s`]) long enough for the loop to reach it.
    pub fn shortest_hours_soaking_ends(&self) -> f64 {
        let ramp_s = ramp_seconds(self.max_c - self.min_c, self.max_rate_c_per_min);
        (WARM_UP_S.0 + ramp_s + end_soak_s(self)) / 3600.0
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
