//! Accuracy figures a gyro engineer reads.
//!
//! - MSD, IFOG paper Eq. 24: mean squared deviation of the 1-s means of the
//!   output from the known rate (`ref_dph`); with no reference, from the
//!   output's own mean (so it is the variance of the 1-s means), °²/h².
//! - Bias STD of 100-s cluster means, RLG paper: the standard deviation
//!   (n − 1) of the means of consecutive 100-s clusters of `output − reference`, °/h.

/// 1-s averaging for the MSD, s.
pub const MSD_WINDOW_S: f64 = 1.0;
/// Cluster length for the bias STD, s.
pub const CLUSTER_S: f64 = 100.0;

/// ⌊d / bin_s⌋ for a slowly increasing d, without a division per call: the
/// last bin's interval, shrunk by a guard band far wider than rounding, is
/// checked first, so the result always equals the division's.
#[derive(Clone, Copy, Debug)]
pub struct BinIndex {
    bin_s: f64,
    bin: u64,
    inside: (f64, f64),
}

impl BinIndex {
    /// For bins of `bin_s` seconds.
    pub fn new(bin_s: f64) -> Self {
        BinIndex {
            bin_s,
            bin: 0,
            inside: (f64::INFINITY, f64::NEG_INFINITY),
        }
    }

    /// The bin of offset `d` ≥ 0 (or ⌊d / bin_s⌋ saturated to u64 for any d).
    pub fn of(&mut self, d: f64) -> u64 {
        if d >= self.inside.0 && d < self.inside.1 {
            return self.bin;
        }
        self.bin = (d / self.bin_s).floor() as u64;
        let (lo, hi) = (self.bin as f64 * self.bin_s, (self.bin + 1) as f64 * self.bin_s);
        let guard = 1e-9 * hi.abs().max(self.bin_s);
        self.inside = (lo + guard, hi - guard);
        self.bin
    }
}

/// Means over consecutive time bins of `bin_s` seconds from the first
/// sample, built sample by sample; bins with under half their nominal samples
/// are dropped.
#[derive(Clone, Debug)]
pub struct BinMeans {
    index: BinIndex,
    min_count: usize,
    t0: Option<f64>,
    bin: u64,
    sum: f64,
    count: usize,
    means: Vec<f64>,
}

impl BinMeans {
    /// Empty bins of `bin_s` seconds for samples every `nominal_period_s`.
    pub fn new(bin_s: f64, nominal_period_s: f64) -> Self {
        BinMeans {
            index: BinIndex::new(bin_s),
            min_count: ((0.5 * bin_s / nominal_period_s).floor() as usize).max(1),
            t0: None,
            bin: 0,
            sum: 0.0,
            count: 0,
            means: Vec::new(),
        }
    }

    /// Takes value `v` at time `t`.
    pub fn push(&mut self, t: f64, v: f64) {
        let t0 = *self.t0.get_or_insert(t);
        let b = self.index.of(t - t0);
        if b != self.bin {
            self.close();
            self.bin = b;
        }
        self.sum += v;
        self.count += 1;
    }

    fn close(&mut self) {
        if self.count >= self.min_count {
            self.means.push(self.sum / self.count as f64);
        }
        (self.sum, self.count) = (0.0, 0);
    }

    /// The bin means.
    pub fn finish(mut self) -> Vec<f64> {
        self.close();
        self.means
    }
}

/// Means of `values` over consecutive time bins of `bin_s` seconds (see [`BinMeans`]).
pub fn bin_means(time_s: &[f64], values: &[f64], bin_s: f64, nominal_period_s: f64) -> Vec<f64> {
    let mut bins = BinMeans::new(bin_s, nominal_period_s);
    for (&t, &v) in time_s.iter().zip(values) {
        bins.push(t, v);
    }
    bins.finish()
}

/// Mean of `v` (0 for none).
pub fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        v.iter().sum::<f64>() / v.len() as f64
    }
}

