//! The thermal response bank's fit (`--features response-bank`): the bank's
//! structure fixed from the training runs, its weights from one ridge
//! regression on block means of the filters' outputs.
//!
//! - Filters: [`FILTERS`] time constants log-spaced from [`FASTEST_TAU_S`]
//!   to [`SLOWEST_TAU_S`].
//! - T₀: the middle of the loop temperature range the runs covered; the
//!   covered range: that range; a static cubic in T − T₀.
//! - The blocks: [`BLOCK_S`] means of every channel the bank mixes (the
//!   static powers, the rates ΔT_k, their products with u_c and u_c², the
//!   rates of (T − T₀)² and (T − T₀)³), made sample by sample by rbf-core's
//!   extractor ([`rbf_core::FeatureExtractor::update_with_channels`], the
//!   firmware's arithmetic), samples still warming up left out.
//! - The weights: [`solve_weights`], one ridge regression with an offset per
//!   run, the columns standardised and the penalty on the dynamic ones,
//!   growing with the filter's time constant, each mixture at its own share;
//!   the settled levels' blocks weighed more where they span the range
//!   ([`super::settled_blocks`]).
//! - The network: no centres, the linear layer [c₁ … c₃, 1, 1, 1, 1, 1] on
//!   the bank's inputs and the constant c₀.
//!
//! Why these choices, and the measurements behind them: docs/methods.md
//! ("The thermal response bank").

use nalgebra::{DMatrix, DVector};
use rbf_core::features::loop_reading;
use rbf_core::model::{Model, ModelBody, ModelInfo};
use rbf_core::rbf::{RbfNetwork, RbfParams};
use rbf_core::response_bank::{POWER_RESPONSES, RESPONSE_FILTERS, RESPONSES, ResponseBank, WEIGHT_ROWS};
use rbf_core::{CompensatorConfig, FeatureConfig, FeatureExtractor, FeatureSet};

use super::FitOptions;
use super::linalg::{GramStats, ridge_factor, ridge_solve_weighted};
use super::settled_blocks::settled_block_weights;
use crate::dataset::{RunSet, SampleVisit};

/// Filters the fitted bank runs.
pub const FILTERS: usize = 12;
/// The fastest filter's time constant, s.
pub const FASTEST_TAU_S: f64 = 10.0;
/// The slowest filter's time constant, s (1.1 h).
pub const SLOWEST_TAU_S: f64 = 1.1 * 3600.0;
/// Powers of T − T₀ in the static part.
pub const STATIC_DEGREE: u8 = 3;
/// Length of the blocks the weights are fitted on, s.
pub const BLOCK_S: f64 = 10.0;
/// Ridge penalty λ (times the number of blocks) on a standardised dynamic
/// column whose filter's time constant is [`PRIOR_TAU_S`] and whose
/// mixture's share is 1; a column of filter k in mixture m takes
/// λ·s_m·τ_k/[`PRIOR_TAU_S`] ([`MIXTURE_PRIOR_SHARE`]).
pub const RIDGE_LAMBDA: f64 = 1e-4;
/// The time constant at which a dynamic column's penalty is [`RIDGE_LAMBDA`], s.
///
/// The penalty grows in proportion to the filter's time constant: a prior
/// whose variance falls as 1/τ_k, so that the slow responses a chamber run
/// of a few holds barely excites stay near zero instead of taking weights
/// that fit the run and not the in-use histories (docs/methods.md, "The
/// identification").
pub const PRIOR_TAU_S: f64 = 600.0;
/// Each mixture's share s_m of the prior's penalty (a channel of filter k
/// takes λ·s_m·τ_k/[`PRIOR_TAU_S`]), in the bank's order: the rate response
/// R₀, the gained ones u_c·R₁ and u_c²·R₂, the filtered powers H₂ and H₃.
///
/// The gained responses and the filtered powers correct the rate response
/// (a Shupe gain that drifts with temperature); a slow filter's channel of
/// a power is nearly that power less its lag, so under the rate response's
/// prior their weights traded with the static cubic, and the settled curve
/// a soak test reads came out of the run's history. Held 3× and 10× nearer
/// zero, the rate response 0.3× (measured: docs/methods.md, "The
/// identification"; docs/decisions.md, "Each mixture its own prior").
pub const MIXTURE_PRIOR_SHARE: [f64; MIXTURES] = [0.3, 3.0, 3.0, 10.0, 10.0];
/// Mixtures of the filters the bank holds: the three rate responses and the two filtered powers.
pub const MIXTURES: usize = RESPONSES + POWER_RESPONSES;
/// Channels a block holds: the static powers, then each mixture's [`FILTERS`] channels.
const CHANNELS: usize = STATIC_DEGREE as usize + MIXTURES * FILTERS;

/// The filters' time constants, s: log-spaced from [`FASTEST_TAU_S`] to [`SLOWEST_TAU_S`].
pub fn taus_s() -> [f32; FILTERS] {
    let ratio = (SLOWEST_TAU_S / FASTEST_TAU_S).ln() / (FILTERS - 1) as f64;
    std::array::from_fn(|k| (FASTEST_TAU_S * (ratio * k as f64).exp()) as f32)
}

