//! The thermal response bank: the loop temperature's history through twelve
//! derivative filters, mixed into a static curve of the mean coil
//! temperature and three rate responses whose gains drift with it.
//!
//! The filters are those of every ΔT in [`crate::features`]:
//! `ΔT_k = (T − S_k)/(τ_k + dt)`, `S_k += dt·ΔT_k`, in °C/min, at time
//! constants τ_k from seconds to hours. Where the [lag bank](crate::lag_bank)
//! fixes the shape of the rate terms (one gain polynomial times each rate),
//! this bank leaves every response free: each of three rate responses R_j is
//! its own mixture of the filters' rates, so the trainer fits one impulse
//! response per power of the temperature.
//!
//! ```text
//! T̂      = T + Σ_k a_k·ΔT_k                 mean coil temperature, °C (a_k = weights[0][k], minutes)
//! û      = T̂ − T₀                           û_c: û clamped to [coil_min_c − T₀, coil_max_c − T₀]
//! R_j    = Σ_k weights[j+1][k]·ΔT_k          j = 0, 1, 2
//! P_q    = (T − T₀)^q, q = 2, 3               (tangent beyond the covered range, as below)
//! H_q    = Σ_k weights[q+2][k]·ΔP_q,k          ΔP_q,k: P_q through the same filters, per minute
//! inputs = [û, û², …, û^static_degree, R_0, û_c·R_1, û_c²·R_2, H_2, H_3]
//! ```
//!
//! The H_q are the bank's Hammerstein part: the square and cube of the loop
//! temperature through the same filters. A Shupe coefficient that drifts with
//! the temperature of each layer makes the bias the rate of a polynomial of a
//! lagged temperature, which products of T with its rates (the R_j) follow
//! only while the lag is short against the change; the filtered powers follow
//! it at any lag (docs/methods.md).
//!
//! Past the covered range of T̂ each power continues along its tangent at
//! the range's edge (`p(û_c) + p′(û_c)·(û − û_c)`), as the lag bank's do:
//! a quartic left to itself beyond its data turns within a few degrees. The
//! rate gains take û_c, so they stop drifting at the range's edge. With
//! every a_k zero, T̂ is T.
//!
//! The model's linear layer gives the static curve's coefficients and takes
//! the three responses with weight 1; flag 1 (input clamped) is raised when
//! T̂ leaves the range, through the first input's training range.

use serde::{Deserialize, Serialize};

/// Derivative filters a response bank holds.
pub const RESPONSE_FILTERS: usize = 12;
/// Highest power of û = T̂ − T₀ among a bank's inputs.
pub const MAX_RESPONSE_DEGREE: u8 = 4;
/// Rate responses R_j a bank produces (weight rows 1 ..= 3).
pub const RESPONSES: usize = 3;
/// Filtered powers H_q of the loop temperature a bank produces (q = 2, 3;
/// weight rows 4 and 5).
pub const POWER_RESPONSES: usize = 2;
/// Weight rows: the coil lags, the rate responses and the filtered powers.
pub const WEIGHT_ROWS: usize = 1 + RESPONSES + POWER_RESPONSES;
/// Most inputs a response bank gives: the static powers and the responses.
pub const MAX_RESPONSE_INPUTS: usize = MAX_RESPONSE_DEGREE as usize + RESPONSES + POWER_RESPONSES;
/// Longest filter time constant, s (one day), as for every ΔT window.
const MAX_TAU_S: f32 = 86_400.0;
/// Largest |temperature| a bank's reference and range may name, °C.
const MAX_TEMP_C: f32 = 1000.0;
/// Largest |weight| accepted: coil lags in minutes, rate gains in °/h per °C/min.
const MAX_WEIGHT: f32 = 1.0e6;

/// The configuration of a thermal response bank, stored in the model blob.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ResponseBank {
    /// Filter time constants τ_k, s, fastest first; the first `filters` are
    /// used, the others are 0.
    pub taus_s: [f32; RESPONSE_FILTERS],
    /// Number of filters in use, 1 ..= [`RESPONSE_FILTERS`].
    pub filters: u8,
    /// Reference temperature T₀ of the powers, °C.
    pub ref_c: f32,
    /// Lower end of the range of T̂ the static powers are followed over, °C
    /// (beyond it they continue along their tangent).
    pub coil_min_c: f32,
    /// Upper end of that range, °C.
    pub coil_max_c: f32,
    /// Powers of û among the inputs, 1 ..= [`MAX_RESPONSE_DEGREE`].
    pub static_degree: u8,
    /// Row 0: coil lags a_k, minutes (T̂ = T + Σ a_k·ΔT_k, ΔT_k in °C/min).
    /// Rows 1 ..= 3: the responses' weights, R_j = Σ weights[j+1][k]·ΔT_k in
    /// °/h (row 1 in °/h per °C/min, rows 2 and 3 per °C/min and per °C and
    /// °C² of û_c). Rows 4 and 5: the filtered powers' weights, H_q =
    /// Σ weights[q+2][k]·ΔP_q,k in °/h (per °C^q/min). Unused filters' weights are 0.
    pub weights: [[f32; RESPONSE_FILTERS]; WEIGHT_ROWS],
}

