//! The thermal response bank: the loop temperature's history through twelve
//! derivative filters, mixed into a static curve of the loop temperature
//! and five responses, two of them with gains that drift with it.
//!
//! The filters are those of every ΔT in [`crate::features`]:
//! `ΔT_k = (T − S_k)/(τ_k + dt)`, `S_k += dt·ΔT_k`, in °C/min, at time
//! constants τ_k from seconds to hours. Where the [lag bank](crate::lag_bank)
//! fixes the shape of the rate terms (one gain polynomial times each rate),
//! this bank leaves every response free: each response is its own mixture
//! of the filters' rates, so the trainer fits one impulse response per
//! power of the temperature.
//!
//! ```text
//! u      = T − T₀                            u_c: u clamped to [range_min_c − T₀, range_max_c − T₀]
//! P_q    = u^q inside the range, its tangent at the edge beyond (q = 2, 3, 4)
//! R_j    = Σ_k weights[j][k]·ΔT_k             j = 0, 1, 2
//! H_q    = Σ_k weights[q+1][k]·ΔP_q,k          ΔP_q,k: P_q through the same filters, per minute (q = 2, 3)
//! inputs = [u, P_2, …, P_static_degree, R_0, u_c·R_1, u_c²·R_2, H_2, H_3]
//! ```
//!
//! The H_q are the bank's Hammerstein part: the square and cube of the loop
//! temperature through the same filters. A Shupe coefficient that drifts with
//! the temperature of each layer makes the bias the rate of a polynomial of a
//! lagged temperature, which products of T with its rates (the R_j) follow
//! only while the lag is short against the change; the filtered powers follow
//! it at any lag (docs/methods.md).
//!
//! Past the covered range each power continues along its tangent at the
//! range's edge (`p(u_c) + p′(u_c)·(u − u_c)`), as the lag bank's do: a
//! quartic left to itself beyond its data turns within a few degrees. The
//! rate gains take u_c, so they stop drifting at the range's edge.
//!
//! The model's linear layer gives the static curve's coefficients and takes
//! the five responses with weight 1; flag 1 (input clamped) is raised when
//! T leaves the range, through the first input's training range.
//!
//! Per sample the bank runs its filters and mixes them in one pass
//! ([`ResponseBank::step`]): nothing of the bank is copied, and the filters'
//! rates are given ([`BankChannels`]) to the trainer, which identifies the
//! weights from this very arithmetic.

use serde::{Deserialize, Serialize};

#[cfg(test)]
use crate::filter::SECONDS_PER_MINUTE;
use crate::filter::{DerivativeFilter, DerivativeGain};

/// Derivative filters a response bank holds.
pub const RESPONSE_FILTERS: usize = 12;
/// Highest power of u = T − T₀ among a bank's inputs.
pub const MAX_RESPONSE_DEGREE: u8 = 4;
/// Rate responses R_j a bank produces (weight rows 0 ..= 2).
pub const RESPONSES: usize = 3;
/// Filtered powers H_q of the loop temperature a bank produces (q = 2, 3;
/// weight rows 3 and 4).
pub const POWER_RESPONSES: usize = 2;
/// Weight rows: the rate responses, then the filtered powers.
pub const WEIGHT_ROWS: usize = RESPONSES + POWER_RESPONSES;
/// Signals each filter runs on: T, P_2 and P_3.
pub const BANK_SIGNALS: usize = 1 + POWER_RESPONSES;
/// Most inputs a response bank gives: the static powers and the responses.
pub const MAX_RESPONSE_INPUTS: usize = MAX_RESPONSE_DEGREE as usize + WEIGHT_ROWS;
/// Longest filter time constant, s (one day), as for every ΔT window.
const MAX_TAU_S: f32 = 86_400.0;
/// Largest |temperature| a bank's reference and range may name, °C.
const MAX_TEMP_C: f32 = 1000.0;
/// Largest |weight| accepted, °/h per °C^q/min.
const MAX_WEIGHT: f32 = 1.0e6;