/// Block means of the channels a response bank mixes, and their targets.
#[derive(Clone, Debug, Default)]
pub struct ChannelBlocks {
    /// Per block, the `CHANNELS` channel means: u, u², u³, then per mixture
    /// (R₀, u_c·R₁, u_c²·R₂, H₂, H₃) its filters' channels.
    pub x: Vec<[f64; CHANNELS]>,
    /// Mean bias target of each block, °/h.
    pub y: Vec<f64>,
    /// Run of each block.
    pub run: Vec<usize>,
    /// Start of each block on its run's clock, s.
    pub time_s: Vec<f64>,
    /// Number of runs.
    pub runs: usize,
    /// Per-sample range of each channel.
    pub range: Vec<(f64, f64)>,
    /// How many times each block counts in the regression
    /// ([`super::settled_blocks::settled_block_weights`]).
    pub weight: Vec<f64>,
}

/// The static part and mixtures of a bank, as [`solve_weights`] gives them.
#[derive(Clone, Debug, PartialEq)]
pub struct Weights {
    /// c₀, °/h: the runs' offsets, averaged by their blocks.
    pub constant_dph: f64,
    /// c₁ … c₃: °/h per °C^p of u = T − T₀.
    pub static_dph: [f64; STATIC_DEGREE as usize],
    /// The bank's weight rows: the three responses', the two filtered powers'.
    pub bank: [[f32; RESPONSE_FILTERS]; WEIGHT_ROWS],
}

impl Weights {
    /// The bias these weights give for a block's channel means `x`, °/h: the
    /// weights as the model stores them (f32), summed in f64.
    pub fn bias_dph(&self, x: &[f64; CHANNELS]) -> f64 {
        let statics = STATIC_DEGREE as usize;
        let statics_dph: f64 = (0..statics).map(|p| f64::from(self.static_dph[p] as f32) * x[p]).sum();
        let dynamic_dph: f64 = (0..MIXTURES)
            .flat_map(|m| (0..FILTERS).map(move |k| (m, k)))
            .map(|(m, k)| f64::from(self.bank[m][k]) * x[statics + m * FILTERS + k])
            .sum();
        self.constant_dph + statics_dph + dynamic_dph
    }
}

/// The bank and its deployable model for `train`.
pub fn identify<T: RunSet + ?Sized>(train: &T, opts: &FitOptions) -> anyhow::Result<Model> {
    let (bank, blocks) = plain_bank_and_blocks(train, opts.block_s)?;
    fitted_model(bank, &blocks, opts)
}

/// A fitted bank and what the structure choice reads of it.
pub struct Identified {
    /// The deployable model.
    pub model: Model,
    /// Its residual 100-s cluster STD on the training runs, °/h (RMS over the runs).
    pub training_std100_dph: f64,
    /// Its held-out score ([`held_out_rms`]), °/h.
    pub held_out_rms_dph: f64,
    /// Its regression weighed the runs' settled levels ([`super::settled_blocks`]).
    pub settled_levels_weighed: bool,
    /// Hours of training its regression fitted: its [`BLOCK_S`] blocks, h.
    pub training_hours: f64,
}

/// [`identify`], with the fitted model's training residual and held-out
/// score, from the same channel blocks: the model is linear in its
/// channels, so their block means give the block means of its bias, and
/// the runs are read once.
pub fn identify_with_residual<T: RunSet + ?Sized>(train: &T, opts: &FitOptions) -> anyhow::Result<Identified> {
    let (bank, blocks) = plain_bank_and_blocks(train, opts.block_s)?;
    let w = solve_weights(&blocks)?;
    let training_std100_dph = training_std100_of_weights(&blocks, &w)?;
    let held_out_rms_dph = held_out_rms(&blocks, f64::from(bank.ref_c), opts.folds);
    Ok(Identified {
        model: fitted_model_with(bank, &w, &blocks, opts)?,
        training_std100_dph,
        held_out_rms_dph,
        settled_levels_weighed: blocks.settled_levels_weighed(),
        training_hours: blocks.hours(),
    })
}

/// The bank's held-out score on `blocks`, °/h: refitted ([`solve_weights`])
/// without each fold of whole thermal events ([`super::events::thermal_folds`]
/// over the blocks' loop temperature, `ref_c` + u; at most `folds`
/// contiguous folds where the runs hold too few events), the residual on
/// the held-out blocks scored as the lag bank's candidates are
/// ([`super::events::held_out_rms`]). Infinite where a fold cannot be fitted.
pub fn held_out_rms(blocks: &ChannelBlocks, ref_c: f64, folds: usize) -> f64 {
    let temp_c: Vec<f64> = blocks.x.iter().map(|x| x[0] + ref_c).collect();
    let f = super::events::thermal_folds(&temp_c, &blocks.run, BLOCK_S, folds);
    let fits: Option<Vec<Weights>> = (0..f.held_out.len())
        .map(|k| solve_weights(&blocks.subset(&f.train_rows(k, blocks.y.len()))).ok())
        .collect();
    let Some(fits) = fits else {
        return f64::INFINITY;
    };
    let held: Vec<&[usize]> = f.held_out.iter().map(Vec::as_slice).collect();
    super::events::held_out_rms(&held, &blocks.run, BLOCK_S, |fold, i| {
        blocks.y[i] - fits[fold].bias_dph(&blocks.x[i])
    })
}

/// The configuration whose blocks give the loop temperature's range the
/// bank is centred on. Read only where the bank is identified: the default
/// fit does not prepare it beside the lag bank's ladders, since on runs
/// where the bank is not worth trying ([`StructureChoice::worth_trying`])
/// it would be a builder's work for nothing.
fn range_config() -> FeatureConfig {
    FeatureConfig::single(FeatureSet::Temp, 0.0)
}