impl ResponseBank {
    /// A bank of filters at `taus_s` (fastest first) about `ref_c`, °C, over
    /// the coil range `coil_min_c ..= coil_max_c`, °C, with `static_degree`
    /// powers and every weight 0 (T̂ = T, no response); `None` when invalid.
    pub fn new(taus_s: &[f32], ref_c: f32, coil_min_c: f32, coil_max_c: f32, static_degree: u8) -> Option<Self> {
        let mut taus = [0.0; RESPONSE_FILTERS];
        taus.get_mut(..taus_s.len())?.copy_from_slice(taus_s);
        let bank = ResponseBank {
            taus_s: taus,
            filters: taus_s.len() as u8,
            ref_c,
            coil_min_c,
            coil_max_c,
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

    /// Number of powers of û among the inputs (at most [`MAX_RESPONSE_DEGREE`]).
    pub const fn static_inputs(&self) -> usize {
        let d = self.static_degree;
        (if d < MAX_RESPONSE_DEGREE {
            d
        } else {
            MAX_RESPONSE_DEGREE
        }) as usize
    }

    /// Number of model inputs: the static powers, the three responses, the two filtered powers.
    pub const fn dims(&self) -> usize {
        self.static_inputs() + RESPONSES + POWER_RESPONSES
    }

    /// The powers P_2, P_3 of the loop temperature about T₀ that the
    /// filtered-power filters run on, °C² and °C³: (T − T₀)^q inside the
    /// covered range, along its tangent at the range's edge beyond it.
    #[inline(always)]
    pub fn loop_powers(&self, temp_c: f32) -> [f32; POWER_RESPONSES] {
        let u = temp_c - self.ref_c;
        let uc = crate::model::clamp(temp_c, self.coil_min_c, self.coil_max_c) - self.ref_c;
        let beyond = u - uc;
        let uc2 = uc * uc;
        [uc * (uc + 2.0 * beyond), uc2 * (uc + 3.0 * beyond)]
    }

    /// The time constants in use, s.
    pub fn taus(&self) -> &[f32] {
        self.taus_s.get(..self.filter_count()).unwrap_or(&[])
    }

    /// True when the bank can run: 1 ..= [`RESPONSE_FILTERS`] filters with
    /// finite time constants in (0, 1 day], strictly increasing, the unused
    /// ones 0; a static degree of 1 ..= 4; reference and range within
    /// ±1000 °C with min < max; finite weights of at most 1e6 in size, those
    /// of unused filters 0.
    pub fn is_valid(&self) -> bool {
        let n = self.filters as usize;
        let used_and_unused_ok = |row: &[f32; RESPONSE_FILTERS], used: &dyn Fn(f32) -> bool| {
            row.get(..n).is_some_and(|r| r.iter().all(|&v| used(v)))
                && row.get(n..).is_some_and(|r| r.iter().all(|&v| v == 0.0))
        };
        let taus_ok = used_and_unused_ok(&self.taus_s, &|tau| tau.is_finite() && tau > 0.0 && tau <= MAX_TAU_S)
            && self.taus().windows(2).all(|w| w[0] < w[1]);
        let weights_ok = self
            .weights
            .iter()
            .all(|row| used_and_unused_ok(row, &|w| w.is_finite() && w.abs() <= MAX_WEIGHT));
        (1..=RESPONSE_FILTERS).contains(&n)
            && taus_ok
            && weights_ok
            && (1..=MAX_RESPONSE_DEGREE).contains(&self.static_degree)
            && [self.ref_c, self.coil_min_c, self.coil_max_c]
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_TEMP_C)
            && self.coil_min_c < self.coil_max_c
    }

    /// The model inputs from the loop temperature `temp_c`, °C, the
    /// filters' rates, °C/min, and the rates of the powers
    /// ([`Self::loop_powers`]) through the same filters, °C^q/min (filters
    /// past [`Self::filter_count`] are ignored), written to the first
    /// [`Self::dims`] slots of `out`.
    #[inline(always)]
    pub fn inputs(
        &self,
        temp_c: f32,
        rates_c_per_min: &[f32; RESPONSE_FILTERS],
        power_rates: &[[f32; RESPONSE_FILTERS]; POWER_RESPONSES],
        out: &mut [f32],
    ) {
        // One pass over the filters for all four mixtures.
        let [lag, w0, w1, w2, h2, h3] = &self.weights;
        let (mut s2, mut s3) = (0.0f32, 0.0f32);
        for (((r2, r3), a), b) in power_rates[0]
            .iter()
            .zip(&power_rates[1])
            .zip(h2)
            .zip(h3)
            .take(self.filter_count())
        {
            s2 += a * r2;
            s3 += b * r3;
        }
        let (mut t_hat, mut r0, mut r1, mut r2) = (temp_c, 0.0f32, 0.0f32, 0.0f32);
        for ((((r, a), b0), b1), b2) in rates_c_per_min
            .iter()
            .zip(lag)
            .zip(w0)
            .zip(w1)
            .zip(w2)
            .take(self.filter_count())
        {
            t_hat += a * r;
            r0 += b0 * r;
            r1 += b1 * r;
            r2 += b2 * r;
        }
        let u = t_hat - self.ref_c;
        // Compare-and-select clamp, as the lag bank's (f32::clamp could panic).
        let uc = crate::model::clamp(t_hat, self.coil_min_c, self.coil_max_c) - self.ref_c;
        let beyond = u - uc;
        let uc2 = uc * uc;
        let powers = [
            u,
            uc * (uc + 2.0 * beyond),
            uc2 * (uc + 3.0 * beyond),
            uc2 * uc * (uc + 4.0 * beyond),
        ];
        let responses = [r0, uc * r1, uc2 * r2, s2, s3];
        let s = self.static_inputs();
        for (o, v) in out.iter_mut().zip(powers.iter().take(s).chain(&responses)) {
            *o = *v;
        }
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
    /// û^power, û = T̂ − T₀.
    Static {
        /// 1 ..= 4.
        power: u8,
    },
    /// R_0, û_c·R_1 or û_c²·R_2.
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
    /// `T̂ − T₀ [°C]`, `(T̂ − T₀)² [°C²]`, `R₀ [°/h]`, `û_c·R₁ [°/h]`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ResponseInput::Static { power: 1 } => f.write_str("T̂ − T₀ [°C]"),
            ResponseInput::Static { power: 2 } => f.write_str("(T̂ − T₀)² [°C²]"),
            ResponseInput::Static { power } => write!(f, "(T̂ − T₀)^{power} [°C^{power}]"),
            ResponseInput::Response { index: 0 } => f.write_str("R₀ [°/h]"),
            ResponseInput::Response { index: 1 } => f.write_str("û_c·R₁ [°/h]"),
            ResponseInput::Response { index: 2 } => f.write_str("û_c²·R₂ [°/h]"),
            ResponseInput::Response { index } => write!(f, "R{index} [°/h]"),
            ResponseInput::FilteredPower { power: 2 } => f.write_str("H₂: filtered (T − T₀)² [°/h]"),
            ResponseInput::FilteredPower { power: 3 } => f.write_str("H₃: filtered (T − T₀)^3 [°/h]"),
            ResponseInput::FilteredPower { power } => write!(f, "H{power}: filtered (T − T₀)^{power} [°/h]"),
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
        b.weights[0][..3].copy_from_slice(&[-2.0, -8.0, 0.0]);
        b.weights[1][..3].copy_from_slice(&[1.0, 0.5, 0.25]);
        b.weights[2][..3].copy_from_slice(&[0.0, 2.0, 0.0]);
        b.weights[3][..3].copy_from_slice(&[0.0, 0.0, 4.0]);
        b
    }

    const NO_POWER_RATES: [[f32; RESPONSE_FILTERS]; POWER_RESPONSES] = [[0.0; RESPONSE_FILTERS]; POWER_RESPONSES];

    #[test]
    fn the_filtered_powers_mix_the_power_rates_with_rows_four_and_five() {
        let mut b = bank();
        b.weights[4][..3].copy_from_slice(&[1.0, 2.0, 0.0]);
        b.weights[5][..3].copy_from_slice(&[0.0, 0.5, 4.0]);
        let power_rates = [rates(&[1.0, 0.25, 8.0]), rates(&[2.0, 4.0, 0.125])];
        let mut out = [0.0; MAX_RESPONSE_INPUTS];
        b.inputs(25.0, &rates(&[]), &power_rates, &mut out);
        // H₂ = 1·1 + 2·0.25 = 1.5 (the third filter's weight is 0); H₃ = 0.5·4 + 4·0.125 = 2.5.
        assert_eq!(out[7..9], [1.5, 2.5]);
        assert_eq!(
            b.input(7).map(|i| i.to_string()).as_deref(),
            Some("H₂: filtered (T − T₀)² [°/h]")
        );
    }

    #[test]
    fn the_filtered_powers_of_t_follow_their_tangent_past_the_covered_range() {
        let b = bank();
        // T₀ = 20, range 0 … 40: inside, the plain powers.
        assert_eq!(b.loop_powers(25.0), [25.0, 125.0]);
        // 4 °C past the top edge (u_c = 20): the tangents there.
        assert_eq!(
            b.loop_powers(44.0),
            [400.0 + 2.0 * 20.0 * 4.0, 8000.0 + 3.0 * 400.0 * 4.0]
        );
        assert_eq!(b.loop_powers(-2.0), [400.0 + 80.0, -8000.0 - 2400.0]);
    }

    fn rates(head: &[f32]) -> [f32; RESPONSE_FILTERS] {
        let mut r = [0.0; RESPONSE_FILTERS];
        r[..head.len()].copy_from_slice(head);
        r
    }

    #[test]
    fn inputs_are_the_coil_temperature_s_powers_and_the_three_responses() {
        let b = bank();
        let mut out = [9.0; MAX_RESPONSE_INPUTS + 1];
        b.inputs(25.0, &rates(&[0.5, 0.25, 1.0]), &NO_POWER_RATES, &mut out);
        // T̂ = 25 − 2·0.5 − 8·0.25 = 22, û = 2; R₀ = 0.5 + 0.125 + 0.25 = 0.875,
        // R₁ = 0.5, R₂ = 4.
        assert_eq!(out, [2.0, 4.0, 8.0, 16.0, 0.875, 1.0, 16.0, 0.0, 0.0, 9.0]);
        assert_eq!(b.dims(), 9);
        let quadratic = ResponseBank { static_degree: 2, ..b };
        let mut out = [9.0; 8];
        quadratic.inputs(25.0, &rates(&[0.5, 0.25, 1.0]), &NO_POWER_RATES, &mut out);
        assert_eq!(out, [2.0, 4.0, 0.875, 1.0, 16.0, 0.0, 0.0, 9.0]);
    }

    #[test]
    fn with_no_coil_lag_the_coil_temperature_is_the_loop_temperature_bit_for_bit() {
        let mut b = bank();
        b.weights[0] = [0.0; RESPONSE_FILTERS];
        b.ref_c = 0.0;
        b.coil_min_c = -500.0;
        b.coil_max_c = 500.0;
        for (t, r) in [(23.456_79_f32, 0.1234_f32), (-7.3, -3.7), (61.0e-3, 1.0e-7)] {
            let mut out = [0.0; MAX_RESPONSE_INPUTS];
            b.inputs(t, &rates(&[r, -r, 2.0 * r]), &NO_POWER_RATES, &mut out);
            assert_eq!(out[0].to_bits(), t.to_bits(), "T = {t}");
        }
    }

    #[test]
    fn past_the_covered_range_the_powers_follow_their_tangent() {
        let b = bank();
        let mut out = [0.0; MAX_RESPONSE_INPUTS];
        // T = T̂ = 44 °C, 4 °C past the edge at û_c = 20: the tangents at 20.
        b.inputs(44.0, &rates(&[]), &NO_POWER_RATES, &mut out);
        assert_eq!(
            out[..4],
            [
                24.0,
                400.0 + 2.0 * 20.0 * 4.0,
                8000.0 + 3.0 * 400.0 * 4.0,
                160_000.0 + 4.0 * 8000.0 * 4.0
            ]
        );
        // Below the range: the edge at û_c = −20.
        b.inputs(-2.0, &rates(&[]), &NO_POWER_RATES, &mut out);
        assert_eq!(out[..4], [-22.0, 400.0 + 80.0, -8000.0 - 2400.0, 160_000.0 + 64_000.0]);
        // The gains of R₁ and R₂ stop at the edge.
        let mut hot = b;
        hot.weights[0] = [0.0; RESPONSE_FILTERS];
        hot.inputs(44.0, &rates(&[0.0, 1.0, 1.0]), &NO_POWER_RATES, &mut out);
        assert_eq!(out[4..7], [0.75, 40.0, 1600.0]);
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
        let broken: [fn(&mut ResponseBank); 6] = [
            |b| b.weights[2][1] = f32::NAN,
            |b| b.weights[1][0] = 2.0e6,
            |b| b.weights[3][5] = 1.0,
            |b| b.taus_s[7] = 5.0,
            |b| b.filters = 17,
            |b| b.coil_max_c = f32::INFINITY,
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
                "T̂ − T₀ [°C]",
                "(T̂ − T₀)² [°C²]",
                "(T̂ − T₀)^3 [°C^3]",
                "(T̂ − T₀)^4 [°C^4]",
                "R₀ [°/h]",
                "û_c·R₁ [°/h]",
                "û_c²·R₂ [°/h]",
                "H₂: filtered (T − T₀)² [°/h]",
                "H₃: filtered (T − T₀)^3 [°/h]"
            ]
        );
        assert_eq!(b.input(9), None);
    }
}