/// The configuration of a thermal response bank, stored in the model blob
/// (encoded as one tuple, see the `Serialize` impl).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResponseBank {
    /// Filter time constants τ_k, s, fastest first; the first `filters` are
    /// used, the others are 0.
    pub taus_s: [f32; RESPONSE_FILTERS],
    /// Number of filters in use, 1 ..= [`RESPONSE_FILTERS`].
    pub filters: u8,
    /// Reference temperature T₀ of the powers, °C.
    pub ref_c: f32,
    /// Lower end of the range of T the powers are followed over, °C
    /// (beyond it they continue along their tangent).
    pub range_min_c: f32,
    /// Upper end of that range, °C.
    pub range_max_c: f32,
    /// Powers of u among the inputs, 1 ..= [`MAX_RESPONSE_DEGREE`].
    pub static_degree: u8,
    /// Rows 0 ..= 2: the rate responses' weights, R_j = Σ `weights[j][k]`·ΔT_k
    /// in °/h (row 0 in °/h per °C/min, rows 1 and 2 per °C/min and per °C
    /// and °C² of u_c). Rows 3 and 4: the filtered powers' weights, H_q =
    /// Σ `weights[q+1][k]`·ΔP_q,k in °/h (per °C^q/min). Unused filters' weights are 0.
    pub weights: [[f32; RESPONSE_FILTERS]; WEIGHT_ROWS],
}

/// The state of a response bank's filters: the derivative filter of each
/// signal (T, P_2, P_3) per time constant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BankFilters {
    /// The filters per signal; their smoothed values S_k in the signal's unit (°C, °C², °C³).
    pub filters: [[DerivativeFilter; RESPONSE_FILTERS]; BANK_SIGNALS],
}

/// The filters' outputs for one sample: the rate of each signal (T, P_2,
/// P_3) through each filter, per minute; what the trainer identifies the
/// weights from.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BankChannels {
    /// ΔT_k, ΔP_2,k, ΔP_3,k: °C/min, °C²/min, °C³/min.
    pub rates: [[f32; RESPONSE_FILTERS]; BANK_SIGNALS],
}

/// Values of a bank in its encoding after the two counts: T₀, the range,
/// the time constants and the weights, in that order.
const ENCODED_FLOATS: usize = 3 + RESPONSE_FILTERS + WEIGHT_ROWS * RESPONSE_FILTERS;

