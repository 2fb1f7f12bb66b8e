//! All-`f32` arithmetic that gives the same bits on host and target: the
//! exponential of the Gaussian basis, and the clamp every input range uses.
//!
//! `libm::expf` follows musl and computes in `f64`, which is soft-float on a
//! Cortex-M4F (single-precision FPU) and dominated a 32-centre evaluation
//! (docs/decisions.md, "Measurements behind design choices").
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

/// Fraction bits of the fixed-point exponent [`exp2_neg_fixed`] takes.
pub const EXP2_FRAC_BITS: u32 = 9;
/// Exponents u ≥ this saturate (the true 2^−u is below 5.5e-20). Twice the
/// 32 bits a Gaussian term needs: the RBF table path offsets every exponent
/// by up to 32 to take the input's shared term out of its loop.
pub const EXP2_RANGE: u32 = 64;
/// Cells of one octave of the fixed-point exponent: 2^F.
pub const EXP2_CELLS: usize = 1 << EXP2_FRAC_BITS;
/// Largest cell index [`exp2_neg_fixed`] reads: the exponent saturates at
/// 64 − 2^−F.
pub const EXP2_FIXED_MAX: i32 = ((EXP2_RANGE as i32) << EXP2_FRAC_BITS) - 1;
/// Bound of the relative error of [`exp2_neg_fixed`] against 2^−u for the u
/// whose truncation gave the index, u < EXP2_RANGE − 2^−F: 2^(2^−(F+1)) − 1
/// from the cell's width, plus the entry's rounding to f32 (2^−24). Beyond,
/// the result is below 2^−63 where the truth is below 2^−64 + 2^−73.
pub const EXP2_FIXED_REL_ERROR: f64 = 6.7718e-4 + 6.0e-8;

/// e^−x for 0 ≤ x ≤ ln 2 in f64 by its Taylor series (26 terms: truncation
/// below 1e-19), evaluated at compile time.
const fn exp_neg_f64(x: f64) -> f64 {
    let mut term = 1.0;
    let mut sum = 1.0;
    let mut n = 1;
    while n < 26 {
        term = -term * x / n as f64;
        sum += term;
        n += 1;
    }
    sum
}

/// 2^−((j + ½)/2^F) rounded to f32, for the cells j of the first octave (the
/// middle of each cell, so that truncating the fixed-point exponent errs
/// symmetrically). Computed at compile time with IEEE f64 arithmetic (a
/// Taylor series), hence the same bits on every machine.
const EXP2_OCTAVE: [f32; EXP2_CELLS] = {
    let mut t = [0.0f32; EXP2_CELLS];
    let mut j = 0;
    while j < EXP2_CELLS {
        t[j] = exp_neg_f64((j as f64 + 0.5) / EXP2_CELLS as f64 * core::f64::consts::LN_2) as f32;
        j += 1;
    }
    t
};

/// The one table behind [`exp2_neg_fixed`]: per cell j of an octave, the
/// bits of 2^−((j + ½)/2^F) plus j·2^(23−F) (2 KiB).
///
/// Every value of the octave lies in (½, 1], an f32 with the exponent field
/// 126, and 2^−n·x for n < 64 stays a normal f32, so cell c = n·2^F + j is
/// the octave's bits minus n·2^23: the exponent field lowered by n, the
/// mantissa untouched, exactly the f32 of 2^−((c + ½)/2^F). With j·2^(23−F)
/// folded into the entry, that is `entry(j) − c·2^(23−F)`: one subtraction
/// with a shifted operand (`SUB r, r, c, LSL #14` on a Cortex-M4).
///
/// Read on every Gaussian of every sample: the firmware keeps it in RAM
/// (memory.x and firmware::board; docs/firmware.md), where a read takes no
/// flash wait state.
pub static EXP2_OCTAVE_BITS: [u32; EXP2_CELLS] = {
    let mut t = [0u32; EXP2_CELLS];
    let mut j = 0;
    while j < EXP2_CELLS {
        t[j] = EXP2_OCTAVE[j].to_bits() + ((j as u32) << (23 - EXP2_FRAC_BITS));
        j += 1;
    }
    t
};

/// 2^−u for a fixed-point exponent `u_fixed` = trunc(u · 2^F): one
/// saturation (USAT on a Cortex-M4), one bit-field extract (UBFX), one table
/// load and one subtraction in the exponent bits; no polynomial, no branch.
///
/// For 0 ≤ `u_fixed` < [`EXP2_FIXED_MAX`] the result is exactly the f32 of
/// 2^−((u_fixed + ½)/2^F), the middle of its cell (relative error ≤
/// [`EXP2_FIXED_REL_ERROR`] against 2^−u). From `EXP2_FIXED_MAX` on the
/// exponent saturates: the result lies in (2^−65, 2^−63), below 1.1e-19.
/// Slightly negative inputs (−2^F ≤ `u_fixed` < 0, the rounding of a u that
/// is 0) read within that bound of 1.
#[inline(always)]
pub fn exp2_neg_fixed(u_fixed: i32) -> f32 {
    // The cell within its octave comes from the unsaturated exponent: a
    // bit-field extract, where the saturated one would cost a copy and a
    // clear. Only outside [0, max) do the two differ, where the result is
    // already bounded as documented.
    let octave_cell = (u_fixed as u32) & (EXP2_CELLS as u32 - 1);
    let cell = u_fixed.clamp(0, EXP2_FIXED_MAX) as u32;
    let entry = EXP2_OCTAVE_BITS.get(octave_cell as usize).copied().unwrap_or(0);
    f32::from_bits(entry.wrapping_sub(cell << (23 - EXP2_FRAC_BITS)))
}

