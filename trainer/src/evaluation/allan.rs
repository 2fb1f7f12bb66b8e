//! Overlapping Allan deviation of a rate series (IEEE Std 952 / 1554) and the
//! noise terms read off it.
//!
//! With angle θ_k = τ₀ Σ_{i<k} y_i (θ₀ = 0) and cluster time τ = mτ₀:
//! σ²(τ) = Σ_{k=0}^{N−2m} (θ_{k+2m} − 2θ_{k+m} + θ_k)² / (2 τ² (N − 2m + 1)),
//! N + 1 angle samples. The same arithmetic as allantools' `oadev` with
//! `data_type="freq"`, which the tests compare against.
//!
//! The bias instability is read by one rule ([`read_floor`]), the same for
//! `trainer eval`, `trainer fit` and `trainer report`, among the cluster
//! times whose estimate is confident, τ ≤ T/10 (T the run's length; there
//! the 1-σ uncertainty u of σ is at most 24 %, [`relative_error`]):
//!
//! - **a floor** where the curve has flattened: the lowest σ of the first
//!   flat stretch from short τ on (three or more octave points joined by
//!   slopes within τ^±¼; white rate noise falls as τ^−½, a flicker floor is
//!   flat, the simulator's Gauss–Markov instability is a flat hump that
//!   falls again past its correlation time, so the stretch, not the
//!   curve's minimum, is its floor) that stands above the white-noise line
//!   q/√τ (q the lowest σ·√τ up to that τ) by more than 2u: bias
//!   instability = σ/0.664 (IEEE Std 952, flicker floor) ± u;
//! - **no floor** otherwise (white noise still dominant at T/10, a flat
//!   stretch within white noise's scatter, or a V into rate random walk):
//!   the figure is the lowest confident σ / 0.664, an upper bound of the
//!   bias instability (`≤` in tables, "no floor above the white noise by
//!   τ … (T/10)" on the plot).
//!
//! Noise-only simulated runs of 4, 12 and 24 h with a known bias
//! instability confirm it within u (`trainer/tests/cli_tests/figures.rs`).

use serde::Serialize;

/// Allan deviation at octave-spaced cluster times, with read-offs.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AllanDeviation {
    /// Cluster times τ, s.
    pub tau_s: Vec<f64>,
    /// Overlapping Allan deviation at each τ, °/h.
    pub adev_dph: Vec<f64>,
    /// Angle random walk read on the τ^−½ slope, °/√h.
    pub arw_deg_per_sqrt_h: f64,
    /// Bias instability, °/h: the lowest σ of the first flat stretch within
    /// the confident τ / 0.664 when [`Self::floor_reached`]; else an upper
    /// bound, the lowest confident σ / 0.664 (see the module docs).
    pub bias_instability_dph: f64,
    /// τ of the floor (or of the lowest confident σ), s.
    pub floor_tau_s: f64,
    /// Whether the curve reached a flat minimum within τ ≤ T/10.
    pub floor_reached: bool,
    /// 1-σ relative uncertainty of σ at [`Self::floor_tau_s`], % ([`relative_error`]).
    pub floor_uncertainty_pct: f64,
    /// Longest confident cluster time, T/10 of the run's length T, s.
    pub confident_tau_max_s: f64,
}

/// Flicker floor of the Allan deviation relative to the bias instability.
pub const FLICKER_FLOOR: f64 = 0.664;

/// Fewest independent clusters (T/τ) for a confident σ(τ): 10, i.e. a 1-σ
/// uncertainty of at most 1/√18 ≈ 24 % ([`relative_error`]).
pub const CONFIDENT_CLUSTERS: f64 = 10.0;

/// Steepest log-log slope within a flat stretch: white rate noise
/// falls as τ^−½ and rate random walk rises as τ^+½; a flicker floor is flat.
pub const FLAT_SLOPE: f64 = 0.25;

/// Relative 1-σ uncertainty of an Allan deviation at cluster time `tau_s`
/// from a run `duration_s` long: 1/√(2(T/τ − 1)), the approximation of
/// IEEE Std 952 (Annex C) with T/τ independent clusters. Conservative for the
/// overlapping estimator, whose equivalent degrees of freedom are more.
/// Infinite when the run holds fewer than two clusters.
pub fn relative_error(tau_s: f64, duration_s: f64) -> f64 {
    let clusters = duration_s / tau_s;
    if clusters > 1.0 {
        1.0 / (2.0 * (clusters - 1.0)).sqrt()
    } else {
        f64::INFINITY
    }
}

