//! Training data: rbf-core features per sample, averaged over blocks.
//!
//! Features are computed per sample by [`rbf_core::Compensator::features`], the
//! very function the firmware runs, then averaged with the bias target over
//! blocks (1 s by default) inside each segment. Samples whose features are
//! still warming up or whose temperature is a held value are left out of the
//! averages; blocks with under half their nominal samples are dropped.
//!
//! A streamed run keeps at most [`MAX_BLOCKS_PER_RUN`] blocks: past that,
//! adjacent blocks of a segment are merged in pairs (sample-weighted means)
//! and the run goes on in blocks twice as long, so the memory a fit holds
//! does not grow with the run's length ([`Blocks::merge_pairs`]).

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use rbf_core::axis::Axis;
use rbf_core::lag_bank::{BANK_FILTERS, GainOf, LagBank};
use rbf_core::{Compensator, CompensatorConfig, FeatureConfig, FeatureSet, Flags, GyroSample, MAX_INPUTS};

use crate::chunked::Batch;
use crate::metrics::BinIndex;
use crate::run::{Run, RunReader, StreamedRun};

/// Block-averaged features and targets of one or more runs.
#[derive(Clone, Debug, Default)]
pub struct Blocks {
    /// Number of features per block.
    pub dims: usize,
    /// Mean features of each block (first `dims` entries used).
    pub x: Vec<[f64; MAX_INPUTS]>,
    /// Mean bias target of each block (rate − reference), °/h.
    pub y: Vec<f64>,
    /// Index of the run each block came from.
    pub run: Vec<usize>,
    /// Per-sample feature range over the samples used, (min, max) per feature.
    pub sample_range: Vec<(f64, f64)>,
    /// Seconds of usable samples behind the blocks.
    pub usable_s: f64,
    /// Start of each block since its segment (the run's start or its last
    /// gap) began, s: which blocks a slower filter's warm-up would have
    /// left out. Filled by [`BlockBuilder`]; empty for blocks made otherwise.
    pub segment_s: Vec<f32>,
    /// Start of each block on the run's clock, s (filled as `segment_s`).
    pub time_s: Vec<f64>,
    /// Samples behind each block's means (filled as `segment_s`).
    pub samples: Vec<u32>,
    /// How many times adjacent blocks were merged in pairs
    /// ([`Blocks::merge_pairs`]): the blocks are 2^`doublings` times the
    /// block length asked for ([`Blocks::length_s`]).
    pub doublings: u32,
}

impl Blocks {
    /// Number of blocks.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// True when there are no blocks.
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    /// Length of these blocks, s, when `block_s` was asked for: `block_s`
    /// unless they were merged ([`Blocks::doublings`]).
    pub fn length_s(&self, block_s: f64) -> f64 {
        block_s * f64::from(1u32 << self.doublings.min(31))
    }

    /// Merges adjacent blocks in pairs, in place: blocks `block_s` ×
    /// 2^`doublings` long become twice as long, on a grid that starts at
    /// each segment's start (block k of a segment joins block k ± 1 into
    /// block ⌊k/2⌋). Blocks of different runs or segments are never merged;
    /// a block whose partner was dropped (too few usable samples) or lies
    /// across a gap stays on its own. Features and targets are means
    /// weighted by the samples behind them, so a merged block holds the
    /// means of all its samples; `samples` adds up, and `time_s` and
    /// `segment_s` give the merged block's start on the grid. Blocks made
    /// without start times (`segment_s` empty) are merged by consecutive
    /// pairs within a run. The per-sample ranges and usable time do not change.
    pub fn merge_pairs(&mut self, block_s: f64) {
        let n = self.len();
        let length_s = self.length_s(block_s);
        let Blocks {
            x,
            y,
            run,
            segment_s,
            time_s,
            samples,
            ..
        } = self;
        let runs = std::mem::take(run);
        let mix = |kept: usize, i: usize, partner: Option<(usize, f64, f64)>| {
            let (mut xi, mut yi) = (x[i], y[i]);
            if let Some((j, a, b)) = partner {
                for (m, v) in xi.iter_mut().zip(&x[j]) {
                    *m = a * *m + b * v;
                }
                yi = a * yi + b * y[j];
            }
            x[kept] = xi;
            y[kept] = yi;
            run.push(runs[i]);
        };
        let kept = if segment_s.len() == n && time_s.len() == n && samples.len() == n {
            let same_run = |i: usize, j: usize| runs[i] == runs[j];
            merge_on_grid(&same_run, segment_s, time_s, samples, length_s, mix)
        } else {
            merge_consecutive(&runs, mix)
        };
        x.truncate(kept);
        y.truncate(kept);
        if segment_s.len() == n && time_s.len() == n && samples.len() == n {
            segment_s.truncate(kept);
            time_s.truncate(kept);
            samples.truncate(kept);
        }
        self.doublings += 1;
    }

    /// Feature `i` of block `row`.
    pub fn feature(&self, row: usize, i: usize) -> f64 {
        self.x[row][i]
    }

    /// Range (min, max) of block-mean feature `i`.
    pub fn block_range(&self, i: usize) -> (f64, f64) {
        self.x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
            (lo.min(r[i]), hi.max(r[i]))
        })
    }

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

    /// Appends `other`'s blocks (`block_s` asked for); whichever of the
    /// two holds shorter blocks is merged first ([`Blocks::merge_pairs`]),
    /// so that all blocks keep one length.
    fn append(&mut self, mut other: Blocks, block_s: f64) {
        if self.is_empty() {
            self.doublings = self.doublings.max(other.doublings);
        }
        while other.doublings < self.doublings {
            other.merge_pairs(block_s);
        }
        while self.doublings < other.doublings {
            self.merge_pairs(block_s);
        }
        if self.x.is_empty() && self.sample_range.is_empty() {
            self.sample_range = other.sample_range.clone();
        } else {
            for (a, b) in self.sample_range.iter_mut().zip(&other.sample_range) {
                *a = (a.0.min(b.0), a.1.max(b.1));
            }
        }
        self.dims = other.dims;
        self.x.extend(other.x);
        self.y.extend(other.y);
        self.run.extend(other.run);
        self.segment_s.extend(other.segment_s);
        self.time_s.extend(other.time_s);
        self.samples.extend(other.samples);
        self.usable_s += other.usable_s;
    }
}

