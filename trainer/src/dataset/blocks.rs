//! [`Blocks`]: the block means of one configuration's features and targets
//! over one or more runs, and their merging in pairs into blocks twice as
//! long ([`Blocks::merge_pairs`]), which keeps what a long run holds bounded.

use rbf_core::MAX_INPUTS;

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
    /// left out. Filled by [`BlockBuilder`](super::BlockBuilder); empty for
    /// blocks made otherwise.
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

    /// Appends `other`'s blocks (`block_s` asked for); whichever of the
    /// two holds shorter blocks is merged first ([`Blocks::merge_pairs`]),
    /// so that all blocks keep one length.
    pub(super) fn append(&mut self, mut other: Blocks, block_s: f64) {
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
pub(super) fn merge_on_grid(
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

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "merged blocks start exactly on their grid; exactness is what these tests guard"
)]
mod tests {
    use super::*;

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
}
