//! The cubic-in-temperature baseline: the form PX4 and ArduPilot use for
//! gyro temperature calibration, here for comparison in the same tool.
//!
//! `bias = c0 + c1·u + c2·u² + c3·u³`, with `u = T − T_ref` in °C and T
//! clamped to the training range by the caller ([`crate::Model`]).

use crate::error::ModelError;

/// An exponent written as superscript digits (`²`, `³`, `¹²`), nothing for
/// 1: how model descriptions write the powers of their inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Superscript(pub u8);

impl core::fmt::Display for Superscript {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
        if self.0 == 1 {
            return Ok(());
        }
        let (hundreds, tens, ones) = (self.0 / 100, self.0 / 10 % 10, self.0 % 10);
        for (digit, shown) in [(hundreds, hundreds > 0), (tens, self.0 >= 10), (ones, true)] {
            if shown {
                core::fmt::Write::write_char(f, DIGITS[usize::from(digit)])?;
            }
        }
        Ok(())
    }
}

/// Cubic polynomial in loop temperature about a reference temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Poly3 {
    /// Reference temperature T_ref, °C (mid training range).
    pub ref_temp_c: f32,
    /// Coefficients c0 [°/h], c1 [°/h/°C], c2 [°/h/°C²], c3 [°/h/°C³].
    pub coeffs: [f32; 4],
}

impl Poly3 {
    /// Builds the polynomial, refusing non-finite values.
    pub fn new(ref_temp_c: f32, coeffs: [f32; 4]) -> Result<Self, ModelError> {
        if !ref_temp_c.is_finite() || coeffs.iter().any(|c| !c.is_finite()) {
            return Err(ModelError::NonFiniteParameter);
        }
        Ok(Poly3 { ref_temp_c, coeffs })
    }

    /// Upper bound of |bias| for temperatures in [`lo_c`, `hi_c`], °/h
    /// (interval arithmetic in f64; +∞ if the terms overflow).
    pub fn output_bound(&self, lo_c: f32, hi_c: f32) -> f64 {
        let u = (f64::from(lo_c) - f64::from(self.ref_temp_c))
            .abs()
            .max((f64::from(hi_c) - f64::from(self.ref_temp_c)).abs());
        let [c0, c1, c2, c3] = self.coeffs.map(|c| f64::from(c).abs());
        c0 + u * (c1 + u * (c2 + u * c3))
    }

    /// Bias at loop temperature `temp_c` (already clamped), °/h. Horner form.
    pub fn eval(&self, temp_c: f32) -> f32 {
        let u = temp_c - self.ref_temp_c;
        let [c0, c1, c2, c3] = self.coeffs;
        c0 + u * (c1 + u * (c2 + u * c3))
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    #[test]
    fn exponents_are_written_as_superscript_digits_and_one_as_nothing() {
        let shown = [1, 2, 3, 4, 10, 255].map(|p| Superscript(p).to_string());
        assert_eq!(shown, ["", "²", "³", "⁴", "¹⁰", "²⁵⁵"]);
    }

    #[test]
    fn evaluates_about_the_reference_temperature() {
        let p = Poly3::new(25.0, [1.0, 2.0, 0.5, 0.25]).unwrap();
        assert_eq!(p.eval(25.0), 1.0);
        // u = 2: 1 + 4 + 2 + 2 = 9 (exact in f32).
        assert_eq!(p.eval(27.0), 9.0);
        assert_eq!(Poly3::new(f32::INFINITY, [0.0; 4]), Err(ModelError::NonFiniteParameter));
    }
}