/// One merge of [`Blocks::merge_pairs`] over `n = samples.len()` blocks
/// `length_s` long: which pairs merge, from the blocks' runs
/// (`same_run(i, j)`) and places on their segments' grids, their merged
/// starts and samples written in place, and `mix(kept, i, partner)` to
/// move block i's means to row `kept`, with `partner` = (j, weight of i,
/// weight of j) merged in. Returns the number of blocks kept.
fn merge_on_grid(
    same_run: &dyn Fn(usize, usize) -> bool,
    segment_s: &mut [f32],
    time_s: &mut [f64],
    samples: &mut [u32],
    length_s: f64,
    mut mix: impl FnMut(usize, usize, Option<(usize, f64, f64)>),
) -> usize {
    let n = samples.len();
    // Index of block i on the current grid, and its segment's start.
    let index = |segment_s: &[f32], i: usize| (f64::from(segment_s[i]) / length_s).round() as u64;
    let segment_start = |segment_s: &[f32], time_s: &[f64], i: usize| time_s[i] - f64::from(segment_s[i]);
    let mut kept = 0;
    let mut i = 0;
    while i < n {
        let j = i + 1;
        let (ki, start_i) = (index(segment_s, i), segment_start(segment_s, time_s, i));
        let pair = j < n
            && same_run(i, j)
            && index(segment_s, j) / 2 == ki / 2
            && index(segment_s, j) > ki
            && (segment_start(segment_s, time_s, j) - start_i).abs() < 0.5 * length_s;
        let (ni, nj) = (samples[i], if pair { samples[j] } else { 0 });
        let total = f64::from(ni + nj);
        mix(kept, i, pair.then(|| (j, f64::from(ni) / total, f64::from(nj) / total)));
        let cell_s = (ki / 2) as f64 * 2.0 * length_s;
        time_s[kept] = start_i + cell_s;
        segment_s[kept] = cell_s as f32;
        samples[kept] = ni + nj;
        kept += 1;
        i = if pair { j + 1 } else { j };
    }
    kept
}

/// [`merge_on_grid`] for blocks made without start times: consecutive
/// pairs of one run (`runs`), weighted alike.
fn merge_consecutive(runs: &[usize], mut mix: impl FnMut(usize, usize, Option<(usize, f64, f64)>)) -> usize {
    let mut kept = 0;
    let mut i = 0;
    while i < runs.len() {
        let pair = i + 1 < runs.len() && runs[i + 1] == runs[i];
        mix(kept, i, pair.then_some((i + 1, 0.5, 0.5)));
        kept += 1;
        i += if pair { 2 } else { 1 };
    }
    kept
}

/// The blocks of one configuration while a [`BlockBuilder`] reads a run:
/// the means stored `dims` to a block (a [`Blocks`] row has room for
/// [`MAX_INPUTS`]), so that the most blocks a run holds cost the least memory.
#[derive(Default)]
struct Store {
    dims: usize,
    x: Vec<f64>,
    y: Vec<f64>,
    segment_s: Vec<f32>,
    time_s: Vec<f64>,
    samples: Vec<u32>,
}

impl Store {
    fn len(&self) -> usize {
        self.y.len()
    }

    /// [`Blocks::merge_pairs`] of these blocks, `length_s` long.
    fn merge_pairs(&mut self, length_s: f64) {
        let dims = self.dims;
        let Store {
            x,
            y,
            segment_s,
            time_s,
            samples,
            ..
        } = self;
        let kept = merge_on_grid(
            &|_, _| true,
            segment_s,
            time_s,
            samples,
            length_s,
            |kept, i, partner| {
                for d in 0..dims {
                    x[kept * dims + d] = match partner {
                        Some((j, a, b)) => a * x[i * dims + d] + b * x[j * dims + d],
                        None => x[i * dims + d],
                    };
                }
                y[kept] = match partner {
                    Some((j, a, b)) => a * y[i] + b * y[j],
                    None => y[i],
                };
            },
        );
        x.truncate(kept * dims);
        y.truncate(kept);
        segment_s.truncate(kept);
        time_s.truncate(kept);
        samples.truncate(kept);
    }

    /// These blocks into `out` (run `run`), `target_offset_dph` subtracted from their targets.
    fn into_blocks(self, out: &mut Blocks, run: usize, target_offset_dph: f64) {
        out.x = self
            .x
            .chunks_exact(self.dims.max(1))
            .map(|means| {
                let mut row = [0.0; MAX_INPUTS];
                row[..means.len()].copy_from_slice(means);
                row
            })
            .collect();
        out.y = self.y.into_iter().map(|y| y - target_offset_dph).collect();
        out.run = vec![run; out.y.len()];
        out.segment_s = self.segment_s;
        out.time_s = self.time_s;
        out.samples = self.samples;
    }
}

/// Most configurations one [`BlockBuilder`] builds at once.
pub const MAX_GROUP: usize = 2;
/// Distinct inputs one builder accumulates: the union of its sets' inputs.
const MAX_SLOTS: usize = 2 * MAX_INPUTS;

/// Running sums of one block, and the range of its samples' inputs, per slot.
struct Accumulator {
    sum_x: [f64; MAX_SLOTS],
    sum_y: f64,
    count: usize,
    min_x: [f32; MAX_SLOTS],
    max_x: [f32; MAX_SLOTS],
}

impl Default for Accumulator {
    fn default() -> Self {
        Accumulator {
            sum_x: [0.0; MAX_SLOTS],
            sum_y: 0.0,
            count: 0,
            min_x: [f32::INFINITY; MAX_SLOTS],
            max_x: [f32::NEG_INFINITY; MAX_SLOTS],
        }
    }
}

/// Where one accumulator slot's value comes from: input `input` of the
/// vector of configuration `config` (0 = the computed one).
#[derive(Clone, Copy)]
struct Slot {
    config: usize,
    input: usize,
}

/// Builds the block means of one run sample by sample: the streaming core of
/// [`sample_block_means`] and [`RunFiles`]. One compensator computes the features of
/// the first configuration; configurations that share its filters
/// (`shares_filters`: the multi-scale sets at the same windows) take them
/// converted. An input two sets share (same name: the same computation) is
/// summed once, so a second multi-scale set costs only its own inputs.
pub struct BlockBuilder {
    configs: Vec<FeatureConfig>,
    /// The distinct inputs summed, in order of first appearance.
    slots: Vec<Slot>,
    /// Per configuration, the slot of each of its inputs.
    slot_of: Vec<Vec<usize>>,
    /// Configurations whose converted vector some slot reads (besides the first).
    converted: Vec<usize>,
    config: CompensatorConfig,
    block_index: BinIndex,
    /// The length of the blocks being built now, s (doubled by each merge).
    block_s: f64,
    /// Blocks held per configuration before they are merged in pairs.
    max_blocks: usize,
    nominal_period_s: f64,
    min_count: usize,
    compensator: Compensator,
    acc: Accumulator,
    /// Per configuration: its ranges, usable time and merges so far.
    outputs: Vec<Blocks>,
    /// Per configuration: its blocks so far.
    stores: Vec<Store>,
    segment_start_s: f64,
    current_block: Option<(u64, u64)>,
    started: bool,
    run_index: usize,
}

