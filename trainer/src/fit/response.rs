//! The thermal response bank's fit (`--features response-bank`): the bank's
//! structure fixed from the training runs, its weights from one ridge
//! regression on block means. A simple working identification; the weights
//! come from [`solve_weights`] alone, so a better method replaces that.
//!
//! - Filters: [`RESPONSE_FILTERS`] time constants log-spaced from
//!   [`FASTEST_TAU_S`] to [`SLOWEST_TAU_S`].
//! - T₀: the middle of the loop temperature range the runs covered; the coil
//!   range: that range; a static quartic; no coil lag (T̂ = T).
//! - The blocks: [`BLOCK_S`] means of T and of every filter's rate, made by
//!   the extractor of rbf-core (the firmware's code) as the lag bank's
//!   blocks are, in two halves of [`BANK_FILTERS`] filters (a plain lag bank
//!   each), joined on their start times. The slow half's warm-up (three of
//!   its fastest time constants) leaves out the start of every segment.
//! - The network: no centres, the linear layer [c₁ … c₄, 1, 1, 1] on the
//!   bank's inputs and the constant c₀.

use std::collections::HashMap;

use nalgebra::{DMatrix, DVector};
use rbf_core::FeatureConfig;
use rbf_core::lag_bank::{BANK_FILTERS, LagBank};
use rbf_core::model::{Model, ModelBody, ModelInfo};
use rbf_core::rbf::{RbfNetwork, RbfParams};
use rbf_core::response_bank::{MAX_RESPONSE_DEGREE, RESPONSE_FILTERS, RESPONSES, ResponseBank};

use super::FitOptions;
use super::linalg::{GramStats, ridge_solve_from};
use crate::dataset::{Blocks, RunSet};

/// The fastest filter's time constant, s.
pub const FASTEST_TAU_S: f64 = 10.0;
/// The slowest filter's time constant, s (11 h).
pub const SLOWEST_TAU_S: f64 = 11.0 * 3600.0;
/// Length of the blocks the weights are fitted on, s.
pub const BLOCK_S: f64 = 10.0;
/// Ridge penalty λ (times the number of blocks) on the standardised rate columns.
pub const RIDGE_LAMBDA: f64 = 1e-2;

/// The filters' time constants, s: log-spaced from [`FASTEST_TAU_S`] to [`SLOWEST_TAU_S`].
pub fn taus_s() -> [f32; RESPONSE_FILTERS] {
    let ratio = (SLOWEST_TAU_S / FASTEST_TAU_S).ln() / (RESPONSE_FILTERS - 1) as f64;
    std::array::from_fn(|k| (FASTEST_TAU_S * (ratio * k as f64).exp()) as f32)
}

/// Block means of the loop temperature and of every filter's rate.
#[derive(Clone, Debug, Default)]
pub struct RateBlocks {
    /// Mean loop temperature of each block, °C.
    pub temp_c: Vec<f64>,
    /// Mean rate of each filter in each block, °C/min.
    pub rates: Vec<[f64; RESPONSE_FILTERS]>,
    /// Mean bias target of each block, °/h.
    pub y: Vec<f64>,
    /// Run of each block.
    pub run: Vec<usize>,
    /// Per-sample loop temperature range, °C.
    pub temp_range_c: (f64, f64),
    /// Per-sample range of each filter's rate, °C/min.
    pub rate_range: [(f64, f64); RESPONSE_FILTERS],
}

/// The static part and responses of a bank, as [`solve_weights`] gives them.
#[derive(Clone, Debug, PartialEq)]
pub struct Weights {
    /// c₀, °/h.
    pub constant_dph: f64,
    /// c₁ … c₄: °/h per °C^p of û = T̂ − T₀.
    pub static_dph: [f64; MAX_RESPONSE_DEGREE as usize],
    /// The bank's weight rows: coil lags (minutes), then the three responses'.
    pub bank: [[f32; RESPONSE_FILTERS]; 1 + RESPONSES],
}

