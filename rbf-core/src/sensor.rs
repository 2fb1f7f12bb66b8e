//! Sensor conversions shared by the firmware drivers and the trainer, so that
//! both see the loop temperature at exactly the same resolution.

/// TMP117 temperature resolution, °C per LSB (datasheet: 7.8125 m°C).
pub const TMP117_LSB_C: f32 = 0.007_812_5;

/// Converts a TMP117 temperature-result register value to °C (exact in f32).
pub fn tmp117_celsius(raw: i16) -> f32 {
    raw as f32 * TMP117_LSB_C
}

/// The TMP117 register value nearest to `temp_c` (saturating at the i16 range;
/// NaN maps to 0 and is caught by the plausibility check downstream).
pub fn tmp117_raw(temp_c: f64) -> i16 {
    let code = libm::round(temp_c / TMP117_LSB_C as f64);
    if code.is_nan() {
        0
    } else if code >= i16::MAX as f64 {
        i16::MAX
    } else if code <= i16::MIN as f64 {
        i16::MIN
    } else {
        code as i16
    }
}

/// `temp_c` as the loop thermometer (a TMP117) reports it, °C.
///
/// The firmware can see no finer than one LSB, so every computation on
/// recorded runs takes the temperature through this function too.
pub fn tmp117_quantise(temp_c: f64) -> f32 {
    tmp117_celsius(tmp117_raw(temp_c))
}

#[cfg(test)]
#[allow(clippy::float_cmp, reason = "TMP117 codes are exact binary fractions")]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_quantise_to_the_nearest_lsb() {
        assert_eq!(tmp117_celsius(0x0C80), 25.0); // datasheet example: 0x0C80 = 25 °C
        assert_eq!(tmp117_celsius(-1), -0.007_812_5);
        assert_eq!(tmp117_raw(25.0), 0x0C80);
        assert_eq!(tmp117_quantise(25.004), 25.0 + TMP117_LSB_C);
        assert_eq!(tmp117_quantise(24.996), 25.0 - TMP117_LSB_C);
        assert_eq!(tmp117_raw(1e9), i16::MAX);
        assert_eq!(tmp117_raw(f64::NAN), 0);
    }
}