impl BlockBuilder {
    /// A builder for run number `run_index` of nominal period `nominal_period_s`,
    /// for `configs` (the first computed, the others sharing its filters).
    /// `None` when `configs` is empty, longer than [`MAX_GROUP`], or one does
    /// not share the first's filters.
    pub fn new(run_index: usize, configs: &[FeatureConfig], nominal_period_s: f64, block_s: f64) -> Option<Self> {
        let (first, siblings) = configs.split_first()?;
        if configs.len() > MAX_GROUP || !siblings.iter().all(|c| shares_filters(first, c)) {
            return None;
        }
        let mut slots: Vec<Slot> = Vec::new();
        let mut names = Vec::new();
        let slot_of = configs
            .iter()
            .enumerate()
            .map(|(config, c)| {
                (0..c.dims())
                    .map(|input| {
                        let name = c.set.name(input);
                        names.iter().position(|n| *n == name).unwrap_or_else(|| {
                            names.push(name);
                            slots.push(Slot { config, input });
                            slots.len() - 1
                        })
                    })
                    .collect::<Vec<_>>()
            })
            .collect();
        if slots.len() > MAX_SLOTS {
            return None;
        }
        let mut converted: Vec<usize> = slots.iter().map(|s| s.config).filter(|&c| c > 0).collect();
        converted.dedup();
        let outputs = configs
            .iter()
            .map(|c| Blocks {
                dims: c.dims(),
                sample_range: vec![(f64::INFINITY, f64::NEG_INFINITY); c.dims()],
                ..Blocks::default()
            })
            .collect();
        let stores = configs
            .iter()
            .map(|c| Store {
                dims: c.dims(),
                ..Store::default()
            })
            .collect();
        Some(BlockBuilder {
            configs: configs.to_vec(),
            slots,
            slot_of,
            converted,
            config: CompensatorConfig::for_nominal_period_s(nominal_period_s),
            block_index: BinIndex::new(block_s),
            block_s,
            max_blocks: usize::MAX,
            nominal_period_s,
            min_count: ((0.5 * block_s / nominal_period_s).floor() as usize).max(1),
            compensator: Compensator::new(),
            acc: Accumulator::default(),
            outputs,
            stores,
            segment_start_s: 0.0,
            current_block: None,
            started: false,
            run_index,
        })
    }

    /// This builder holding at most `max_blocks` blocks per configuration
    /// (at least 2): before a block would pass that, they are merged in
    /// pairs ([`Blocks::merge_pairs`]) and the run goes on in blocks twice
    /// as long; a run that was merged ends with at most `max_blocks / 2`.
    /// Unbounded unless set.
    pub fn with_max_blocks(mut self, max_blocks: usize) -> Self {
        self.max_blocks = max_blocks.max(2);
        if max_blocks <= MAX_BLOCKS_PER_RUN {
            // Room for the most blocks from the start: the store never
            // moves as it grows, and pages it never fills are never touched.
            for store in &mut self.stores {
                store.x.reserve_exact(max_blocks * store.dims);
                store.y.reserve_exact(max_blocks);
                store.segment_s.reserve_exact(max_blocks);
                store.time_s.reserve_exact(max_blocks);
                store.samples.reserve_exact(max_blocks);
            }
        }
        self
    }

    /// Merges the blocks held in pairs and makes the blocks to come twice as long.
    fn double_block_length(&mut self) {
        for (store, out) in self.stores.iter_mut().zip(&mut self.outputs) {
            store.merge_pairs(self.block_s);
            out.doublings += 1;
        }
        self.block_s *= 2.0;
        self.block_index = BinIndex::new(self.block_s);
        self.min_count = ((0.5 * self.block_s / self.nominal_period_s).floor() as usize).max(1);
    }

    fn flush(&mut self) {
        let acc = std::mem::take(&mut self.acc);
        // The block being closed: its segment's start and its index in it.
        let (segment_start_s, since_start_s) = self.current_block.map_or((0.0, 0.0), |(start, index)| {
            (f64::from_bits(start), index as f64 * self.block_s)
        });
        let keep = acc.count >= self.min_count;
        let n = acc.count as f64;
        for ((out, store), slot_of) in self.outputs.iter_mut().zip(&mut self.stores).zip(&self.slot_of) {
            // The range covers every usable sample, in blocks kept or not.
            for (r, &s) in out.sample_range.iter_mut().zip(slot_of) {
                *r = (r.0.min(acc.min_x[s] as f64), r.1.max(acc.max_x[s] as f64));
            }
            if keep {
                store.x.extend(slot_of.iter().map(|&s| acc.sum_x[s] / n));
                store.y.push(acc.sum_y / n);
                store.segment_s.push(since_start_s as f32);
                store.time_s.push(segment_start_s + since_start_s);
                store.samples.push(acc.count as u32);
            }
        }
    }

    /// Takes the next sample at `time_s` with bias target `target_dph` (rate − reference).
    pub fn push(&mut self, time_s: f64, sample: &GyroSample, target_dph: f64) {
        if !self.started || self.config.is_gap(sample.dt_s) {
            self.segment_start_s = time_s;
        }
        self.started = true;
        let mut block = (
            self.segment_start_s.to_bits(),
            self.block_index.of(time_s - self.segment_start_s),
        );
        if self.current_block != Some(block) {
            self.flush();
            let held = self.stores.first().map_or(0, Store::len);
            // Merged before the block to come would pass the limit, and when
            // it starts a merged one (its index is even, so that it does not
            // share a merged block's place on the grid); at the limit
            // whatever the index.
            if held + 1 >= self.max_blocks && (block.1.is_multiple_of(2) || held >= self.max_blocks) {
                self.double_block_length();
                block.1 = self.block_index.of(time_s - self.segment_start_s);
            }
            self.current_block = Some(block);
        }
        let Some(head) = self.configs.first() else {
            return;
        };
        let frame = self.compensator.features(head, &self.config, sample);
        let unusable = Flags::WARMING_UP | Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL;
        let Some(computed) = frame.features.filter(|_| frame.flags.0 & unusable.0 == 0) else {
            return;
        };
        let mut vectors = [computed; MAX_GROUP];
        for &c in &self.converted {
            match computed.to_multiscale_set(head.set, self.configs[c].set) {
                Some(v) => vectors[c] = v,
                None => return,
            }
        }
        let mut values = [0.0f32; MAX_SLOTS];
        for (v, slot) in values.iter_mut().zip(&self.slots) {
            *v = vectors[slot.config].as_slice()[slot.input];
        }
        let acc = &mut self.acc;
        for (s, &v) in values.iter().enumerate().take(self.slots.len()) {
            acc.sum_x[s] += v as f64;
            acc.min_x[s] = acc.min_x[s].min(v);
            acc.max_x[s] = acc.max_x[s].max(v);
        }
        acc.sum_y += target_dph;
        acc.count += 1;
        for out in &mut self.outputs {
            out.usable_s += self.nominal_period_s;
        }
    }

