//! The thermal lag bank: the loop temperature's history through a bank of
//! derivative filters, shaped into the inputs of a grey-box thermal model.
//!
//! A fiber coil is a body that heat diffuses through: its layers, its hub and
//! its mean temperature are low-pass (lag) responses of what the loop sensor
//! sees, with time constants from minutes to hours that differ from unit to
//! unit. With the sensor's temperature T through first-order derivative
//! filters ΔT_k at time constants τ_k (the same filter as every ΔT in
//! [`crate::features`]: `ΔT = (T − S)/(τ + dt)`, `S += dt·ΔT`, in °C/min),
//! a lag of T is `S_k = T − τ_k·ΔT_k`, so any mixture of lags at those time
//! constants is T plus a weighted sum of the ΔT_k. The bank gives the model:
//!
//! ```text
//! T̂      = T + Σ_k a_k·ΔT_k                     the mean coil temperature, °C (a_k in minutes)
//! u      = T̂ − T₀                                (T₀: the training range's middle)
//! g      = 1 + g₁·(T̂ − T₀) + g₂·(T̂ − T₀)²       the Shupe gain's temperature dependence
//! inputs = [T̂, u², u³ (up to `static_degree`), g·ΔT_1, …, g·ΔT_K]
//! ```
//!
//! The gain is a polynomial in the coil's temperature T̂ ([`GainOf::Coil`]):
//! the Shupe and stress coefficients are properties of the fiber and its
//! potting, which sit at the coil's temperature, not the sensor's. Banks
//! written before this choice existed evaluate the gain at the loop
//! temperature T ([`GainOf::Loop`]) and still do, bit for bit; the two differ
//! by the coil lag times the rate, which a chamber ramp at one rate cannot
//! tell from the static slope but a fast in-use swing shows (docs/methods.md).
//!
//! Beyond the bank's range of T̂ (the range the training runs covered,
//! widened where the trainer's edge test trusts the cubic), the powers continue
//! along their tangent at the range's edge (u_c the clamped u: u² becomes
//! u_c² + 2u_c(u − u_c), u³ becomes u_c³ + 3u_c²(u − u_c)), so the static
//! curve extrapolates as a straight line with its edge slope: a cubic left
//! to itself beyond its data swings the wrong way within a few degrees, and
//! a short chamber run (or a slow gyro that never reaches the chamber's
//! extremes) leaves in-use temperatures outside the range.
//!
//! The static bias is a curve of the mean coil temperature (Gaussians over T̂
//! and its powers); the Shupe, stress and gradient biases are linear in the
//! coil's temperature rates (IFOG paper Eq. 13), each a mixture of the bank's
//! rates, with a gain that drifts with temperature. The trainer identifies
//! τ_k, a_k, g₁, g₂ from the chamber runs (docs/methods.md); the firmware
//! computes exactly these inputs with this code.

use serde::{Deserialize, Serialize};

/// Most derivative filters a lag bank holds.
pub const BANK_FILTERS: usize = 8;
/// Highest power of (T̂ − T₀) among a bank's inputs.
pub const MAX_STATIC_DEGREE: u8 = 3;
/// Longest filter time constant, s (one day), as for every ΔT window.
const MAX_TAU_S: f32 = 86_400.0;
/// Largest |a_k|, minutes: a coil cannot lag its sensor by more than a day per °C/min.
const MAX_COIL_LAG_MIN: f32 = 1440.0;
/// Largest |temperature| a bank's reference and range may name, °C.
pub const MAX_TEMP_C: f32 = 1000.0;

/// The temperature the Shupe gain g is a polynomial in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GainOf {
    /// The loop sensor's temperature T: the form of banks written before
    /// [`GainOf::Coil`] (their blobs name no gain temperature).
    #[default]
    Loop,
    /// The estimated mean coil temperature T̂: the fiber's own temperature.
    Coil,
}