/// The bank's structure for `train` (weights 0) and the block means of its
/// channels; the loop temperature's range is read from `range_config`'s
/// blocks of `block_s` (computed unless prepared).
pub fn plain_bank_and_blocks<T: RunSet + ?Sized>(
    train: &T,
    block_s: f64,
) -> anyhow::Result<(ResponseBank, ChannelBlocks)> {
    let temp = range_config();
    let (lo, hi) = train
        .block_means(&temp, block_s)?
        .sample_range
        .first()
        .copied()
        .unwrap_or((f64::NAN, f64::NAN));
    anyhow::ensure!(
        lo.is_finite() && hi > lo,
        "the training runs cover no temperature range ({lo} … {hi} °C)"
    );
    let ref_c = (0.5 * (lo + hi)) as f32;
    let bank = ResponseBank::new(&taus_s(), ref_c, lo as f32, hi as f32, STATIC_DEGREE)
        .ok_or_else(|| anyhow::anyhow!("no valid response bank over {lo} … {hi} °C"))?;
    let mut blocks = channel_blocks(train, &bank)?;
    let temp_c: Vec<f64> = blocks.x.iter().map(|x| x[0] + f64::from(ref_c)).collect();
    blocks.weight = settled_block_weights(&blocks.time_s, &temp_c, &blocks.run, BLOCK_S);
    anyhow::ensure!(
        blocks.y.len() > 4 * (blocks.runs + CHANNELS),
        "{} blocks of {BLOCK_S} s: too few to fit the response bank's {CHANNELS} weights",
        blocks.y.len()
    );
    Ok((bank, blocks))
}

/// The fitted model of `bank` on `blocks`.
pub fn fitted_model(bank: ResponseBank, blocks: &ChannelBlocks, opts: &FitOptions) -> anyhow::Result<Model> {
    fitted_model_with(bank, &solve_weights(blocks)?, blocks, opts)
}

/// The model of `bank` with the weights `w` solved on `blocks`.
fn fitted_model_with(
    mut bank: ResponseBank,
    w: &Weights,
    blocks: &ChannelBlocks,
    opts: &FitOptions,
) -> anyhow::Result<Model> {
    bank.weights = w.bank;
    anyhow::ensure!(bank.is_valid(), "the fitted response bank is out of range");
    model(bank, w, blocks, opts)
}

/// One block being summed.
struct BlockSum {
    key: (usize, u64, u64),
    start_s: f64,
    x: [f64; CHANNELS],
    y: f64,
    count: usize,
    min_count: usize,
}

/// Block means of `bank`'s channels over every run of `train`, sample by
/// sample through rbf-core's extractor; a gap or a missing loop reading
/// restarts the filters, as the compensator does.
fn channel_blocks<T: RunSet + ?Sized>(train: &T, bank: &ResponseBank) -> anyhow::Result<ChannelBlocks> {
    let config = FeatureConfig::response_bank(*bank);
    let mut out = ChannelBlocks {
        range: vec![(f64::INFINITY, f64::NEG_INFINITY); CHANNELS],
        ..ChannelBlocks::default()
    };
    let mut extractor = FeatureExtractor::new();
    let mut current: Option<BlockSum> = None;
    let mut segment = (usize::MAX, 0u64, 0.0f64);
    let statics = STATIC_DEGREE as usize;
    let mut visit = |v: &SampleVisit| {
        let gap = CompensatorConfig::for_nominal_period_s(v.nominal_period_s).is_gap(v.sample.dt_s);
        let Some(temp_c) = v.sample.temps_c[rbf_core::features::LOOP_THERMOMETER] else {
            extractor.restart();
            return;
        };
        if v.run != segment.0 || gap {
            extractor.restart();
            segment = (v.run, segment.1 + 1, v.time_s);
        }
        let dt = if v.run == segment.0 && !gap { v.sample.dt_s } else { 0.0 };
        let (features, channels) = extractor.update_with_channels(&config, dt, &loop_reading(temp_c));
        if features.warming_up || !v.target_dph.is_finite() {
            return;
        }
        let key = (v.run, segment.1, ((v.time_s - segment.2) / BLOCK_S).floor() as u64);
        if current.as_ref().is_none_or(|b| b.key != key) {
            if let Some(done) = current.take() {
                out.push(done);
            }
            current = Some(BlockSum {
                key,
                start_s: segment.2 + key.2 as f64 * BLOCK_S,
                x: [0.0; CHANNELS],
                y: 0.0,
                count: 0,
                min_count: ((0.5 * BLOCK_S / v.nominal_period_s).floor() as usize).max(1),
            });
        }
        let Some(block) = current.as_mut() else {
            return;
        };
        let inputs = features.as_slice();
        // u_c: the covered range holds every training sample (it is their range).
        let u_c =
            f64::from(temp_c).clamp(f64::from(bank.range_min_c), f64::from(bank.range_max_c)) - f64::from(bank.ref_c);
        let mut values = [0.0f64; CHANNELS];
        for (v, i) in values.iter_mut().zip(inputs).take(statics) {
            *v = f64::from(*i);
        }
        for k in 0..FILTERS {
            let r = f64::from(channels.rates[0][k]);
            values[statics + k] = r;
            values[statics + FILTERS + k] = u_c * r;
            values[statics + 2 * FILTERS + k] = u_c * u_c * r;
            values[statics + 3 * FILTERS + k] = f64::from(channels.rates[1][k]);
            values[statics + 4 * FILTERS + k] = f64::from(channels.rates[2][k]);
        }
        for ((sum, range), v) in block.x.iter_mut().zip(&mut out.range).zip(values) {
            *sum += v;
            *range = (range.0.min(v), range.1.max(v));
        }
        block.y += v.target_dph;
        block.count += 1;
        out.runs = out.runs.max(v.run + 1);
    };
    train.for_each_sample(&mut visit)?;
    if let Some(done) = current.take() {
        out.push(done);
    }
    Ok(out)
}

