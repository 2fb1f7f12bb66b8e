//! Evaluating a network: the polynomial path ([`RbfNetwork::eval`]), the
//! integer table path ([`RbfNetwork::eval_table`]), the kernels of a shared
//! basis weighted per layer, and the linear terms.

use super::{MAX_INPUTS_ALL, RbfNetwork, TABLE_MAX_INPUTS};

/// Inverse of [`super::deployment::pack_coefficients`].
#[inline(always)]
fn unpack_coefficients(p: u64, q: u64) -> [i32; 4] {
    [
        p as u32 as i32,
        (p >> 32) as u32 as i32,
        q as u32 as i32,
        (q >> 32) as u32 as i32,
    ]
}

/// Σ_pos 2^−v_j − Σ_neg 2^−v_j with v_j = B_j [+ Q when `ADD_Q`] + Σ_i hi(A_ji, q_i)
/// over the first `M` kernel inputs: the per-centre loops of
/// [`RbfNetwork::eval_table`], one small function per (M, ADD_Q) so that
/// each loop is straight-line; everything around it is shared.
#[inline(always)]
fn exp2_sums<const M: usize, const ADD_Q: bool>(
    positive: &[[u64; 2]],
    negative: &[[u64; 2]],
    q: &[i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> f32 {
    let q = *q;
    exp2_sum::<M, ADD_Q>(positive, q, shared) - exp2_sum::<M, ADD_Q>(negative, q, shared)
}

/// Σ_j 2^−v_j over `centres`, in their order.
///
/// Over three kernel inputs, two centres per iteration: LLVM's own
/// unrolling would hold two centres' eight coefficient words, the three
/// q_i, the table, the pointer and the count at once, one register more
/// than a Cortex-M4 has free (r7 is the frame pointer), and rebuild the
/// table's address in every iteration. The empty `black_box` (no
/// instruction) keeps it from unrolling this loop further. With fewer
/// kernel inputs the registers suffice and LLVM's unrolling is left alone.
#[inline(always)]
fn exp2_sum<const M: usize, const ADD_Q: bool>(centers: &[[u64; 2]], q: [i32; TABLE_MAX_INPUTS], shared: i32) -> f32 {
    let table = &crate::fastmath::EXP2_OCTAVE_BITS;
    let mut sum = 0.0f32;
    if M < 3 {
        for center in centers {
            sum += exp2_term::<M, ADD_Q>(table, center, q, shared);
        }
        return sum;
    }
    let mut pairs = centers.chunks_exact(2);
    for pair in &mut pairs {
        if let [first, second] = pair {
            sum += exp2_term::<M, ADD_Q>(table, first, q, shared);
            core::hint::black_box(());
            sum += exp2_term::<M, ADD_Q>(table, second, q, shared);
        }
    }
    for center in pairs.remainder() {
        sum += exp2_term::<M, ADD_Q>(table, center, q, shared);
    }
    sum
}

/// Σ_j w_j[a]·2^−v_j for the three layers `a`, over `centres` in order
/// (the kernel of [`RbfNetwork::kernel_dots`]): one table exponential and
/// three multiply-adds per centre.
#[inline(always)]
fn exp2_dots<const M: usize, const ADD_Q: bool>(
    centers: &[[u64; 2]],
    weights: &[[f32; 3]],
    q: [i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> [f32; 3] {
    let table = &crate::fastmath::EXP2_OCTAVE_BITS;
    let (mut x, mut y, mut z) = (0.0f32, 0.0f32, 0.0f32);
    for (center, &[wx, wy, wz]) in centers.iter().zip(weights) {
        let g = exp2_term::<M, ADD_Q>(table, center, q, shared);
        x += wx * g;
        y += wy * g;
        z += wz * g;
    }
    [x, y, z]
}

/// 2^−v_j of one centre's packed coefficients.
#[inline(always)]
fn exp2_term<const M: usize, const ADD_Q: bool>(
    table: &[u32; crate::fastmath::EXP2_CELLS],
    &[p, r]: &[u64; 2],
    q: [i32; TABLE_MAX_INPUTS],
    shared: i32,
) -> f32 {
    let [a1, a2, a3, b] = unpack_coefficients(p, r);
    let mut v = if ADD_Q { b.wrapping_add(shared) } else { b };
    if M >= 1 {
        v = v.wrapping_add(mul_hi(a1, q[0]));
    }
    if M >= 2 {
        v = v.wrapping_add(mul_hi(a2, q[1]));
    }
    if M >= 3 {
        v = v.wrapping_add(mul_hi(a3, q[2]));
    }
    crate::fastmath::exp2_neg_q16(table, v)
}

/// High word of the 64-bit product: one SMMUL/SMMLA on a Cortex-M4.
#[inline(always)]
fn mul_hi(a: i32, b: i32) -> i32 {
    ((i64::from(a) * i64::from(b)) >> 32) as i32
}

impl<const K: usize, const D: usize> RbfNetwork<K, D> {
    /// Evaluates the network on its polynomial path, °/h: the Gaussians at
    /// `x_kernel` (input units, already clamped by the caller), the linear
    /// terms at `x_linear` (the model clamps them to a wider range); `N` is
    /// the model's input count.
    ///
    /// Cost: `K_used × kernel_inputs` multiply-adds, `K_used` f32
    /// exponentials ([`crate::fastmath::exp_neg`]) and `inputs_used` linear
    /// terms, independent of the values. [`Self::eval_table`] is the fast path.
    pub fn eval<const N: usize>(&self, x_kernel: &[f32; N], x_linear: &[f32; N]) -> f32 {
        self.linear_sum(x_linear) + self.polynomial_gaussians(x_kernel)
    }

    /// The Gaussian sum of [`Self::eval`], °/h.
    fn polynomial_gaussians(&self, x_kernel: &[f32]) -> f32 {
        let k = self.centers_used.min(K);
        if k == 0 {
            // A network of linear terms alone (a response bank's): nothing to normalise.
            return 0.0;
        }
        let m = self.kernel_inputs.min(D);
        let mut z = [0.0f32; D];
        for (((zi, x), o), s) in z
            .iter_mut()
            .zip(x_kernel)
            .zip(&self.offset)
            .zip(&self.inv_scale)
            .take(m)
        {
            *zi = (x - o) * s;
        }
        let z = z.get(..m).unwrap_or(&[]);
        let mut sum = 0.0f32;
        for ((c, w), g) in self
            .centers
            .iter()
            .zip(&self.weights)
            .zip(&self.neg_half_inv_var)
            .take(k)
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in z.iter().zip(c) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            sum += w * crate::fastmath::exp_neg(dist_sq * g);
        }
        sum
    }

    /// Evaluates the network on its table path (only meaningful when
    /// [`Self::table_ready`]), °/h: the Gaussians at the kernel inputs
    /// `x_kernel` as they come (the saturating conversion clamps them to the
    /// box given to [`Self::prepare_table`]; NaN reads as the box's centre),
    /// the linear terms at `x_linear`; `x_kernel` holds a feature vector's
    /// slots, the first `kernel_inputs` of which the Gaussians see.
    ///
    /// Σ_j W_j exp(−‖z − c_j‖²/2σ²) = 2^(E+T) · 2^−Q · (Σ_pos 2^−v_j − Σ_neg 2^−v_j)
    /// with the fixed-point exponents of [`Self::prepare_table`] and the
    /// table exponential. Per centre: one integer multiply-accumulate of
    /// high words (SMMLA) per kernel input onto B_j, one saturation, one
    /// table load, the exponent subtraction, one float add; no branch, no
    /// conversion, no weight multiplication. Integer arithmetic, so host and
    /// target agree bit for bit.
    ///
    /// `N` is the caller's linear input count (the linear sum is straight-line).
    #[inline(always)]
    pub fn eval_table<const N: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL], x_linear: &[f32; N]) -> f32 {
        self.linear_sum(x_linear) + self.table_gaussians(x_kernel)
    }

    /// The Gaussian sum of [`Self::eval_table`], °/h.
    #[inline(always)]
    pub(crate) fn table_gaussians(&self, x_kernel: &[f32; MAX_INPUTS_ALL]) -> f32 {
        match self.kernel_inputs {
            1 => self.table_gaussians_over::<1>(x_kernel),
            2 => self.table_gaussians_over::<2>(x_kernel),
            _ => self.table_gaussians_over::<3>(x_kernel),
        }
    }

    /// [`Self::table_gaussians`] over the first `M` kernel inputs: the
    /// inputs past them take no instruction.
    #[inline(always)]
    fn table_gaussians_over<const M: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL]) -> f32 {
        // `as` saturates (VCVT does the same): the clamp to the box. NaN
        // converts to 0, the box's centre.
        let q: [i32; TABLE_MAX_INPUTS] =
            core::array::from_fn(
                |i| match (i < M, x_kernel.get(i), self.kernel_mid.get(i), self.kernel_gain.get(i)) {
                    (true, Some(x), Some(mid), Some(gain)) => ((x - mid) * gain) as i32,
                    _ => 0,
                },
            );
        // Q·2^16 = Σ_i hi(q_i, hi(q_i, H_i)): SMMUL + SMMLA. (hi(hi(q, q), H)
        // would let the compiler see a non-negative factor and widen it.)
        let mut shared = 0i32;
        for (qi, h) in q.iter().zip(&self.shared_coeff).take(M) {
            shared = shared.wrapping_add(mul_hi(*qi, mul_hi(*qi, *h)));
        }
        let (positive, rest) = self.exponent.split_at(self.positive.min(K));
        let negative = rest.get(..self.negative).unwrap_or(&[]);
        if self.q_in_sum {
            exp2_sums::<M, true>(positive, negative, &q, shared) * self.weight_scale
        } else {
            let sums = exp2_sums::<M, false>(positive, negative, &q, 0);
            let factor = crate::fastmath::exp2_neg_q16(&crate::fastmath::EXP2_OCTAVE_BITS, shared) * self.weight_scale;
            sums * factor
        }
    }

    /// Σ_j w_j[a]·exp(−‖z − c_j‖²/2σ²) for each of the three output layers
    /// `a` of a shared basis ([`crate::shared_basis`]): the kernel values are
    /// computed once per centre and weighted three times. On the table path
    /// (only meaningful when [`Self::table_ready`] with every centre at
    /// weight 1, which puts every centre in `exponent` in order with
    /// E = 0) the kernels are 2^T · 2^−Q · 2^−v_j as in
    /// [`Self::eval_table`]; otherwise the polynomial path's exponentials at
    /// `x_kernel` clamped by the caller. Each layer's sum depends only on
    /// its own weights: a layer evaluates to the same bits whichever other
    /// layers are present.
    #[inline(always)]
    pub(crate) fn kernel_dots(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        if !self.table {
            return self.polynomial_kernel_dots(x_kernel, weights);
        }
        match self.kernel_inputs {
            1 => self.table_kernel_dots::<1>(x_kernel, weights),
            2 => self.table_kernel_dots::<2>(x_kernel, weights),
            _ => self.table_kernel_dots::<3>(x_kernel, weights),
        }
    }

    /// [`Self::kernel_dots`] on the table path over the first `M` kernel inputs.
    #[inline(always)]
    fn table_kernel_dots<const M: usize>(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        let q: [i32; TABLE_MAX_INPUTS] =
            core::array::from_fn(
                |i| match (i < M, x_kernel.get(i), self.kernel_mid.get(i), self.kernel_gain.get(i)) {
                    (true, Some(x), Some(mid), Some(gain)) => ((x - mid) * gain) as i32,
                    _ => 0,
                },
            );
        let mut shared = 0i32;
        for (qi, h) in q.iter().zip(&self.shared_coeff).take(M) {
            shared = shared.wrapping_add(mul_hi(*qi, mul_hi(*qi, *h)));
        }
        let centers = self.exponent.get(..self.positive.min(K)).unwrap_or(&[]);
        let (sums, factor) = if self.q_in_sum {
            (exp2_dots::<M, true>(centers, weights, q, shared), self.weight_scale)
        } else {
            let factor = crate::fastmath::exp2_neg_q16(&crate::fastmath::EXP2_OCTAVE_BITS, shared) * self.weight_scale;
            (exp2_dots::<M, false>(centers, weights, q, 0), factor)
        };
        sums.map(|s| s * factor)
    }

    /// [`Self::kernel_dots`] on the polynomial path. Its normalisation and
    /// kernel loop repeat [`Self::polynomial_gaussians`]' on purpose: one
    /// helper taking a closure for both cost the board image flash and every
    /// evaluation instructions (`cargo xtask bench-fw` shows both).
    fn polynomial_kernel_dots(&self, x_kernel: &[f32; MAX_INPUTS_ALL], weights: &[[f32; 3]]) -> [f32; 3] {
        let m = self.kernel_inputs.min(D);
        let mut z = [0.0f32; D];
        for (((zi, x), o), s) in z
            .iter_mut()
            .zip(x_kernel)
            .zip(&self.offset)
            .zip(&self.inv_scale)
            .take(m)
        {
            *zi = (x - o) * s;
        }
        let z = z.get(..m).unwrap_or(&[]);
        let mut sums = [0.0f32; 3];
        for ((c, w), g) in self
            .centers
            .iter()
            .zip(weights)
            .zip(&self.neg_half_inv_var)
            .take(self.centers_used.min(K))
        {
            let mut dist_sq = 0.0f32;
            for (zi, ci) in z.iter().zip(c) {
                let diff = zi - ci;
                dist_sq += diff * diff;
            }
            let kernel = crate::fastmath::exp_neg(dist_sq * g);
            for (s, wa) in sums.iter_mut().zip(w) {
                *s += wa * kernel;
            }
        }
        sums
    }

    /// [`Self::linear_sum_boxed`] with an output layer's own (b_i, c″)
    /// ([`Self::linear_box_terms`]).
    #[inline(always)]
    pub(crate) fn linear_sum_with<const N: usize>(
        &self,
        raw: &[f32; MAX_INPUTS_ALL],
        coeff: &[f32; D],
        constant: f32,
    ) -> f32 {
        let mut y = constant;
        for (((x, mid), gain), b) in raw
            .iter()
            .zip(&self.linear_box_mid)
            .zip(&self.linear_box_gain)
            .zip(coeff)
            .take(N)
        {
            y += b * (((x - mid) * gain) as i32) as f32;
        }
        y
    }

    /// The linear terms at `raw` clamped to the box given to
    /// [`Self::prepare_linear`] by the saturating conversion (NaN reads as
    /// the box's centre): no compare, no branch.
    #[inline(always)]
    pub(crate) fn linear_sum_boxed<const N: usize>(&self, raw: &[f32; MAX_INPUTS_ALL]) -> f32 {
        let mut y = self.linear_box_constant;
        for (((x, mid), gain), b) in raw
            .iter()
            .zip(&self.linear_box_mid)
            .zip(&self.linear_box_gain)
            .zip(&self.linear_box_coeff)
            .take(N)
        {
            y += b * (((x - mid) * gain) as i32) as f32;
        }
        y
    }

    /// c′ + Σ a′_i x_i: the linear terms with the normalisation folded in.
    #[inline(always)]
    pub(crate) fn linear_sum<const N: usize>(&self, x_linear: &[f32; N]) -> f32 {
        let mut y = self.constant_raw;
        for (a, x) in self.linear_raw.iter().zip(x_linear) {
            y += a * x;
        }
        y
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::rbf::RbfParams;
    use crate::rbf::tests::one_center;

    /// Kernel inputs as a feature vector's slots (the rest 0).
    fn slots(x: &[f32]) -> [f32; MAX_INPUTS_ALL] {
        core::array::from_fn(|i| x.get(i).copied().unwrap_or(0.0))
    }

    #[test]
    fn both_paths_evaluate_the_documented_formula() {
        let poly = one_center();
        let mut table = one_center();
        table.prepare_table(&[0.0, -5.0], &[40.0, 5.0]);
        assert!(table.table_ready() && !poly.table_ready());
        // The table path: each Gaussian within the table exponential's bound,
        // twice (its own term and the shared factor), W = 2; the polynomial
        // path is far closer.
        let tol = 2.0 * 2.0 * crate::fastmath::EXP2_FIXED_REL_ERROR + 1e-6;
        let both = |kernel: [f32; 2], linear: [f32; 2]| {
            let p = poly.eval(&[kernel[0], kernel[1], 0.0], &[linear[0], linear[1], 0.0]);
            (f64::from(p), f64::from(table.eval_table(&slots(&kernel), &linear)))
        };
        let cases = [
            // At the centre: c + 0 + W·exp(0) = 1 + 2 = 3.
            ([20.0, 0.0], [20.0, 0.0], 3.0),
            // One σ away along T (z = 1): 1 + 0.5 + 2·e^{−1/2}.
            ([30.0, 0.0], [30.0, 0.0], 1.0 + 0.5 + 2.0 * (-0.5f64).exp()),
            // The Gaussians and the linear terms take their own inputs.
            ([30.0, 0.0], [40.0, 0.0], 1.0 + 0.5 * 2.0 + 2.0 * (-0.5f64).exp()),
            // Off-axis: z = (−1, 2), ‖z‖² = 5.
            ([10.0, 2.0], [10.0, 2.0], 1.0 - 0.5 + 2.0 * (-2.5f64).exp()),
        ];
        for (kernel, linear, expected) in cases {
            let (p, t) = both(kernel, linear);
            assert!((p - expected).abs() < 1e-6, "{kernel:?}: polynomial {p} vs {expected}");
            assert!((t - expected).abs() < tol, "{kernel:?}: table {t} vs {expected}");
        }
    }

    #[test]
    fn the_table_path_clamps_kernel_inputs_to_its_box() {
        let mut table = one_center();
        table.prepare_table(&[0.0, -5.0], &[40.0, 5.0]);
        let at = |t: f32, r: f32| table.eval_table(&slots(&[t, r]), &[20.0, 0.0]).to_bits();
        assert_eq!(at(55.0, 0.0), at(40.0, 0.0), "above the box: its edge");
        assert_eq!(at(-1e30, 0.0), at(0.0, 0.0), "far below: its edge");
        assert_eq!(at(20.0, f32::INFINITY), at(20.0, 5.0));
        assert_eq!(at(f32::NAN, 0.0), at(20.0, 0.0), "NaN reads as the box's centre");
    }

    #[test]
    fn table_path_matches_the_polynomial_path_within_its_bound() {
        // The same network with per-centre widths (polynomial exponential) and
        // with a shared width (table exponential), over a grid of inputs.
        let centers = [0.3, -0.2, 0.1, -1.0, 0.5, 0.8, 1.2, 0.0, -0.7];
        let build = |widths: &[f32]| {
            RbfNetwork::<4, 3>::new(&RbfParams {
                offset: &[25.0, 0.0, 0.0],
                scale: &[10.0, 1.0, 20.0],
                kernel_inputs: 3,
                centers: &centers,
                widths,
                weights: &[1.5, -2.0, 0.7],
                linear: &[],
                constant: 0.0,
            })
            .unwrap()
        };
        let (lo, hi) = ([5.0, -2.0, -40.0], [45.0, 2.0, 40.0]);
        // σ = 0.8: T = S Σh² = 13.5, the shared term is a factor; σ = 0.3:
        // T = 96, it is added to every exponent.
        for (sigma, q_in_sum) in [(0.8f32, false), (0.3, true)] {
            let mut table = build(&[sigma; 3]);
            table.prepare_table(&lo, &hi);
            let mut exact = build(&[sigma, sigma, sigma * (1.0 + f32::EPSILON)]);
            exact.prepare_table(&lo, &hi);
            assert!(table.table_ready() && !exact.table_ready());
            assert_eq!(table.q_in_sum, q_in_sum, "σ = {sigma}");
            // Each term's table error, and the shared factor's on the sum.
            let rel = (1.0 + crate::fastmath::EXP2_FIXED_REL_ERROR).powi(2) - 1.0;
            let bound = (1.5 + 2.0 + 0.7) * rel;
            for i in 0..40 {
                let x = [5.0 + i as f32, -2.0 + 0.1 * i as f32, 40.0 - 2.0 * i as f32];
                let (a, b) = (table.eval_table(&slots(&x), &x), exact.eval(&x, &x));
                assert!((a - b).abs() as f64 <= bound + 1e-5, "σ = {sigma}, {x:?}: {a} vs {b}");
            }
        }
    }
}
