//! Training data: rbf-core features per sample, averaged over blocks.
//!
//! Features are computed per sample by [`rbf_core::Compensator::features`], the
//! very function the firmware runs, then averaged with the bias target over
//! blocks (1 s by default) inside each segment. Samples whose features are
//! still warming up or whose temperature is a held value are left out of the
//! averages; blocks with under half their nominal samples are dropped.

use std::path::PathBuf;
use std::sync::Mutex;

use rbf_core::{Compensator, CompensatorConfig, FeatureConfig, FeatureSet, Flags, GyroSample, MAX_INPUTS};

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

#[derive(Default)]
struct Accumulator {
    sum_x: [f64; MAX_INPUTS],
    sum_y: f64,
    count: usize,
}

/// Builds the block means of one run sample by sample, for one feature
/// configuration: the streaming core of [`block_means`] and [`RunFiles`].
pub struct BlockBuilder {
    features: FeatureConfig,
    config: CompensatorConfig,
    block_index: BinIndex,
    nominal_period_s: f64,
    min_count: usize,
    compensator: Compensator,
    acc: Accumulator,
    segment_start_s: f64,
    current_block: Option<(u64, u64)>,
    started: bool,
    out: Blocks,
    run_index: usize,
}

impl BlockBuilder {
    /// A builder for run number `run_index` of nominal period `nominal_period_s`.
    pub fn new(run_index: usize, features: FeatureConfig, nominal_period_s: f64, block_s: f64) -> Self {
        let dims = features.dims();
        BlockBuilder {
            features,
            config: CompensatorConfig::for_nominal_period_s(nominal_period_s),
            block_index: BinIndex::new(block_s),
            nominal_period_s,
            min_count: ((0.5 * block_s / nominal_period_s).floor() as usize).max(1),
            compensator: Compensator::new(),
            acc: Accumulator::default(),
            segment_start_s: 0.0,
            current_block: None,
            started: false,
            out: Blocks {
                dims,
                sample_range: vec![(f64::INFINITY, f64::NEG_INFINITY); dims],
                ..Blocks::default()
            },
            run_index,
        }
    }

    fn flush(&mut self) {
        let acc = std::mem::take(&mut self.acc);
        if acc.count >= self.min_count {
            let n = acc.count as f64;
            let mut mean = [0.0; MAX_INPUTS];
            for (m, s) in mean.iter_mut().zip(&acc.sum_x) {
                *m = s / n;
            }
            self.out.x.push(mean);
            self.out.y.push(acc.sum_y / n);
            self.out.run.push(self.run_index);
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
        let frame = self.compensator.features(&self.features, &self.config, sample);
        let unusable = Flags::WARMING_UP | Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL;
        let Some(fv) = frame.features.filter(|_| frame.flags.0 & unusable.0 == 0) else {
            return;
        };
        for (k, &v) in fv.as_slice().iter().enumerate() {
            self.acc.sum_x[k] += v as f64;
            let r = &mut self.out.sample_range[k];
            *r = (r.0.min(v as f64), r.1.max(v as f64));
        }
        self.acc.sum_y += target_dph;
        self.acc.count += 1;
        self.out.usable_s += self.nominal_period_s;
    }

    /// The blocks; `target_offset_dph` is subtracted from every block's target
    /// (the run mean, for runs without `ref_dph`, known only at the end).
    pub fn finish(mut self, target_offset_dph: f64) -> Blocks {
        self.flush();
        for y in &mut self.out.y {
            *y -= target_offset_dph;
        }
        self.out
    }
}

/// Runs the trainer learns from: in memory ([`Run`]) or streamed from files
/// ([`RunFiles`]), seen through their block means.
pub trait RunSet {
    /// Number of runs.
    fn count(&self) -> usize;
    /// Block means of every run's features for `features`, concatenated.
    fn block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks>;
    /// Computes the blocks of several configurations where one pass over the
    /// data serves them all; later [`RunSet::block_means`] calls use them.
    fn prepare(&self, _configs: &[FeatureConfig], _block_s: f64) -> anyhow::Result<()> {
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

    fn block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        Ok(block_means(self, features, block_s))
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

    fn block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        Ok(block_means(self, features, block_s))
    }
}

/// Block means of the features and bias target of each run, concatenated.
pub fn block_means(runs: &[Run], features: &FeatureConfig, block_s: f64) -> Blocks {
    let mut all = Blocks {
        dims: features.dims(),
        ..Blocks::default()
    };
    for (index, run) in runs.iter().enumerate() {
        let reference = run.reference_dph();
        let mut builder = BlockBuilder::new(index, *features, run.nominal_period_s, block_s);
        for (i, sample) in run.samples().enumerate() {
            builder.push(run.time_s[i], &sample, run.rate_dph[i] - reference.at(i));
        }
        all.append(builder.finish(0.0));
    }
    all
}

/// Run files read in streaming passes: only block means and running sums are
/// ever held, whatever the file's length. One pass computes the blocks of
/// every configuration [`RunSet::prepare`] asks for; the parsing runs on its
/// own thread, ahead of the feature computation.
pub struct RunFiles {
    paths: Vec<PathBuf>,
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
        RunFiles {
            paths: paths.to_vec(),
            cache: Mutex::new(Vec::new()),
        }
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
        let run = StreamedRun::open(path, mask)?;
        let (period_s, has_ref) = (run.nominal_period_s, run.has_ref);
        let mut builders: Vec<BlockBuilder> = configs
            .iter()
            .map(|c| BlockBuilder::new(index, *c, period_s, block_s))
            .collect();
        let mut rate_sum = 0.0f64;
        let rows = run.for_each(|row, sample| {
            let target = row.rate_dph - row.ref_dph.unwrap_or(0.0);
            rate_sum += row.rate_dph;
            for b in &mut builders {
                b.push(row.time_s, sample, target);
            }
        })?;
        if rows < 2 {
            anyhow::bail!("{}: run has {rows} data rows; at least 2 are needed", path.display());
        }
        let offset = if has_ref { 0.0 } else { rate_sum / rows as f64 };
        Ok(builders.into_iter().map(|b| b.finish(offset)).collect())
    }
}

impl RunSet for RunFiles {
    fn count(&self) -> usize {
        self.paths.len()
    }

    fn thermometer_mask(&self) -> anyhow::Result<u8> {
        self.paths.iter().try_fold(u8::MAX, |m, path| {
            Ok(m & RunReader::open(path)?.columns().thermometer_mask())
        })
    }

    fn block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        let key = cache_key(features, block_s);
        if let Some(b) = self.cached(&key) {
            return Ok(b);
        }
        self.prepare(std::slice::from_ref(features), block_s)?;
        self.cached(&key)
            .ok_or_else(|| anyhow::anyhow!("block means were not cached"))
    }

    fn prepare(&self, configs: &[FeatureConfig], block_s: f64) -> anyhow::Result<()> {
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
