//! An SVR's training data ([`SvrData`]): blocks merged to a few hundred
//! rows, normalised, in contiguous validation folds; and the clustered
//! validation RMS that `svr-pso` and the thermometer search both score with.

use rbf_core::MAX_INPUTS;

use super::linalg::{FeatureRow, Normaliser};
use crate::dataset::Blocks;

/// Rows an SVR is trained on (means of consecutive blocks, about 100 s each on
/// a 17-h chamber run, the RLG paper's smoothing): the dual's kernel matrix is l².
pub(super) const MAX_SVR_ROWS: usize = 600;
/// Contiguous validation folds of the PSO's fitness.
pub(super) const FOLDS: usize = 3;
/// One fold: training rows and validation rows (indices into the merged blocks).
pub(super) struct Fold {
    pub(super) train: Vec<usize>,
    pub(super) validate: Vec<usize>,
}

/// An SVR's training data: merged, normalised blocks with their folds.
pub(super) struct SvrData {
    pub(super) norm: Normaliser,
    /// Normalised inputs of the rows used.
    pub(super) x: Vec<FeatureRow>,
    /// Bias target of the rows used, °/h.
    pub(super) y: Vec<f64>,
    /// Inputs per row.
    pub(super) dims: usize,
    /// Offset-free RMS of `y`, °/h (> 0).
    pub(super) y_std: f64,
    /// The contiguous validation folds.
    pub(super) folds: Vec<Fold>,
    /// Rows per 100-s cluster of the validation residual.
    pub(super) per_cluster: usize,
}

impl SvrData {
    /// Means of consecutive blocks of one run (n blocks each, the fewest that
    /// give ≤ [`MAX_SVR_ROWS`] rows), normalised, in [`FOLDS`] contiguous
    /// folds. Means, not every n-th block: a 1-s block carries the gyro's
    /// white noise and the thermometers' quantisation, which at 1200 rows
    /// would hide the differences between models the swarm and the choice
    /// of thermometers must see.
    pub(super) fn new(blocks: &Blocks, block_s: f64) -> anyhow::Result<SvrData> {
        let group = blocks.len().div_ceil(MAX_SVR_ROWS).max(1);
        let merged = merge_blocks(blocks, group);
        let norm = Normaliser::fit(&merged);
        let x: Vec<FeatureRow> = merged.x.iter().map(|r| norm.apply(r)).collect();
        let y = merged.y;
        let y_std = offset_free_rms(y.iter().copied());
        anyhow::ensure!(y_std.is_finite(), "no blocks to fit an SVR on");
        let folds = contiguous_folds(x.len(), FOLDS);
        // Scored on 100-s cluster means of the residual, as `rbf` is: at 1 s
        // white noise hides model errors ten times smaller than itself.
        let per_cluster = (crate::metrics::CLUSTER_S / (block_s * group as f64)).round().max(1.0) as usize;
        Ok(SvrData {
            norm,
            x,
            y,
            dims: blocks.dims,
            y_std: y_std.max(1e-12),
            folds,
            per_cluster,
        })
    }
}

/// Means of `group` consecutive blocks (features and target) within each
/// run; a run's last, shorter group is a mean too.
fn merge_blocks(blocks: &Blocks, group: usize) -> Blocks {
    let mut merged = Blocks {
        dims: blocks.dims,
        sample_range: blocks.sample_range.clone(),
        usable_s: blocks.usable_s,
        ..Blocks::default()
    };
    let mut start = 0;
    while start < blocks.len() {
        let run = blocks.run[start];
        let end = (start..blocks.len().min(start + group))
            .find(|&i| blocks.run[i] != run)
            .unwrap_or(blocks.len().min(start + group));
        let n = (end - start) as f64;
        let mut x = [0.0; MAX_INPUTS];
        for row in &blocks.x[start..end] {
            for (m, v) in x.iter_mut().zip(row) {
                *m += v / n;
            }
        }
        merged.x.push(x);
        merged.y.push(blocks.y[start..end].iter().sum::<f64>() / n);
        merged.run.push(run);
        start = end;
    }
    merged
}

/// `count` contiguous folds over `n` rows: each validates on one contiguous
/// stretch and trains on the rest (never random rows: neighbours correlate).
fn contiguous_folds(n: usize, count: usize) -> Vec<Fold> {
    let count = count.clamp(1, n.max(1));
    (0..count)
        .map(|f| {
            let (start, end) = (f * n / count, (f + 1) * n / count);
            Fold {
                train: (0..n).filter(|i| *i < start || *i >= end).collect(),
                validate: (start..end).collect(),
            }
        })
        .collect()
}

/// [`offset_free_rms`] of the means of consecutive groups of `per_cluster`
/// residuals (a short last group included).
pub(super) fn cluster_rms(residuals: impl Iterator<Item = f64>, per_cluster: usize) -> f64 {
    let r: Vec<f64> = residuals.collect();
    offset_free_rms(
        r.chunks(per_cluster.max(1))
            .map(|c| c.iter().sum::<f64>() / c.len() as f64),
    )
}

/// RMS of `residuals` about their mean (the gyro's constant offset is not
/// the thermal model's business); +∞ for none.
pub(super) fn offset_free_rms(residuals: impl Iterator<Item = f64>) -> f64 {
    let r: Vec<f64> = residuals.collect();
    if r.is_empty() {
        return f64::INFINITY;
    }
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    (r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / r.len() as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folds_are_contiguous_and_cover_every_row_once() {
        let folds = contiguous_folds(10, 3);
        assert_eq!(folds.len(), 3);
        let mut seen: Vec<usize> = folds.iter().flat_map(|f| f.validate.clone()).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..10).collect::<Vec<_>>());
        for f in &folds {
            assert!(f.validate.windows(2).all(|w| w[1] == w[0] + 1));
            assert_eq!(f.train.len() + f.validate.len(), 10);
        }
    }
}
