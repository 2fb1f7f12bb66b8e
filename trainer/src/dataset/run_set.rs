//! [`RunSet`]: the runs a fit learns from, seen through their block means
//! (or sample by sample, [`SampleVisit`]), and its implementation for runs
//! held in memory ([`sample_block_means`]).

use rbf_core::thermometer::ThermometerSet;
use rbf_core::{FeatureConfig, GyroSample};

use super::blocks::Blocks;
use super::builder::BlockBuilder;
use super::derive::{block_source, derive_blocks};
use crate::reading::run::samples::Run;

/// Runs the trainer learns from: in memory ([`Run`]) or streamed from files
/// ([`RunFiles`](super::RunFiles)), seen through their block means.
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
    /// The thermometer columns every run has.
    fn thermometers(&self) -> anyhow::Result<ThermometerSet>;
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
fn common_thermometers(runs: &[Run]) -> ThermometerSet {
    runs.iter()
        .fold(ThermometerSet::ALL, |m, r| m.intersection(r.thermometers))
}

impl RunSet for [Run] {
    fn count(&self) -> usize {
        self.len()
    }

    fn thermometers(&self) -> anyhow::Result<ThermometerSet> {
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

/// Arrays of runs (so that `&[]` reads as "no validation runs"): the runs
/// as a slice.
impl<const N: usize> RunSet for [Run; N] {
    fn count(&self) -> usize {
        N
    }

    fn thermometers(&self) -> anyhow::Result<ThermometerSet> {
        self[..].thermometers()
    }

    fn filtered_block_means(&self, features: &FeatureConfig, block_s: f64) -> anyhow::Result<Blocks> {
        self[..].filtered_block_means(features, block_s)
    }

    fn for_each_sample(&self, visit: &mut dyn FnMut(&SampleVisit)) -> anyhow::Result<()> {
        self[..].for_each_sample(visit)
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
