//! Cubic-in-T baseline fit (the PX4 / ArduPilot form) by least squares on block means.

use nalgebra::{DMatrix, DVector};
use rbf_core::model::{ModelBody, ModelInfo};
use rbf_core::poly::Poly3;
use rbf_core::{FeatureConfig, FeatureSet, Model};

use super::FitOptions;
use crate::dataset::RunSet;

/// Fits bias = c0 + c1 u + c2 u² + c3 u³, u = T − T_ref, T_ref mid training range.
pub fn fit<T: RunSet + ?Sized>(train: &T, opts: &FitOptions) -> anyhow::Result<Model> {
    let features = FeatureConfig::single(FeatureSet::Temp, 0.0);
    let blocks = train.block_means(&features, opts.block_s)?;
    super::check_excitation(&blocks, FeatureSet::Temp, None, opts.block_s)?;
    let (lo, hi) = blocks.sample_range[0];
    let ref_temp_c = (0.5 * (lo + hi)) as f32;
    let u: Vec<f64> = blocks.x.iter().map(|r| r[0] - ref_temp_c as f64).collect();
    let a = DMatrix::from_fn(u.len(), 4, |r, c| u[r].powi(c as i32));
    let y = DVector::from_column_slice(&blocks.y);
    let coeffs = a
        .svd(true, true)
        .solve(&y, 1e-12)
        .map_err(|e| anyhow::anyhow!("cubic least squares failed: {e}"))?;
    let poly = Poly3::new(
        ref_temp_c,
        [coeffs[0] as f32, coeffs[1] as f32, coeffs[2] as f32, coeffs[3] as f32],
    )
    .map_err(|e| anyhow::anyhow!("fitted cubic is not deployable: {e}"))?;
    let info = ModelInfo {
        serial: super::serial(opts)?,
    };
    Model::new(features, &super::deploy_ranges(&blocks), ModelBody::Poly3(poly), info)
        .map_err(|e| anyhow::anyhow!("fitted cubic is not deployable: {e}"))
}
