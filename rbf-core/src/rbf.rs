//! Fixed-capacity Gaussian RBF network.
//!
//! ```text
//! z_i  = (x_i − offset_i) / scale_i                         (normalised inputs)
//! y    = c + Σ_i a_i z_i + Σ_j W_j exp(−‖z_[..m] − c_j‖² / 2σ_j²)
//! ```
//! The centres c_j and widths σ_j live in normalised units. The Gaussians see
//! the first m = `kernel_inputs` inputs (all of them in the IFOG paper's
//! network; only T in the partially linear default, whose ΔT terms enter
//! linearly as the Shupe effect does); the linear terms see all of them. Capacity is in the
//! type (`K` centres, `D` inputs); the cost of [`RbfNetwork::eval`] depends only
//! on the model's shape, never on the input values (no data-dependent loops).

use crate::model::ModelError;

/// Parameters of a network, as slices (host construction and blob decoding).
#[derive(Clone, Copy, Debug)]
pub struct RbfParams<'a> {
    /// Per-input offset subtracted before scaling (training mean), input units.
    pub offset: &'a [f32],
    /// Per-input scale divided by (training standard deviation), input units.
    pub scale: &'a [f32],
    /// How many leading inputs the Gaussians see (1 ..= inputs).
    pub kernel_inputs: usize,
    /// Centres in normalised units, row-major: `centers[j * kernel_inputs + i]`.
    pub centers: &'a [f32],
    /// Gaussian width σ_j of each centre, normalised units.
    pub widths: &'a [f32],
    /// Output weight W_j of each centre, °/h.
    pub weights: &'a [f32],
    /// Linear coefficient a_i per normalised input, °/h; empty for none.
    pub linear: &'a [f32],
    /// Constant term c, °/h.
    pub constant: f32,
}

/// A Gaussian RBF network holding at most `K` centres over at most `D` inputs.
#[derive(Clone, Debug, PartialEq)]
pub struct RbfNetwork<const K: usize, const D: usize> {
    centers_used: usize,
    inputs_used: usize,
    kernel_inputs: usize,
    offset: [f32; D],
    scale: [f32; D],
    inv_scale: [f32; D],
    centers: [[f32; D]; K],
    widths: [f32; K],
    neg_half_inv_var: [f32; K],
    weights: [f32; K],
    linear: [f32; D],
    has_linear: bool,
    constant: f32,
}

fn all_finite(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite())
}

impl<const K: usize, const D: usize> RbfNetwork<K, D> {
    /// Builds a network, checking shapes against capacity and every parameter.
    pub fn new(p: &RbfParams<'_>) -> Result<Self, ModelError> {
        let d = p.offset.len();
        let k = p.widths.len();
        if d == 0 || d > D || k > K {
            return Err(ModelError::ShapeOverCapacity);
        }
        let m = p.kernel_inputs;
        let linear_ok = p.linear.is_empty() || p.linear.len() == d;
        if !(1..=d).contains(&m) || p.scale.len() != d || p.centers.len() != k * m || p.weights.len() != k || !linear_ok
        {
            return Err(ModelError::ShapeMismatch);
        }
        let finite = all_finite(p.offset)
            && all_finite(p.scale)
            && all_finite(p.centers)
            && all_finite(p.widths)
            && all_finite(p.weights)
            && all_finite(p.linear)
            && p.constant.is_finite();
        if !finite {
            return Err(ModelError::NonFiniteParameter);
        }
        if p.scale.iter().chain(p.widths).any(|&v| v <= 0.0) {
            return Err(ModelError::InvalidParameter);
        }
        let mut net = RbfNetwork {
            centers_used: k,
            inputs_used: d,
            kernel_inputs: m,
            offset: [0.0; D],
            scale: [1.0; D],
            inv_scale: [1.0; D],
            centers: [[0.0; D]; K],
            widths: [1.0; K],
            neg_half_inv_var: [0.0; K],
            weights: [0.0; K],
            linear: [0.0; D],
            has_linear: !p.linear.is_empty(),
            constant: p.constant,
        };
        // Zipped iterators rather than indexing: the firmware validates blobs
        // on a path proven panic-free at link time (panic_free_check.rs).
        let copy = |dst: &mut [f32], src: &[f32]| dst.iter_mut().zip(src).for_each(|(d, s)| *d = *s);
        copy(&mut net.offset, p.offset);
        copy(&mut net.scale, p.scale);
        copy(&mut net.linear, p.linear);
        copy(&mut net.widths, p.widths);
        copy(&mut net.weights, p.weights);
        for (inv, s) in net.inv_scale.iter_mut().zip(p.scale) {
            *inv = 1.0 / s;
        }
        for (row, src) in net.centers.iter_mut().zip(p.centers.chunks_exact(m.max(1))) {
            copy(row, src);
        }
        for (g, w) in net.neg_half_inv_var.iter_mut().zip(p.widths) {
            *g = -0.5 / (w * w);
            if !g.is_finite() {
                return Err(ModelError::InvalidParameter);
            }
        }
        if !(all_finite(&net.inv_scale)) {
            return Err(ModelError::InvalidParameter);
        }
        Ok(net)
    }