/// The configuration of a lag bank, stored in the model blob.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(from = "WireLagBank", into = "WireLagBank")]
pub struct LagBank {
    /// Filter time constants τ_k, s, fastest first (the first `filters` are used;
    /// the others are 0, so a decoded bank equals itself and re-encodes to the same bytes).
    pub taus_s: [f32; BANK_FILTERS],
    /// Number of filters in use, 1 ..= [`BANK_FILTERS`].
    pub filters: u8,
    /// Coil-lag weights a_k, minutes: T̂ = T + Σ a_k·ΔT_k with ΔT_k in °C/min.
    pub coil_lag_min: [f32; BANK_FILTERS],
    /// Reference temperature T₀ of the powers and of the gain, °C.
    pub ref_c: f32,
    /// Shupe gain slope g₁, per °C.
    pub gain_per_c: f32,
    /// Shupe gain curvature g₂, per °C².
    pub gain_per_c2: f32,
    /// Powers of (T̂ − T₀) among the inputs: 1 (T̂ alone) ..= [`MAX_STATIC_DEGREE`].
    pub static_degree: u8,
    /// The range of T̂ the static cubic is followed over, °C: the range the
    /// training runs covered, widened at an end where the trainer's edge test
    /// trusted the cubic past it; the powers continue along their tangent
    /// beyond it. (Flag 1 is the model's: T̂ outside its training range.)
    pub coil_min_c: f32,
    /// Upper end of that range, °C.
    pub coil_max_c: f32,
    /// The temperature the gain is a polynomial in. The blob carries it in
    /// the top bit of the static degree's byte ([`COIL_GAIN_BIT`]), so a bank
    /// written before it (degree 1 … 3) decodes as [`GainOf::Loop`].
    pub gain_of: GainOf,
}

/// The bit of the encoded static degree that marks a gain of T̂.
pub const COIL_GAIN_BIT: u8 = 0x80;

/// [`LagBank`] as the blob encodes it: the same fields in the same order,
/// the gain's temperature folded into the static degree's byte.
#[derive(Clone, Copy, Serialize, Deserialize)]
struct WireLagBank {
    taus_s: [f32; BANK_FILTERS],
    filters: u8,
    coil_lag_min: [f32; BANK_FILTERS],
    ref_c: f32,
    gain_per_c: f32,
    gain_per_c2: f32,
    degree_and_gain: u8,
    coil_min_c: f32,
    coil_max_c: f32,
}

impl From<LagBank> for WireLagBank {
    fn from(b: LagBank) -> Self {
        let gain = match b.gain_of {
            GainOf::Loop => 0,
            GainOf::Coil => COIL_GAIN_BIT,
        };
        WireLagBank {
            taus_s: b.taus_s,
            filters: b.filters,
            coil_lag_min: b.coil_lag_min,
            ref_c: b.ref_c,
            gain_per_c: b.gain_per_c,
            gain_per_c2: b.gain_per_c2,
            degree_and_gain: b.static_degree | gain,
            coil_min_c: b.coil_min_c,
            coil_max_c: b.coil_max_c,
        }
    }
}

impl From<WireLagBank> for LagBank {
    fn from(w: WireLagBank) -> Self {
        LagBank {
            taus_s: w.taus_s,
            filters: w.filters,
            coil_lag_min: w.coil_lag_min,
            ref_c: w.ref_c,
            gain_per_c: w.gain_per_c,
            gain_per_c2: w.gain_per_c2,
            static_degree: w.degree_and_gain & !COIL_GAIN_BIT,
            coil_min_c: w.coil_min_c,
            coil_max_c: w.coil_max_c,
            gain_of: if w.degree_and_gain & COIL_GAIN_BIT == 0 {
                GainOf::Loop
            } else {
                GainOf::Coil
            },
        }
    }
}

impl LagBank {
    /// A bank of filters at `taus_s` (fastest first) with no coil lag, unit
    /// gain and T̂ alone: the plain filter outputs, which the trainer's search
    /// starts from.
    pub fn plain(taus_s: &[f32], ref_c: f32) -> Option<LagBank> {
        let mut taus = [0.0; BANK_FILTERS];
        taus.get_mut(..taus_s.len())?.copy_from_slice(taus_s);
        let bank = LagBank {
            taus_s: taus,
            filters: taus_s.len() as u8,
            coil_lag_min: [0.0; BANK_FILTERS],
            ref_c,
            gain_per_c: 0.0,
            gain_per_c2: 0.0,
            static_degree: 1,
            coil_min_c: -MAX_TEMP_C,
            coil_max_c: MAX_TEMP_C,
            gain_of: GainOf::Loop,
        };
        bank.is_valid().then_some(bank)
    }