    /// The blocks of each configuration, in order; `target_offset_dph` is
    /// subtracted from every block's target (the run mean, for runs without
    /// `ref_dph`, known only at the end).
    pub fn finish(mut self, target_offset_dph: f64) -> Vec<Blocks> {
        self.flush();
        // A run that passed the limit ends with at most half of it: what the
        // fit holds after the pass is then no more than a run of half the
        // limit's length holds.
        let merged = self.outputs.first().is_some_and(|o| o.doublings > 0);
        while merged && self.stores.first().is_some_and(|s| s.len() > self.max_blocks / 2) {
            self.double_block_length();
        }
        for (out, store) in self.outputs.iter_mut().zip(self.stores.drain(..)) {
            store.into_blocks(out, self.run_index, target_offset_dph);
        }
        self.outputs
    }
}

/// True when `b`'s features are `a`'s converted ([`rbf_core::FeatureVector::to_multiscale_set`]):
/// the same configuration, or both multi-scale with the same ΔT windows (and
/// so the same warm-up).
fn shares_filters(a: &FeatureConfig, b: &FeatureConfig) -> bool {
    let windows = |c: &FeatureConfig| c.windows_s().map(f32::to_bits);
    a == b || (a.set.is_multiscale() && b.set.is_multiscale() && windows(a) == windows(b))
}

/// Input 3 of the multi-scale sets: ΔT₃, the slowest rate, °C/min.
const SLOWEST_RATE_INPUT: usize = 3;

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
fn plain_bank(bank: &LagBank) -> Option<LagBank> {
    LagBank::plain(bank.taus_s.get(..bank.filter_count())?, 0.0)
}

/// `blocks` of [`block_source`]`(features)` turned into `features`' blocks.
fn derive_blocks(blocks: Blocks, features: &FeatureConfig) -> Blocks {
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
fn slice_plain(have: &LagBank, blocks: &Blocks, want: &LagBank) -> Option<Blocks> {
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

/// Runs the trainer learns from: in memory ([`Run`]) or streamed from files
/// ([`RunFiles`]), seen through their block means.
pub trait RunSet {
    /// Number of runs.
    fn count(&self) -> usize;
    /// Block means of every run's features for `features`, concatenated; a
    /// lagged set's are derived from the second-order set's ([`block_source`]).
    fn block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        let blocks = self.filtered_block_means(&block_source(features), block_s)?;
        Ok(derive_blocks(blocks, features))
    }
    /// Computes the blocks of several configurations where one pass over the
    /// data serves them all; later [`RunSet::block_means`] calls use them.
    fn prepare(&self, configs: &[FeatureConfig], block_s: f64) -> anyhow::Result<()> {
        let mut sources: Vec<FeatureConfig> = Vec::with_capacity(configs.len());
        for source in configs.iter().map(block_source) {
            if !sources.contains(&source) {
                sources.push(source);
            }
        }
        self.prepare_filtered(&sources, block_s)
    }
    /// Block means of a configuration computed from the samples (its own
    /// [`block_source`]).
    fn filtered_block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks>;
    /// [`RunSet::prepare`] for configurations computed from the samples.
    fn prepare_filtered(&self, _configs: &[FeatureConfig], _block_s: f64) -> anyhow::Result<()> {
        Ok(())
    }
    /// Lets go of the blocks [`RunSet::prepare`] kept of `configs` (computed
    /// from the samples, as [`block_source`] gives them): a later
    /// [`RunSet::block_means`] of one reads the runs again.
    fn release(&self, _configs: &[FeatureConfig], _block_s: f64) {}
    /// The thermometer columns every run has (bit i = `temp_a` … `temp_h`).
    fn thermometer_mask(&self) -> anyhow::Result<u8>;
    /// Hands every sample of every run, in order, to `visit`: for fits whose
    /// sums do not fit in a feature vector (the response bank's filter
    /// channels). Targets are `rate − ref_dph` (the rate itself without a
    /// reference: such fits take an offset per run).
    fn for_each_sample(&self, visit: &mut dyn FnMut(&SampleVisit)) -> anyhow::Result<()>;
}

/// One sample as [`RunSet::for_each_sample`] gives it.
pub struct SampleVisit<'a> {
    /// Index of the run.
    pub run: usize,
    /// The run's nominal sample period, s.
    pub nominal_period_s: f64,
    /// Sample time, s.
    pub time_s: f64,
    /// The sample as the firmware sees it.
    pub sample: &'a GyroSample,
    /// Bias target, °/h: rate − reference.
    pub target_dph: f64,
}

/// [`RunSet::for_each_sample`] over runs in memory.
fn visit_runs(runs: &[Run], visit: &mut dyn FnMut(&SampleVisit)) {
    for (index, run) in runs.iter().enumerate() {
        let reference = run.reference_dph();
        for (i, sample) in run.samples().enumerate() {
            visit(&SampleVisit {
                run: index,
                nominal_period_s: run.nominal_period_s,
                time_s: run.time_s[i],
                sample: &sample,
                target_dph: run.rate_dph[i] - reference.at(i),
            });
        }
    }
}

/// The thermometers all of `runs` have.
fn common_thermometers(runs: &[Run]) -> u8 {
    runs.iter().fold(u8::MAX, |m, r| m & r.thermometer_mask)
}

impl RunSet for [Run] {
    fn count(&self) -> usize {
        self.len()
    }

    fn thermometer_mask(&self) -> anyhow::Result<u8> {
        Ok(common_thermometers(self))
    }

    fn filtered_block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        Ok(sample_block_means(self, features, block_s))
    }

    fn for_each_sample(&self, visit: &mut dyn FnMut(&SampleVisit)) -> anyhow::Result<()> {
        visit_runs(self, visit);
        Ok(())
    }
}

/// Arrays of runs (so that `&[]` reads as "no validation runs").
impl<const N: usize> RunSet for [Run; N] {
    fn count(&self) -> usize {
        N
    }

    fn thermometer_mask(&self) -> anyhow::Result<u8> {
        Ok(common_thermometers(self))
    }

    fn filtered_block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        Ok(sample_block_means(self, features, block_s))
    }

    fn for_each_sample(&self, visit: &mut dyn FnMut(&SampleVisit)) -> anyhow::Result<()> {
        visit_runs(self, visit);
        Ok(())
    }
}