impl ChannelBlocks {
    /// The blocks `rows` (ascending), their runs renumbered from 0 in order
    /// so that a run left out entirely leaves no offset to fit.
    fn subset(&self, rows: &[usize]) -> ChannelBlocks {
        let mut number = vec![usize::MAX; self.runs.max(1)];
        let mut runs = 0;
        let mut run = Vec::with_capacity(rows.len());
        for &i in rows {
            let r = &mut number[self.run[i].min(self.runs.max(1) - 1)];
            if *r == usize::MAX {
                *r = runs;
                runs += 1;
            }
            run.push(*r);
        }
        ChannelBlocks {
            x: rows.iter().map(|&i| self.x[i]).collect(),
            y: rows.iter().map(|&i| self.y[i]).collect(),
            run,
            time_s: rows.iter().map(|&i| self.time_s[i]).collect(),
            weight: rows.iter().map(|&i| self.weight_of(i)).collect(),
            runs,
            range: self.range.clone(),
        }
    }

    /// Keeps `block` if it holds at least half its nominal samples.
    fn push(&mut self, block: BlockSum) {
        if block.count < block.min_count {
            return;
        }
        let n = block.count as f64;
        self.x.push(block.x.map(|v| v / n));
        self.y.push(block.y / n);
        self.run.push(block.key.0);
        self.time_s.push(block.start_s);
        self.weight.push(1.0);
    }

    /// How many times block `i` counts in the regression: its `weight`, 1
    /// where none was set (blocks assembled without [`plain_bank_and_blocks`]).
    fn weight_of(&self, i: usize) -> f64 {
        self.weight.get(i).copied().unwrap_or(1.0)
    }

    /// Whether any block counts more than once: the runs' settled levels
    /// span their range and are weighed ([`super::settled_blocks`]).
    pub fn settled_levels_weighed(&self) -> bool {
        self.weight.iter().any(|&w| w > 1.0)
    }

    /// Hours of training the blocks hold ([`BLOCK_S`] each), h.
    pub fn hours(&self) -> f64 {
        self.y.len() as f64 * BLOCK_S / 3600.0
    }
}

/// The regression's design on `blocks`: an offset column per run, then the
/// `CHANNELS` channels centred and scaled to unit standard deviation (the
/// penalty then weighs every dynamic column alike).
struct Design {
    /// Rows: the blocks; columns: the runs' offsets, then the channels.
    a: DMatrix<f64>,
    /// Each column's mean before centring (0 for the offsets).
    mean: Vec<f64>,
    /// Each column's standard deviation before scaling (1 for the offsets and constant channels).
    scale: Vec<f64>,
    /// Offset columns.
    runs: usize,
}

impl Design {
    fn of(blocks: &ChannelBlocks) -> Design {
        let n = blocks.y.len();
        let runs = blocks.runs.max(1);
        let cols = runs + CHANNELS;
        let mut a = DMatrix::<f64>::zeros(n, cols);
        for (i, (x, &run)) in blocks.x.iter().zip(&blocks.run).enumerate() {
            a[(i, run.min(runs - 1))] = 1.0;
            for (c, v) in x.iter().enumerate() {
                a[(i, runs + c)] = *v;
            }
        }
        let mut mean = vec![0.0; cols];
        let mut scale = vec![1.0; cols];
        for c in runs..cols {
            let col = a.column(c);
            let m = col.mean();
            let sd = (col.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n.max(1) as f64).sqrt();
            mean[c] = m;
            scale[c] = if sd > 0.0 { sd } else { 1.0 };
            a.column_mut(c).iter_mut().for_each(|v| *v = (*v - m) / scale[c]);
        }
        Design { a, mean, scale, runs }
    }

    fn cols(&self) -> usize {
        self.a.ncols()
    }

    /// The prior's penalty on column `c`, in units of λ·n: s_m·τ_k/τ₀ on
    /// the channel of mixture m and filter k ([`MIXTURE_PRIOR_SHARE`]), none
    /// on the offsets and the static powers.
    fn penalty_scale(&self, c: usize) -> f64 {
        let taus = taus_s();
        match c.checked_sub(self.runs + STATIC_DEGREE as usize) {
            Some(dynamic) => MIXTURE_PRIOR_SHARE[dynamic / FILTERS] * f64::from(taus[dynamic % FILTERS]) / PRIOR_TAU_S,
            None => 0.0,
        }
    }
}

