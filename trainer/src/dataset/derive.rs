//! Blocks of one configuration derived from the blocks of another, without
//! another pass over the samples: a lagged multi-scale set from the
//! second-order set ([`Blocks::with_coil_lag`]), a shaped lag bank from the
//! plain bank over its filters ([`bank_blocks`]), a stretch of a plain bank
//! from a ladder that holds its filters (`slice_plain`).

use rbf_core::lag_bank::{BANK_FILTERS, GainOf, LagBank};
use rbf_core::{FeatureConfig, FeatureSet, MAX_INPUTS};

use super::blocks::Blocks;

/// Input 3 of the multi-scale sets: ΔT₃, the slowest rate, °C/min.
const SLOWEST_RATE_INPUT: usize = 3;

impl Blocks {
    /// These blocks of [`FeatureSet::MultiScaleSecondOrder`] as blocks of
    /// [`FeatureSet::MultiScaleLagged`] with coil lag `coil_lag_min`: input 0
    /// becomes T − L·ΔT₃ (the block mean of that input is the same combination
    /// of the block means; the firmware computes it per sample). Its per-sample
    /// range becomes the widest the two inputs' ranges allow, which clamps
    /// only inputs the training runs cannot have produced.
    pub fn with_coil_lag(mut self, coil_lag_min: u16) -> Blocks {
        let lag = f64::from(coil_lag_min);
        for row in &mut self.x {
            row[0] -= lag * row[SLOWEST_RATE_INPUT];
        }
        if let [temp, _, _, slowest, ..] = self.sample_range[..] {
            self.sample_range[0] = (temp.0 - lag * slowest.1, temp.1 - lag * slowest.0);
        }
        self
    }
}

/// The configuration whose blocks `features`' blocks are made from: the
/// second-order multi-scale set over the same windows for a lagged set
/// ([`Blocks::with_coil_lag`]), the plain bank over the same filters for a
/// shaped lag bank ([`bank_blocks`]), else `features` itself.
pub fn block_source(features: &FeatureConfig) -> FeatureConfig {
    match features.set {
        FeatureSet::MultiScaleLagged { .. } => FeatureConfig {
            set: FeatureSet::MultiScaleSecondOrder,
            ..*features
        },
        FeatureSet::LagBank(bank) => plain_bank(&bank).map_or(*features, FeatureConfig::lag_bank),
        _ => *features,
    }
}

/// The plain bank over `bank`'s filters: inputs [T, ΔT_1 … ΔT_n], no coil
/// lag, unit gain (`None` for a bank of no filters).
pub(super) fn plain_bank(bank: &LagBank) -> Option<LagBank> {
    LagBank::plain(bank.taus_s.get(..bank.filter_count())?, 0.0)
}

/// `blocks` of [`block_source`]`(features)` turned into `features`' blocks.
pub(super) fn derive_blocks(blocks: Blocks, features: &FeatureConfig) -> Blocks {
    match features.set {
        FeatureSet::MultiScaleLagged { coil_lag_min } => blocks.with_coil_lag(coil_lag_min),
        FeatureSet::LagBank(bank) if plain_bank(&bank) != Some(bank) => bank_blocks(&blocks, &bank),
        _ => blocks,
    }
}

