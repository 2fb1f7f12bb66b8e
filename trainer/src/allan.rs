//! Overlapping Allan deviation of a rate series (IEEE Std 952 / 1554) and the
//! noise terms read off it.
//!
//! With angle θ_k = τ₀ Σ_{i<k} y_i (θ₀ = 0) and cluster time τ = mτ₀:
//! σ²(τ) = Σ_{k=0}^{N−2m} (θ_{k+2m} − 2θ_{k+m} + θ_k)² / (2 τ² (N − 2m + 1)),
//! N + 1 angle samples. The same arithmetic as allantools' `oadev` with
//! `data_type="freq"`, which the tests compare against.

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
    /// Bias instability: the floor of the curve / 0.664, °/h.
    pub bias_instability_dph: f64,
    /// τ at the floor, s.
    pub floor_tau_s: f64,
}

/// Flicker floor of the Allan deviation relative to the bias instability.
const FLICKER_FLOOR: f64 = 0.664;

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
    let (floor_index, floor) = adev
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, a)| a.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .unwrap_or((0, f64::NAN));
    AllanDeviation {
        floor_tau_s: tau.get(floor_index).copied().unwrap_or(f64::NAN),
        tau_s: tau,
        adev_dph: adev,
        arw_deg_per_sqrt_h: arw,
        bias_instability_dph: floor / FLICKER_FLOOR,
    }
}

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

    #[test]
    fn a_constant_rate_has_zero_allan_deviation_and_short_series_give_nan() {
        let a = oadev(&[5.0; 64], 1.0, &[1, 4]);
        assert!(a.iter().all(|v| v.abs() < 1e-12), "{a:?}");
        assert!(oadev(&[1.0, 2.0], 1.0, &[4])[0].is_nan());
        assert_eq!(octave_sizes(100), vec![1, 2, 4, 8, 16, 32]);
    }
}