/// The weights by ridge regression of the block targets on an offset per
/// run and the `CHANNELS` channels, the channels standardised, the
/// penalty on the dynamic ones only: λ·n·s_m·τ_k/τ₀ on the channel of
/// mixture m and filter k ([`RIDGE_LAMBDA`], [`MIXTURE_PRIOR_SHARE`], [`PRIOR_TAU_S`]),
/// n the number of blocks; each block's squared residual counted
/// `blocks.weight` times (the settled ones more where they span the range:
/// [`super::settled_blocks`]).
pub fn solve_weights(blocks: &ChannelBlocks) -> anyhow::Result<Weights> {
    let statics = STATIC_DEGREE as usize;
    let n = blocks.y.len();
    let mut design = Design::of(blocks);
    let root_weight: Vec<f64> = (0..n).map(|i| blocks.weight_of(i).sqrt()).collect();
    for (mut row, w) in design.a.row_iter_mut().zip(&root_weight) {
        row *= *w;
    }
    let y = DVector::from_iterator(n, blocks.y.iter().zip(&root_weight).map(|(y, w)| y * w));
    // n stays the number of blocks: the prior's strength is per block, whatever their weights.
    let stats = GramStats::new(&design.a, &y);
    let (runs, cols) = (design.runs, design.cols());
    let (mean, scale) = (&design.mean, &design.scale);
    let penalty_scale = |c: usize| design.penalty_scale(c);
    let beta = ridge_solve_weighted(&stats, cols, RIDGE_LAMBDA, penalty_scale)
        .ok_or_else(|| anyhow::anyhow!("the response bank's regression is singular"))?;
    let raw: Vec<f64> = (0..cols).map(|c| beta[c] / scale[c]).collect();
    let shift: f64 = (runs..cols).map(|c| raw[c] * mean[c]).sum();
    let mut blocks_of = vec![0usize; runs];
    for &r in &blocks.run {
        blocks_of[r.min(runs - 1)] += 1;
    }
    let constant_dph = (0..runs).map(|r| beta[r] * blocks_of[r] as f64).sum::<f64>() / n.max(1) as f64 - shift;
    let mut bank = [[0.0f32; RESPONSE_FILTERS]; WEIGHT_ROWS];
    for (m, row) in bank.iter_mut().enumerate() {
        for (k, w) in row.iter_mut().take(FILTERS).enumerate() {
            *w = raw[runs + statics + m * FILTERS + k] as f32;
        }
    }
    Ok(Weights {
        constant_dph,
        static_dph: std::array::from_fn(|p| raw[runs + p]),
        bank,
    })
}

/// How loosely `blocks` pin the static curve that [`solve_weights`] would
/// identify on them: the posterior variance of the curve at the settled
/// temperatures `levels_c` about its mean over them, averaged over the
/// levels, per unit variance of a block's noise. The ridge regression is
/// read as the Bayesian one it is (its penalty a Gaussian prior on the
/// standardised weights), so the figure counts both the noise and how far
/// the slow responses can trade against the cubic where the runs leave them
/// unexcited: what a soak test at those levels reads as misidentified
/// settled bias. Only the channels matter, not the targets, so a plan can
/// be scored on its simulated loop temperature alone (`trainer plan`;
/// docs/plan.md). `None` where the regression is singular.
pub fn static_curve_variance(bank: &ResponseBank, blocks: &ChannelBlocks, levels_c: &[f64]) -> Option<f64> {
    let statics = STATIC_DEGREE as usize;
    let design = Design::of(blocks);
    let cols = design.cols();
    let cholesky = ridge_factor(&design.a.tr_mul(&design.a), blocks.y.len(), cols, RIDGE_LAMBDA, |c| {
        design.penalty_scale(c)
    })?;
    // The static coefficients' posterior covariance: their columns of the inverse.
    let mut unit = DMatrix::<f64>::zeros(cols, statics);
    for p in 0..statics {
        unit[(design.runs + p, p)] = 1.0;
    }
    let inverse = cholesky.solve(&unit);
    let covariance = inverse.rows(design.runs, statics).clone_owned();
    // Each level's static inputs on the standardised scale, about their mean.
    let rows: Vec<DVector<f64>> = levels_c
        .iter()
        .map(|&t| {
            let (powers, _) = bank.powers(t as f32);
            DVector::from_iterator(
                statics,
                (0..statics).map(|p| f64::from(powers[p]) / design.scale[design.runs + p]),
            )
        })
        .collect();
    let m = rows.len().max(1) as f64;
    let centre = rows.iter().fold(DVector::zeros(statics), |acc, r| acc + r) / m;
    let variance = rows
        .iter()
        .map(|r| {
            let d = r - &centre;
            (d.transpose() * &covariance * &d)[(0, 0)]
        })
        .sum::<f64>()
        / m;
    variance.is_finite().then_some(variance)
}

/// The model of `bank` with the static coefficients and constant of `w`:
/// a network of no centres whose linear layer takes the mixtures with
/// weight 1; the training ranges those the runs' samples reached.
fn model(bank: ResponseBank, w: &Weights, blocks: &ChannelBlocks, opts: &FitOptions) -> anyhow::Result<Model> {
    let dims = bank.dims();
    let statics = bank.static_inputs();
    let mut linear: Vec<f32> = w.static_dph[..statics].iter().map(|&c| c as f32).collect();
    linear.extend([1.0f32; MIXTURES]);
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

/// Training ranges of the bank's inputs: each static power over the values
/// its samples took, each mixture over the interval sum of its weighted
/// channels' per-sample ranges (no sample went beyond them).
fn input_ranges(bank: &ResponseBank, blocks: &ChannelBlocks) -> Vec<(f32, f32)> {
    let statics = STATIC_DEGREE as usize;
    let mut ranges: Vec<(f64, f64)> = blocks.range.iter().take(statics).copied().collect();
    for (m, row) in bank.weights.iter().enumerate() {
        let channel = &blocks.range[statics + m * FILTERS..statics + (m + 1) * FILTERS];
        ranges.push(row.iter().zip(channel).fold((0.0, 0.0), |acc, (&w, &(lo, hi))| {
            let (a, b) = (f64::from(w) * lo, f64::from(w) * hi);
            (acc.0 + a.min(b), acc.1 + a.max(b))
        }));
    }
    ranges.iter().map(|&(lo, hi)| (lo as f32, hi as f32)).collect()
}

/// The default's choice between the lag bank and the response bank.
///
/// The lag bank's grey box holds few parameters tied by physics, and where
/// it represents a gyro it carries to in-use histories best; a coil unlike
/// the one it encodes (several radial layers with their own Shupe residuals,
/// a hub path, self-heating) it cannot follow even on its own training run.
/// The free response bank then takes over, but only where the grey box
/// misses the training run by a wide margin (its residual's 100-s cluster
/// STD above 1/[`RESPONSE_BANK_MARGIN`] times the response bank's) and the
/// response bank predicts held-out thermal events better than the lag bank
/// does: where its many weights only follow the run's noise, it does not.
/// Where both follow the run, the simpler structure is kept (docs/methods.md).
///
/// Where the lag bank's residual is already near the runs' noise floor
/// ([`super::forecast::white_noise_std100`]) no bank can leave the margin
/// below it, and the response bank is not identified at all
/// ([`Self::worth_trying`]): its scores are then `None`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StructureChoice {
    /// The lag bank's residual 100-s cluster STD on the training runs, °/h.
    pub lag_bank_std100_dph: f64,
    /// The share of it white noise explains, °/h (`None`: runs too short to tell).
    pub noise_floor_std100_dph: Option<f64>,
    /// The response bank's, °/h (`None`: not identified).
    pub response_bank_std100_dph: Option<f64>,
    /// The lag bank's held-out score (its chosen candidate's), °/h.
    pub lag_bank_held_out_rms_dph: f64,
    /// The response bank's held-out score on the same kind of folds ([`held_out_rms`]), °/h.
    pub response_bank_held_out_rms_dph: Option<f64>,
    /// The response bank was chosen.
    pub response_bank: bool,
    /// The response bank's regression weighed the runs' settled levels
    /// ([`super::settled_blocks`]; `None`: not identified).
    pub response_bank_settled_levels_weighed: Option<bool>,
    /// Hours of training the response bank's regression fitted, h (`None`: not identified).
    pub response_bank_training_hours: Option<f64>,
}

