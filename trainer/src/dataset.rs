//! Training data: rbf-core features per sample, averaged over blocks.
//!
//! Features are computed per sample by [`rbf_core::Compensator::features`], the
//! very function the firmware runs, then averaged with the bias target over
//! blocks (1 s by default) inside each segment. Samples whose features are
//! still warming up or whose temperature is a held value are left out of the
//! averages; blocks with under half their nominal samples are dropped.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use rbf_core::record::Axis;
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

    fn append(&mut self, other: Blocks) {
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
        self.usable_s += other.usable_s;
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
    nominal_period_s: f64,
    min_count: usize,
    compensator: Compensator,
    acc: Accumulator,
    outputs: Vec<Blocks>,
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
        Some(BlockBuilder {
            configs: configs.to_vec(),
            slots,
            slot_of,
            converted,
            config: CompensatorConfig::for_nominal_period_s(nominal_period_s),
            block_index: BinIndex::new(block_s),
            nominal_period_s,
            min_count: ((0.5 * block_s / nominal_period_s).floor() as usize).max(1),
            compensator: Compensator::new(),
            acc: Accumulator::default(),
            outputs,
            segment_start_s: 0.0,
            current_block: None,
            started: false,
            run_index,
        })
    }

    fn flush(&mut self) {
        let acc = std::mem::take(&mut self.acc);
        let keep = acc.count >= self.min_count;
        let n = acc.count as f64;
        for (out, slot_of) in self.outputs.iter_mut().zip(&self.slot_of) {
            // The range covers every usable sample, in blocks kept or not.
            for (r, &s) in out.sample_range.iter_mut().zip(slot_of) {
                *r = (r.0.min(acc.min_x[s] as f64), r.1.max(acc.max_x[s] as f64));
            }
            if keep {
                let mut mean = [0.0; MAX_INPUTS];
                for (m, &s) in mean.iter_mut().zip(slot_of) {
                    *m = acc.sum_x[s] / n;
                }
                out.x.push(mean);
                out.y.push(acc.sum_y / n);
                out.run.push(self.run_index);
            }
        }
    }

    /// Takes the next sample at `time_s` with bias target `target_dph` (rate − reference).
    pub fn push(&mut self, time_s: f64, sample: &GyroSample, target_dph: f64) {
        if !self.started || self.config.is_gap(sample.dt_s) {
            self.segment_start_s = time_s;
        }
        self.started = true;
        let block = (
            self.segment_start_s.to_bits(),
            self.block_index.of(time_s - self.segment_start_s),
        );
        if self.current_block != Some(block) {
            self.flush();
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
        for out in &mut self.outputs {
            for y in &mut out.y {
                *y -= target_offset_dph;
            }
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
/// ([`Blocks::with_coil_lag`]), else `features` itself.
pub fn block_source(features: &FeatureConfig) -> FeatureConfig {
    match features.set {
        FeatureSet::MultiScaleLagged { .. } => FeatureConfig {
            set: FeatureSet::MultiScaleSecondOrder,
            ..*features
        },
        _ => *features,
    }
}

/// `blocks` of [`block_source`]`(features)` turned into `features`' blocks.
fn derive_blocks(blocks: Blocks, features: &FeatureConfig) -> Blocks {
    match features.set {
        FeatureSet::MultiScaleLagged { coil_lag_min } => blocks.with_coil_lag(coil_lag_min),
        _ => blocks,
    }
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
    /// The thermometer columns every run has (bit i = `temp_a` … `temp_h`).
    fn thermometer_mask(&self) -> anyhow::Result<u8>;
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
        builder.finish(0.0).into_iter().for_each(|b| all.append(b));
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
    cache: Mutex<Vec<(CacheKey, Blocks)>>,
}

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
            cache: Mutex::new(Vec::new()),
        }
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

    fn cached(&self, key: &CacheKey) -> Option<Blocks> {
        let cache = self.cache.lock().ok()?;
        cache.iter().find(|(k, _)| k == key).map(|(_, b)| b.clone())
    }

    fn is_cached(&self, key: &CacheKey) -> bool {
        self.cache.lock().is_ok_and(|cache| cache.iter().any(|(k, _)| k == key))
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
                let (tx, rx) = std::sync::mpsc::sync_channel::<Arc<Batch>>(4);
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
        let key = cache_key(features, block_s);
        if let Some(b) = self.cached(&key) {
            return Ok(b);
        }
        self.prepare_filtered(std::slice::from_ref(features), block_s)?;
        self.cached(&key)
            .ok_or_else(|| anyhow::anyhow!("block means were not cached"))
    }

    fn prepare_filtered(&self, configs: &[FeatureConfig], block_s: f64) -> anyhow::Result<()> {
        let wanted: Vec<FeatureConfig> = configs
            .iter()
            .filter(|c| !self.is_cached(&cache_key(c, block_s)))
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
                all.append(blocks);
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
}
