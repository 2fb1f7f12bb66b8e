//! [`BlockBuilder`]: the block means of one run, computed sample by sample
//! with the firmware's feature code, for one configuration or a group of
//! them that shares its filters ([`MAX_GROUP`]).

use rbf_core::{Compensator, CompensatorConfig, FeatureConfig, Flags, GyroSample, MAX_INPUTS};

use super::blocks::{Blocks, merge_on_grid};
use crate::metrics::BinIndex;

/// Blocks a streamed run keeps per configuration before merging them in
/// pairs ([`Blocks::merge_pairs`]): 32768 (9.1 h of 1-s blocks), so runs of
/// a working day keep every 1-s block and longer ones end with between
/// 8192 and 16384 blocks of 2, 4, 8 … s ([`BlockBuilder::with_max_blocks`]):
/// what a fit holds no longer grows with the run's length.
pub const MAX_BLOCKS_PER_RUN: usize = 32_768;

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

impl Accumulator {
    /// Adds one sample's slot values (slot 0 first).
    fn add(&mut self, values: &[f32]) {
        for (((&v, sum), min), max) in values
            .iter()
            .zip(&mut self.sum_x)
            .zip(&mut self.min_x)
            .zip(&mut self.max_x)
        {
            *sum += v as f64;
            // Comparisons rather than f32::min/max: the same result on the finite values
            // (and a NaN is skipped either way), without the NaN handling in the loop.
            if v < *min {
                *min = v;
            }
            if v > *max {
                *max = v;
            }
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
/// [`sample_block_means`](super::sample_block_means) and
/// [`RunFiles`](super::RunFiles). One compensator computes the features of
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
    /// The slots are the computed vector's inputs, in order (a builder of one
    /// configuration, as the lag bank's ladders): summed without the copy into slots.
    direct: bool,
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
        let direct = slots.iter().enumerate().all(|(i, s)| s.config == 0 && s.input == i);
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
            direct,
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
        // By reference: a copy of the returned vector reads, in wide loads, what the
        // compensator has just written field by field, and stalls on it.
        let Some(computed) = frame.features.as_ref().filter(|_| frame.flags.0 & unusable.0 == 0) else {
            return;
        };
        if self.direct {
            self.acc.add(computed.as_slice());
        } else {
            let mut vectors = [*computed; MAX_GROUP];
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
            self.acc.add(values.get(..self.slots.len()).unwrap_or(&[]));
        }
        let acc = &mut self.acc;
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

/// `configs` (indices) grouped so that each group shares the filters of its first.
pub(super) fn filter_groups(configs: &[FeatureConfig]) -> Vec<Vec<usize>> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::test_support::multiscale;
    use rbf_core::FeatureSet;

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
}