/// The blocks of a shaped lag bank from those of the plain bank over its
/// filters, without another pass over the samples: each block's inputs are
/// `bank`'s inputs ([`LagBank::inputs`], the firmware's code) at the block's
/// mean temperature and mean rates. The bank's inputs are smooth in those
/// (powers of T̂ and a gain of T̂ or T times the rates), and within a 1-s block
/// the temperature moves by hundredths of a degree, so the mean of the
/// inputs and the inputs of the means differ far below the bias noise
/// (`the_default_fit_from_derived_blocks_matches_the_fit_on_per_sample_blocks`
/// bounds it). The per-sample ranges (the model's clamping box) are the
/// derived blocks' ranges widened by how far the plain inputs' samples went
/// beyond their block means, through the bank's coil lags and gain.
pub fn bank_blocks(plain: &Blocks, bank: &LagBank) -> Blocks {
    let n = bank.filter_count();
    let inputs = |temp_c: f64, rates: &[f64]| {
        let mut r = [0.0f32; BANK_FILTERS];
        for (r, v) in r.iter_mut().zip(rates) {
            *r = *v as f32;
        }
        let mut out = [0.0f32; MAX_INPUTS];
        bank.inputs(temp_c as f32, &r, &mut out);
        out.map(f64::from)
    };
    let mut out = Blocks {
        dims: bank.dims(),
        y: plain.y.clone(),
        run: plain.run.clone(),
        usable_s: plain.usable_s,
        segment_s: plain.segment_s.clone(),
        time_s: plain.time_s.clone(),
        samples: plain.samples.clone(),
        doublings: plain.doublings,
        ..Blocks::default()
    };
    out.x = plain.x.iter().map(|row| inputs(row[0], &row[1..=n])).collect();
    // How far samples went below and above their blocks' means, per plain input.
    let beyond: Vec<(f64, f64)> = (0..=n)
        .map(|i| {
            let (lo, hi) = plain.block_range(i);
            let (sample_lo, sample_hi) = plain.sample_range.get(i).copied().unwrap_or((lo, hi));
            ((lo - sample_lo).max(0.0), (sample_hi - hi).max(0.0))
        })
        .collect();
    let statics = bank.static_inputs();
    let lag: f64 = bank.coil_lag_min[..n]
        .iter()
        .zip(&beyond[1..])
        .map(|(a, m)| f64::from(a.abs()) * m.0.max(m.1))
        .sum();
    let coil = {
        let (lo, hi) = out.block_range(0);
        (lo - beyond[0].0 - lag, hi + beyond[0].1 + lag)
    };
    // The gain's largest size, and its largest change within a block, over
    // the temperatures the samples reached: the loop's, or the coil's for a
    // gain of T̂ (whose samples also move with the lags).
    let ((gain_lo, gain_hi), (below, above)) = match bank.gain_of {
        GainOf::Loop => (
            plain
                .sample_range
                .first()
                .copied()
                .unwrap_or_else(|| plain.block_range(0)),
            beyond[0],
        ),
        GainOf::Coil => (coil, (beyond[0].0 + lag, beyond[0].1 + lag)),
    };
    let gain_at = |t: f64| f64::from(bank.gain(t as f32));
    let gain = gain_at(gain_lo).abs().max(gain_at(gain_hi).abs());
    let gain_change = [gain_lo, gain_hi]
        .iter()
        .flat_map(|&t| [above, -below].map(|d| (gain_at(t + d) - gain_at(t)).abs()))
        .fold(0.0, f64::max);
    out.sample_range = (0..out.dims)
        .map(|i| {
            let (lo, hi) = out.block_range(i);
            if i == 0 {
                coil
            } else if i < statics {
                // The powers of T̂ over the widened coil range (T̂ = T at rest).
                let ref_c = f64::from(bank.ref_c);
                [coil.0, coil.1, ref_c.clamp(coil.0, coil.1)]
                    .iter()
                    .map(|&t| inputs(t, &[])[i])
                    .fold((lo, hi), |(lo, hi), v| (lo.min(v), hi.max(v)))
            } else {
                let (below, above) = beyond[1 + i - statics];
                let drift = gain_change * lo.abs().max(hi.abs());
                (lo - gain * below - drift, hi + gain * above + drift)
            }
        })
        // The inputs' spread within a block away from the extremes (noise
        // through the gain) is not in those margins; an even power of
        // (T̂ − T₀) (input i is power i + 1) never goes below 0.
        .enumerate()
        .map(|(i, (lo, hi))| {
            let lo = lo - SPREAD_MARGIN * (hi - lo);
            let even_power = (1..statics).contains(&i) && i % 2 == 1;
            (
                if even_power { lo.max(0.0) } else { lo },
                hi + SPREAD_MARGIN * (hi - lo),
            )
        })
        .collect();
    out
}

/// Margin on every derived range, as a fraction of its span.
const SPREAD_MARGIN: f64 = 1e-3;

