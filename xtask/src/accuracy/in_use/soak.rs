//! What the bench reads on a plant's soak tests (two, of other levels and
//! another order: issue 48 judges on a soak test unlike the one it
//! describes): the worse spread of the two, judged; and what kind of error
//! they read. The settled biases of both after one fit are split into
//!
//! - the part a cubic in the loop temperature explains: a static curve the
//!   fit misidentified, read alike whatever order the levels come in; more
//!   settled evidence or a better-identified static part removes it;
//! - what is left about that cubic: the order the levels came in (a state
//!   slower than the model's responses, its sign set by the last step) and
//!   the noise of the levels' means.
//!
//! A cubic because the plant's settled bias is one (the static curve of the
//! mean coil temperature, which a steady loop sensor reads with a fixed
//! offset; docs/simulator.md) and so is the model's static part.

use nalgebra::{DMatrix, DVector};

use crate::accuracy::SoakReading;

/// One fit's readings on the plant's soak tests, in the bench's order of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct SoakScores {
    pub readings: Vec<SoakReading>,
}

impl SoakScores {
    /// The figure the targets judge: the worse settled spread after
    /// compensation, °/h; `None` where a soak test shows under two plateaus.
    pub fn worst_dph(&self) -> Option<f64> {
        self.worst_of(|r| r.after_dph)
    }

    /// The worse of `spread` over the soak tests, °/h; `None` without
    /// readings or where one test gives none.
    pub fn worst_of(&self, spread: impl Fn(&SoakReading) -> Option<f64>) -> Option<f64> {
        if self.readings.is_empty() {
            return None;
        }
        self.readings
            .iter()
            .try_fold(0.0f64, |worst, r| Some(worst.max(spread(r)?)))
    }

    /// The model's own settled spread, °/h: on each soak test, each
    /// plateau's compensated bias less the same plateau's bias in the test
    /// simulated again with its thermal bias zeroed (`noise`, one reading
    /// per test in the same order, same seed: the gyro's noise drops out),
    /// max − min; the worse of the tests. What a change to the model or the
    /// plan did to the fit, without the noise's draw that dominates the
    /// figure near 0.01 °/h. `None` where a test's plateaus and its twin's do
    /// not pair up (another count, or loop temperatures more than
    /// [`PAIRED_PLATEAU_C`] apart).
    pub fn model_error_dph(&self, noise: &[SoakReading]) -> Option<f64> {
        if self.readings.is_empty() || self.readings.len() != noise.len() {
            return None;
        }
        self.readings.iter().zip(noise).try_fold(0.0f64, |worst, (r, n)| {
            if r.plateaus.len() < 2 || r.plateaus.len() != n.plateaus_before.len() {
                return None;
            }
            let own = r
                .plateaus
                .iter()
                .zip(&n.plateaus_before)
                .map(|(a, b)| ((a.0 - b.0).abs() <= PAIRED_PLATEAU_C).then_some(a.1 - b.1))
                .collect::<Option<Vec<f64>>>()?;
            let (lo, hi) = own.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &e| {
                (lo.min(e), hi.max(e))
            });
            Some(worst.max(hi - lo))
        })
    }

    /// The static and the order part of every soak test's settled biases.
    pub fn split(&self) -> Option<SoakSplit> {
        let plateaus: Vec<(f64, f64)> = self.readings.iter().flat_map(|r| r.plateaus.iter().copied()).collect();
        split(&plateaus)
    }
}

/// How far apart a plateau's loop temperature in a soak test and in its
/// noise-only twin may lie and still be the same plateau, °C (the twin's
/// loop carries the same thermometer noise, so they agree to hundredths).
pub(super) const PAIRED_PLATEAU_C: f64 = 0.5;

/// Fewest plateaus to split: twice the cubic's four coefficients.
const MIN_PLATEAUS: usize = 8;

/// The two parts of the soak tests' settled biases.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct SoakSplit {
    /// Range (max − min) of the least-squares cubic in the loop temperature
    /// over the plateaus' temperatures, °/h: the static part.
    pub static_range_dph: f64,
    /// RMS of the settled biases about that cubic, °/h: the order and the
    /// noise.
    pub off_static_rms_dph: f64,
}