// The blob encoding: one tuple of the filter count, the static degree and
// the [`ENCODED_FLOATS`] values in order (postcard: two bytes, then each
// f32 little-endian). Written by hand so that one loop reads every value:
// the derive's code per array element costs a board image flash.
impl Serialize for ResponseBank {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(2 + ENCODED_FLOATS)?;
        t.serialize_element(&self.filters)?;
        t.serialize_element(&self.static_degree)?;
        let head = [self.ref_c, self.range_min_c, self.range_max_c];
        for v in head.iter().chain(&self.taus_s).chain(self.weights.iter().flatten()) {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for ResponseBank {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct BankVisitor;
        impl<'de> serde::de::Visitor<'de> for BankVisitor {
            type Value = ResponseBank;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("a response bank")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<ResponseBank, A::Error> {
                use serde::de::Error;
                let short = || A::Error::invalid_length(0, &"a response bank");
                let filters: u8 = seq.next_element()?.ok_or_else(short)?;
                let static_degree: u8 = seq.next_element()?.ok_or_else(short)?;
                let mut bank = ResponseBank {
                    taus_s: [0.0; RESPONSE_FILTERS],
                    filters,
                    ref_c: 0.0,
                    range_min_c: 0.0,
                    range_max_c: 0.0,
                    static_degree,
                    weights: [[0.0; RESPONSE_FILTERS]; WEIGHT_ROWS],
                };
                // Read flat, in one loop kept rolled (its count hidden from
                // the optimiser): unrolled, the reads of every value would
                // each take board flash.
                let mut values = [0.0f32; ENCODED_FLOATS];
                for v in values.iter_mut().take(core::hint::black_box(ENCODED_FLOATS)) {
                    *v = seq.next_element()?.ok_or_else(short)?;
                }
                let (head, rest) = values.split_at(3);
                let (taus, weights) = rest.split_at(RESPONSE_FILTERS);
                bank.taus_s.copy_from_slice(taus);
                bank.weights.as_flattened_mut().copy_from_slice(weights);
                [bank.ref_c, bank.range_min_c, bank.range_max_c] = [head[0], head[1], head[2]];
                Ok(bank)
            }
        }
        d.deserialize_tuple(2 + ENCODED_FLOATS, BankVisitor)
    }
}

impl ResponseBank {
    /// A bank of filters at `taus_s` (fastest first) about `ref_c`, °C, over
    /// the range `range_min_c ..= range_max_c`, °C, with `static_degree`
    /// powers and every weight 0 (no response); `None` when invalid.
    pub fn new(taus_s: &[f32], ref_c: f32, range_min_c: f32, range_max_c: f32, static_degree: u8) -> Option<Self> {
        let mut taus = [0.0; RESPONSE_FILTERS];
        taus.get_mut(..taus_s.len())?.copy_from_slice(taus_s);
        let bank = ResponseBank {
            taus_s: taus,
            filters: taus_s.len() as u8,
            ref_c,
            range_min_c,
            range_max_c,
            static_degree,
            weights: [[0.0; RESPONSE_FILTERS]; WEIGHT_ROWS],
        };
        bank.is_valid().then_some(bank)
    }

    /// Number of filters in use (at most [`RESPONSE_FILTERS`]).
    pub const fn filter_count(&self) -> usize {
        let n = self.filters as usize;
        if n < RESPONSE_FILTERS { n } else { RESPONSE_FILTERS }
    }

    /// Number of powers of u among the inputs (at most [`MAX_RESPONSE_DEGREE`]).
    pub const fn static_inputs(&self) -> usize {
        let d = self.static_degree;
        (if d < MAX_RESPONSE_DEGREE {
            d
        } else {
            MAX_RESPONSE_DEGREE
        }) as usize
    }

    /// Number of model inputs: the static powers and the five responses.
    pub const fn dims(&self) -> usize {
        self.static_inputs() + WEIGHT_ROWS
    }

    /// The powers u, P_2, P_3, P_4 of the loop temperature about T₀, °C^q:
    /// u^q inside the covered range, along its tangent at the range's edge
    /// beyond it; and u_c, °C, the clamped u the rate gains take.
    #[inline(always)]
    pub fn powers(&self, temp_c: f32) -> ([f32; MAX_RESPONSE_DEGREE as usize], f32) {
        let u = temp_c - self.ref_c;
        // Compare-and-select clamp, as the lag bank's (f32::clamp could panic).
        let uc = crate::fastmath::clamp(temp_c, self.range_min_c, self.range_max_c) - self.ref_c;
        let beyond = u - uc;
        let uc2 = uc * uc;
        (
            [
                u,
                uc * (uc + 2.0 * beyond),
                uc2 * (uc + 3.0 * beyond),
                uc2 * uc * (uc + 4.0 * beyond),
            ],
            uc,
        )
    }

    /// The time constants in use, s.
    pub fn taus(&self) -> &[f32] {
        self.taus_s.get(..self.filter_count()).unwrap_or(&[])
    }

    /// Filters started on the loop temperature `temp_c`, °C: every filter
    /// of every signal at its present value (all rates 0).
    pub fn start(&self, temp_c: f32) -> BankFilters {
        let ([_, p2, p3, _], _) = self.powers(temp_c);
        BankFilters {
            filters: [
                [DerivativeFilter::settled_at(temp_c); RESPONSE_FILTERS],
                [DerivativeFilter::settled_at(p2); RESPONSE_FILTERS],
                [DerivativeFilter::settled_at(p3); RESPONSE_FILTERS],
            ],
        }
    }