/// The blocks of the plain bank `want` cut from `have`, those of a plain
/// bank whose filters include `want`'s in a row (a filter computes the same
/// values whatever bank it is in): those filters' columns, without the
/// blocks that `want`'s longer warm-up (a slower fastest filter) leaves
/// out. `None` when `have` does not hold `want`'s filters or its blocks do
/// not say when they started.
pub(super) fn slice_plain(have: &LagBank, blocks: &Blocks, want: &LagBank) -> Option<Blocks> {
    let (h, w) = (have.filter_count(), want.filter_count());
    let bits = |taus: &[f32]| taus.iter().map(|t| t.to_bits()).collect::<Vec<_>>();
    let wanted = bits(&want.taus_s[..w]);
    let first = (0..=h.checked_sub(w)?).find(|&f| bits(&have.taus_s[f..f + w]) == wanted)?;
    if plain_bank(have) != Some(*have) || blocks.segment_s.len() != blocks.len() {
        return None;
    }
    let warmup_s = FeatureConfig::lag_bank(*want).warmup_s();
    let columns = |row: &[f64; MAX_INPUTS]| {
        let mut out = [0.0; MAX_INPUTS];
        out[0] = row[0];
        out[1..=w].copy_from_slice(&row[1 + first..=first + w]);
        out
    };
    let mut sample_range = vec![*blocks.sample_range.first()?];
    sample_range.extend_from_slice(blocks.sample_range.get(1 + first..=first + w)?);
    let mut out = Blocks {
        dims: 1 + w,
        sample_range,
        doublings: blocks.doublings,
        ..Blocks::default()
    };
    for i in (0..blocks.len()).filter(|&i| blocks.segment_s[i] >= warmup_s) {
        out.x.push(columns(&blocks.x[i]));
        out.y.push(blocks.y[i]);
        out.run.push(blocks.run[i]);
        out.segment_s.push(blocks.segment_s[i]);
        if let (Some(t), Some(n)) = (blocks.time_s.get(i), blocks.samples.get(i)) {
            out.time_s.push(*t);
            out.samples.push(*n);
        }
    }
    out.usable_s = blocks.usable_s * out.len() as f64 / blocks.len().max(1) as f64;
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::test_support::{multiscale, simulated_run};
    use crate::dataset::{RunFiles, RunSet, sample_block_means};
    use crate::reading::run::samples::Run;

    #[test]
    fn lagged_blocks_derived_from_the_second_order_blocks_match_the_per_sample_features() {
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 3.0, 7);
        let run = Run::load(&path).unwrap();
        let lagged = multiscale(FeatureSet::MultiScaleLagged { coil_lag_min: 40 }, 15.0);
        assert_eq!(
            block_source(&lagged),
            multiscale(FeatureSet::MultiScaleSecondOrder, 15.0)
        );
        let runs = std::slice::from_ref(&run);
        // What the firmware's features average to, computed sample by sample.
        let direct = sample_block_means(runs, &lagged, 1.0);
        let derived = runs.block_means(&lagged, 1.0).unwrap();
        assert_eq!(derived.len(), direct.len());
        assert_eq!(derived.y, direct.y);
        for (d, e) in derived.x.iter().zip(&direct.x) {
            assert!((d[0] - e[0]).abs() < 1e-4, "T̄ {} against {}", d[0], e[0]);
            assert_eq!(d[1..8], e[1..8]);
        }
        let (span, true_span) = (derived.sample_range[0], direct.sample_range[0]);
        assert!(
            span.0 <= true_span.0 && span.1 >= true_span.1,
            "{span:?} must hold {true_span:?}"
        );
        assert_eq!(derived.sample_range[1..], direct.sample_range[1..]);
        // Streamed runs give the same, from the second-order set's cached pass.
        let streamed = RunFiles::new(std::slice::from_ref(&path));
        streamed.prepare(&[lagged], 1.0).unwrap();
        assert_eq!(streamed.block_means(&lagged, 1.0).unwrap().x, derived.x);
    }

    /// A shaped bank over `taus`: coil lags of minutes, a gain that drifts, a cubic static part.
    fn shaped_bank(taus: &[f32]) -> LagBank {
        let mut bank = LagBank::plain(taus, 25.0).unwrap();
        for (k, a) in bank.coil_lag_min.iter_mut().take(taus.len()).enumerate() {
            *a = [0.5, -2.0, 6.0, -20.0, 40.0][k % 5];
        }
        bank.gain_per_c = 3e-3;
        bank.static_degree = 3;
        (bank.coil_min_c, bank.coil_max_c) = (10.0, 40.0);
        assert!(bank.is_valid());
        bank
    }

    #[test]
    fn the_default_fit_from_derived_blocks_matches_the_fit_on_per_sample_blocks() {
        // A shaped bank's blocks come from the plain bank's (no second pass):
        // the bank's inputs of the block means, against the block means of
        // the per-sample inputs the firmware computes.
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 3.0, 7);
        let run = Run::load(&path).unwrap();
        let runs = std::slice::from_ref(&run);
        let bank = shaped_bank(&[30.0, 120.0, 480.0, 1920.0, 7680.0]);
        let shaped = FeatureConfig::lag_bank(bank);
        assert_eq!(
            block_source(&shaped),
            FeatureConfig::lag_bank(LagBank::plain(&bank.taus_s[..5], 0.0).unwrap())
        );
        let direct = sample_block_means(runs, &shaped, 1.0);
        let derived = runs.block_means(&shaped, 1.0).unwrap();
        assert_eq!((derived.len(), derived.dims), (direct.len(), direct.dims));
        assert_eq!(derived.y, direct.y);
        // Each input within a millionth of its span (f32 inputs of 10 samples a block).
        for i in 0..direct.dims {
            let (lo, hi) = direct.block_range(i);
            let worst = derived
                .x
                .iter()
                .zip(&direct.x)
                .map(|(d, e)| (d[i] - e[i]).abs())
                .fold(0.0, f64::max);
            assert!(worst <= 1e-5 * (hi - lo), "input {i}: {worst} of span {}", hi - lo);
            // The clamping box holds every sample, and not much more.
            let (got, truth) = (derived.sample_range[i], direct.sample_range[i]);
            assert!(
                got.0 <= truth.0 && got.1 >= truth.1,
                "input {i}: {got:?} must hold {truth:?}"
            );
            let slack = (truth.0 - got.0) + (got.1 - truth.1);
            assert!(
                slack <= 0.01 * (truth.1 - truth.0),
                "input {i}: {got:?} against {truth:?}"
            );
        }
    }
}
