//! The forecast of the residual a fitted model leaves in use
//! (`predicted_in_use_std100_dph`): the 100-s cluster STD of the residual on
//! temperature histories unlike the training runs.
//!
//! The deployed model's residual 100-s cluster STD on its own training runs
//! holds two parts: the gyro's white noise, which is the same in use, and the
//! model's error, which grows in use as far as the histories differ from the
//! runs. The forecast keeps the first ([`white_noise_std100`], the floor) and
//! scales the second by a factor per structure ([`in_use_std100`],
//! [`LAG_BANK_EXCESS_FACTOR`], [`response_bank_excess_factor`]). It is for
//! temperature changes no faster than the runs held: a run without fast
//! changes (`missing:`'s "no fast change") leaves more in use than forecast.
//! Held-out thermal events, the other candidate, forecast too much after a
//! planned run: it holds each level once, so its held-out part is unlike the
//! rest and unlike the in-use histories, which stay inside the range the run
//! covered. They still choose between the structures
//! ([`super::response::StructureChoice`]). The measurements behind the
//! factors: docs/methods.md, "The forecast".

use rbf_core::model::Model;

use crate::dataset::RunSet;

/// The lag bank's model error in use as a multiple of its model error on the
/// training runs: its few parameters, tied by physics, carry to other
/// histories about as well as they follow the training run.
pub const LAG_BANK_EXCESS_FACTOR: f64 = 1.0;

/// The response bank's model error in use as a multiple of its model error
/// on the training runs, at most: its many weights follow the training run
/// closer than any other history. Runs up to [`RESPONSE_BANK_EXCESS_HOURS`]
/// long take it; longer ones less ([`response_bank_excess_factor`]).
pub const RESPONSE_BANK_EXCESS_FACTOR: f64 = 2.0;

/// Hours of training over which the response bank's excess factor less one
/// falls as one over the hours: `1 + RESPONSE_BANK_EXCESS_HOURS / hours`,
/// 2 after a 12-h run, 1.5 after 24 h. Its weights are as many
/// whatever the run's length, so the more blocks each weight is fitted on,
/// the nearer its training residual comes to what other histories leave.
/// Measured with `bench/accuracy/soak_sweep.py --pairs 5` (docs/methods.md,
/// "The forecast").
pub const RESPONSE_BANK_EXCESS_HOURS: f64 = 12.0;

/// The response bank's factor where its regression weighed the runs'
/// settled levels ([`super::settled_blocks`]): part of its training residual
/// is then the price of holding the settled curve, not weights that follow
/// the run, and it carries to other histories nearly as it is.
pub const WEIGHED_RESPONSE_BANK_EXCESS_FACTOR: f64 = 1.25;

/// The response bank's excess factor: [`WEIGHED_RESPONSE_BANK_EXCESS_FACTOR`]
/// where its regression weighed the runs' settled levels
/// (`settled_levels_weighed`); elsewhere `1 +`
/// [`RESPONSE_BANK_EXCESS_HOURS`]` / training_hours` (the hours its
/// regression fitted), at most [`RESPONSE_BANK_EXCESS_FACTOR`] (an unknown
/// or zero length takes it).
pub fn response_bank_excess_factor(settled_levels_weighed: bool, training_hours: f64) -> f64 {
    if settled_levels_weighed {
        WEIGHED_RESPONSE_BANK_EXCESS_FACTOR
    } else {
        // A NaN length is 0 here (f64::max), and 12 h / 0 is infinite: both take the cap.
        (1.0 + RESPONSE_BANK_EXCESS_HOURS / training_hours.max(0.0)).min(RESPONSE_BANK_EXCESS_FACTOR)
    }
}

/// The in-use 100-s cluster STD forecast from a training residual, °/h: the
/// white-noise floor as it is, the rest (in quadrature) times
/// `excess_factor`. Without a floor the whole residual is scaled. A floor
/// above the residual (both are estimates) counts as the residual: no model
/// error.
pub fn in_use_std100(training: TrainingResidual, excess_factor: f64) -> f64 {
    let total = training.std100_dph;
    match training.noise_floor_std100_dph.filter(|f| f.is_finite()) {
        Some(floor) => {
            let floor = floor.min(total);
            let excess_sq = total * total - floor * floor;
            (floor * floor + excess_factor * excess_factor * excess_sq).sqrt()
        }
        None => excess_factor * total,
    }
}

