//! Preparing a network for the firmware's evaluation: the integer table
//! path's fixed-point exponents ([`RbfNetwork::prepare_table`]), the linear
//! terms over their boxes, and the bound of the output over an input box.

use super::{RbfNetwork, TABLE_MAX_INPUTS, U_FRAC};

/// Bound every fixed-point partial sum must stay under (no i32 overflow).
const FIXED_LIMIT: f64 = (1u32 << 30) as f64;
/// Exponent range a Gaussian term needs: terms below 2^−32 of the largest
/// weight may be dropped. The offset T may use the rest of the table's range.
const GAUSS_EXP2_RANGE: u32 = 32;

/// [A₁, A₂, A₃, B] as two 64-bit words: loaded with two LDRDs.
pub(super) fn pack_coefficients(c: [i32; 4]) -> [u64; 2] {
    let word = |lo: i32, hi: i32| u64::from(lo as u32) | (u64::from(hi as u32) << 32);
    [word(c[0], c[1]), word(c[2], c[3])]
}

/// The largest ⌈log₂ |w|⌉ over the nonzero `weights`, exactly, from their
/// bits: the exponent, one more where the significand is not a power of
/// two. `None` when every weight is 0 or one is ±∞ or NaN. Integer work in
/// one out-of-line loop: exact by construction, where a rounded f64 log2
/// and `ceil` are exact only by care, and small in the board image.
#[inline(never)]
fn max_ceil_log2_abs(weights: &[f32]) -> Option<i32> {
    let mut max = None;
    for w in weights {
        let bits = w.to_bits() & 0x7FFF_FFFF;
        let (biased, significand) = ((bits >> 23) as i32, bits & 0x007F_FFFF);
        let e = match biased {
            _ if bits == 0 => continue,
            0xFF => return None,
            // Subnormal: |w| = significand · 2^−149.
            0 => 31 - significand.leading_zeros() as i32 - 149 + i32::from(!significand.is_power_of_two()),
            _ => biased - 127 + i32::from(significand != 0),
        };
        max = Some(max.map_or(e, |m: i32| m.max(e)));
    }
    max
}

/// 2^n for an integer-valued `n`, exactly `libm::exp2(n) as f32` (0 below
/// 2^−149, +∞ above 2^127) built in the exponent bits: libm's exp2 would
/// bring its lookup table into the firmware for a power of two.
fn exp2_integer(n: f64) -> f32 {
    if n > 127.0 {
        f32::INFINITY
    } else if n >= -126.0 {
        f32::from_bits(((n as i32 + 127) as u32) << 23)
    } else if n >= -149.0 {
        f32::from_bits(1 << (n as i32 + 149) as u32)
    } else {
        0.0
    }
}

impl<const K: usize, const D: usize> RbfNetwork<K, D> {
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

    /// Folds the input normalisation into the linear terms (f64, rounded once).
    pub(super) fn fold_linear(&mut self, d: usize) {
        let mut constant = f64::from(self.constant);
        for i in 0..d.min(D) {
            let a = f64::from(self.linear[i]) * f64::from(self.inv_scale[i]);
            self.linear_raw[i] = a as f32;
            constant -= a * f64::from(self.offset[i]);
        }
        self.constant_raw = constant as f32;
    }