/// Block means of the features and bias target of each run, concatenated,
/// every configuration computed sample by sample (a lagged set too; the
/// trainer derives those instead, [`RunSet::block_means`]).
pub fn sample_block_means(runs: &[Run], features: &FeatureConfig, block_s: f64) -> Blocks {
    let mut all = Blocks {
        dims: features.dims(),
        ..Blocks::default()
    };
    for (index, run) in runs.iter().enumerate() {
        let reference = run.reference_dph();
        let Some(mut builder) = BlockBuilder::new(index, &[*features], run.nominal_period_s, block_s) else {
            continue;
        };
        for (i, sample) in run.samples().enumerate() {
            builder.push(run.time_s[i], &sample, run.rate_dph[i] - reference.at(i));
        }
        builder.finish(0.0).into_iter().for_each(|b| all.append(b, block_s));
    }
    all
}

/// Run files read in streaming passes: only block means and running sums are
/// ever held, whatever the file's length. One pass computes the blocks of
/// every configuration [`RunSet::prepare`] asks for; the parsing runs on its
/// own thread, ahead of the feature computation.
pub struct RunFiles {
    paths: Vec<PathBuf>,
    /// The gyro axis read from multi-axis runs (`None`: single-axis runs).
    axis: Option<Axis>,
    /// Blocks held per run and configuration ([`BlockBuilder::with_max_blocks`]).
    max_blocks_per_run: usize,
    cache: Mutex<Vec<(CacheKey, Blocks)>>,
}

/// Blocks a streamed run keeps per configuration before merging them in
/// pairs ([`Blocks::merge_pairs`]): 32768 (9.1 h of 1-s blocks), so runs of
/// a working day keep every 1-s block and longer ones end with between
/// 8192 and 16384 blocks of 2, 4, 8 … s ([`BlockBuilder::with_max_blocks`]):
/// what a fit holds no longer grows with the run's length.
pub const MAX_BLOCKS_PER_RUN: usize = 32_768;

type CacheKey = (FeatureConfigKey, u64);
type FeatureConfigKey = (FeatureSet, [u32; 3]);

fn cache_key(features: &FeatureConfig, block_s: f64) -> CacheKey {
    let w = features.windows_s();
    let mut bits = [0u32; 3];
    for (b, v) in bits.iter_mut().zip(w.iter()) {
        *b = v.to_bits();
    }
    ((features.set, bits), block_s.to_bits())
}

impl RunFiles {
    /// Runs read from `paths` (nothing is read yet).
    pub fn new(paths: &[PathBuf]) -> Self {
        Self::for_axis(paths, None)
    }

    /// Runs read from `paths`, each as the single-axis run of `axis` (see
    /// [`RunReader::select_axis`]); `None` reads single-axis runs.
    pub fn for_axis(paths: &[PathBuf], axis: Option<Axis>) -> Self {
        RunFiles {
            paths: paths.to_vec(),
            axis,
            max_blocks_per_run: MAX_BLOCKS_PER_RUN,
            cache: Mutex::new(Vec::new()),
        }
    }

    /// These runs keeping at most `max_blocks` blocks per run and
    /// configuration (default [`MAX_BLOCKS_PER_RUN`]; `usize::MAX`: every
    /// block as asked, memory growing with the run).
    pub fn with_max_blocks_per_run(mut self, max_blocks: usize) -> Self {
        self.max_blocks_per_run = max_blocks;
        self
    }

    /// A reader of `path` on this set's axis.
    fn open(&self, path: &std::path::Path) -> Result<RunReader, crate::run::RunError> {
        let mut reader = RunReader::open(path)?;
        match self.axis {
            Some(axis) => reader.select_axis(axis)?,
            None => reader.require_single_axis()?,
        }
        Ok(reader)
    }

    /// The files.
    pub fn paths(&self) -> &[PathBuf] {
        &self.paths
    }

    /// The blocks of `features` from the cache: computed for it, or cut from
    /// a plain bank's that holds its filters ([`slice_plain`]).
    fn cached(&self, features: &FeatureConfig, block_s: f64) -> Option<Blocks> {
        let key = cache_key(features, block_s);
        let cache = self.cache.lock().ok()?;
        if let Some((_, b)) = cache.iter().find(|(k, _)| *k == key) {
            return Some(b.clone());
        }
        let FeatureSet::LagBank(want) = features.set else {
            return None;
        };
        cache.iter().find_map(|(((set, _), block), b)| match set {
            FeatureSet::LagBank(have) if *block == key.1 => slice_plain(have, b, &want),
            _ => None,
        })
    }

    fn is_cached(&self, features: &FeatureConfig, block_s: f64) -> bool {
        self.cached(features, block_s).is_some()
    }