    /// One sample of the loop temperature `temp_c`, °C, `dt_s` after the
    /// last (finite, > 0): runs every filter of every signal, writes their
    /// rates to `channels` when given (the trainer's identification; the
    /// firmware passes none) and the model inputs to the first
    /// [`Self::dims`] slots of `out`. Filters past [`Self::filter_count`] have τ = 0 and
    /// weights 0: they run (one loop of fixed length) and add nothing.
    #[inline(always)]
    pub fn step(
        &self,
        temp_c: f32,
        dt_s: f32,
        filters: &mut BankFilters,
        mut channels: Option<&mut BankChannels>,
        out: &mut [f32],
    ) {
        let (powers, uc) = self.powers(temp_c);
        let signals = [temp_c, powers[1], powers[2]];
        let [w0, w1, w2, h2, h3] = &self.weights;
        let [f_t, f_p2, f_p3] = &mut filters.filters;
        let mut sums = [0.0f32; WEIGHT_ROWS];
        for k in 0..RESPONSE_FILTERS {
            // One division per filter, its gains shared by the three signals.
            let gain = DerivativeGain::new(self.taus_s[k], dt_s);
            let rt = f_t[k].update_with(signals[0], gain);
            let rp2 = f_p2[k].update_with(signals[1], gain);
            let rp3 = f_p3[k].update_with(signals[2], gain);
            if let Some(c) = channels.as_deref_mut() {
                [c.rates[0][k], c.rates[1][k], c.rates[2][k]] = [rt, rp2, rp3];
            }
            sums[0] += w0[k] * rt;
            sums[1] += w1[k] * rt;
            sums[2] += w2[k] * rt;
            sums[3] += h2[k] * rp2;
            sums[4] += h3[k] * rp3;
        }
        self.inputs(powers, uc, sums, out);
    }

    /// The model inputs from the powers and u_c ([`Self::powers`]) and the
    /// five mixtures of the filters' rates (R_0, R_1, R_2, H_2, H_3, °/h),
    /// written to the first [`Self::dims`] slots of `out`.
    #[inline(always)]
    pub fn inputs(
        &self,
        powers: [f32; MAX_RESPONSE_DEGREE as usize],
        uc: f32,
        sums: [f32; WEIGHT_ROWS],
        out: &mut [f32],
    ) {
        let [r0, r1, r2, s2, s3] = sums;
        let responses = [r0, uc * r1, uc * uc * r2, s2, s3];
        let s = self.static_inputs();
        for (o, v) in out.iter_mut().zip(powers.iter().take(s).chain(&responses)) {
            *o = *v;
        }
    }

    /// The model inputs once every filter reads a steady ramp of
    /// `rate_c_per_min` at loop temperature `temp_c` (each power's rate its
    /// derivative: q·u_c^(q−1)·rate, the tangent's slope beyond the range),
    /// written to the first [`Self::dims`] slots of `out`.
    pub fn settled_inputs(&self, temp_c: f32, rate_c_per_min: f32, out: &mut [f32]) {
        let (powers, uc) = self.powers(temp_c);
        let rates = [
            rate_c_per_min,
            2.0 * uc * rate_c_per_min,
            3.0 * uc * uc * rate_c_per_min,
        ];
        let mut sums = [0.0f32; WEIGHT_ROWS];
        for (row, (sum, weights)) in sums.iter_mut().zip(&self.weights).enumerate() {
            let rate = rates[row.saturating_sub(RESPONSES - 1)];
            *sum = weights.iter().map(|w| w * rate).sum();
        }
        self.inputs(powers, uc, sums, out);
    }