/// The response bank replaces the lag bank when its training residual is
/// below this share of the lag bank's.
pub const RESPONSE_BANK_MARGIN: f64 = 0.6;

/// The lowest share of the runs' noise floor a bank's training residual
/// reaches: its weights cannot follow the noise of runs hours long further
/// (docs/methods.md, "When the default takes it").
pub const NOISE_FLOOR_SHARE: f64 = 0.9;

impl StructureChoice {
    /// Whether the response bank could replace a lag bank whose training
    /// residual is `lag_bank_std100_dph` over runs whose noise floor is
    /// `noise_floor_std100_dph`, °/h: only where [`RESPONSE_BANK_MARGIN`] of
    /// the lag bank's residual lies above [`NOISE_FLOOR_SHARE`] of the
    /// floor. An unknown floor leaves the choice to the scores.
    pub fn worth_trying(lag_bank_std100_dph: f64, noise_floor_std100_dph: Option<f64>) -> bool {
        noise_floor_std100_dph
            .is_none_or(|floor| RESPONSE_BANK_MARGIN * lag_bank_std100_dph >= NOISE_FLOOR_SHARE * floor)
    }

    /// The choice between a lag bank whose training residual and held-out
    /// score are `lag_bank` ([training residual, held-out score], °/h) and
    /// the identified `response` bank, if it was identified, over runs
    /// whose noise floor is `noise_floor_std100_dph`.
    pub fn between(lag_bank: [f64; 2], noise_floor_std100_dph: Option<f64>, response: Option<&Identified>) -> Self {
        StructureChoice {
            response_bank_settled_levels_weighed: response.map(|r| r.settled_levels_weighed),
            response_bank_training_hours: response.map(|r| r.training_hours),
            ..Self::from_scores(
                lag_bank,
                noise_floor_std100_dph,
                response.map(|r| [r.training_std100_dph, r.held_out_rms_dph]),
            )
        }
    }

    /// The choice from each structure's [training residual, held-out score], °/h.
    pub fn from_scores(
        lag_bank: [f64; 2],
        noise_floor_std100_dph: Option<f64>,
        response_bank: Option<[f64; 2]>,
    ) -> Self {
        let [lag_bank_std100_dph, lag_bank_held_out_rms_dph] = lag_bank;
        StructureChoice {
            lag_bank_std100_dph,
            noise_floor_std100_dph,
            response_bank_std100_dph: response_bank.map(|r| r[0]),
            lag_bank_held_out_rms_dph,
            response_bank_held_out_rms_dph: response_bank.map(|r| r[1]),
            response_bank: response_bank.is_some_and(|[train, held_out]| {
                train < RESPONSE_BANK_MARGIN * lag_bank_std100_dph && held_out < lag_bank_held_out_rms_dph
            }),
            response_bank_settled_levels_weighed: None,
            response_bank_training_hours: None,
        }
    }
}