/// Sample standard deviation (n − 1) of `v`; NaN for fewer than two values.
pub fn sample_std(v: &[f64]) -> f64 {
    if v.len() < 2 {
        return f64::NAN;
    }
    let m = mean(v);
    (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
}

/// MSD of a deviation series (output − reference), on 1-s means, °²/h².
/// `about_mean`: no known reference, so deviations are taken from their mean.
pub fn msd(time_s: &[f64], deviation_dph: &[f64], nominal_period_s: f64, about_mean: bool) -> f64 {
    msd_of_means(
        &bin_means(time_s, deviation_dph, MSD_WINDOW_S, nominal_period_s),
        about_mean,
    )
}

/// MSD from the 1-s means of a deviation series (see [`msd`]).
pub fn msd_of_means(means: &[f64], about_mean: bool) -> f64 {
    let center = if about_mean { mean(means) } else { 0.0 };
    mean(&means.iter().map(|m| (m - center).powi(2)).collect::<Vec<_>>())
}

/// Bias STD of 100-s cluster means of a deviation series, °/h.
pub fn cluster_std(time_s: &[f64], deviation_dph: &[f64], nominal_period_s: f64) -> f64 {
    sample_std(&bin_means(time_s, deviation_dph, CLUSTER_S, nominal_period_s))
}

/// Improvement from `before` to `after` in percent: (1 − after/before) × 100.
pub fn improvement_pct(before: f64, after: f64) -> f64 {
    (1.0 - after / before) * 100.0
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    #[test]
    fn cluster_std_of_a_known_step_series() {
        // 10 Hz for 400 s: clusters of 100 s read 0, 2, 0, 2 → sample std = 2/√3·√(…)
        let t: Vec<f64> = (0..4000).map(|i| i as f64 * 0.1).collect();
        let v: Vec<f64> = t
            .iter()
            .map(|&t| if ((t / 100.0) as usize) % 2 == 1 { 2.0 } else { 0.0 })
            .collect();
        let means = bin_means(&t, &v, CLUSTER_S, 0.1);
        assert_eq!(means, vec![0.0, 2.0, 0.0, 2.0]);
        let expected = (4.0f64 / 3.0).sqrt(); // mean 1, squares sum 4, n−1 = 3
        assert!((cluster_std(&t, &v, 0.1) - expected).abs() < 1e-12);
    }

    #[test]
    fn msd_is_against_the_reference_or_about_the_mean() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.5).collect();
        let v = vec![3.0; 100];
        assert!(
            (msd(&t, &v, 0.5, false) - 9.0).abs() < 1e-12,
            "constant 3 °/h off the reference"
        );
        assert!(
            msd(&t, &v, 0.5, true).abs() < 1e-12,
            "no reference: a constant offset is no deviation"
        );
    }

    #[test]
    fn bin_index_equals_the_division_everywhere() {
        for bin_s in [1.0, 100.0, 0.3, 1.0 / 3.0] {
            let mut index = BinIndex::new(bin_s);
            for i in 0..200_000u32 {
                // Steps that land on and next to bin edges, and a jump back.
                let d = if i == 150_000 {
                    0.5
                } else {
                    f64::from(i) * 0.01 + f64::from(i % 7) * 1e-13
                };
                assert_eq!(index.of(d), (d / bin_s).floor() as u64, "d = {d}, bin {bin_s}");
            }
        }
    }

    #[test]
    fn sparse_bins_are_dropped() {
        // A 1-s bin with a single 10-Hz sample (the tail) is not a mean of 1 s.
        let t: Vec<f64> = (0..11).map(|i| i as f64 * 0.1).collect();
        assert_eq!(bin_means(&t, &[1.0; 11], 1.0, 0.1).len(), 1);
        assert!((improvement_pct(2.0, 0.5) - 75.0).abs() < 1e-12);
    }
}