    /// True when the bank can run: 1 ..= [`RESPONSE_FILTERS`] filters with
    /// finite time constants in (0, 1 day], strictly increasing, the unused
    /// ones 0; a static degree of 1 ..= 4; reference and range within
    /// ±1000 °C with min < max; finite weights of at most 1e6 in size, those
    /// of unused filters 0.
    pub fn is_valid(&self) -> bool {
        let n = self.filter_count();
        let mut ok = (1..=RESPONSE_FILTERS).contains(&usize::from(self.filters))
            && (1..=MAX_RESPONSE_DEGREE).contains(&self.static_degree)
            && self.range_min_c < self.range_max_c;
        for v in [self.ref_c, self.range_min_c, self.range_max_c] {
            ok &= v.abs() <= MAX_TEMP_C; // false for NaN
        }
        // Used slots finite and in range (time constants increasing), unused
        // ones 0, compared as bit patterns: for floats of sign 0 the bits
        // order as the values do, and NaN and ∞ lie above every limit (integer
        // compares: a few bytes of code each, where a float compare and its
        // flag transfer take four instructions).
        const MAGNITUDE: u32 = 0x7FFF_FFFF;
        let mut previous_tau = 0u32;
        for k in 0..RESPONSE_FILTERS {
            let used = k < n;
            let tau = self.taus_s[k].to_bits();
            ok &= if used {
                tau > previous_tau && tau <= MAX_TAU_S.to_bits()
            } else {
                tau == 0
            };
            previous_tau = tau;
            for row in &self.weights {
                let w = row[k].to_bits() & MAGNITUDE;
                ok &= if used { w <= MAX_WEIGHT.to_bits() } else { w == 0 };
            }
        }
        ok
    }

    /// What input `i` is (`None` past the last).
    pub fn input(&self, i: usize) -> Option<ResponseInput> {
        let s = self.static_inputs();
        if i < s {
            Some(ResponseInput::Static { power: i as u8 + 1 })
        } else if i < s + RESPONSES {
            Some(ResponseInput::Response { index: (i - s) as u8 })
        } else if i < self.dims() {
            Some(ResponseInput::FilteredPower {
                power: (i - s - RESPONSES + 2) as u8,
            })
        } else {
            None
        }
    }
}

/// One input of a response bank ([`ResponseBank::input`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResponseInput {
    /// u^power, u = T − T₀ (along its tangent past the covered range).
    Static {
        /// 1 ..= 4.
        power: u8,
    },
    /// R_0, u_c·R_1 or u_c²·R_2.
    Response {
        /// j: 0, 1 or 2.
        index: u8,
    },
    /// H_q: the power (T − T₀)^q through the bank's filters, mixed.
    FilteredPower {
        /// q: 2 or 3.
        power: u8,
    },
}

impl core::fmt::Display for ResponseInput {
    /// `T − T₀ [°C]`, `(T − T₀)² [°C²]`, `R₀ [°/h]`, `u_c·R₁ [°/h]`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ResponseInput::Static { power: 1 } => f.write_str("T − T₀ [°C]"),
            ResponseInput::Static { power } => {
                let p = crate::poly::Superscript(power);
                write!(f, "(T − T₀){p} [°C{p}]")
            }
            ResponseInput::Response { index: 0 } => f.write_str("R₀ [°/h]"),
            ResponseInput::Response { index: 1 } => f.write_str("u_c·R₁ [°/h]"),
            ResponseInput::Response { index: 2 } => f.write_str("u_c²·R₂ [°/h]"),
            ResponseInput::Response { index } => write!(f, "R{index} [°/h]"),
            ResponseInput::FilteredPower { power: 2 } => f.write_str("H₂: filtered (T − T₀)² [°/h]"),
            ResponseInput::FilteredPower { power: 3 } => f.write_str("H₃: filtered (T − T₀)³ [°/h]"),
            ResponseInput::FilteredPower { power } => {
                write!(
                    f,
                    "H{power}: filtered (T − T₀){} [°/h]",
                    crate::poly::Superscript(power)
                )
            }
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