/// The bank and its deployable model for `train`.
pub fn identify<T: RunSet + ?Sized>(train: &T, opts: &FitOptions) -> anyhow::Result<Model> {
    let taus = taus_s();
    let blocks = rate_blocks(train, &taus)?;
    let (lo, hi) = blocks.temp_range_c;
    anyhow::ensure!(
        lo.is_finite() && hi > lo,
        "the training runs cover no temperature range ({lo} … {hi} °C)"
    );
    let ref_c = (0.5 * (lo + hi)) as f32;
    let mut bank = ResponseBank::new(&taus, ref_c, lo as f32, hi as f32, MAX_RESPONSE_DEGREE)
        .ok_or_else(|| anyhow::anyhow!("no valid response bank over {lo} … {hi} °C"))?;
    let w = solve_weights(&blocks, f64::from(ref_c))?;
    bank.weights = w.bank;
    anyhow::ensure!(bank.is_valid(), "the fitted response bank is out of range");
    model(bank, &w, &blocks, opts)
}

/// The blocks of `train` for filters `taus`: two plain lag banks' blocks
/// (the first and second half of the filters), joined where both hold a
/// block of the same run, start and sample count.
pub fn rate_blocks<T: RunSet + ?Sized>(train: &T, taus: &[f32; RESPONSE_FILTERS]) -> anyhow::Result<RateBlocks> {
    let half = |k: usize| -> anyhow::Result<Blocks> {
        let bank = LagBank::plain(&taus[k * BANK_FILTERS..(k + 1) * BANK_FILTERS], 0.0)
            .ok_or_else(|| anyhow::anyhow!("no plain lag bank over {taus:?}"))?;
        let config = FeatureConfig::lag_bank(bank);
        train.prepare(&[config], BLOCK_S)?;
        train.block_means(&config, BLOCK_S)
    };
    let (fast, slow) = (half(0)?, half(1)?);
    anyhow::ensure!(
        fast.time_s.len() == fast.len() && slow.time_s.len() == slow.len(),
        "blocks without start times"
    );
    let key = |b: &Blocks, i: usize| (b.run[i], b.time_s[i].to_bits(), b.samples.get(i).copied());
    let slow_at: HashMap<_, usize> = (0..slow.len()).map(|i| (key(&slow, i), i)).collect();
    let mut out = RateBlocks {
        temp_range_c: fast.sample_range.first().copied().unwrap_or((f64::NAN, f64::NAN)),
        ..RateBlocks::default()
    };
    for (k, r) in out.rate_range.iter_mut().enumerate() {
        let (b, i) = if k < BANK_FILTERS {
            (&fast, k)
        } else {
            (&slow, k - BANK_FILTERS)
        };
        *r = b.sample_range.get(1 + i).copied().unwrap_or((0.0, 0.0));
    }
    for i in 0..fast.len() {
        let Some(&j) = slow_at.get(&key(&fast, i)) else {
            continue;
        };
        let mut rates = [0.0; RESPONSE_FILTERS];
        rates[..BANK_FILTERS].copy_from_slice(&fast.x[i][1..=BANK_FILTERS]);
        rates[BANK_FILTERS..].copy_from_slice(&slow.x[j][1..=BANK_FILTERS]);
        out.temp_c.push(fast.x[i][0]);
        out.rates.push(rates);
        out.y.push(fast.y[i]);
        out.run.push(fast.run[i]);
    }
    anyhow::ensure!(
        out.y.len() > 4 * (1 + MAX_RESPONSE_DEGREE as usize + RESPONSES * RESPONSE_FILTERS),
        "{} blocks of {BLOCK_S} s after the slow filters' warm-up: too few to fit the response bank",
        out.y.len()
    );
    Ok(out)
}