/// The residual 100-s cluster STD on the training runs of the bank whose
/// weights are `w`, from its channels' block means, °/h (RMS over the runs):
/// the weights as the model stores them (f32), summed in f64.
fn training_std100_of_weights(blocks: &ChannelBlocks, w: &Weights) -> anyhow::Result<f64> {
    let residual: Vec<f64> = blocks.x.iter().zip(&blocks.y).map(|(x, y)| y - w.bias_dph(x)).collect();
    super::forecast::rms_cluster_std_over_runs(&blocks.run, &blocks.time_s, &residual, BLOCK_S)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform draws in −0.5 … 0.5 from xorshift32 seeded with `seed`.
    fn uniform_from(seed: u32) -> impl FnMut() -> f64 {
        let mut state = seed;
        move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            f64::from(state) / f64::from(u32::MAX) - 0.5
        }
    }

    /// No blocks yet, of two runs, every channel ranging over −1 … 1.
    fn two_runs_of_blocks() -> ChannelBlocks {
        ChannelBlocks {
            runs: 2,
            range: vec![(-1.0, 1.0); CHANNELS],
            ..ChannelBlocks::default()
        }
    }

    #[test]
    fn the_filters_span_ten_seconds_to_1_1_hours_evenly_on_a_log_scale() {
        let t = taus_s();
        assert!(
            (t[0] - 10.0).abs() < 1e-4 && (t[FILTERS - 1] - 3_960.0).abs() < 0.01,
            "{t:?}"
        );
        let ratio = t[1] / t[0];
        assert!(t.windows(2).all(|w| (w[1] / w[0] - ratio).abs() < 1e-4 * ratio));
    }

    #[test]
    fn the_regression_recovers_a_static_cubic_a_filtered_power_and_an_offset_per_run() {
        // Targets of the model's form plus noise, the channels independent of
        // the temperature: the static part comes back closely (unpenalised),
        // each run's offset is its own, the responses come back slightly
        // shrunk by the ridge and the other weights stay small.
        let mut uniform = uniform_from(7);
        let statics = STATIC_DEGREE as usize;
        let mut blocks = two_runs_of_blocks();
        for i in 0..6000 {
            let run = i / 3000;
            let u = 30.0 * (i as f64 / 300.0).sin();
            let mut x = [0.0; CHANNELS];
            x[..statics].copy_from_slice(&[u, u * u, u * u * u]);
            for v in x.iter_mut().skip(statics) {
                *v = uniform();
            }
            let h2 = statics + 3 * FILTERS + 5;
            let r0 = statics + 2;
            let offset = [0.5, -0.25][run];
            let y = offset + 0.02 * u - 0.001 * u * u + 2e-5 * u.powi(3) + 0.3 * x[r0] - 0.2 * x[h2] + 0.01 * uniform();
            blocks.x.push(x);
            blocks.y.push(y);
            blocks.run.push(run);
        }
        let w = solve_weights(&blocks).unwrap();
        for (c, e) in w.static_dph.iter().zip([0.02, -0.001, 2e-5]) {
            assert!((c - e).abs() < 1e-6 + 1e-3 * e.abs(), "{:?}", w.static_dph);
        }
        assert!(
            (w.constant_dph - 0.125).abs() < 2e-3,
            "c₀ = {} (the runs' offsets averaged)",
            w.constant_dph
        );
        for (m, row) in w.bank.iter().enumerate() {
            for (k, &b) in row.iter().enumerate() {
                let want = match (m, k) {
                    (0, 2) => 0.3,
                    (3, 5) => -0.2,
                    _ => 0.0,
                };
                assert!((f64::from(b) - want).abs() < 0.01, "row {m} filter {k}: {b}");
            }
        }
    }

    /// The weights solved on blocks whose target is 0.4 × one random signal
    /// placed alike in the channels `first` and `second` (indices into a
    /// block's channels), which the run therefore cannot tell apart, over a
    /// static sweep that carries no target: the prior alone splits the
    /// response. Returns the two channels' weights as the model stores them.
    fn split_of_one_signal_in_two_channels(first: usize, second: usize, seed: u32) -> (f64, f64) {
        let mut uniform = uniform_from(seed);
        let statics = STATIC_DEGREE as usize;
        let mut blocks = two_runs_of_blocks();
        for i in 0..4000 {
            let mut x = [0.0; CHANNELS];
            let u = 20.0 * (i as f64 / 500.0).sin();
            x[..statics].copy_from_slice(&[u, u * u, u * u * u]);
            let shared = uniform();
            x[first] = shared;
            x[second] = shared;
            blocks.x.push(x);
            blocks.y.push(0.4 * shared + 0.001 * uniform());
            blocks.run.push(i / 2000);
        }
        let w = solve_weights(&blocks).unwrap();
        let weight = |c: usize| f64::from(w.bank[(c - statics) / FILTERS][(c - statics) % FILTERS]);
        (weight(first), weight(second))
    }

    /// Asserts that the two weights of [`split_of_one_signal_in_two_channels`]
    /// stand in `expected_ratio` (named `what`) and together carry the 0.4 response.
    fn assert_split((first, second): (f64, f64), expected_ratio: f64, what: &str) {
        assert!(
            (first / second / expected_ratio - 1.0).abs() < 1e-3,
            "weights {first}, {second}: ratio {} against {what} = {expected_ratio}",
            first / second
        );
        assert!(
            (first + second - 0.4).abs() < 0.01,
            "together they carry the response: {first} + {second}"
        );
    }

    #[test]
    fn a_response_the_run_cannot_place_between_the_rate_and_the_filtered_square_goes_to_the_rate() {
        // One signal in filter 4's channel of the rate response R₀ and of the
        // filtered square H₂: the prior decides, in the inverse ratio of the
        // mixtures' shares (w_R₀·s_R₀ = w_H₂·s_H₂), so a correction term does
        // not take what the leading response explains.
        let statics = STATIC_DEGREE as usize;
        let (w_rate, w_square) = split_of_one_signal_in_two_channels(statics + 4, statics + 3 * FILTERS + 4, 12);
        assert_split(
            (w_rate, w_square),
            MIXTURE_PRIOR_SHARE[3] / MIXTURE_PRIOR_SHARE[0],
            "s_H₂/s_R₀",
        );
    }

    #[test]
    fn a_response_seen_by_a_fast_and_a_slow_filter_alike_goes_to_the_fast_one_in_the_ratio_of_their_time_constants() {
        // The same signal in the rate channel of filter 1 (τ ≈ 20 s) and of
        // filter 9 (τ ≈ 3 h): the run cannot tell them apart, so the prior
        // decides. Each weight's penalty grows with its filter's τ, so the
        // standardised weights split in the inverse ratio of their penalties
        // (w₁·τ₁ = w₉·τ₉): almost all on the fast filter, none swinging.
        let statics = STATIC_DEGREE as usize;
        let (w_fast, w_slow) = split_of_one_signal_in_two_channels(statics + 1, statics + 9, 11);
        let taus = taus_s();
        assert_split((w_fast, w_slow), f64::from(taus[9] / taus[1]), "τ₉/τ₁");
    }

    #[test]
    fn the_held_out_score_is_near_the_noise_where_the_banks_form_explains_the_targets_and_not_where_it_cannot() {
        // Blocks of 10 s over two runs, channels drawn at random; targets of
        // the bank's form plus noise score near the noise's 100-s means, the
        // same channels with a slow wander no channel carries score far above.
        let mut uniform = uniform_from(11);
        let statics = STATIC_DEGREE as usize;
        let mut explained = two_runs_of_blocks();
        let mut wander = Vec::new();
        for i in 0..4000 {
            let run = i / 2000;
            let u = 30.0 * (i as f64 / 400.0).sin();
            let mut x = [0.0; CHANNELS];
            x[..statics].copy_from_slice(&[u, u * u, u * u * u]);
            for v in x.iter_mut().skip(statics) {
                *v = uniform();
            }
            let y = 0.02 * u + 0.3 * x[statics + 2] + 0.01 * uniform();
            explained.x.push(x);
            explained.y.push(y);
            explained.run.push(run);
            explained.time_s.push((i % 2000) as f64 * BLOCK_S);
            wander.push(y + 0.05 * (i as f64 / 97.0).sin() * (i as f64 / 613.0).cos());
        }
        let good = held_out_rms(&explained, 0.0, 5);
        let mut unexplained = explained.clone();
        unexplained.y = wander;
        let bad = held_out_rms(&unexplained, 0.0, 5);
        assert!(good < 0.003, "explained: {good:e} °/h (noise 100-s means about 1e-3)");
        assert!(bad > 5.0 * good, "unexplained wander {bad:e} against {good:e} °/h");
    }

    #[test]
    fn the_residual_from_the_channel_blocks_is_the_fitted_models_own() {
        // The residual the structure choice reads from the channels' block
        // means (no second pass over the runs) agrees with the deployable
        // model evaluated on the run's block means of the same length: a
        // channel weighted wrongly, or a weight not as the blob stores it,
        // would not.
        use crate::dataset::RunFiles;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.csv");
        let mut sim = crate::simulate::ChamberRun::ifog(1.5, 3);
        sim.duration_s = Some(4.0 * 3600.0);
        sim.sample_rate_hz = 5.0;
        sim.write_csv(&mut std::fs::File::create(&path).unwrap()).unwrap();
        let train = RunFiles::new(std::slice::from_ref(&path));
        let opts = FitOptions {
            progress: false,
            ..FitOptions::default()
        };
        let identified = identify_with_residual(&train, &opts).unwrap();
        let from_channels = identified.training_std100_dph;
        let from_model = super::super::forecast::training_residual(&train, &identified.model, BLOCK_S)
            .unwrap()
            .std100_dph;
        assert!(
            from_channels > 0.0 && (from_channels / from_model - 1.0).abs() < 0.02,
            "channels {from_channels:e}, model {from_model:e} °/h"
        );
    }

    #[test]
    fn the_response_bank_replaces_the_lag_bank_only_where_the_lag_bank_misses_its_run_and_the_bank_predicts_held_out_events_better()
     {
        let choice = |lag: f64, response: f64, lag_held_out: f64, response_held_out: f64| {
            StructureChoice::from_scores([lag, lag_held_out], None, Some([response, response_held_out])).response_bank
        };
        assert!(
            choice(0.02, 0.006, 0.05, 0.03),
            "the grey box misses its run by 3× and predicts worse"
        );
        assert!(
            !choice(0.02, 0.006, 0.05, 0.08),
            "the free bank follows the run but predicts held-out events worse: over-fitted"
        );
        assert!(
            !choice(0.006, 0.0058, 0.05, 0.01),
            "both follow the run: the grey box stays"
        );
        assert!(!choice(0.01, 0.0061, 0.05, 0.01), "a 1.6× gap is not wide enough");
        assert!(!choice(0.006, 0.017, 0.05, 0.01));
        assert!(!choice(0.02, 0.006, 0.05, f64::INFINITY), "a bank no fold could fit");
        assert!(
            !StructureChoice::from_scores([0.02, 0.05], Some(0.005), None).response_bank,
            "a bank not identified"
        );
    }

    #[test]
    fn the_response_bank_is_tried_only_where_the_lag_bank_leaves_room_above_the_noise_floor() {
        // 0.6 × 0.0070 = 0.0042 lies under 0.9 × 0.0060 = 0.0054: no bank gets there.
        assert!(!StructureChoice::worth_trying(0.0070, Some(0.0060)));
        // 0.6 × 0.0200 = 0.012 lies well above it.
        assert!(StructureChoice::worth_trying(0.0200, Some(0.0060)));
        assert!(
            StructureChoice::worth_trying(0.0070, None),
            "no floor known: the scores decide"
        );
        let at_floor = StructureChoice::from_scores([0.0070, 0.01], Some(0.0060), None);
        assert_eq!(at_floor.response_bank_std100_dph, None);
        assert_eq!(at_floor.noise_floor_std100_dph, Some(0.0060));
    }
}