    /// One pass over run `index`: blocks for each of `configs`.
    fn pass(&self, index: usize, configs: &[FeatureConfig], block_s: f64) -> anyhow::Result<Vec<Blocks>> {
        let path = &self.paths[index];
        let mask = configs.iter().fold(0, |m, c| m | c.set.thermometer_mask());
        let run = StreamedRun::from_reader(self.open(path)?, mask)?;
        let (period_s, has_ref) = (run.nominal_period_s, run.has_ref);
        // Configurations sharing filters go to one builder.
        let groups = filter_groups(configs);
        let mut builders = groups
            .iter()
            .map(|members| {
                let group: Vec<FeatureConfig> = members.iter().map(|&i| configs[i]).collect();
                BlockBuilder::new(index, &group, period_s, block_s)
                    .map(|b| b.with_max_blocks(self.max_blocks_per_run))
                    .ok_or_else(|| anyhow::anyhow!("feature configurations grouped wrongly"))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        // The first builder runs here with the run's sums; every other on a
        // thread of its own, fed the same batches (each builder's features
        // are sequential, but the builders are independent).
        let mut rest = builders.split_off(1.min(builders.len()));
        let mut rate_sum = 0.0f64;
        let rows = std::thread::scope(|scope| -> anyhow::Result<usize> {
            let mut feeds = Vec::new();
            let mut workers = Vec::new();
            for builder in &mut rest {
                // One batch waiting at most: a batch is parsed again only
                // after the reader consumed it, but the other builders may
                // still hold it, and a backlog of them here would be memory
                // that grows the longer the run lets a slower builder lag.
                let (tx, rx) = std::sync::mpsc::sync_channel::<Arc<Batch>>(1);
                feeds.push(tx);
                workers.push(scope.spawn(move || {
                    for batch in rx {
                        feed(builder, &batch);
                    }
                }));
            }
            let rows = run.for_each_batch(|batch| {
                let batch = Arc::new(batch);
                for tx in &feeds {
                    // A worker stops only by panicking, reported at its join.
                    let _ = tx.send(Arc::clone(&batch));
                }
                for i in 0..batch.len() {
                    rate_sum += batch.rate_dph(i);
                }
                if let Some(first) = builders.first_mut() {
                    feed(first, &batch);
                }
            });
            drop(feeds);
            for worker in workers {
                worker
                    .join()
                    .map_err(|_| anyhow::anyhow!("a block-means thread panicked"))?;
            }
            rows
        })?;
        builders.append(&mut rest);
        if rows < 2 {
            anyhow::bail!("{}: run has {rows} data rows; at least 2 are needed", path.display());
        }
        let offset = if has_ref { 0.0 } else { rate_sum / rows as f64 };
        let mut out: Vec<Option<Blocks>> = configs.iter().map(|_| None).collect();
        for (members, builder) in groups.into_iter().zip(builders) {
            for (i, blocks) in members.into_iter().zip(builder.finish(offset)) {
                out[i] = Some(blocks);
            }
        }
        out.into_iter()
            .map(|b| b.ok_or_else(|| anyhow::anyhow!("a feature configuration was not built")))
            .collect()
    }
}

/// Pushes the rows of `batch` into `builder`.
fn feed(builder: &mut BlockBuilder, batch: &Batch) {
    for i in 0..batch.len() {
        let target = batch.rate_dph(i) - batch.ref_dph(i).unwrap_or(0.0);
        builder.push(batch.time_s(i), &batch.sample(i), target);
    }
}

/// `configs` (indices) grouped so that each group shares the filters of its first.
fn filter_groups(configs: &[FeatureConfig]) -> Vec<Vec<usize>> {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (i, c) in configs.iter().enumerate() {
        match groups
            .iter_mut()
            .find(|g| g.len() < MAX_GROUP && shares_filters(&configs[g[0]], c))
        {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    groups
}

impl RunSet for RunFiles {
    fn count(&self) -> usize {
        self.paths.len()
    }

    fn thermometer_mask(&self) -> anyhow::Result<u8> {
        self.paths
            .iter()
            .try_fold(u8::MAX, |m, path| Ok(m & self.open(path)?.columns().thermometer_mask()))
    }

    fn filtered_block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        if let Some(b) = self.cached(features, block_s) {
            return Ok(b);
        }
        self.prepare_filtered(std::slice::from_ref(features), block_s)?;
        self.cached(features, block_s)
            .ok_or_else(|| anyhow::anyhow!("block means were not cached"))
    }

    fn for_each_sample(&self, visit: &mut dyn FnMut(&SampleVisit)) -> anyhow::Result<()> {
        for (index, path) in self.paths.iter().enumerate() {
            let run = StreamedRun::from_reader(self.open(path)?, 0)?;
            let period_s = run.nominal_period_s;
            let rows = run.for_each_batch(|batch| {
                for i in 0..batch.len() {
                    visit(&SampleVisit {
                        run: index,
                        nominal_period_s: period_s,
                        time_s: batch.time_s(i),
                        sample: &batch.sample(i),
                        target_dph: batch.rate_dph(i) - batch.ref_dph(i).unwrap_or(0.0),
                    });
                }
            })?;
            anyhow::ensure!(
                rows >= 2,
                "{}: run has {rows} data rows; at least 2 are needed",
                path.display()
            );
        }
        Ok(())
    }

    fn release(&self, configs: &[FeatureConfig], block_s: f64) {
        if let Ok(mut cache) = self.cache.lock() {
            let keys: Vec<CacheKey> = configs.iter().map(|c| cache_key(c, block_s)).collect();
            cache.retain(|(k, _)| !keys.contains(k));
        }
    }

    fn prepare_filtered(&self, configs: &[FeatureConfig], block_s: f64) -> anyhow::Result<()> {
        let wanted: Vec<FeatureConfig> = configs
            .iter()
            .filter(|c| !self.is_cached(c, block_s))
            .copied()
            .collect();
        if wanted.is_empty() {
            return Ok(());
        }
        let mut merged: Vec<Blocks> = wanted
            .iter()
            .map(|c| Blocks {
                dims: c.dims(),
                ..Blocks::default()
            })
            .collect();
        for index in 0..self.paths.len() {
            for (all, blocks) in merged.iter_mut().zip(self.pass(index, &wanted, block_s)?) {
                all.append(blocks, block_s);
            }
        }
        let mut cache = self.cache.lock().map_err(|_| anyhow::anyhow!("block cache poisoned"))?;
        for (c, b) in wanted.iter().zip(merged) {
            cache.push((cache_key(c, block_s), b));
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "one pass must give exactly what separate passes give; exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::simulate::ChamberRun;

    fn multiscale(set: FeatureSet, window_s: f32) -> FeatureConfig {
        FeatureConfig::multiscale(set, [window_s, 16.0 * window_s, 256.0 * window_s])
    }

    /// A 3-h simulated IFOG run at 10 Hz and `ramp_c_per_min`, written into `dir`.
    fn simulated_run(dir: &tempfile::TempDir, ramp_c_per_min: f64, seed: u64) -> PathBuf {
        let path = dir.path().join("run.csv");
        let mut sim = ChamberRun::ifog(ramp_c_per_min, seed);
        sim.duration_s = Some(3.0 * 3600.0);
        sim.sample_rate_hz = 10.0;
        sim.write_csv(&mut std::fs::File::create(&path).unwrap()).unwrap();
        path
    }

    #[test]
    fn one_pass_over_both_multiscale_sets_gives_each_set_s_own_blocks_bit_for_bit() {
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 2.0, 5);
        let configs = [
            multiscale(FeatureSet::MultiScale, 15.0),
            multiscale(FeatureSet::MultiScaleSecondOrder, 15.0),
            FeatureConfig::single(FeatureSet::TempRateProduct, 60.0),
            multiscale(FeatureSet::MultiScaleSecondOrder, 60.0),
            multiscale(FeatureSet::MultiScale, 60.0),
        ];
        let streamed = RunFiles::new(std::slice::from_ref(&path));
        streamed.prepare(&configs, 1.0).unwrap();
        let run = Run::load(&path).unwrap();
        for config in &configs {
            // The in-memory path builds each configuration alone.
            let alone = sample_block_means(std::slice::from_ref(&run), config, 1.0);
            let shared = streamed.block_means(config, 1.0).unwrap();
            assert!(alone.len() > 10_000, "{config:?}: {} blocks", alone.len());
            assert_eq!(shared.dims, alone.dims, "{config:?}");
            assert_eq!(shared.x, alone.x, "{config:?}");
            assert_eq!(shared.y, alone.y, "{config:?}");
            assert_eq!(shared.run, alone.run, "{config:?}");
            assert_eq!(shared.sample_range, alone.sample_range, "{config:?}");
            assert_eq!(shared.usable_s, alone.usable_s, "{config:?}");
        }
    }

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

    #[test]
    fn a_stretch_of_a_cached_ladder_gives_the_blocks_of_its_own_pass() {
        // The bank search's ladders are built in one pass; a chosen stretch of
        // one (a slower first filter: a longer warm-up) is cut from it.
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 2.0, 9);
        let ladder = FeatureConfig::lag_bank(LagBank::plain(&[15.0, 60.0, 240.0, 960.0, 3840.0], 0.0).unwrap());
        let streamed = RunFiles::new(std::slice::from_ref(&path));
        streamed.prepare(&[ladder], 1.0).unwrap();
        let run = Run::load(&path).unwrap();
        for taus in [
            &[60.0, 240.0, 960.0][..],
            &[15.0, 60.0][..],
            &[240.0, 960.0, 3840.0][..],
        ] {
            let stretch = FeatureConfig::lag_bank(LagBank::plain(taus, 0.0).unwrap());
            assert!(streamed.is_cached(&stretch, 1.0), "{taus:?}: cut, not read again");
            let cut = streamed.block_means(&stretch, 1.0).unwrap();
            let own = sample_block_means(std::slice::from_ref(&run), &stretch, 1.0);
            assert_eq!(cut.len(), own.len(), "{taus:?}");
            // Bit for bit, but for the block where the warm-up ends: the
            // compensator sums its f32 time steps, and one sample may fall
            // either side of the end.
            let warmup_s = stretch.warmup_s();
            for i in (0..own.len()).filter(|&i| (own.segment_s[i] - warmup_s).abs() >= 1.0) {
                assert!(
                    cut.x[i] == own.x[i] && cut.y[i] == own.y[i],
                    "{taus:?}: block {i} differs"
                );
            }
            assert_eq!(cut.sample_range[1..], own.sample_range[1..], "{taus:?}");
        }
        let elsewhere = FeatureConfig::lag_bank(LagBank::plain(&[60.0, 960.0], 0.0).unwrap());
        assert!(!streamed.is_cached(&elsewhere, 1.0), "not a stretch: filters apart");
    }

    #[test]
    fn only_configurations_that_share_filters_are_built_together() {
        let configs = [
            multiscale(FeatureSet::MultiScale, 15.0),
            multiscale(FeatureSet::MultiScale, 60.0),
            multiscale(FeatureSet::MultiScaleSecondOrder, 15.0),
            FeatureConfig::single(FeatureSet::TempRateProduct, 15.0),
            multiscale(FeatureSet::MultiScaleSecondOrder, 60.0),
        ];
        assert_eq!(filter_groups(&configs), vec![vec![0, 2], vec![1, 4], vec![3]]);
        let repeats = [multiscale(FeatureSet::MultiScale, 15.0); MAX_GROUP + 1];
        assert_eq!(filter_groups(&repeats), vec![(0..MAX_GROUP).collect(), vec![MAX_GROUP]]);
        assert!(
            BlockBuilder::new(0, &configs[..2], 1.0, 1.0).is_none(),
            "different windows"
        );
        assert!(BlockBuilder::new(0, &configs[2..4], 1.0, 1.0).is_none(), "paper set");
        assert!(BlockBuilder::new(0, &[], 1.0, 1.0).is_none());
        let pair = BlockBuilder::new(0, &[configs[0], configs[2]], 1.0, 1.0).unwrap();
        // Seven of the second-order set's eight inputs are the first-order set's.
        assert_eq!(pair.slots.len(), 9);
    }

    #[test]
    fn the_default_fit_streamed_in_chunks_writes_the_blob_of_the_fit_on_runs_read_line_by_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 1.0, 11);
        let opts = crate::fit::FitOptions {
            progress: false,
            ..crate::fit::FitOptions::default()
        };
        let streamed = RunFiles::new(std::slice::from_ref(&path));
        let none = RunFiles::new(&[]);
        let from_files = crate::fit::fit(&streamed, &none, &opts).unwrap();
        let runs = [Run::load(&path).unwrap()];
        let no_runs: [Run; 0] = [];
        let in_memory = crate::fit::fit(&runs[..], &no_runs[..], &opts).unwrap();
        assert!(from_files.bank.is_some(), "the default is the lag bank");
        assert_eq!(
            crate::blobfile::encode_model(&from_files.model).unwrap(),
            crate::blobfile::encode_model(&in_memory.model).unwrap()
        );
    }
    /// Blocks of run `run` starting `segment_start_s` on the run's clock, at
    /// grid indices `indices` (1-s blocks), with `samples` each; feature 0
    /// and the target are `value(index)`.
    fn push_segment(b: &mut Blocks, run: usize, segment_start_s: f64, indices: &[(u64, u32)]) {
        for &(k, n) in indices {
            let value = 10.0 * run as f64 + segment_start_s + k as f64 + f64::from(n) / 1000.0;
            let mut x = [0.0; MAX_INPUTS];
            x[0] = value;
            x[1] = -value;
            b.x.push(x);
            b.y.push(2.0 * value);
            b.run.push(run);
            b.segment_s.push(k as f32);
            b.time_s.push(segment_start_s + k as f64);
            b.samples.push(n);
        }
    }

    #[test]
    fn merged_pairs_are_sample_weighted_means_within_a_segment_and_a_run() {
        let mut b = Blocks {
            dims: 2,
            sample_range: vec![(0.0, 1.0); 2],
            usable_s: 12.0,
            ..Blocks::default()
        };
        // Run 0: block 3 dropped; a gap at 6.5 s starts a segment whose
        // block 0 was dropped (its block 1 shares a grid cell with the first
        // segment's block 0 by index, not by time); run 1 starts at 0 again.
        push_segment(&mut b, 0, 0.0, &[(0, 100), (1, 60), (2, 100), (4, 80), (5, 100)]);
        push_segment(&mut b, 0, 6.5, &[(1, 100), (2, 100)]);
        push_segment(&mut b, 1, 0.0, &[(1, 100), (2, 100), (3, 90)]);
        let before = b.clone();
        b.merge_pairs(1.0);
        assert_eq!((b.doublings, b.length_s(1.0), b.length_s(0.5)), (1, 2.0, 1.0));
        // (first, second) blocks of `before` behind each merged block.
        let expected: [(usize, Option<usize>); 7] = [
            (0, Some(1)),
            (2, None),
            (3, Some(4)),
            (5, None),
            (6, None),
            (7, None),
            (8, Some(9)),
        ];
        assert_eq!(b.len(), expected.len());
        for (m, &(i, j)) in expected.iter().enumerate() {
            let (ni, nj) = (before.samples[i], j.map_or(0, |j| before.samples[j]));
            let mean = |v: &dyn Fn(usize) -> f64| {
                (f64::from(ni) * v(i) + j.map_or(0.0, |j| f64::from(nj) * v(j))) / f64::from(ni + nj)
            };
            let x0 = mean(&|k| before.x[k][0]);
            assert!((b.x[m][0] - x0).abs() < 1e-12, "block {m}: {} against {x0}", b.x[m][0]);
            assert!((b.x[m][1] + x0).abs() < 1e-12, "block {m}");
            assert!((b.y[m] - mean(&|k| before.y[k])).abs() < 1e-12, "block {m}");
            assert_eq!(b.samples[m], ni + nj, "block {m}");
            assert_eq!(b.run[m], before.run[i], "block {m}");
            // The merged block starts on the 2-s grid of its own segment.
            let grid_s = (before.segment_s[i] / 2.0).floor() * 2.0;
            assert_eq!(b.segment_s[m], grid_s, "block {m}");
            let segment_start_s = before.time_s[i] - f64::from(before.segment_s[i]);
            assert_eq!(b.time_s[m], segment_start_s + f64::from(grid_s), "block {m}");
        }
        assert_eq!((b.usable_s, &b.sample_range), (before.usable_s, &before.sample_range));
        // A second merge: 4-s cells, still never across a run or a gap.
        b.merge_pairs(1.0);
        assert_eq!(b.segment_s, [0.0, 4.0, 0.0, 0.0]);
        assert_eq!(b.run, [0, 0, 0, 1]);
        assert_eq!(b.samples, [260, 180, 200, 290]);
        assert_eq!(b.length_s(1.0), 4.0);
    }

    #[test]
    fn appending_merges_the_shorter_blocks_to_the_longer_ones_length() {
        let mut long = Blocks::default();
        push_segment(&mut long, 0, 0.0, &[(0, 10), (1, 10), (2, 10), (3, 10)]);
        long.merge_pairs(1.0);
        let mut short = Blocks::default();
        push_segment(&mut short, 1, 0.0, &[(0, 10), (1, 10), (2, 10), (3, 10)]);
        let mut all = Blocks::default();
        all.append(short.clone(), 1.0);
        all.append(long, 1.0);
        assert_eq!((all.doublings, all.len()), (1, 4));
        assert_eq!(all.samples, [20, 20, 20, 20]);
        assert_eq!(all.run, [1, 1, 0, 0]);
    }

    #[test]
    fn a_streamed_run_past_the_block_limit_keeps_it_and_the_means_of_all_its_samples() {
        let dir = tempfile::tempdir().unwrap();
        let path = simulated_run(&dir, 2.0, 13);
        let bank = FeatureConfig::lag_bank(LagBank::plain(LADDER_S, 0.0).unwrap());
        let every = RunFiles::new(std::slice::from_ref(&path)).with_max_blocks_per_run(usize::MAX);
        let every = every.block_means(&bank, 1.0).unwrap();
        assert!(every.len() > 10_000, "{} blocks", every.len());
        let limit = 2000;
        let bounded = RunFiles::new(std::slice::from_ref(&path)).with_max_blocks_per_run(limit);
        let bounded = bounded.block_means(&bank, 1.0).unwrap();
        // 3 h of 1-s blocks: merged three times while read (1350 8-s blocks),
        // once more at the end (at most half the limit), to 16-s blocks.
        assert_eq!(bounded.doublings, 4);
        assert!(
            bounded.len() <= limit / 2 && bounded.len() > limit / 4,
            "{} blocks",
            bounded.len()
        );
        assert_eq!(bounded.length_s(1.0), 16.0);
        assert_eq!(
            (bounded.usable_s, &bounded.sample_range),
            (every.usable_s, &every.sample_range)
        );
        // Each 16-s block against the 1-s blocks in its cell: the same
        // samples (but where a cell's edge block has under half its samples)
        // and then the same means.
        let mut same = 0;
        for m in 0..bounded.len() {
            let start = bounded.time_s[m];
            let cell: Vec<usize> = (0..every.len())
                .filter(|&i| every.time_s[i] >= start - 1e-6 && every.time_s[i] < start + 16.0 - 1e-6)
                .collect();
            let n: u32 = cell.iter().map(|&i| every.samples[i]).sum();
            assert!(
                n.abs_diff(bounded.samples[m]) < 10,
                "block {m}: {n} against {}",
                bounded.samples[m]
            );
            if n != bounded.samples[m] {
                continue;
            }
            same += 1;
            let weighted = |v: &dyn Fn(usize) -> f64| {
                cell.iter().map(|&i| f64::from(every.samples[i]) * v(i)).sum::<f64>() / f64::from(n)
            };
            for k in 0..bank.dims() {
                let want = weighted(&|i| every.x[i][k]);
                let tolerance = 1e-9 * (1.0 + want.abs());
                assert!((bounded.x[m][k] - want).abs() < tolerance, "block {m} input {k}");
            }
            assert!((bounded.y[m] - weighted(&|i| every.y[i])).abs() < 1e-9, "block {m}");
        }
        assert!(same * 100 >= 98 * bounded.len(), "{same} of {} blocks", bounded.len());
    }

    /// The ladder the merge tests read.
    const LADDER_S: &[f32] = &[15.0, 60.0, 240.0, 960.0];

    #[test]
    fn the_default_fit_on_merged_blocks_predicts_as_the_fit_on_every_block() {
        // A 3-h run held in 1350 8-s blocks (as a 20-h run ends at the
        // default limit) against all its 10800 1-s blocks: the compensated cluster
        // STD, scored on every sample of the training run and of a run with
        // another ramp rate, within 5 % of each other.
        let dir = tempfile::tempdir().unwrap();
        let train = simulated_run(&dir, 1.0, 17);
        let held_dir = tempfile::tempdir().unwrap();
        let held = simulated_run(&held_dir, 2.5, 19);
        let opts = crate::fit::FitOptions {
            progress: false,
            ..crate::fit::FitOptions::default()
        };
        let none = RunFiles::new(&[]);
        let fit = |max_blocks| {
            let runs = RunFiles::new(std::slice::from_ref(&train)).with_max_blocks_per_run(max_blocks);
            let model = crate::fit::fit(&runs, &none, &opts).unwrap().model;
            let bank = FeatureConfig::lag_bank(
                plain_bank(match &model.features().set {
                    FeatureSet::LagBank(bank) => bank,
                    set => panic!("{set:?}: the default is the lag bank"),
                })
                .unwrap(),
            );
            let doublings = runs.block_means(&bank, opts.block_s).unwrap().doublings;
            (model, doublings)
        };
        let (every, d_every) = fit(usize::MAX);
        let (merged, d_merged) = fit(4096);
        assert_eq!((d_every, d_merged), (0, 3));
        for path in [&train, &held] {
            let score = |m: &rbf_core::Model| crate::evaluate::evaluate_file(m, path, None).unwrap();
            let (a, b) = (score(&every), score(&merged));
            let (std_every, std_merged) = (a.cluster_std_after_dph, b.cluster_std_after_dph);
            assert!(
                std_merged <= 1.05 * std_every && std_every <= 1.05 * std_merged,
                "{}: cluster STD {std_merged} °/h merged against {std_every} °/h (raw {})",
                path.display(),
                a.cluster_std_before_dph
            );
            assert!(b.cluster_std_improvement_pct > 0.5 * a.cluster_std_improvement_pct);
        }
    }
}
