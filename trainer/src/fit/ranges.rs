//! The clamp ranges a fitted model deploys with, shared by every method's
//! fit (a module of its own so that the methods, children of `fit`, do not
//! import their parent).

use crate::dataset::Blocks;

/// Clamp ranges for deployment: the per-sample feature range seen in training.
pub(crate) fn deploy_ranges(blocks: &Blocks) -> Vec<(f32, f32)> {
    blocks
        .sample_range
        .iter()
        .map(|&(lo, hi)| (lo as f32, hi as f32))
        .collect()
}