/// What a linear model leaves of its training runs, at the 100-s scale.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainingResidual {
    /// The residual's 100-s cluster STD, °/h (RMS over the runs).
    pub std100_dph: f64,
    /// The part of it white noise explains ([`white_noise_std100`]), °/h;
    /// `None` where the runs hold too few adjacent blocks to tell.
    pub noise_floor_std100_dph: Option<f64>,
}

/// The residual of `model` on the block means of `train` ([`TrainingResidual`]).
/// For models linear in their inputs (the lag and response banks) the block
/// means of the inputs give the block means of the bias.
pub fn training_residual<T: RunSet + ?Sized>(
    train: &T,
    model: &Model,
    block_s: f64,
) -> anyhow::Result<TrainingResidual> {
    let blocks = train.block_means(model.features(), block_s)?;
    let dims = blocks.dims.min(rbf_core::MAX_INPUTS);
    // A long run's blocks are merged: their length, not `block_s`, is the period.
    let period_s = blocks.length_s(block_s);
    let residual: Vec<f64> = (0..blocks.len())
        .map(|i| {
            let x: Vec<f32> = blocks.x[i][..dims].iter().map(|&v| v as f32).collect();
            blocks.y[i] - f64::from(model.eval(&rbf_core::FeatureVector::from_values(&x)).bias_dph)
        })
        .collect();
    let time: Vec<f64> = (0..blocks.len())
        .map(|i| blocks.time_s.get(i).copied().unwrap_or(i as f64 * period_s))
        .collect();
    Ok(TrainingResidual {
        std100_dph: rms_cluster_std_over_runs(&blocks.run, &time, &residual, period_s)?,
        noise_floor_std100_dph: white_noise_std100(&blocks.run, &time, &residual, period_s),
    })
}

/// Adjacent block pairs a run needs before its white noise is estimated.
pub const MIN_NOISE_PAIRS: usize = 16;

/// The 100-s cluster STD that white noise alone would give `residual_dph`
/// (blocks of `period_s` starting at `time_s`, of run `run`), °/h, RMS over
/// the runs: each run's Allan variance at τ = `period_s` from its adjacent
/// blocks, scaled as white noise scales (σ²₁₀₀ = σ²(τ)·τ / 100 s).
///
/// At one block's length the residual is the gyro's noise: the thermal
/// part changes little from one block to the next, and the difference of
/// adjacent blocks removes it. Flicker and random walk add to the 100-s
/// figure on top of this, so it is a lower bound of what no thermal model
/// can remove. `None` where no run holds [`MIN_NOISE_PAIRS`] adjacent pairs.
pub fn white_noise_std100(run: &[usize], time_s: &[f64], residual_dph: &[f64], period_s: f64) -> Option<f64> {
    rms_over_runs(run, time_s, residual_dph, |time_s, residual_dph| {
        let (mut sum, mut pairs) = (0.0f64, 0usize);
        for (t, r) in time_s.windows(2).zip(residual_dph.windows(2)) {
            let d = r[1] - r[0];
            if (t[1] - t[0] - period_s).abs() < 0.5 * period_s && d.is_finite() {
                sum += d * d;
                pairs += 1;
            }
        }
        (pairs >= MIN_NOISE_PAIRS).then(|| (0.5 * sum / pairs as f64 * period_s / crate::metrics::CLUSTER_S).sqrt())
    })
}

