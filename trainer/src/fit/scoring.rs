//! The clustered validation RMS that `svr-pso` and the thermometer search
//! both score with.

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
