//! The forecast of the residual a fitted model leaves in use
//! (`predicted_in_use_std100_dph`): the 100-s cluster STD of the residual on
//! temperature histories unlike the training runs.
//!
//! The forecast is the deployed model's residual 100-s cluster STD on its
//! own training runs times a factor per structure
//! ([`LAG_BANK_FORECAST_FACTOR`], [`RESPONSE_BANK_FORECAST_FACTOR`]). Held-out
//! thermal events, the other candidate, forecast too much after a planned
//! run: it holds each level once, so its held-out part is unlike the rest and
//! unlike the in-use histories, which stay inside the range the run covered.
//! They still choose between the structures ([`super::response::StructureChoice`]).
//! The measurements behind the factors: docs/methods.md, "The forecast".

use rbf_core::model::Model;

use crate::dataset::RunSet;

/// The lag bank's in-use residual as a multiple of its training residual:
/// its few parameters, tied by physics, carry to other histories about as
/// well as they follow the training run.
pub const LAG_BANK_FORECAST_FACTOR: f64 = 1.1;

/// The response bank's in-use residual as a multiple of its training
/// residual: its many weights follow the training run to its noise.
pub const RESPONSE_BANK_FORECAST_FACTOR: f64 = 2.0;

/// The residual 100-s cluster STD of `model` on the block means of `train`
/// (RMS over the runs), °/h. For models linear in their inputs (the lag and
/// response banks) the block means of the inputs give the block means of
/// the bias.
pub fn training_std100<T: RunSet + ?Sized>(train: &T, model: &Model, block_s: f64) -> anyhow::Result<f64> {
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
    rms_cluster_std_over_runs(&blocks.run, &time, &residual, period_s)
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
    let runs = run.iter().max().map_or(0, |&r| r + 1);
    let mut sum_sq = 0.0;
    let mut counted = 0usize;
    for r in 0..runs {
        let rows: Vec<usize> = (0..run.len()).filter(|&i| run[i] == r).collect();
        let time: Vec<f64> = rows.iter().map(|&i| time_s[i]).collect();
        let residual: Vec<f64> = rows.iter().map(|&i| residual_dph[i]).collect();
        let std = crate::metrics::cluster_std(&time, &residual, period_s);
        if std.is_finite() {
            sum_sq += std * std;
            counted += 1;
        }
    }
    anyhow::ensure!(counted > 0, "no training run is long enough for a 100-s cluster STD");
    Ok((sum_sq / counted as f64).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

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