/// Where the bias instability is read on a curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floor {
    /// Index of the reading in the curve.
    pub index: usize,
    /// Whether the minimum is flat ([`FLAT_SLOPE`]) within the confident τ.
    pub reached: bool,
}

/// The bias-instability reading of a curve σ(τ) from a run `duration_s`
/// long (the module docs' rule): the lowest σ of the first flat stretch
/// among τ ≤ T/10 (reached), or else the lowest σ there (not reached).
/// `None` when no τ is confident.
pub fn read_floor(tau_s: &[f64], adev_dph: &[f64], duration_s: f64) -> Option<Floor> {
    let confident: Vec<usize> = (0..tau_s.len().min(adev_dph.len()))
        .filter(|&i| tau_s[i] * CONFIDENT_CLUSTERS <= duration_s && adev_dph[i].is_finite() && adev_dph[i] > 0.0)
        .collect();
    let lowest = |positions: &[usize]| {
        positions
            .iter()
            .copied()
            .min_by(|&a, &b| adev_dph[a].total_cmp(&adev_dph[b]))
    };
    let slope = |a: usize, b: usize| (adev_dph[b] / adev_dph[a]).ln() / (tau_s[b] / tau_s[a]).ln();
    // White rate noise alone, σ = q/√τ: q the lowest σ·√τ up to τ (any
    // other noise only adds to it).
    let white_dph = |upto: usize| {
        confident
            .iter()
            .filter(|&&i| i <= upto)
            .map(|&i| adev_dph[i] * tau_s[i].sqrt())
            .fold(f64::INFINITY, f64::min)
            / tau_s[upto].sqrt()
    };
    // A floor stands above the white noise by more than twice its 1-σ
    // uncertainty; flat within that, the curve may be white noise's scatter.
    let above_white = |i: usize| adev_dph[i] > white_dph(i) * (1.0 + 2.0 * relative_error(tau_s[i], duration_s));
    // The flat stretches from short τ on: neighbours joined by slopes
    // within ±FLAT_SLOPE, at least FLAT_POINTS of them; the first whose
    // lowest σ stands above the white noise is the floor.
    let mut stretches: Vec<(usize, usize)> = Vec::new();
    let mut open: Option<(usize, usize)> = None;
    for p in 0..confident.len().saturating_sub(1) {
        let flat = slope(confident[p], confident[p + 1]).abs() <= FLAT_SLOPE;
        open = match (flat, open) {
            (true, None) => Some((p, p + 1)),
            (true, Some((first, _))) => Some((first, p + 1)),
            (false, Some(s)) => {
                stretches.push(s);
                None
            }
            (false, None) => None,
        };
    }
    stretches.extend(open);
    let floor = stretches
        .into_iter()
        .filter(|(first, last)| last - first + 1 >= FLAT_POINTS)
        .filter_map(|(first, last)| lowest(&confident[first..=last]))
        .find(|&i| above_white(i));
    match floor {
        Some(index) => Some(Floor { index, reached: true }),
        None => Some(Floor {
            index: lowest(&confident)?,
            reached: false,
        }),
    }
}

/// Fewest octave points of a flat stretch: two slopes, so that one
/// estimate's scatter (up to 24 % at T/10) does not make a floor.
pub const FLAT_POINTS: usize = 3;

/// Overlapping Allan deviation of `rate_dph` sampled every `tau0_s` at cluster sizes `m`.
pub fn oadev(rate_dph: &[f64], tau0_s: f64, m: &[usize]) -> Vec<f64> {
    let mut theta = Vec::with_capacity(rate_dph.len() + 1);
    theta.push(0.0);
    let mut acc = 0.0;
    for &y in rate_dph {
        acc += y;
        theta.push(acc * tau0_s);
    }
    let n = theta.len();
    m.iter()
        .map(|&m| {
            if m == 0 || n < 2 * m + 1 {
                return f64::NAN;
            }
            let terms = n - 2 * m;
            let sum: f64 = (0..terms)
                .map(|k| (theta[k + 2 * m] - 2.0 * theta[k + m] + theta[k]).powi(2))
                .sum();
            let tau = m as f64 * tau0_s;
            (sum / (2.0 * tau * tau * terms as f64)).sqrt()
        })
        .collect()
}

/// Most values an Allan series keeps before [`Decimated`] halves it (2^20:
/// 8 MiB; runs up to this many samples are analysed at full rate).
pub const MAX_ALLAN_POINTS: usize = 1 << 20;