    /// Enables the integer table path for Gaussian inputs clamped to
    /// [`kernel_lo`, `kernel_hi`] (input units: the training box) when its
    /// conditions hold: one shared width, at most [`TABLE_MAX_INPUTS`] kernel
    /// inputs, each with a non-empty range, a nonzero weight, a shared-term
    /// offset T ≤ 32 (it must fit the table beside the 32 a term needs) and
    /// every fixed-point quantity of the evaluation provably inside i32.
    /// Otherwise the polynomial path stays. f64 arithmetic rounded once:
    /// deterministic, so host and target prepare the same bits.
    ///
    /// The table path clamps kernel inputs itself, by the saturating
    /// conversion q_i = i32(x_i − mid_i)·gain_i) that maps the box onto the
    /// whole i32 range: z_i = m_i + h_i·q_i/2^31 with m_i, h_i the box's
    /// normalised centre and half-width. Then
    /// S‖z − c_j‖² = S‖m − c_j‖² + Σ_i 2S(m_i − c_ji)h_i·q_i/2^31 + S Σ_i h_i²(q_i/2^31)²,
    /// whose last sum (call it Q, 0 ≤ Q ≤ T) is the same for every centre.
    pub fn prepare_table(&mut self, kernel_lo: &[f32], kernel_hi: &[f32]) {
        self.table = false;
        let (m, k) = (self.kernel_inputs, self.centers_used.min(K));
        let widths = self.widths.get(..k).unwrap_or(&[]);
        let weights = self.weights.get(..k).unwrap_or(&[]);
        let shared = widths
            .first()
            .is_some_and(|w0| widths.iter().all(|w| w.to_bits() == w0.to_bits()));
        let Some(e) = max_ceil_log2_abs(weights) else {
            return;
        };
        if !shared || m > TABLE_MAX_INPUTS {
            return;
        }
        let e = f64::from(e);
        let sigma = f64::from(widths.first().copied().unwrap_or(1.0));
        let s = core::f64::consts::LOG2_E / (2.0 * sigma * sigma);
        let (u_one, q_one) = (f64::from(1u32 << U_FRAC), f64::from(1u32 << 31));
        // The saturating map of each kernel input, and its box in normalised units.
        let (mut mid_z, mut half_z) = ([0.0f64; TABLE_MAX_INPUTS], [0.0f64; TABLE_MAX_INPUTS]);
        let mut t_real = 0.0;
        for i in 0..m {
            let (Some(lo), Some(hi)) = (kernel_lo.get(i), kernel_hi.get(i)) else {
                return;
            };
            let half = (f64::from(*hi) - f64::from(*lo)) / 2.0;
            let mid = ((f64::from(*lo) + f64::from(*hi)) / 2.0) as f32;
            let gain = (q_one / half) as f32;
            if !(half > 0.0 && gain.is_finite() && gain > 0.0) {
                return;
            }
            let scale = f64::from(self.scale[i]);
            mid_z[i] = (f64::from(mid) - f64::from(self.offset[i])) / scale;
            half_z[i] = q_one / f64::from(gain) / scale;
            self.kernel_mid[i] = mid;
            self.kernel_gain[i] = gain;
            t_real += s * half_z[i] * half_z[i];
        }
        // The offset T: an integer, so 2^T is exact. Q in fixed point may
        // exceed T by a unit of 2^−16 through rounding: a v_j of −2^−16 reads
        // as 0, an error far below the table's. Narrow Gaussians over
        // a wide box (T > 32) add Q to every exponent instead (one more
        // instruction per centre): then Q itself must fit.
        let t = libm::ceil(t_real);
        let q_max = t_real * u_one;
        if q_max.is_nan() || q_max >= FIXED_LIMIT {
            return;
        }
        let factored = t <= f64::from(crate::fastmath::EXP2_RANGE - GAUSS_EXP2_RANGE);
        let (offset, q_in_sum) = if factored { (t, 0.0) } else { (0.0, q_max) };
        // Q·2^16 = Σ_i hi(q_i, hi(q_i, H_i)) with H_i = S h_i² 2^18.
        for (h, hz) in self.shared_coeff.iter_mut().zip(&half_z).take(m) {
            let h_fixed = s * hz * hz * f64::from(1u32 << (U_FRAC + 2));
            if h_fixed.is_nan() || h_fixed >= FIXED_LIMIT * 2.0 {
                return;
            }
            *h = h_fixed as i32;
        }
        let mut slot = 0;
        for positive in [true, false] {
            for (c, &w) in self.centers.iter().zip(weights) {
                if w == 0.0 || (w > 0.0) != positive {
                    continue;
                }
                let Some(packed) = self.exponent.get_mut(slot) else {
                    return;
                };
                let mut coeffs = [0i32; 4];
                let (mut dist_sq, mut products_max) = (0.0f64, 0.0f64);
                for (((a, ci), mz), hz) in coeffs.iter_mut().zip(c).zip(&mid_z).zip(&half_z).take(m) {
                    // hi(A, q) = A·q/2^32 = 2S(m − c)h·(q/2^31)·2^16.
                    let diff = mz - f64::from(*ci);
                    let a_real = 2.0 * s * diff * hz;
                    let a_fixed = a_real * u_one * 2.0;
                    if a_fixed.abs() >= FIXED_LIMIT {
                        return;
                    }
                    *a = a_fixed as i32;
                    dist_sq += diff * diff;
                    products_max += a_real.abs() * u_one;
                }
                let b = (s * dist_sq + e + offset - libm::log2(f64::from(w).abs())) * u_one;
                if b + products_max + q_in_sum >= FIXED_LIMIT {
                    return;
                }
                coeffs[3] = b as i32;
                *packed = pack_coefficients(coeffs);
                slot += 1;
            }
            if positive {
                self.positive = slot;
            }
        }
        self.negative = slot - self.positive;
        let weight_scale = exp2_integer(e + offset);
        if weight_scale.is_finite() && weight_scale > 0.0 {
            self.weight_scale = weight_scale;
            self.q_in_sum = !factored;
            self.table = true;
        }
    }

