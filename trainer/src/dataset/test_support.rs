//! Helpers the dataset tests share.

use std::path::PathBuf;

use rbf_core::{FeatureConfig, FeatureSet};

use crate::simulate::ChamberRun;

/// The multi-scale `set` over windows `window_s`, 16 and 256 times that.
pub(super) fn multiscale(set: FeatureSet, window_s: f32) -> FeatureConfig {
    FeatureConfig::multiscale(set, [window_s, 16.0 * window_s, 256.0 * window_s])
}

/// A 3-h simulated IFOG run at 10 Hz and `ramp_c_per_min`, written into `dir`.
pub(super) fn simulated_run(dir: &tempfile::TempDir, ramp_c_per_min: f64, seed: u64) -> PathBuf {
    let path = dir.path().join("run.csv");
    let mut sim = ChamberRun::ifog(ramp_c_per_min, seed);
    sim.duration_s = Some(3.0 * 3600.0);
    sim.sample_rate_hz = 10.0;
    sim.write_csv(&mut std::fs::File::create(&path).unwrap()).unwrap();
    path
}