    /// Number of filters in use (at most [`BANK_FILTERS`]).
    pub const fn filter_count(&self) -> usize {
        let n = self.filters as usize;
        if n < BANK_FILTERS { n } else { BANK_FILTERS }
    }

    /// Number of powers of (T̂ − T₀) among the inputs (at most [`MAX_STATIC_DEGREE`]).
    pub const fn static_inputs(&self) -> usize {
        let d = self.static_degree;
        (if d < MAX_STATIC_DEGREE { d } else { MAX_STATIC_DEGREE }) as usize
    }

    /// Number of model inputs: the static powers, then one rate per filter.
    pub const fn dims(&self) -> usize {
        self.static_inputs() + self.filter_count()
    }

    /// The time constants in use, s.
    pub fn taus(&self) -> &[f32] {
        self.taus_s.get(..self.filter_count()).unwrap_or(&[])
    }

    /// The coil-lag weights in use, minutes.
    pub fn coil_lags(&self) -> &[f32] {
        self.coil_lag_min.get(..self.filter_count()).unwrap_or(&[])
    }

    /// True when the bank can run: 1 ..= [`BANK_FILTERS`] filters with finite
    /// time constants in (0, 1 day], strictly increasing; finite weights within
    /// a day; a static degree of 1 ..= 3; finite gain and reference.
    pub fn is_valid(&self) -> bool {
        let n = self.filters as usize;
        let taus_ok = self.taus_s.get(..n).is_some_and(|t| {
            t.iter().all(|&tau| tau.is_finite() && tau > 0.0 && tau <= MAX_TAU_S) && t.windows(2).all(|w| w[0] < w[1])
        }) && self
            .taus_s
            .get(n..)
            .is_some_and(|unused| unused.iter().all(|&tau| tau == 0.0));
        let lags_ok = self
            .coil_lag_min
            .iter()
            .all(|a| a.is_finite() && a.abs() <= MAX_COIL_LAG_MIN);
        (1..=BANK_FILTERS).contains(&n)
            && taus_ok
            && lags_ok
            && (1..=MAX_STATIC_DEGREE).contains(&self.static_degree)
            && [self.ref_c, self.gain_per_c, self.gain_per_c2]
                .iter()
                .all(|v| v.is_finite())
            && [self.ref_c, self.coil_min_c, self.coil_max_c]
                .iter()
                .all(|v| v.abs() <= MAX_TEMP_C)
            && self.coil_min_c <= self.coil_max_c
    }

    /// The estimated mean coil temperature T̂, °C, from the loop temperature
    /// and the filters' rates, °C/min.
    #[inline(always)]
    pub fn coil_temp_c(&self, temp_c: f32, rates_c_per_min: &[f32; BANK_FILTERS]) -> f32 {
        let mut t_hat = temp_c;
        for (a, r) in self.coil_lag_min.iter().zip(rates_c_per_min).take(self.filter_count()) {
            t_hat += a * r;
        }
        t_hat
    }

    /// The temperature the gain is evaluated at, °C: the loop temperature or
    /// the coil's, per [`Self::gain_of`].
    #[inline(always)]
    pub fn gain_temp_c(&self, temp_c: f32, coil_temp_c: f32) -> f32 {
        match self.gain_of {
            GainOf::Loop => temp_c,
            GainOf::Coil => coil_temp_c,
        }
    }

    /// The Shupe gain g at the gain temperature `gain_temp_c`, °C ([`Self::gain_temp_c`]).
    #[inline(always)]
    pub fn gain(&self, gain_temp_c: f32) -> f32 {
        let dt = gain_temp_c - self.ref_c;
        1.0 + dt * (self.gain_per_c + dt * self.gain_per_c2)
    }

    /// The model inputs from the loop temperature, °C, and the filters' rates,
    /// °C/min (filters past [`Self::filter_count`] are ignored).
    #[inline(always)]
    pub fn inputs(&self, temp_c: f32, rates_c_per_min: &[f32; BANK_FILTERS], out: &mut [f32]) {
        let t_hat = self.coil_temp_c(temp_c, rates_c_per_min);
        let u = t_hat - self.ref_c;
        // Tangent continuation past the covered range (module docs), with
        // the model's compare-and-select clamp (f32::max/min are library
        // calls on a Cortex-M4F; f32::clamp would panic on a range upside
        // down, which the decoder refuses anyway).
        let clamped = crate::fastmath::clamp(t_hat, self.coil_min_c, self.coil_max_c);
        let uc = clamped - self.ref_c;
        let beyond = u - uc;
        let powers = [t_hat, uc * (uc + 2.0 * beyond), uc * uc * (uc + 3.0 * beyond)];
        let s = self.static_inputs();
        let gain = self.gain(self.gain_temp_c(temp_c, t_hat));
        for (o, p) in out.iter_mut().zip(powers.iter().take(s)) {
            *o = *p;
        }
        for (o, r) in out.iter_mut().skip(s).zip(rates_c_per_min).take(self.filter_count()) {
            *o = gain * r;
        }
    }