    fn bank() -> ResponseBank {
        let mut b = ResponseBank::new(&[10.0, 60.0, 600.0], 20.0, 0.0, 40.0, 4).unwrap();
        b.weights[0][..3].copy_from_slice(&[1.0, 0.5, 0.25]);
        b.weights[1][..3].copy_from_slice(&[0.0, 2.0, 0.0]);
        b.weights[2][..3].copy_from_slice(&[0.0, 0.0, 4.0]);
        b
    }

    #[test]
    fn inputs_are_the_powers_and_the_five_mixtures_with_the_gains_of_u_c() {
        let b = bank();
        let mut out = [9.0; MAX_RESPONSE_INPUTS + 1];
        let (powers, uc) = b.powers(22.0);
        b.inputs(powers, uc, [0.875, 0.5, 4.0, 1.5, 2.5], &mut out);
        // u = 2: the powers 2, 4, 8, 16; R₀, u_c·R₁ = 1, u_c²·R₂ = 16, H₂, H₃.
        assert_eq!(out, [2.0, 4.0, 8.0, 16.0, 0.875, 1.0, 16.0, 1.5, 2.5, 9.0]);
        assert_eq!(b.dims(), 9);
        let quadratic = ResponseBank { static_degree: 2, ..b };
        let mut out = [9.0; 8];
        quadratic.inputs(powers, uc, [0.875, 0.5, 4.0, 1.5, 2.5], &mut out);
        assert_eq!(out, [2.0, 4.0, 0.875, 1.0, 16.0, 1.5, 2.5, 9.0]);
    }

    #[test]
    fn past_the_covered_range_the_powers_follow_their_tangent_and_the_gains_stop() {
        let b = bank();
        // T₀ = 20, range 0 … 40; 4 °C past the top edge (u_c = 20): the tangents there.
        let (powers, uc) = b.powers(44.0);
        assert_eq!(uc, 20.0);
        assert_eq!(
            powers,
            [
                24.0,
                400.0 + 2.0 * 20.0 * 4.0,
                8000.0 + 3.0 * 400.0 * 4.0,
                160_000.0 + 4.0 * 8000.0 * 4.0
            ]
        );
        let (powers, uc) = b.powers(-2.0);
        assert_eq!(uc, -20.0);
        assert_eq!(powers, [-22.0, 400.0 + 80.0, -8000.0 - 2400.0, 160_000.0 + 64_000.0]);
        let mut out = [0.0; MAX_RESPONSE_INPUTS];
        b.inputs(b.powers(44.0).0, 20.0, [0.0, 1.0, 1.0, 0.0, 0.0], &mut out);
        assert_eq!(out[5..7], [20.0, 400.0]);
    }

    #[test]
    fn a_step_runs_every_signal_through_every_filter_and_mixes_the_rates() {
        let b = bank();
        let mut filters = b.start(20.0);
        let mut channels = BankChannels::default();
        let mut out = [0.0; MAX_RESPONSE_INPUTS];
        b.step(20.0, 1.0, &mut filters, Some(&mut channels), &mut out);
        assert_eq!(channels, BankChannels::default(), "a steady signal has no rate");
        assert_eq!(out[4..], [0.0; WEIGHT_ROWS]);
        // A 1-°C step: each filter's rate is 60·1/(τ + dt) per minute and its state moves by dt/(τ + dt).
        b.step(21.0, 1.0, &mut filters, Some(&mut channels), &mut out);
        let expected: Vec<f32> = [10.0f32, 60.0, 600.0]
            .iter()
            .map(|tau| SECONDS_PER_MINUTE * (1.0 / (tau + 1.0)))
            .collect();
        assert_eq!(channels.rates[0][..3], expected[..]);
        assert_eq!(
            channels.rates[0][3], SECONDS_PER_MINUTE,
            "an unused slot (τ = 0) follows the signal"
        );
        // The square's filters see (21 − 20)² − 0 = 1 °C².
        assert_eq!(channels.rates[1][..3], expected[..]);
        assert_eq!(filters.filters[0][0].smoothed(), 20.0 + 1.0 / 11.0);
        let r0 = expected[0] + 0.5 * expected[1] + 0.25 * expected[2];
        assert!((out[4] - r0).abs() < 1e-6, "R₀ = {}", out[4]);
        assert!((out[5] - 1.0 * 2.0 * expected[1]).abs() < 1e-6, "u_c·R₁ = {}", out[5]);
    }