/// The weights by ridge regression of the block targets on
/// [1, û … û⁴, ΔT_k, û·ΔT_k, û²·ΔT_k] (û = T − T₀, no coil lag), the
/// columns standardised, the penalty λ·n ([`RIDGE_LAMBDA`]) on the rate
/// columns only.
pub fn solve_weights(blocks: &RateBlocks, ref_c: f64) -> anyhow::Result<Weights> {
    const STATIC: usize = MAX_RESPONSE_DEGREE as usize;
    const F: usize = RESPONSE_FILTERS;
    let n = blocks.y.len();
    let cols = 1 + STATIC + RESPONSES * F;
    let mut a = DMatrix::<f64>::zeros(n, cols);
    for (i, (t, rates)) in blocks.temp_c.iter().zip(&blocks.rates).enumerate() {
        let u = t - ref_c;
        a[(i, 0)] = 1.0;
        for p in 1..=STATIC {
            a[(i, p)] = u.powi(p as i32);
        }
        for (j, gain) in [1.0, u, u * u].iter().enumerate() {
            for (k, r) in rates.iter().enumerate() {
                a[(i, 1 + STATIC + j * F + k)] = gain * r;
            }
        }
    }
    // Standardised columns (the constant kept): the penalty then weighs every
    // rate column alike.
    let mut mean = vec![0.0; cols];
    let mut scale = vec![1.0; cols];
    for c in 1..cols {
        let col = a.column(c);
        let m = col.mean();
        let sd = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt();
        mean[c] = m;
        scale[c] = if sd > 0.0 { sd } else { 1.0 };
        a.column_mut(c).iter_mut().for_each(|v| *v = (*v - m) / scale[c]);
    }
    let y = DVector::from_column_slice(&blocks.y);
    let stats = GramStats::new(&a, &y);
    let beta = ridge_solve_from(&stats, cols, RIDGE_LAMBDA, 1 + STATIC)
        .ok_or_else(|| anyhow::anyhow!("the response bank's regression is singular"))?;
    let raw: Vec<f64> = (0..cols).map(|c| beta[c] / scale[c]).collect();
    let constant_dph = beta[0] - (1..cols).map(|c| raw[c] * mean[c]).sum::<f64>();
    let mut bank = [[0.0f32; F]; 1 + RESPONSES];
    for (j, row) in bank.iter_mut().skip(1).enumerate() {
        for (k, w) in row.iter_mut().enumerate() {
            *w = raw[1 + STATIC + j * F + k] as f32;
        }
    }
    Ok(Weights {
        constant_dph,
        static_dph: std::array::from_fn(|p| raw[1 + p]),
        bank,
    })
}

/// The model of `bank` with the static coefficients and constant of `w`:
/// a network of no centres whose linear layer takes the responses with
/// weight 1; the training ranges those the runs' samples could reach.
fn model(bank: ResponseBank, w: &Weights, blocks: &RateBlocks, opts: &FitOptions) -> anyhow::Result<Model> {
    let dims = bank.dims();
    let statics = bank.static_inputs();
    let mut linear: Vec<f32> = w.static_dph[..statics].iter().map(|&c| c as f32).collect();
    linear.extend([1.0f32; RESPONSES]);
    let net = RbfNetwork::new(&RbfParams {
        offset: &vec![0.0; dims],
        scale: &vec![1.0; dims],
        kernel_inputs: 1,
        centers: &[],
        widths: &[],
        weights: &[],
        linear: &linear,
        constant: w.constant_dph as f32,
    })
    .map_err(|e| anyhow::anyhow!("fitted network is not deployable: {e}"))?;
    let ranges = input_ranges(&bank, blocks);
    let info = ModelInfo {
        serial: super::serial(opts)?,
    };
    Model::new(FeatureConfig::response_bank(bank), &ranges, ModelBody::Rbf(net), info)
        .map_err(|e| anyhow::anyhow!("fitted model is not deployable: {e}"))
}