/// RMS over the runs of each run's 100-s cluster STD of `residual_dph`
/// (blocks of `period_s` starting at `time_s`, of run `run`), °/h; runs too
/// short for two clusters are left out.
pub fn rms_cluster_std_over_runs(
    run: &[usize],
    time_s: &[f64],
    residual_dph: &[f64],
    period_s: f64,
) -> anyhow::Result<f64> {
    rms_over_runs(run, time_s, residual_dph, |time_s, residual_dph| {
        Some(crate::metrics::cluster_std(time_s, residual_dph, period_s)).filter(|std| std.is_finite())
    })
    .ok_or_else(|| anyhow::anyhow!("no training run is long enough for a 100-s cluster STD"))
}

/// RMS over the runs of `per_run` (given each run's times and residuals, in
/// block order), the runs it gives `None` for left out; `None` if it gives
/// none.
fn rms_over_runs(
    run: &[usize],
    time_s: &[f64],
    residual_dph: &[f64],
    per_run: impl Fn(&[f64], &[f64]) -> Option<f64>,
) -> Option<f64> {
    let runs = run.iter().max().map_or(0, |&r| r + 1);
    let values: Vec<f64> = (0..runs)
        .filter_map(|r| {
            let rows: Vec<usize> = (0..run.len()).filter(|&i| run[i] == r).collect();
            let time: Vec<f64> = rows.iter().map(|&i| time_s[i]).collect();
            let residual: Vec<f64> = rows.iter().map(|&i| residual_dph[i]).collect();
            per_run(&time, &residual)
        })
        .collect();
    (!values.is_empty()).then(|| (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_forecast_keeps_the_noise_floor_and_scales_only_the_model_error() {
        let residual = |std100_dph, noise_floor_std100_dph| TrainingResidual {
            std100_dph,
            noise_floor_std100_dph,
        };
        let near = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // 5 mdph over a 3-mdph floor: 4 mdph of model error, doubled in use.
        let f = in_use_std100(residual(0.005, Some(0.003)), 2.0);
        assert!(near(f, (0.003f64.powi(2) + 0.008f64.powi(2)).sqrt()), "{f}");
        // Factor 1: the training residual itself.
        assert!(near(in_use_std100(residual(0.005, Some(0.003)), 1.0), 0.005));
        // At its floor the residual is white noise, whatever the factor;
        // a floor estimated above the residual counts as the residual.
        assert!(near(in_use_std100(residual(0.003, Some(0.003)), 2.0), 0.003));
        assert!(near(in_use_std100(residual(0.003, Some(0.0035)), 2.0), 0.003));
        // No floor to tell: the whole residual scaled.
        assert!(near(in_use_std100(residual(0.003, None), 2.0), 0.006));
    }

    #[test]
    fn a_response_bank_that_weighed_settled_levels_forecasts_less_excess_and_the_same_floor() {
        // The weighed fit's residual holds the price of the settled curve,
        // which carries to other histories: its excess is scaled less.
        let residual = TrainingResidual {
            std100_dph: 0.02,
            noise_floor_std100_dph: Some(0.005),
        };
        let weighed = in_use_std100(residual, response_bank_excess_factor(true, 24.0));
        let plain = in_use_std100(residual, response_bank_excess_factor(false, 24.0));
        assert!(residual.std100_dph < weighed && weighed < plain, "{weighed} {plain}");
        let at_floor = TrainingResidual {
            std100_dph: 0.005,
            noise_floor_std100_dph: Some(0.005),
        };
        let (w, p) = (
            in_use_std100(at_floor, response_bank_excess_factor(true, 24.0)),
            in_use_std100(at_floor, response_bank_excess_factor(false, 24.0)),
        );
        assert!((w - 0.005).abs() < 1e-12 && (p - 0.005).abs() < 1e-12, "{w} {p}");
    }

    #[test]
    fn a_plain_response_bank_fitted_on_more_hours_forecasts_less_excess_up_to_the_cap() {
        let factor = |hours| response_bank_excess_factor(false, hours);
        // One over the hours past the cap's 12 h: 1.5 after the 24-h plan, 1.25 after 48 h.
        assert!((factor(24.0) - 1.5).abs() < 1e-12, "{}", factor(24.0));
        assert!((factor(48.0) - 1.25).abs() < 1e-12, "{}", factor(48.0));
        assert!(factor(48.0) < factor(24.0) && factor(48.0) > 1.0);
        // Shorter runs, and a length unknown, zero or not a number, take the cap.
        for hours in [3.0, 12.0, 0.0, -1.0, f64::NAN] {
            let f = factor(hours);
            assert!((f - RESPONSE_BANK_EXCESS_FACTOR).abs() < 1e-12, "{hours} h: {f}");
        }
        // A fit that weighed settled levels keeps its own factor, whatever its length.
        for hours in [3.0, 12.0, 24.0] {
            let f = response_bank_excess_factor(true, hours);
            assert!(
                (f - WEIGHED_RESPONSE_BANK_EXCESS_FACTOR).abs() < 1e-12,
                "{hours} h: {f}"
            );
        }
    }

    #[test]
    fn the_noise_floor_is_the_white_noise_of_the_residual_whatever_slow_drift_rides_on_it() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        // Two 4-h runs of 4-s blocks: white noise of 0.02 °/h per block, run 1
        // with a slow swing of ±0.05 °/h (a 2-h period) on top.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let white = Normal::new(0.0, 0.02).unwrap();
        let period_s = 4.0;
        let (mut run, mut time, mut noise, mut drifting) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for r in 0..2 {
            for i in 0..3600 {
                let t = f64::from(i) * period_s;
                let n = white.sample(&mut rng);
                run.push(r);
                time.push(t);
                noise.push(n);
                drifting.push(
                    n + if r == 1 {
                        0.05 * (t / 7200.0 * std::f64::consts::TAU).sin()
                    } else {
                        0.0
                    },
                );
            }
        }
        // White noise: 100-s means of 25 blocks have 0.02/√25 = 0.004 °/h.
        let floor = white_noise_std100(&run, &time, &noise, period_s).unwrap();
        assert!((floor - 0.004).abs() < 0.0003, "{floor}");
        let measured = rms_cluster_std_over_runs(&run, &time, &noise, period_s).unwrap();
        assert!(
            (floor / measured - 1.0).abs() < 0.1,
            "{floor} against {measured} measured"
        );
        // The swing raises the residual's 100-s STD, not its noise floor.
        let with_drift = white_noise_std100(&run, &time, &drifting, period_s).unwrap();
        assert!((with_drift / floor - 1.0).abs() < 0.01, "{with_drift} against {floor}");
        assert!(rms_cluster_std_over_runs(&run, &time, &drifting, period_s).unwrap() > 3.0 * floor);
        // A gap is no pair; runs of too few pairs give no floor.
        assert!(white_noise_std100(&run[..10], &time[..10], &noise[..10], period_s).is_none());
        let gapped: Vec<f64> = (0..40).map(|i| f64::from(i) * 2.0 * period_s).collect();
        assert!(white_noise_std100(&[0; 40], &gapped, &noise[..40], period_s).is_none());
    }

    #[test]
    fn the_rms_over_runs_weighs_each_run_alike_and_skips_runs_too_short() {
        // Run 0: 100-s clusters alternating ±1 (cluster STD 2/√3·…); run 1:
        // flat (0); run 2: one cluster only (left out).
        let mut run = Vec::new();
        let mut time = Vec::new();
        let mut residual = Vec::new();
        for i in 0..400 {
            run.push(0);
            time.push(i as f64);
            residual.push(if (i / 100) % 2 == 0 { 1.0 } else { -1.0 });
        }
        for i in 0..400 {
            run.push(1);
            time.push(i as f64);
            residual.push(0.0);
        }
        for i in 0..50 {
            run.push(2);
            time.push(i as f64);
            residual.push(5.0);
        }
        let first = crate::metrics::cluster_std(&time[..400], &residual[..400], 1.0);
        let rms = rms_cluster_std_over_runs(&run, &time, &residual, 1.0).unwrap();
        assert!((rms - first / 2f64.sqrt()).abs() < 1e-12, "{rms} against {first}");
        assert!(rms_cluster_std_over_runs(&[0; 50], &time[..50], &residual[..50], 1.0).is_err());
    }
}