    /// Upper bound of |output| when the linear terms see inputs in
    /// [`linear_lo`, `linear_hi`] and the Gaussians inputs in [`kernel_lo`,
    /// `kernel_hi`] (per input, input units), °/h; +∞ when a normalised input
    /// could leave the finite f32 range (where 0 × ∞ would give NaN).
    ///
    /// Interval arithmetic in f64: |c| + Σ|a_i|·max|z_i| + Σ|W_j| (each Gaussian ≤ 1).
    pub fn output_bound(&self, linear_lo: &[f32], linear_hi: &[f32], kernel_lo: &[f32], kernel_hi: &[f32]) -> f64 {
        let d = self.inputs_used.min(D);
        let max_abs_z = |lo: &[f32], hi: &[f32], i: usize| {
            let z = |x: Option<&f32>| {
                ((f64::from(x.copied().unwrap_or(f32::NAN)) - f64::from(self.offset[i])) * f64::from(self.inv_scale[i]))
                    .abs()
            };
            let m = z(lo.get(i)).max(z(hi.get(i)));
            // Far inside f32: a normalised value, its square and its product stay finite.
            if m <= 1e15 { m } else { f64::INFINITY }
        };
        let mut bound = f64::from(self.constant).abs();
        for i in 0..d {
            let z_linear = max_abs_z(linear_lo, linear_hi, i);
            let z_kernel = max_abs_z(kernel_lo, kernel_hi, i);
            if z_kernel.is_infinite() {
                return f64::INFINITY;
            }
            bound += f64::from(self.linear[i]).abs() * z_linear;
            if z_linear.is_infinite() {
                return f64::INFINITY;
            }
        }
        bound
            + self.weights[..self.centers_used.min(K)]
                .iter()
                .map(|w| f64::from(*w).abs())
                .sum::<f64>()
    }

    /// Number of centres in use.
    pub fn centers_used(&self) -> usize {
        self.centers_used
    }

    /// Number of inputs in use.
    pub fn inputs_used(&self) -> usize {
        self.inputs_used
    }

    /// Number of leading inputs the Gaussians see.
    pub fn kernel_inputs(&self) -> usize {
        self.kernel_inputs
    }

    /// Input offsets (training means), input units.
    pub fn offset(&self) -> &[f32] {
        &self.offset[..self.inputs_used]
    }

    /// Input scales (training standard deviations), input units.
    pub fn scale(&self) -> &[f32] {
        &self.scale[..self.inputs_used]
    }

    /// Centre `j` in normalised units, over the kernel inputs (empty past the last centre).
    pub fn center(&self, j: usize) -> &[f32] {
        self.centers.get(j).map_or(&[], |c| &c[..self.kernel_inputs])
    }

    /// Gaussian widths σ_j, normalised units.
    pub fn widths(&self) -> &[f32] {
        &self.widths[..self.centers_used]
    }

    /// Output weights W_j, °/h.
    pub fn weights(&self) -> &[f32] {
        &self.weights[..self.centers_used]
    }

    /// Linear coefficients per normalised input, °/h (empty when the model has none).
    pub fn linear(&self) -> &[f32] {
        if self.has_linear {
            &self.linear[..self.inputs_used]
        } else {
            &[]
        }
    }

    /// Constant term, °/h.
    pub fn constant(&self) -> f32 {
        self.constant
    }

    /// Evaluates the network, °/h: the Gaussians at `x_kernel`, the linear terms
    /// at `x_linear` (input units; the model clamps them to different ranges).
    ///
    /// Cost: `K_used × kernel_inputs`
    /// multiply-adds, `K_used` f32 exponentials ([`crate::fastmath::exp_neg`]) and
    /// `inputs_used` linear terms, independent of the values; about 45
    /// instructions per centre at 3 kernel inputs on a Cortex-M4F.
    pub fn eval(&self, x_kernel: &[f32], x_linear: &[f32]) -> f32 {
        let d = self.inputs_used.min(D);
        let m = self.kernel_inputs.min(d);
        let k = self.centers_used.min(K);
        let normalise =
            |x: &[f32], i: usize| (x.get(i).copied().unwrap_or(self.offset[i]) - self.offset[i]) * self.inv_scale[i];
        let mut y = self.constant;
        for i in 0..d {
            y += self.linear[i] * normalise(x_linear, i);
        }
        let mut z = [0.0f32; D];
        for (i, zi) in z.iter_mut().enumerate().take(m) {
            *zi = normalise(x_kernel, i);
        }
        // Monomorphised per kernel-input count so the distance loop has no
        // branches; every variant sums in the same order, so results are identical.
        y + match m {
            1 => self.gaussian_sum::<1>(&z, k),
            2 => self.gaussian_sum::<2>(&z, k),
            3 => self.gaussian_sum::<3>(&z, k),
            _ => self.gaussian_sum_any(&z, m, k),
        }
    }