/// A rate series kept for the Allan deviation, sample by sample, in bounded
/// memory: past [`MAX_ALLAN_POINTS`] values, adjacent pairs are averaged and
/// the base interval doubles (the Allan deviation is then known from τ of
/// twice the previous base on, which long runs do not miss).
#[derive(Clone, Debug, Default)]
pub struct Decimated {
    values: Vec<f64>,
    factor: usize,
    pending_sum: f64,
    pending: usize,
}

impl Decimated {
    /// An empty series.
    pub fn new() -> Self {
        Decimated {
            factor: 1,
            ..Decimated::default()
        }
    }

    /// Takes the next sample.
    pub fn push(&mut self, v: f64) {
        self.pending_sum += v;
        self.pending += 1;
        if self.pending < self.factor {
            return;
        }
        self.values.push(self.pending_sum / self.factor as f64);
        (self.pending_sum, self.pending) = (0.0, 0);
        if self.values.len() >= MAX_ALLAN_POINTS {
            self.values = self.values.chunks_exact(2).map(|p| 0.5 * (p[0] + p[1])).collect();
            self.factor *= 2;
        }
    }

    /// The series and how many samples each value averages.
    pub fn finish(self) -> (Vec<f64>, usize) {
        (self.values, self.factor)
    }
}

/// Octave cluster sizes 1, 2, 4, … leaving at least 8 terms in the sum.
pub fn octave_sizes(samples: usize) -> Vec<usize> {
    std::iter::successors(Some(1usize), |m| m.checked_mul(2))
        .take_while(|&m| samples + 1 >= 2 * m + 8)
        .collect()
}

/// The Allan deviation at octave τ and its ARW and bias-instability read-offs.
pub fn analyse(rate_dph: &[f64], tau0_s: f64) -> AllanDeviation {
    let m = octave_sizes(rate_dph.len());
    let adev = oadev(rate_dph, tau0_s, &m);
    let tau: Vec<f64> = m.iter().map(|&m| m as f64 * tau0_s).collect();
    // ARW: σ(τ)·√(τ/3600 s/h) where the local slope is close to −½ (white rate
    // noise); else at the shortest τ.
    let mut arw_estimates = Vec::new();
    for i in 0..tau.len().saturating_sub(1) {
        let slope = (adev[i + 1] / adev[i]).ln() / (tau[i + 1] / tau[i]).ln();
        if (-0.6..=-0.4).contains(&slope) {
            arw_estimates.push(adev[i] * (tau[i] / 3600.0).sqrt());
        }
    }
    arw_estimates.sort_by(f64::total_cmp);
    let arw = arw_estimates
        .get(arw_estimates.len() / 2)
        .copied()
        .unwrap_or_else(|| adev.first().map_or(f64::NAN, |a| a * (tau[0] / 3600.0).sqrt()));
    let duration_s = rate_dph.len() as f64 * tau0_s;
    let floor = read_floor(&tau, &adev, duration_s);
    let floor_tau_s = floor.map_or(f64::NAN, |f| tau[f.index]);
    AllanDeviation {
        bias_instability_dph: floor.map_or(f64::NAN, |f| adev[f.index] / FLICKER_FLOOR),
        floor_tau_s,
        floor_reached: floor.is_some_and(|f| f.reached),
        floor_uncertainty_pct: 100.0 * relative_error(floor_tau_s, duration_s),
        confident_tau_max_s: duration_s / CONFIDENT_CLUSTERS,
        tau_s: tau,
        adev_dph: adev,
        arw_deg_per_sqrt_h: arw,
    }
}

impl AllanDeviation {
    /// The bias instability as a table cell: `1.23e-3`, or `≤1.23e-3` when
    /// no floor was reached (an upper bound), or `—` without a confident τ.
    pub fn bias_instability_cell(&self) -> String {
        let v = self.bias_instability_dph;
        match (v.is_finite(), self.floor_reached) {
            (false, _) => "—".to_owned(),
            (true, true) => format!("{v:.2e}"),
            (true, false) => format!("≤{v:.2e}"),
        }
    }
}

