//! A model described in words and tidy numbers: what `trainer inspect`
//! prints and what report.md lists about the model it evaluates.

use rbf_core::Model;
use rbf_core::model::ModelBody;

/// `n` and the noun, singular for one (`1 centre`, `12 centres`).
pub fn count(n: u64, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

/// `x` with `digits` significant digits, without trailing zeros; `?` when
/// not finite, scientific notation outside 1e-4 … 1e7.
pub fn sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return "?".to_owned();
    }
    if x == 0.0 {
        return "0".to_owned();
    }
    let magnitude = x.abs().log10().floor() as i64;
    if !(-4..=6).contains(&magnitude) {
        return format!("{x:.*e}", digits.saturating_sub(1));
    }
    let decimals = (digits as i64 - 1 - magnitude).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        s
    }
}

/// Centres the model uses (0 for a polynomial).
pub fn centers(model: &Model) -> usize {
    match model.body() {
        ModelBody::Rbf(net) => net.centers_used(),
        ModelBody::Poly3(_) => 0,
    }
}

/// Every input of the model by name with its training range (min, max).
pub fn training_ranges(model: &Model) -> Vec<(String, f32, f32)> {
    let f = model.features();
    (0..f.dims())
        .map(|i| {
            let (lo, hi) = model.input_range(i).unwrap_or((f32::NAN, f32::NAN));
            (f.set.name(i).map_or_else(|| "?".to_owned(), |n| n.to_string()), lo, hi)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits_drop_trailing_zeros() {
        assert_eq!(sig(15.000000953674316, 4), "15");
        assert_eq!(sig(-0.012345, 3), "-0.0123");
        assert_eq!(sig(1.5e-7, 3), "1.50e-7");
        assert_eq!(sig(0.0, 3), "0");
        assert_eq!(sig(f64::NAN, 3), "?");
    }

    #[test]
    fn one_is_singular() {
        assert_eq!(count(1, "centre", "centres"), "1 centre");
        assert_eq!(count(0, "centre", "centres"), "0 centres");
    }
}