/// [`exp2_neg_fixed`] of `u_q16 >> (16 − F)` for an exponent in Q16, bit
/// for bit, in the form a Cortex-M4 does in two instructions: the cell
/// within its octave is the bit field 16 − F .. 16 of `u_q16` (UBFX), and
/// the saturation takes the shift with it (USAT with ASR). `table` is
/// [`EXP2_OCTAVE_BITS`] (a loop passes the address it holds in a register).
#[inline(always)]
pub fn exp2_neg_q16(table: &[u32; EXP2_CELLS], u_q16: i32) -> f32 {
    const SHIFT: u32 = 16 - EXP2_FRAC_BITS;
    let octave_cell = ((u_q16 as u32) << (32 - 16)) >> (32 - EXP2_FRAC_BITS);
    let cell = (u_q16 >> SHIFT).clamp(0, EXP2_FIXED_MAX) as u32;
    let entry = table.get(octave_cell as usize).copied().unwrap_or(0);
    f32::from_bits(entry.wrapping_sub(cell << (23 - EXP2_FRAC_BITS)))
}

/// `v` limited to [lo, hi], NaN mapped to `lo`; never panics. Two compare
/// and selects (f32::max/min are library calls on a Cortex-M4F, whose FPU has
/// no VMAXNM).
#[inline(always)]
pub(crate) fn clamp(v: f32, lo: f32, hi: f32) -> f32 {
    let above = if v > lo { v } else { lo };
    if above < hi { above } else { hi }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_exponential_stays_within_its_bound() {
        let mut worst = 0.0f64;
        let mut u = 0.0f64;
        while u < 63.99 {
            let fixed = (u * f64::from(1u32 << EXP2_FRAC_BITS)) as i32;
            let got = f64::from(exp2_neg_fixed(fixed));
            let want = (-u).exp2();
            worst = worst.max((got / want - 1.0).abs());
            u += 0.000_37;
        }
        assert!(worst <= EXP2_FIXED_REL_ERROR, "worst relative error {worst:e}");
        assert!(worst > 0.9 * 6.7718e-4, "the bound is tight: {worst:e}");
        let bits = |u: i32| exp2_neg_fixed(u).to_bits();
        let first_cell_middle = (-0.5f64 / f64::from(1u32 << EXP2_FRAC_BITS)).exp2() as f32;
        assert_eq!(
            bits(0),
            first_cell_middle.to_bits(),
            "the middle of the first cell: 2^−(½/512)"
        );
    }

    /// The 2^F·64-entry table the octave table replaces, as it was
    /// computed: each cell's f64 value times an exact power of two, rounded
    /// once to f32 (that table stored 0 in place of its last entry).
    fn full_table() -> std::vec::Vec<u32> {
        let len = (EXP2_RANGE as usize) << EXP2_FRAC_BITS;
        let fraction: std::vec::Vec<f64> = (0..EXP2_CELLS)
            .map(|j| exp_neg_f64((j as f64 + 0.5) / EXP2_CELLS as f64 * core::f64::consts::LN_2))
            .collect();
        let mut power = 1.0f64;
        (0..len)
            .map(|i| {
                if i > 0 && i % EXP2_CELLS == 0 {
                    power *= 0.5;
                }
                ((fraction[i % EXP2_CELLS] * power) as f32).to_bits()
            })
            .collect()
    }

    #[test]
    fn octave_table_reproduces_every_entry_of_the_full_table_bit_for_bit() {
        let full = full_table();
        assert_eq!(full.len(), EXP2_FIXED_MAX as usize + 1);
        for (i, want) in full.iter().enumerate() {
            assert_eq!(exp2_neg_fixed(i as i32).to_bits(), *want, "index {i}");
        }
    }

    #[test]
    fn the_q16_form_reads_the_same_cell_as_the_fixed_point_form_bit_for_bit() {
        // Every octave cell, the saturation at both ends, and the whole i32 range sparsely.
        let shift = 16 - EXP2_FRAC_BITS;
        let dense = -(1 << 17)..(EXP2_FIXED_MAX + 600) << shift;
        let sparse = (i32::MIN..=i32::MAX).step_by(65_537);
        for u in dense.step_by(7).chain(sparse).chain([i32::MIN, -1, 0, i32::MAX]) {
            assert_eq!(
                exp2_neg_q16(&EXP2_OCTAVE_BITS, u).to_bits(),
                exp2_neg_fixed(u >> shift).to_bits(),
                "u = {u}"
            );
        }
    }

    #[test]
    fn saturated_and_negative_exponents_stay_within_their_documented_bounds() {
        for u in [
            EXP2_FIXED_MAX + 1,
            EXP2_FIXED_MAX + 300,
            1 << 20,
            (1 << 22) + 77,
            i32::MAX,
        ] {
            let v = f64::from(exp2_neg_fixed(u));
            assert!(v > (-65f64).exp2() && v < (-63f64).exp2(), "u = {u}: {v:e}");
        }
        // The table path's exponents round to −1 at worst (u = 0 by a unit).
        let at_minus_one = f64::from(exp2_neg_fixed(-1));
        assert!((at_minus_one - 1.0).abs() < EXP2_FIXED_REL_ERROR, "{at_minus_one}");
        for u in -(EXP2_CELLS as i32)..0 {
            let v = exp2_neg_fixed(u);
            assert!((0.9..1.0).contains(&v), "u = {u}: {v}");
        }
    }

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
