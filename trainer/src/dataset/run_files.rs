//! [`RunFiles`]: run files read in streaming passes, one pass building the
//! blocks of every configuration asked for, kept in a cache until released;
//! a run holds at most [`MAX_BLOCKS_PER_RUN`] blocks per configuration.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use rbf_core::axis::Axis;
use rbf_core::thermometer::ThermometerSet;
use rbf_core::{FeatureConfig, FeatureSet};

use super::blocks::Blocks;
use super::builder::{BlockBuilder, MAX_BLOCKS_PER_RUN, filter_groups};
use super::derive::slice_plain;
use super::run_set::{RunSet, SampleVisit};
use crate::reading::chunked::Batch;
use crate::reading::run::RunReader;
use crate::reading::run::samples::StreamedRun;

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
    fn open(&self, path: &std::path::Path) -> Result<RunReader, crate::reading::run::rows::RunError> {
        let mut reader = RunReader::open(path)?;
        match self.axis {
            Some(axis) => reader.select_axis(axis)?,
            None => reader.header().require_single_axis()?,
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
        let thermometers = configs
            .iter()
            .fold(ThermometerSet::EMPTY, |m, c| m.union(c.set.thermometers()));
        let run = StreamedRun::from_reader(self.open(path)?, thermometers)?;
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

impl RunSet for RunFiles {
    fn count(&self) -> usize {
        self.paths.len()
    }

    fn thermometers(&self) -> anyhow::Result<ThermometerSet> {
        self.paths.iter().try_fold(ThermometerSet::ALL, |m, path| {
            Ok(m.intersection(self.open(path)?.columns().thermometers()))
        })
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
            let run = StreamedRun::from_reader(self.open(path)?, ThermometerSet::EMPTY)?;
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
    use crate::dataset::derive::plain_bank;
    use crate::dataset::sample_block_means;
    use crate::dataset::test_support::{multiscale, simulated_run};
    use crate::reading::run::samples::Run;
    use rbf_core::lag_bank::LagBank;

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
        assert!(
            matches!(from_files.report, crate::fit::FitReport::Bank(_)),
            "the default is the lag bank"
        );
        assert_eq!(
            crate::blobfile::encode_model(&from_files.model, None).unwrap(),
            crate::blobfile::encode_model(&in_memory.model, None).unwrap()
        );
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
            let score = |m: &rbf_core::Model| crate::evaluation::evaluate::evaluate_file(m, path, None).unwrap();
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