/// The rule the bias-instability figures follow, for table footnotes.
pub const FLOOR_RULE: &str = "BI: σ(τ)/0.664 at the first flat stretch of the Allan curve among τ ≤ T/10 that stands \
                              above the white noise by more than twice its uncertainty (IEEE 952; ± its 1-σ uncertainty); \
                              ≤: no such floor, the lowest σ/0.664 there bounds it";

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    #[test]
    fn white_rate_noise_reads_back_its_angle_random_walk() {
        // ARW 0.01 °/√h at 10 Hz: σ = 60 · 0.01 · √10 °/h per sample.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let sigma = 60.0 * 0.01 * 10f64.sqrt();
        let y: Vec<f64> = (0..200_000)
            .map(|_| sigma * Distribution::<f64>::sample(&StandardNormal, &mut rng))
            .collect();
        let a = analyse(&y, 0.1);
        assert!(
            (a.arw_deg_per_sqrt_h - 0.01).abs() < 0.0005,
            "ARW {}",
            a.arw_deg_per_sqrt_h
        );
        // White noise: σ(τ) ∝ τ^−½ all the way down.
        let ratio = a.adev_dph[0] / a.adev_dph[6];
        assert!((ratio - 8.0).abs() < 0.4, "σ(0.1 s)/σ(6.4 s) = {ratio}");
    }

    /// White rate noise of ARW `arw` °/√h plus the simulator's bias
    /// instability `bi_dph` (a Gauss–Markov process of correlation 600 s
    /// whose Allan peak is 0.664·BI), at 1 Hz for `seconds`.
    fn noise(arw: f64, bi_dph: f64, seconds: usize, seed: u64) -> Vec<f64> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let mut normal = || Distribution::<f64>::sample(&StandardNormal, &mut rng);
        let phi = (-1.0f64 / 600.0).exp();
        let drive = FLICKER_FLOOR * bi_dph / 0.62 * (1.0 - phi * phi).sqrt();
        let mut gm = 0.0;
        (0..seconds)
            .map(|_| {
                gm = phi * gm + drive * normal();
                gm + 60.0 * arw * normal()
            })
            .collect()
    }

    #[test]
    fn the_floor_is_read_where_the_estimate_is_confident_or_said_not_reached() {
        // White noise alone on a 4-h run: the curve falls to its last τ and
        // beyond T/10; no floor, and the bound is read at τ ≤ T/10.
        let a = analyse(&noise(0.001, 0.0, 4 * 3600, 5), 1.0);
        assert!(a.floor_tau_s <= 1440.0, "read at τ {} s of a 4-h run", a.floor_tau_s);
        assert!(!a.floor_reached, "{a:?}");
        assert_eq!(a.bias_instability_cell(), format!("≤{:.2e}", a.bias_instability_dph));
        assert!(a.floor_uncertainty_pct <= 25.0, "{}", a.floor_uncertainty_pct);
        // A bias instability of 1e-3 °/h above quiet white noise, 8 h: a floor, near the truth.
        for seed in [1, 2, 3] {
            let a = analyse(&noise(0.0001, 0.001, 8 * 3600, seed), 1.0);
            assert!(a.floor_reached, "seed {seed}: {a:?}");
            assert!(a.floor_tau_s <= 2880.0, "seed {seed}: τ {}", a.floor_tau_s);
            assert!(
                (0.6e-3..=1.5e-3).contains(&a.bias_instability_dph),
                "seed {seed}: BI {} against 1e-3",
                a.bias_instability_dph
            );
        }
    }

    #[test]
    fn a_minimum_that_falls_in_or_rises_out_steeply_is_no_floor() {
        let tau: Vec<f64> = (0..12).map(|k| f64::from(1 << k)).collect();
        let flat: Vec<f64> = tau.iter().map(|t| (1e-4 / t + 1e-6f64).sqrt()).collect();
        let floor = read_floor(&tau, &flat, 1e5).unwrap();
        assert!(floor.reached && tau[floor.index] >= 64.0, "{floor:?}");
        // White noise turning into rate random walk at 64 s: a V, not a floor.
        let vee: Vec<f64> = tau
            .iter()
            .map(|t| 1e-2 / t.min(64.0).sqrt() * (t / 64.0).max(1.0).sqrt())
            .collect();
        assert!(!read_floor(&tau, &vee, 1e5).unwrap().reached);
        // Nothing confident in a run shorter than 10 τ₀.
        assert_eq!(read_floor(&tau, &flat, 5.0), None);
    }

    #[test]
    fn a_constant_rate_has_zero_allan_deviation_and_short_series_give_nan() {
        let a = oadev(&[5.0; 64], 1.0, &[1, 4]);
        assert!(a.iter().all(|v| v.abs() < 1e-12), "{a:?}");
        assert!(oadev(&[1.0, 2.0], 1.0, &[4])[0].is_nan());
        assert_eq!(octave_sizes(100), vec![1, 2, 4, 8, 16, 32]);
    }
}