    /// Prepares the linear terms of the table path for inputs clamped to
    /// [`linear_lo`, `linear_hi`] (input units) by the saturating conversion
    /// q_i = i32((x_i − mid_i)·gain_i), which maps the box onto the i32
    /// range: x_i = mid_i + q_i/gain_i, so a′_i x_i = a′_i mid_i + (a′_i/gain_i)·q_i,
    /// and the constants go into c″. An empty box maps every value to its
    /// one point. f64 arithmetic rounded once: host and target agree.
    pub fn prepare_linear(&mut self, linear_lo: &[f32], linear_hi: &[f32]) {
        let mut constant = f64::from(self.constant_raw);
        let q_one = f64::from(1u32 << 31);
        for i in 0..self.inputs_used.min(D) {
            let (lo, hi) = (
                f64::from(linear_lo.get(i).copied().unwrap_or(0.0)),
                f64::from(linear_hi.get(i).copied().unwrap_or(0.0)),
            );
            let mid = ((lo + hi) / 2.0) as f32;
            let half = (hi - lo) / 2.0;
            let gain = if half > 0.0 { (q_one / half) as f32 } else { 0.0 };
            let a = f64::from(self.linear_raw[i]);
            self.linear_box_mid[i] = mid;
            self.linear_box_gain[i] = gain;
            self.linear_box_coeff[i] = if gain > 0.0 { (a / f64::from(gain)) as f32 } else { 0.0 };
            constant += a * f64::from(mid);
        }
        self.linear_box_constant = constant as f32;
    }

    /// The linear terms of an output layer with coefficients `linear` (per
    /// normalised input, °/h; empty for none) and constant `constant`, °/h,
    /// in the form [`Self::linear_sum_with`] evaluates: (b_i, c″) as
    /// [`Self::fold_linear`] and [`Self::prepare_linear`] derive them for
    /// the network's own terms, in the same f64 steps rounded at the same
    /// places, over the linear boxes already prepared.
    pub(crate) fn linear_box_terms(&self, linear: &[f32], constant: f32) -> ([f32; D], f32) {
        let d = self.inputs_used.min(D);
        let mut raw = [0.0f32; D];
        let mut folded = f64::from(constant);
        for (i, (r, a)) in raw.iter_mut().zip(linear).take(d).enumerate() {
            let a = f64::from(*a) * f64::from(self.inv_scale[i]);
            *r = a as f32;
            folded -= a * f64::from(self.offset[i]);
        }
        let mut boxed = f64::from(folded as f32);
        let mut coeff = [0.0f32; D];
        for i in 0..d {
            let a = f64::from(raw[i]);
            let gain = self.linear_box_gain[i];
            coeff[i] = if gain > 0.0 { (a / f64::from(gain)) as f32 } else { 0.0 };
            boxed += a * f64::from(self.linear_box_mid[i]);
        }
        (coeff, boxed as f32)
    }

    /// [`Self::output_bound`] of an output layer over this network's basis:
    /// `linear` and `constant` in place of the network's, Σ|W_j| given.
    pub(crate) fn layer_output_bound(
        &self,
        linear: &[f32],
        constant: f32,
        weight_abs_sum: f64,
        linear_lo: &[f32],
        linear_hi: &[f32],
    ) -> f64 {
        let d = self.inputs_used.min(D);
        let mut bound = f64::from(constant).abs() + weight_abs_sum;
        for i in 0..d {
            let z = |x: Option<&f32>| {
                ((f64::from(x.copied().unwrap_or(f32::NAN)) - f64::from(self.offset[i])) * f64::from(self.inv_scale[i]))
                    .abs()
            };
            let m = z(linear_lo.get(i)).max(z(linear_hi.get(i)));
            let m = if m <= 1e15 { m } else { f64::INFINITY };
            let a = f64::from(linear.get(i).copied().unwrap_or(0.0)).abs();
            if m.is_infinite() {
                return f64::INFINITY;
            }
            bound += a * m;
        }
        bound
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_powers_of_two_match_libm_bit_for_bit() {
        for n in -200..=200 {
            let n = f64::from(n);
            assert_eq!(exp2_integer(n).to_bits(), (libm::exp2(n) as f32).to_bits(), "2^{n}");
        }
    }
}
