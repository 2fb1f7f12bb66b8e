//! An all-`f32` exponential for the Gaussian basis.
//!
//! `libm::expf` follows musl and computes in `f64`, which is soft-float on a
//! Cortex-M4F (single-precision FPU): about 60 % of a 32-centre evaluation.
//! [`exp`] needs only f32 operations. Being plain IEEE-754 arithmetic in a
//! fixed order (Rust never contracts to FMA), it gives the same bits on the
//! host and the target.
//!
//! Method: Cody–Waite reduction x = n·ln2 + r with |r| ≤ ln2/2 (ln2 split in
//! a 9-bit-exact high part and a low part), exp(r) by its degree-6 Taylor
//! polynomial in Horner form (truncation ≤ |r|⁷/7! ≤ 1.2e-7 relative), and 2ⁿ
//! built in the exponent bits. Measured error over [−87, 88] against f64:
//! ≤ 3 ulp (relative 3.6e-7), asserted by the tests below. Below −87 the true
//! value is under 1.7e-38 and 0 is returned (so are NaN inputs: a Gaussian
//! basis of an unusable input contributes nothing).

/// ln 2 high part: exactly representable with few mantissa bits, so n·LN2_HI is exact for |n| ≤ 2⁸.
const LN2_HI: f32 = 0.693_359_4;
/// ln 2 − LN2_HI.
const LN2_LO: f32 = -2.121_944_4e-4;
/// 1 / ln 2.
const INV_LN2: f32 = core::f32::consts::LOG2_E;
/// Below this the result is flushed to 0 (true value < 1.7e-38).
const MIN_ARG: f32 = -87.0;
/// Above this the argument is clamped (result ≈ 1.65e38, still finite).
const MAX_ARG: f32 = 88.0;

/// e^x in f32 (see the module documentation for accuracy and limits).
#[inline]
#[allow(
    clippy::neg_cmp_op_on_partial_ord,
    reason = "one comparison also catches NaN: 4 instructions less per centre than is_nan() ||"
)]
pub fn exp(x: f32) -> f32 {
    if !(x > MIN_ARG) {
        return 0.0;
    }
    let x = if x > MAX_ARG { MAX_ARG } else { x };
    // Round-half-away-from-zero of x/ln2; `as` saturates and is well defined.
    let t = x * INV_LN2;
    let n = (if t < 0.0 { t - 0.5 } else { t + 0.5 }) as i32;
    let nf = n as f32;
    let r = (x - nf * LN2_HI) - nf * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    // n ∈ [−126, 127] here, so 2ⁿ is a normal f32.
    p * f32::from_bits(((n + 127) as u32) << 23)
}

/// e^x for x ≤ 0, the Gaussian basis's case: [`exp`] without the overflow
/// clamp and with the rounding of x/ln2 specialised to x ≤ 0. Same accuracy;
/// positive x is treated as 0 (result 1). NaN gives 0.
#[inline]
#[allow(
    clippy::neg_cmp_op_on_partial_ord,
    reason = "one comparison also catches NaN: 4 instructions less per centre than is_nan() ||"
)]
pub fn exp_neg(x: f32) -> f32 {
    if !(x > MIN_ARG) {
        return 0.0;
    }
    let x = if x > 0.0 { 0.0 } else { x };
    let n = (x * INV_LN2 - 0.5) as i32;
    let nf = n as f32;
    let r = (x - nf * LN2_HI) - nf * LN2_LO;
    let p = 1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    p * f32::from_bits(((n + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulp_error(x: f32) -> f64 {
        let got = exp(x) as f64;
        let want = (x as f64).exp();
        let ulp = (want as f32).to_bits();
        let ulp_size = (f32::from_bits(ulp + 1) as f64) - (f32::from_bits(ulp) as f64);
        (got - want).abs() / ulp_size
    }

    #[test]
    fn within_three_ulp_of_the_true_exponential_over_the_whole_range() {
        let mut worst: (f64, f32) = (0.0, 0.0);
        let steps = 2_000_000;
        // (MIN_ARG, MAX_ARG]: at MIN_ARG itself the documented flush to 0 applies.
        for i in 1..=steps {
            let x = MIN_ARG + (MAX_ARG - MIN_ARG) * i as f32 / steps as f32;
            let e = ulp_error(x);
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 <= 3.0, "worst error {} ulp at x = {}", worst.0, worst.1);
    }

    #[test]
    fn gaussian_arguments_are_accurate_where_they_matter() {
        // The basis uses x = −‖z − c‖²/2σ² ≤ 0; check dense small arguments too.
        for i in 0..100_000 {
            let x = -(i as f32) * 1e-4;
            let rel = ((exp(x) as f64) - (x as f64).exp()).abs() / (x as f64).exp();
            assert!(rel < 3.6e-7, "x = {x}: relative error {rel}");
        }
        assert_eq!(exp(0.0).to_bits(), 1.0f32.to_bits());
    }

    #[test]
    fn exp_neg_equals_exp_bit_for_bit_on_non_positive_arguments() {
        // Rounding of x/ln2 differs only in form: t − 0.5 truncated toward zero
        // is round-half-away for t ≤ 0, exactly as in `exp`.
        for i in 0..2_000_000 {
            let x = MIN_ARG * i as f32 / 2_000_000.0;
            assert_eq!(exp_neg(x).to_bits(), exp(x).to_bits(), "x = {x}");
        }
        assert_eq!(exp_neg(3.0).to_bits(), 1f32.to_bits());
        assert_eq!(exp_neg(f32::NAN).to_bits(), 0f32.to_bits());
    }

    #[test]
    fn extremes_flush_or_clamp_instead_of_misbehaving() {
        assert_eq!(exp(-87.5).to_bits(), 0f32.to_bits());
        assert_eq!(exp(f32::NEG_INFINITY).to_bits(), 0f32.to_bits());
        assert_eq!(exp(f32::NAN).to_bits(), 0f32.to_bits());
        assert!(exp(1000.0).is_finite());
        assert!(exp(f32::INFINITY).is_finite());
    }
}