/// The split of `plateaus` (loop temperature °C, settled bias after
/// compensation °/h; the plateaus of every soak test of one fit), or `None`
/// under [`MIN_PLATEAUS`].
pub(super) fn split(plateaus: &[(f64, f64)]) -> Option<SoakSplit> {
    if plateaus.len() < MIN_PLATEAUS {
        return None;
    }
    // Centred and scaled to ±1-ish: the powers stay well conditioned.
    let n = plateaus.len() as f64;
    let mid_c = plateaus.iter().map(|p| p.0).sum::<f64>() / n;
    let u: Vec<f64> = plateaus.iter().map(|p| (p.0 - mid_c) / 50.0).collect();
    let a = DMatrix::from_fn(u.len(), 4, |r, c| u[r].powi(c as i32));
    let y = DVector::from_iterator(plateaus.len(), plateaus.iter().map(|p| p.1));
    let coeffs = a.clone().svd(true, true).solve(&y, 1e-12).ok()?;
    let fitted = &a * coeffs;
    let (lo, hi) = fitted.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
        (lo.min(v), hi.max(v))
    });
    let off = (&y - &fitted).norm_squared() / n;
    Some(SoakSplit {
        static_range_dph: hi - lo,
        off_static_rms_dph: off.sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sixteen levels −35 … 60 °C, as two soak tests of eight give.
    fn levels() -> Vec<f64> {
        (0..16).map(|i| -35.0 + 6.3 * i as f64).collect()
    }

    #[test]
    fn a_static_curve_misidentified_reads_as_the_cubic_part_and_leaves_nothing_about_it() {
        let cubic = |t: f64| 0.01 + 2e-4 * t - 1e-5 * t * t + 2e-7 * t * t * t;
        let plateaus: Vec<(f64, f64)> = levels().into_iter().map(|t| (t, cubic(t))).collect();
        let s = split(&plateaus).unwrap();
        let values: Vec<f64> = plateaus.iter().map(|p| p.1).collect();
        let range = values.iter().copied().fold(f64::NEG_INFINITY, f64::max)
            - values.iter().copied().fold(f64::INFINITY, f64::min);
        assert!((s.static_range_dph - range).abs() < 1e-9, "{s:?} against {range}");
        assert!(s.off_static_rms_dph < 1e-9, "{s:?}");
    }

    #[test]
    fn a_sign_set_by_the_order_of_the_levels_reads_as_the_part_off_the_cubic() {
        // ±5 mdph by the direction of the last step, the signs along the
        // temperature axis as two orders mix them (+ − − +, repeated): no
        // cubic follows it.
        let plateaus: Vec<(f64, f64)> = levels()
            .into_iter()
            .enumerate()
            .map(|(i, t)| (t, if matches!(i % 4, 0 | 3) { 0.005 } else { -0.005 }))
            .collect();
        let s = split(&plateaus).unwrap();
        assert!(s.static_range_dph < 0.002, "{s:?}");
        assert!((s.off_static_rms_dph - 0.005).abs() < 5e-4, "{s:?}");
    }

    #[test]
    fn the_worse_soak_test_is_judged_and_one_without_two_plateaus_leaves_no_figure() {
        let reading = |after: Option<f64>| SoakReading {
            after_dph: after,
            ..SoakReading::default()
        };
        let both = SoakScores {
            readings: vec![reading(Some(0.008)), reading(Some(0.013))],
        };
        assert_eq!(both.worst_dph(), Some(0.013));
        let one_short = SoakScores {
            readings: vec![reading(Some(0.008)), reading(None)],
        };
        assert_eq!(one_short.worst_dph(), None);
        assert_eq!(SoakScores::default().worst_dph(), None);
    }

    #[test]
    fn the_model_error_is_the_compensated_bias_less_the_noise_plateau_by_plateau() {
        // Noise of ±4 mdph at four plateaus; the model leaves +1, −1, +2, 0 mdph.
        let temps = [25.0, 0.0, 40.0, -20.0];
        let noise_dph = [0.004, -0.004, 0.003, -0.002];
        let model_dph = [0.001, -0.001, 0.002, 0.0];
        let compensated = SoakReading {
            plateaus: (0..4).map(|i| (temps[i], noise_dph[i] + model_dph[i])).collect(),
            ..SoakReading::default()
        };
        let twin = SoakReading {
            plateaus_before: (0..4).map(|i| (temps[i] + 0.01, noise_dph[i])).collect(),
            ..SoakReading::default()
        };
        let scores = SoakScores {
            readings: vec![compensated.clone()],
        };
        let own = scores.model_error_dph(std::slice::from_ref(&twin)).unwrap();
        assert!((own - 0.003).abs() < 1e-12, "{own}");
        // Plateaus that do not pair up (a missing one, or another level) give no figure.
        let mut short = twin.clone();
        short.plateaus_before.pop();
        assert_eq!(scores.model_error_dph(&[short]), None);
        let mut moved = twin.clone();
        moved.plateaus_before[2].0 += 5.0;
        assert_eq!(scores.model_error_dph(&[moved]), None);
        assert_eq!(scores.model_error_dph(&[]), None);
    }

    #[test]
    fn under_eight_plateaus_there_is_no_split() {
        let plateaus: Vec<(f64, f64)> = levels().into_iter().take(7).map(|t| (t, 0.0)).collect();
        assert_eq!(split(&plateaus), None);
    }
}