    /// What input `i` is (`None` past the last).
    pub fn input(&self, i: usize) -> Option<BankInput> {
        let s = self.static_inputs();
        if i < s {
            Some(BankInput::CoilTemp { power: i as u8 + 1 })
        } else if i < self.dims() {
            Some(BankInput::Rate {
                filter: (i - s) as u8,
                tau_s: self.taus_s[i - s],
            })
        } else {
            None
        }
    }
}

/// One input of a lag bank ([`LagBank::input`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BankInput {
    /// T̂ (power 1) or (T̂ − T₀)^power.
    CoilTemp {
        /// 1, 2 or 3.
        power: u8,
    },
    /// g·ΔT_k of filter `filter` (time constant `tau_s`, s), g the gain ([`LagBank::gain`]).
    Rate {
        /// Index of the filter, fastest first.
        filter: u8,
        /// Its time constant, s.
        tau_s: f32,
    },
}

impl core::fmt::Display for BankInput {
    /// `T̂ [°C]`, `(T̂ − T₀)² [°C²]`, `g·ΔT(τ 240 s) [°C/min]`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            BankInput::CoilTemp { power: 1 } => f.write_str("T̂ [°C]"),
            BankInput::CoilTemp { power } => {
                let p = crate::poly::Superscript(power);
                write!(f, "(T̂ − T₀){p} [°C{p}]")
            }
            BankInput::Rate { tau_s, .. } => write!(f, "g·ΔT(τ {tau_s:.0} s) [°C/min]"),
        }
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    fn bank() -> LagBank {
        LagBank {
            coil_lag_min: [-2.0, -8.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            gain_per_c: 0.0625,
            gain_per_c2: 0.0,
            static_degree: 3,
            ..LagBank::plain(&[60.0, 960.0], 20.0).unwrap()
        }
    }

    #[test]
    fn inputs_are_the_coil_temperature_its_powers_and_the_gained_rates() {
        let b = bank();
        let mut rates = [0.0; BANK_FILTERS];
        rates[..2].copy_from_slice(&[0.5, 0.25]);
        let mut out = [0.0; 5];
        b.inputs(24.0, &rates, &mut out);
        // T̂ = 24 − 2·0.5 − 8·0.25 = 21; u = 1; g = 1 + 4/16 = 1.25.
        assert_eq!(out, [21.0, 1.0, 1.0, 0.625, 0.3125]);
        assert_eq!(b.dims(), 5);
    }

    #[test]
    fn a_coil_gain_is_evaluated_at_the_coil_temperature() {
        let b = LagBank {
            gain_of: GainOf::Coil,
            ..bank()
        };
        let mut rates = [0.0; BANK_FILTERS];
        rates[..2].copy_from_slice(&[0.5, 0.25]);
        let mut out = [0.0; 5];
        b.inputs(24.0, &rates, &mut out);
        // T̂ = 21 (as above); g = 1 + 1/16 at T̂, not 1 + 4/16 at T.
        assert_eq!(out, [21.0, 1.0, 1.0, 0.53125, 0.265625]);
        // At rest T̂ = T: both forms agree.
        let rest = [0.0; BANK_FILTERS];
        let (mut coil, mut loop_) = ([0.0; 5], [0.0; 5]);
        b.inputs(30.0, &rest, &mut coil);
        bank().inputs(30.0, &rest, &mut loop_);
        assert_eq!(coil, loop_);
    }

    #[test]
    fn the_gain_s_temperature_rides_in_the_static_degree_s_byte_and_older_banks_keep_the_loop_gain() {
        let loop_bank = bank();
        let coil_bank = LagBank {
            gain_of: GainOf::Coil,
            ..loop_bank
        };
        let encode = |b: LagBank| {
            let mut buf = [0u8; 256];
            postcard::to_slice(&b, &mut buf).unwrap().to_vec()
        };
        let (loop_bytes, coil_bytes) = (encode(loop_bank), encode(coil_bank));
        // The encodings differ in one byte, the static degree's, which
        // carries the coil gain in its top bit: a bank written before the
        // coil gain (degree 1 … 3 alone) reads as a gain of T.
        assert_eq!(loop_bytes.len(), coil_bytes.len());
        let differ: Vec<usize> = (0..loop_bytes.len())
            .filter(|&i| loop_bytes[i] != coil_bytes[i])
            .collect();
        assert_eq!(differ.len(), 1);
        assert_eq!((loop_bytes[differ[0]], coil_bytes[differ[0]]), (3, 3 | COIL_GAIN_BIT));
        for (b, bytes) in [(loop_bank, &loop_bytes), (coil_bank, &coil_bytes)] {
            assert_eq!(postcard::from_bytes::<LagBank>(bytes).unwrap(), b);
        }
        // The flag beside a degree out of range is still refused as a degree.
        let mut bad = coil_bytes.clone();
        bad[differ[0]] = 4 | COIL_GAIN_BIT;
        assert!(!postcard::from_bytes::<LagBank>(&bad).unwrap().is_valid());
    }

    #[test]
    fn past_the_covered_range_the_powers_follow_their_tangent() {
        let b = LagBank {
            coil_min_c: 10.0,
            coil_max_c: 30.0,
            ..bank()
        };
        let rates = [0.0; BANK_FILTERS];
        let mut out = [0.0; 5];
        // T̂ = 34 °C, 4 °C past the edge at u_c = 10: u² → 100 + 2·10·4, u³ → 1000 + 3·100·4.
        b.inputs(34.0, &rates, &mut out);
        assert_eq!(out[..3], [34.0, 180.0, 2200.0]);
        // Inside the range the powers are exact.
        b.inputs(25.0, &rates, &mut out);
        assert_eq!(out[..3], [25.0, 25.0, 125.0]);
        let mut wrong = b;
        wrong.coil_min_c = 40.0;
        assert!(!wrong.is_valid(), "range upside down");
    }

    #[test]
    fn a_plain_bank_gives_the_loop_temperature_and_the_filter_rates() {
        let b = LagBank::plain(&[15.0, 60.0, 240.0], 25.0).unwrap();
        let mut rates = [0.0; BANK_FILTERS];
        rates[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
        let mut out = [9.0; 4];
        b.inputs(30.0, &rates, &mut out);
        assert_eq!(out, [30.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn invalid_banks_are_refused() {
        assert!(LagBank::plain(&[], 20.0).is_none(), "no filter");
        assert!(LagBank::plain(&[60.0, 60.0], 20.0).is_none(), "not increasing");
        assert!(LagBank::plain(&[0.0, 60.0], 20.0).is_none(), "τ = 0");
        assert!(LagBank::plain(&[60.0, 100_000.0], 20.0).is_none(), "over a day");
        assert!(LagBank::plain(&[1.0; BANK_FILTERS + 1], 20.0).is_none(), "too many");
        let mut b = bank();
        b.coil_lag_min[7] = f32::NAN;
        assert!(!b.is_valid(), "NaN weight, even unused");
        let mut b = bank();
        b.taus_s[5] = f32::NAN;
        assert!(
            !b.is_valid(),
            "an unused time constant that is not 0 (a NaN would not equal itself)"
        );
        let mut b = bank();
        b.static_degree = 4;
        assert!(!b.is_valid());
        let mut b = bank();
        b.gain_per_c2 = f32::INFINITY;
        assert!(!b.is_valid());
    }

    #[test]
    fn inputs_are_named_with_their_time_constants() {
        let b = bank();
        let names: Vec<String> = (0..b.dims()).map(|i| b.input(i).unwrap().to_string()).collect();
        assert_eq!(
            names,
            [
                "T̂ [°C]",
                "(T̂ − T₀)² [°C²]",
                "(T̂ − T₀)³ [°C³]",
                "g·ΔT(τ 60 s) [°C/min]",
                "g·ΔT(τ 960 s) [°C/min]"
            ]
        );
        assert_eq!(b.input(5), None);
    }
}
