//! The network in f64 with exact exponentials: what the deployed
//! evaluation's error is measured against.

use super::RbfNetwork;

impl<const K: usize, const D: usize> RbfNetwork<K, D> {
    /// The network's value in f64 with exact exponentials (libm), from its
    /// stored parameters: the reference for the deployed evaluation's error.
    pub fn eval_reference(&self, x_kernel: &[f64], x_linear: &[f64]) -> f64 {
        let d = self.inputs_used.min(D);
        let z = |x: &[f64], i: usize| {
            (x.get(i).copied().unwrap_or(0.0) - f64::from(self.offset[i])) / f64::from(self.scale[i])
        };
        let mut y = f64::from(self.constant);
        for i in 0..d {
            y += f64::from(self.linear[i]) * z(x_linear, i);
        }
        for j in 0..self.centers_used.min(K) {
            let mut dist_sq = 0.0;
            for i in 0..self.kernel_inputs.min(d) {
                let diff = z(x_kernel, i) - f64::from(self.centers[j][i]);
                dist_sq += diff * diff;
            }
            let sigma = f64::from(self.widths[j]);
            y += f64::from(self.weights[j]) * libm::exp(-dist_sq / (2.0 * sigma * sigma));
        }
        y
    }
}
