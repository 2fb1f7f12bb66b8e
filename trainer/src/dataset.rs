//! Training data: rbf-core features per sample, averaged over blocks.
//!
//! Features are computed per sample by [`rbf_core::Compensator::features`], the
//! very function the firmware runs, then averaged with the bias target over
//! blocks (1 s by default) inside each segment. Samples whose features are
//! still warming up or whose temperature is a held value are left out of the
//! averages; blocks with under half their nominal samples are dropped.

use rbf_core::{Compensator, FeatureConfig, Flags, MAX_INPUTS};

use crate::run::Run;

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

/// Block means of the features and bias target of each run, concatenated.
pub fn block_means(runs: &[Run], features: &FeatureConfig, block_s: f64) -> Blocks {
    let mut all = Blocks {
        dims: features.dims(),
        ..Blocks::default()
    };
    for (index, run) in runs.iter().enumerate() {
        all.append(run_blocks(index, run, features, block_s));
    }
    all
}

fn run_blocks(run_index: usize, run: &Run, features: &FeatureConfig, block_s: f64) -> Blocks {
    let dims = features.dims();
    let config = run.compensator_config();
    let reference = run.reference_dph();
    let min_count = ((0.5 * block_s / run.nominal_period_s).floor() as usize).max(1);
    let mut out = Blocks {
        dims,
        sample_range: vec![(f64::INFINITY, f64::NEG_INFINITY); dims],
        ..Blocks::default()
    };
    let mut compensator = Compensator::new();
    let mut acc = Accumulator::default();
    let mut segment_start_s = 0.0;
    let mut current_block = None;
    let flush = |acc: &mut Accumulator, out: &mut Blocks| {
        if acc.count >= min_count {
            let n = acc.count as f64;
            let mut mean = [0.0; MAX_INPUTS];
            for (m, s) in mean.iter_mut().zip(&acc.sum_x) {
                *m = s / n;
            }
            out.x.push(mean);
            out.y.push(acc.sum_y / n);
            out.run.push(run_index);
        }
        *acc = Accumulator::default();
    };
    for (i, sample) in run.samples().enumerate() {
        let t = run.time_s[i];
        if i == 0 || config.is_gap(sample.dt_s) {
            segment_start_s = t;
        }
        let block = (
            segment_start_s.to_bits(),
            ((t - segment_start_s) / block_s).floor() as u64,
        );
        if current_block != Some(block) {
            flush(&mut acc, &mut out);
            current_block = Some(block);
        }
        let frame = compensator.features(features, &config, &sample);
        let unusable = Flags::WARMING_UP | Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL;
        let Some(fv) = frame.features.filter(|_| frame.flags.0 & unusable.0 == 0) else {
            continue;
        };
        for (k, &v) in fv.as_slice().iter().enumerate() {
            acc.sum_x[k] += v as f64;
            let r = &mut out.sample_range[k];
            *r = (r.0.min(v as f64), r.1.max(v as f64));
        }
        acc.sum_y += run.rate_dph[i] - reference.at(i);
        acc.count += 1;
        out.usable_s += run.nominal_period_s;
    }
    flush(&mut acc, &mut out);
    out
}