    #[test]
    fn settled_inputs_are_what_the_filters_reach_on_a_long_ramp() {
        let mut b = bank();
        b.weights[3][..3].copy_from_slice(&[1.0, 0.0, 0.5]);
        b.weights[4][..3].copy_from_slice(&[0.0, 0.25, 0.0]);
        let (rate_c_per_min, dt_s) = (0.5f32, 1.0f32);
        let mut filters = b.start(10.0);
        let mut channels = BankChannels::default();
        let mut out = [0.0; MAX_RESPONSE_INPUTS];
        let mut temp_c = 10.0;
        for _ in 0..20_000 {
            temp_c += rate_c_per_min / 60.0 * dt_s;
            b.step(temp_c, dt_s, &mut filters, Some(&mut channels), &mut out);
        }
        let mut settled = [0.0; MAX_RESPONSE_INPUTS];
        b.settled_inputs(temp_c, rate_c_per_min, &mut settled);
        // The static powers agree exactly; the responses within the lag of the slowest filter.
        assert_eq!(out[..4], settled[..4]);
        for i in 4..b.dims() {
            let tolerance = 0.02 * settled[i].abs().max(0.1);
            assert!(
                (out[i] - settled[i]).abs() < tolerance,
                "input {i}: {} vs {}",
                out[i],
                settled[i]
            );
        }
    }

    #[test]
    fn invalid_banks_are_refused() {
        let new = |taus: &[f32], degree| ResponseBank::new(taus, 20.0, 0.0, 40.0, degree);
        assert!(new(&[], 4).is_none(), "no filter");
        assert!(new(&[1.0; RESPONSE_FILTERS + 1], 4).is_none(), "too many");
        assert!(new(&[60.0, 60.0], 4).is_none(), "not increasing");
        assert!(new(&[0.0, 60.0], 4).is_none(), "τ = 0");
        assert!(new(&[60.0, 100_000.0], 4).is_none(), "over a day");
        assert!(new(&[60.0], 0).is_none() && new(&[60.0], 5).is_none(), "degree");
        assert!(ResponseBank::new(&[60.0], 20.0, 40.0, 40.0, 1).is_none(), "empty range");
        assert!(ResponseBank::new(&[60.0], 2000.0, 0.0, 40.0, 1).is_none(), "reference");
        let broken: [fn(&mut ResponseBank); 7] = [
            |b| b.weights[2][1] = f32::NAN,
            |b| b.weights[1][0] = 2.0e6,
            |b| b.weights[3][5] = 1.0,
            |b| b.taus_s[7] = 5.0,
            |b| b.filters = 17,
            |b| b.range_max_c = f32::INFINITY,
            |b| b.ref_c = f32::NAN,
        ];
        for (i, breaks) in broken.iter().enumerate() {
            let mut b = bank();
            breaks(&mut b);
            assert!(!b.is_valid(), "defect {i}");
        }
        assert!(bank().is_valid());
    }

    #[test]
    fn inputs_are_named_for_reports() {
        let b = bank();
        let names: Vec<String> = (0..b.dims()).map(|i| b.input(i).unwrap().to_string()).collect();
        assert_eq!(
            names,
            [
                "T − T₀ [°C]",
                "(T − T₀)² [°C²]",
                "(T − T₀)³ [°C³]",
                "(T − T₀)⁴ [°C⁴]",
                "R₀ [°/h]",
                "u_c·R₁ [°/h]",
                "u_c²·R₂ [°/h]",
                "H₂: filtered (T − T₀)² [°/h]",
                "H₃: filtered (T − T₀)³ [°/h]"
            ]
        );
        assert_eq!(b.input(9), None);
    }
}