    /// Σ_j W_j exp(−‖z − c_j‖²/2σ_j²) over the first `k` centres, `N` inputs.
    #[inline(always)]
    fn gaussian_sum<const N: usize>(&self, z: &[f32; D], k: usize) -> f32 {
        let zn: [f32; N] = core::array::from_fn(|i| z.get(i).copied().unwrap_or(0.0));
        let mut sum = 0.0f32;
        for ((c, w), g) in self.centers[..k]
            .iter()
            .zip(&self.weights[..k])
            .zip(&self.neg_half_inv_var[..k])
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in zn.iter().zip(c) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            sum += w * crate::fastmath::exp_neg(dist_sq * g);
        }
        sum
    }

    /// [`Self::gaussian_sum`] for any number of inputs `d` ≤ D.
    fn gaussian_sum_any(&self, z: &[f32; D], d: usize, k: usize) -> f32 {
        let mut sum = 0.0f32;
        for ((c, w), g) in self.centers[..k]
            .iter()
            .zip(&self.weights[..k])
            .zip(&self.neg_half_inv_var[..k])
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in z[..d].iter().zip(&c[..d]) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            sum += w * crate::fastmath::exp_neg(dist_sq * g);
        }
        sum
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    fn one_centre() -> RbfNetwork<4, 3> {
        RbfNetwork::new(&RbfParams {
            offset: &[20.0, 0.0],
            scale: &[10.0, 1.0],
            kernel_inputs: 2,
            centers: &[0.0, 0.0],
            widths: &[1.0],
            weights: &[2.0],
            linear: &[0.5, 0.0],
            constant: 1.0,
        })
        .unwrap()
    }

    #[test]
    fn evaluates_the_documented_formula() {
        let net = one_centre();
        // At the centre: c + 0 + W·exp(0) = 1 + 2 = 3.
        assert_eq!(net.eval(&[20.0, 0.0, 0.0], &[20.0, 0.0, 0.0]), 3.0);
        // One σ away along T (z = 1): 1 + 0.5 + 2·e^{−1/2}.
        let expected = 1.0 + 0.5 + 2.0 * (-0.5f64).exp();
        assert!((net.eval(&[30.0, 0.0, 0.0], &[30.0, 0.0, 0.0]) as f64 - expected).abs() < 1e-6);
        // The Gaussians and the linear terms take their own inputs.
        let split = 1.0 + 0.5 * 2.0 + 2.0 * (-0.5f64).exp();
        assert!((net.eval(&[30.0, 0.0, 0.0], &[40.0, 0.0, 0.0]) as f64 - split).abs() < 1e-6);
    }

    #[test]
    fn refuses_shapes_over_capacity_or_inconsistent() {
        let ok = one_centre();
        assert_eq!(ok.centers_used(), 1);
        let too_many_inputs = RbfParams {
            offset: &[0.0; 4],
            scale: &[1.0; 4],
            kernel_inputs: 4,
            centers: &[],
            widths: &[],
            weights: &[],
            linear: &[],
            constant: 0.0,
        };
        assert_eq!(
            RbfNetwork::<4, 3>::new(&too_many_inputs),
            Err(ModelError::ShapeOverCapacity)
        );
        let bad_centres = RbfParams {
            offset: &[0.0],
            scale: &[1.0],
            kernel_inputs: 1,
            centers: &[0.0, 1.0],
            widths: &[1.0],
            weights: &[1.0],
            linear: &[],
            constant: 0.0,
        };
        assert_eq!(RbfNetwork::<4, 3>::new(&bad_centres), Err(ModelError::ShapeMismatch));
    }

    #[test]
    fn refuses_non_finite_and_non_positive_parameters() {
        let mut widths = [1.0f32];
        let base = |w: &'_ [f32], c: f32| {
            RbfNetwork::<4, 3>::new(&RbfParams {
                offset: &[0.0],
                scale: &[1.0],
                kernel_inputs: 1,
                centers: &[0.0],
                widths: w,
                weights: &[1.0],
                linear: &[],
                constant: c,
            })
        };
        assert_eq!(base(&widths, f32::NAN), Err(ModelError::NonFiniteParameter));
        widths[0] = 0.0;
        assert_eq!(base(&widths, 0.0), Err(ModelError::InvalidParameter));
        widths[0] = 1e-30; // 1/(2σ²) overflows f32
        assert_eq!(base(&widths, 0.0), Err(ModelError::InvalidParameter));
    }
}