/// Training ranges of the bank's inputs: û over the coil range (so flag 1
/// says T̂ left it), its powers over that range, and each response over
/// every combination of its filters' per-sample rate ranges and û_c
/// (interval bounds: no sample went beyond them).
fn input_ranges(bank: &ResponseBank, blocks: &RateBlocks) -> Vec<(f32, f32)> {
    let ref_c = f64::from(bank.ref_c);
    let u = (f64::from(bank.coil_min_c) - ref_c, f64::from(bank.coil_max_c) - ref_c);
    let power_range = |p: i32| {
        let ends = [u.0.powi(p), u.1.powi(p)];
        let lo = if p % 2 == 0 && u.0 < 0.0 && u.1 > 0.0 {
            0.0
        } else {
            ends[0].min(ends[1])
        };
        (lo, ends[0].max(ends[1]))
    };
    let product = |a: (f64, f64), b: (f64, f64)| {
        let c = [a.0 * b.0, a.0 * b.1, a.1 * b.0, a.1 * b.1];
        (
            c.iter().copied().fold(f64::INFINITY, f64::min),
            c.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        )
    };
    let response = |row: &[f32; RESPONSE_FILTERS]| {
        row.iter().zip(&blocks.rate_range).fold((0.0, 0.0), |acc, (&w, &r)| {
            let (lo, hi) = product((f64::from(w), f64::from(w)), r);
            (acc.0 + lo, acc.1 + hi)
        })
    };
    let mut ranges: Vec<(f64, f64)> = (1..=bank.static_inputs() as i32).map(power_range).collect();
    ranges.push(response(&bank.weights[1]));
    ranges.push(product(u, response(&bank.weights[2])));
    ranges.push(product(power_range(2), response(&bank.weights[3])));
    ranges.iter().map(|&(lo, hi)| (lo as f32, hi as f32)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_filters_span_ten_seconds_to_eleven_hours_evenly_on_a_log_scale() {
        let t = taus_s();
        assert!((t[0] - 10.0).abs() < 1e-4 && (t[15] - 39_600.0).abs() < 0.05, "{t:?}");
        let ratio = t[1] / t[0];
        assert!(t.windows(2).all(|w| (w[1] / w[0] - ratio).abs() < 1e-4 * ratio));
    }

    #[test]
    fn the_regression_recovers_a_static_quartic_and_a_response_it_was_made_from() {
        // Targets of the model's form plus noise, the rates independent of
        // the temperature: the static part comes back closely (unpenalised),
        // the response slightly shrunk by the ridge, the other weights small.
        let mut state = 7u32;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f64::from(state) / f64::from(u32::MAX) - 0.5
        };
        let mut blocks = RateBlocks::default();
        for i in 0..4000 {
            let t = 20.0 + 30.0 * (i as f64 / 300.0).sin();
            let rates: [f64; RESPONSE_FILTERS] = std::array::from_fn(|_| uniform());
            let u = t - 20.0;
            let y = 0.5 + 0.02 * u - 0.001 * u * u + 2e-5 * u.powi(3) + 0.3 * rates[3] + 0.01 * uniform();
            blocks.temp_c.push(t);
            blocks.rates.push(rates);
            blocks.y.push(y);
            blocks.run.push(0);
        }
        let w = solve_weights(&blocks, 20.0).unwrap();
        let expected = [0.02, -0.001, 2e-5, 0.0];
        for (c, e) in w.static_dph.iter().zip(expected) {
            assert!((c - e).abs() < 1e-6 + 1e-3 * e.abs(), "{:?}", w.static_dph);
        }
        assert!((w.constant_dph - 0.5).abs() < 1e-3, "c₀ = {}", w.constant_dph);
        assert!(w.bank[0].iter().all(|&a| a == 0.0), "no coil lag");
        for (k, &b) in w.bank[1].iter().enumerate() {
            let want = if k == 3 { 0.3 } else { 0.0 };
            assert!((b - want).abs() < 0.01, "R₀ weights {:?}", w.bank[1]);
        }
        assert!(
            w.bank[2..].iter().flatten().all(|b| b.abs() < 1e-3),
            "{:?}",
            &w.bank[2..]
        );
    }
}
