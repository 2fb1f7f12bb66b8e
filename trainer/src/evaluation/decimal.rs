//! Floats written as `core::fmt`'s `{}` writes them (the shortest decimal
//! that reads back to the same value, never an exponent), at `ryu`'s speed:
//! the compensated output of `trainer compensate` must stay byte-identical
//! to the firmware replay's, which formats with `core::fmt`.

/// Appends `value` exactly as `format!("{value}")` would.
pub fn push_f32(out: &mut Vec<u8>, value: f32) {
    if !value.is_finite() {
        out.extend_from_slice(if value.is_nan() {
            b"NaN"
        } else if value > 0.0 {
            b"inf"
        } else {
            b"-inf"
        });
        return;
    }
    if short_exact_decimal(value) {
        // Two shortest decimals may lie equally near: core::fmt's choice.
        use std::io::Write as _;
        let _ = write!(out, "{value}");
        return;
    }
    let mut buffer = ryu::Buffer::new();
    let text = buffer.format_finite(value).as_bytes();
    let (negative, text) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    // ryu writes `d.ddd`, `0.000ddd`, `ddd.0` or `d.ddde±x`: its digits and
    // the decimal point's place, then laid out without an exponent.
    let (mantissa, exponent) = match text.iter().position(|&b| b == b'e') {
        Some(e) => (&text[..e], parse_exponent(&text[e + 1..])),
        None => (text, 0),
    };
    let mut digits = [0u8; 32];
    let mut count = 0;
    let mut point = None;
    for &b in mantissa {
        if b == b'.' {
            point = Some(count);
        } else if let Some(d) = digits.get_mut(count) {
            *d = b;
            count += 1;
        }
    }
    let mut point = point.unwrap_or(count) as i32 + exponent;
    let leading = digits[..count].iter().take_while(|&&d| d == b'0').count();
    let digits = &digits[leading..count];
    point -= leading as i32;
    let trailing = digits.iter().rev().take_while(|&&d| d == b'0').count();
    let digits = &digits[..digits.len() - trailing];
    if negative {
        out.push(b'-');
    }
    let n = digits.len() as i32;
    if point <= 0 {
        out.extend_from_slice(b"0.");
        out.extend(std::iter::repeat_n(b'0', (-point) as usize));
        out.extend_from_slice(digits);
    } else if point >= n {
        out.extend_from_slice(digits);
        out.extend(std::iter::repeat_n(b'0', (point - n) as usize));
    } else {
        let (int, frac) = digits.split_at(point as usize);
        out.extend_from_slice(int);
        out.push(b'.');
        out.extend_from_slice(frac);
    }
}

/// True when `value`'s exact decimal has at most 10 significant digits
/// (zero included): only then can two shortest decimals (at most 9 digits
/// for an f32) lie equally near it, a tie that ryu and core::fmt break
/// differently.
fn short_exact_decimal(value: f32) -> bool {
    let bits = value.to_bits();
    let biased = (bits >> 23) & 0xff;
    let fraction = u128::from(bits & 0x7f_ffff);
    let (mut mantissa, mut exponent) = if biased == 0 {
        (fraction, -149i32)
    } else {
        (fraction | 0x80_0000, biased as i32 - 150)
    };
    if mantissa == 0 {
        return true;
    }
    let zeros = mantissa.trailing_zeros();
    mantissa >>= zeros;
    exponent += zeros as i32;
    // value = mantissa·2^exponent with an odd mantissa below 2^24; its
    // digits are mantissa·2^exponent, or mantissa·5^-exponent (no trailing
    // zero: odd) when the exponent is negative; past 5^44 they exceed 10.
    let mut digits = match exponent {
        0.. => mantissa << exponent,
        -44..0 => mantissa * 5u128.pow(exponent.unsigned_abs()),
        _ => return false,
    };
    while digits % 10 == 0 {
        digits /= 10;
    }
    digits < 10_000_000_000
}

/// The exponent ryu writes after `e` (`-7`, `20`).
fn parse_exponent(text: &[u8]) -> i32 {
    let (sign, digits) = match text.split_first() {
        Some((b'-', rest)) => (-1, rest),
        _ => (1, text),
    };
    sign * digits
        .iter()
        .fold(0i32, |e, &d| e * 10 + i32::from(d.wrapping_sub(b'0')))
}

/// Appends `value` in decimal, as `format!("{value}")` would.
pub fn push_u8(out: &mut Vec<u8>, value: u8) {
    if value >= 100 {
        out.push(b'0' + value / 100);
    }
    if value >= 10 {
        out.push(b'0' + value / 10 % 10);
    }
    out.push(b'0' + value % 10);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn display(value: f32) -> String {
        let mut out = Vec::new();
        push_f32(&mut out, value);
        String::from_utf8(out).unwrap()
    }

    #[test]
    fn floats_read_as_core_fmt_writes_them_over_the_whole_f32_range() {
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-7,
            1e20,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::EPSILON,
            1.0e-45,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            123456790.0,
            9.685226,
            0.09266329,
            77.0 / 512.0, // 0.150390625: ryu and core::fmt break its tie differently
            -77.0 / 512.0,
            3.0517578e-5,
            1073741824.0,
            16777216.0,
        ];
        for v in special {
            assert_eq!(display(v), format!("{v}"), "{v:e}");
        }
        // Every 1009th bit pattern: all exponents, signs and mantissa shapes.
        let mut bits = 0u32;
        while let Some(next) = bits.checked_add(1009) {
            let v = f32::from_bits(bits);
            assert_eq!(display(v), format!("{v}"), "bits {bits:#x}");
            bits = next;
        }
    }

    #[test]
    fn small_integers_read_as_core_fmt_writes_them() {
        for v in 0..=u8::MAX {
            let mut out = Vec::new();
            push_u8(&mut out, v);
            assert_eq!(out, v.to_string().into_bytes());
        }
    }

    /// Every f32 (about ten minutes in release): `cargo test -p trainer --release decimal -- --ignored`.
    #[test]
    #[ignore = "every f32: minutes"]
    fn every_f32_reads_as_core_fmt_writes_it() {
        let mut out = Vec::new();
        for bits in 0..=u32::MAX {
            let v = f32::from_bits(bits);
            out.clear();
            push_f32(&mut out, v);
            assert_eq!(out, format!("{v}").into_bytes(), "bits {bits:#x}");
        }
    }
}
