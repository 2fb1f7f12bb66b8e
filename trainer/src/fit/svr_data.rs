//! An SVR's training data ([`SvrData`]): blocks merged to a few hundred
//! rows, normalised, in contiguous validation folds ([`super::folds`]).

use rbf_core::MAX_INPUTS;

use super::folds::{FOLDS, Fold, contiguous_folds};
use super::linalg::{FeatureRow, Normaliser};
use super::scoring::offset_free_rms;
use crate::dataset::Blocks;

/// Rows an SVR is trained on (means of consecutive blocks, about 100 s each on
/// a 17-h chamber run, the RLG paper's smoothing): the dual's kernel matrix is l².
pub(super) const MAX_SVR_ROWS: usize = 600;
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
        let per_cluster = (crate::metrics::CLUSTER_S / (blocks.length_s(block_s) * group as f64))
            .round()
            .max(1.0) as usize;
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
