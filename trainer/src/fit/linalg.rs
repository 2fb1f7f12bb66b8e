//! Small linear-algebra pieces shared by the fitters: input normalisation,
//! Gaussian design matrices, Gram statistics and ridge solves.

use nalgebra::{Cholesky, DMatrix, DVector, Dyn};
use rbf_core::MAX_INPUTS;

use crate::dataset::Blocks;

/// A feature row, first `dims` entries used.
pub type FeatureRow = [f64; MAX_INPUTS];

/// Per-input affine normalisation z = (x − offset) / scale, values rounded to
/// f32 so that the fit sees exactly what the deployed model computes.
#[derive(Clone, Debug, PartialEq)]
pub struct Normaliser {
    /// Offsets (training means), input units.
    pub offset: Vec<f64>,
    /// Scales (training standard deviations), input units.
    pub scale: Vec<f64>,
}

impl Normaliser {
    /// Mean and standard deviation of each feature over `blocks`.
    pub fn fit(blocks: &Blocks) -> Normaliser {
        let n = blocks.len().max(1) as f64;
        let (mut offset, mut scale) = (Vec::new(), Vec::new());
        for i in 0..blocks.dims {
            let mean = blocks.x.iter().map(|r| r[i]).sum::<f64>() / n;
            let var = blocks.x.iter().map(|r| (r[i] - mean).powi(2)).sum::<f64>() / n;
            let std = var.sqrt();
            let std = if std > 1e-9 * (mean.abs() + 1.0) { std } else { 1.0 };
            offset.push(mean as f32 as f64);
            scale.push(std as f32 as f64);
        }
        Normaliser { offset, scale }
    }

    /// Normalised copy of a feature row.
    pub fn apply(&self, x: &FeatureRow) -> FeatureRow {
        let mut z = [0.0; MAX_INPUTS];
        for i in 0..self.offset.len() {
            z[i] = (x[i] - self.offset[i]) / self.scale[i];
        }
        z
    }
}

/// Gaussian basis value exp(−‖z − c‖² / 2σ²) over the first `dims` inputs.
pub fn gaussian(z: &FeatureRow, c: &FeatureRow, dims: usize, width: f64) -> f64 {
    let d2: f64 = (0..dims).map(|i| (z[i] - c[i]).powi(2)).sum();
    (-d2 / (2.0 * width * width)).exp()
}

/// The shape of a network's inputs: `dims` inputs, of which the first
/// `kernel` enter the Gaussians (all enter linearly).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct InputShape {
    /// Number of inputs.
    pub dims: usize,
    /// Leading inputs the Gaussians see.
    pub kernel: usize,
}

/// Design matrix with columns [1, z_1 … z_d, φ_1 … φ_K] for the given rows.
pub fn design(z: &[FeatureRow], rows: &[usize], shape: InputShape, centers: &[FeatureRow], width: f64) -> DMatrix<f64> {
    let fixed = 1 + shape.dims;
    DMatrix::from_fn(rows.len(), fixed + centers.len(), |r, c| {
        let zr = &z[rows[r]];
        match c {
            0 => 1.0,
            c if c < fixed => zr[c - 1],
            c => gaussian(zr, &centers[c - fixed], shape.kernel, width),
        }
    })
}

/// Sufficient statistics of a design matrix A and target y for any leading
/// subset of columns: AᵀA, Aᵀy, Aᵀ1, Σy, Σy², n.
#[derive(Clone, Debug)]
pub struct GramStats {
    /// AᵀA.
    pub gram: DMatrix<f64>,
    /// Aᵀy.
    pub aty: DVector<f64>,
    /// Aᵀ1 (column sums).
    pub col_sums: DVector<f64>,
    /// Σy.
    pub sum_y: f64,
    /// Σy².
    pub sum_yy: f64,
    /// Number of rows.
    pub n: usize,
}

impl GramStats {
    /// Statistics of design `a` and target `y`.
    pub fn new(a: &DMatrix<f64>, y: &DVector<f64>) -> GramStats {
        GramStats {
            gram: a.tr_mul(a),
            aty: a.tr_mul(y),
            col_sums: DVector::from_iterator(a.ncols(), a.column_iter().map(|c| c.sum())),
            sum_y: y.sum(),
            sum_yy: y.norm_squared(),
            n: y.len(),
        }
    }

    /// Variance of the residual y − A[:, :p] w (offset-invariant, as the
    /// cluster STD the users judge by), °/h².
    pub fn residual_variance(&self, w: &DVector<f64>) -> f64 {
        let p = w.len();
        let n = self.n.max(1) as f64;
        let g = self.gram.view((0, 0), (p, p));
        let sse = self.sum_yy - 2.0 * w.dot(&self.aty.rows(0, p)) + (g * w).dot(w);
        let mean = (self.sum_y - w.dot(&self.col_sums.rows(0, p))) / n;
        (sse / n - mean * mean).max(0.0)
    }
}

/// The design ([`design`]) and target of cluster means: `rows` in
/// consecutive groups of `rows_per_mean` (a trailing group with under half
/// the rows is dropped), each group's design row and target averaged, so
/// that the residual is the mean residual of each cluster. Built a row at a
/// time: only the cluster means are held, whatever the number of rows.
pub fn cluster_design(
    z: &[FeatureRow],
    y: &[f64],
    rows: &[usize],
    rows_per_mean: usize,
    shape: InputShape,
    centers: &[FeatureRow],
    width: f64,
) -> (DMatrix<f64>, DVector<f64>) {
    let size = rows_per_mean.max(1);
    let starts: Vec<usize> = (0..rows.len())
        .step_by(size)
        .filter(|&s| (rows.len() - s) * 2 >= size)
        .collect();
    let fixed = 1 + shape.dims;
    let mut am = DMatrix::zeros(starts.len(), fixed + centers.len());
    let mut ym = DVector::zeros(starts.len());
    for (k, &s) in starts.iter().enumerate() {
        let group = &rows[s..(s + size).min(rows.len())];
        for &r in group {
            let zr = &z[r];
            am[(k, 0)] += 1.0;
            for c in 1..fixed {
                am[(k, c)] += zr[c - 1];
            }
            for (j, center) in centers.iter().enumerate() {
                am[(k, fixed + j)] += gaussian(zr, center, shape.kernel, width);
            }
            ym[k] += y[r];
        }
        let n = group.len() as f64;
        am.row_mut(k).iter_mut().for_each(|v| *v /= n);
        ym[k] /= n;
    }
    (am, ym)
}

/// Ridge solution on the first `p` columns: (AᵀA + λ n I′) w = Aᵀy, with I′
/// leaving the constant (column 0) unpenalised. `None` if the system is singular.
pub fn ridge_solve(stats: &GramStats, p: usize, lambda: f64) -> Option<DVector<f64>> {
    ridge_solve_weighted(stats, p, lambda, |i| if i == 0 { 0.0 } else { 1.0 })
}

/// Ridge solution on the first `p` columns with a penalty of its own per
/// column: (AᵀA + λ n diag(s)) w = Aᵀy, s_i = `scale(i)` ≥ 0 (0 leaves
/// column i unpenalised): a Gaussian prior on weight i of precision λ n s_i
/// in units of the noise variance.
pub fn ridge_solve_weighted(
    stats: &GramStats,
    p: usize,
    lambda: f64,
    scale: impl Fn(usize) -> f64,
) -> Option<DVector<f64>> {
    let w = ridge_factor(&stats.gram, stats.n, p, lambda, scale)?.solve(&stats.aty.rows(0, p).clone_owned());
    w.iter().all(|v| v.is_finite()).then_some(w)
}

/// The Cholesky factor of [`ridge_solve_weighted`]'s penalised matrix: the
/// first `p` rows and columns of `gram` (AᵀA over `n` rows) plus λ n
/// diag(s), s_i = `scale(i)`. Its inverse is the posterior covariance of the
/// weights per unit noise variance. `None` if it is not positive definite.
pub fn ridge_factor(
    gram: &DMatrix<f64>,
    n: usize,
    p: usize,
    lambda: f64,
    scale: impl Fn(usize) -> f64,
) -> Option<Cholesky<f64, Dyn>> {
    let mut m = gram.view((0, 0), (p, p)).clone_owned();
    let penalty = lambda * n as f64;
    for i in 0..p {
        m[(i, i)] += penalty * scale(i);
    }
    m.cholesky()
}

/// Up to `count` rows spread over the data by farthest-point sampling,
/// starting from the row nearest the mean. Deterministic.
pub fn farthest_points(z: &[FeatureRow], rows: &[usize], dims: usize, count: usize) -> Vec<usize> {
    if rows.is_empty() || count == 0 {
        return Vec::new();
    }
    let dist = |a: &FeatureRow, b: &FeatureRow| (0..dims).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>();
    let mut mean = [0.0; MAX_INPUTS];
    for &r in rows {
        for i in 0..dims {
            mean[i] += z[r][i] / rows.len() as f64;
        }
    }
    let first = rows
        .iter()
        .copied()
        .min_by(|&a, &b| dist(&z[a], &mean).total_cmp(&dist(&z[b], &mean)))
        .unwrap_or(rows[0]);
    let mut chosen = vec![first];
    let mut nearest: Vec<f64> = rows.iter().map(|&r| dist(&z[r], &z[first])).collect();
    // The farthest row, found while the distances are updated (one pass per
    // centre); ties go to the last row, as `max_by` would.
    let farthest = |nearest: &[f64]| {
        nearest
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or((0, 0.0), |(k, &d)| (k, d))
    };
    let (mut k, mut d) = farthest(&nearest);
    while chosen.len() < count.min(rows.len()) {
        if d <= 0.0 {
            break; // all remaining rows coincide with chosen ones
        }
        let next = rows[k];
        chosen.push(next);
        (k, d) = match dims {
            1 => update_nearest::<1>(&mut nearest, z, rows, &z[next]),
            2 => update_nearest::<2>(&mut nearest, z, rows, &z[next]),
            3 => update_nearest::<3>(&mut nearest, z, rows, &z[next]),
            _ => update_nearest::<MAX_INPUTS>(&mut nearest, z, rows, &z[next]),
        };
    }
    chosen
}

/// Lowers each row's nearest-centre distance² (first `N` inputs) by the new
/// centre `c`; returns the farthest row and its distance (ties: the last).
/// Distances are finite and ≥ 0, where a plain comparison equals
/// `total_cmp`; monomorphised per N, as this is the search's hottest loop.
fn update_nearest<const N: usize>(
    nearest: &mut [f64],
    z: &[FeatureRow],
    rows: &[usize],
    c: &FeatureRow,
) -> (usize, f64) {
    let (mut k, mut d) = (0, f64::NEG_INFINITY);
    for (i, (slot, &r)) in nearest.iter_mut().zip(rows).enumerate() {
        let mut dist = 0.0;
        for (a, b) in z[r].iter().zip(c).take(N) {
            dist += (a - b) * (a - b);
        }
        *slot = slot.min(dist);
        if *slot >= d {
            (k, d) = (i, *slot);
        }
    }
    (k, d)
}

/// Every `step`-th row so that at most `max` remain.
pub fn thin(rows: &[usize], max: usize) -> Vec<usize> {
    let step = rows.len().div_ceil(max.max(1)).max(1);
    rows.iter().step_by(step).copied().collect()
}

/// `rows` (ascending indices into `z` and `y`) pooled into at most `max`
/// means of consecutive runs of rows: the same data with less per-row work,
/// keeping the noise averaging that striding ([`thin`]) would throw away.
/// A pool never spans a jump in the indices (a held-out fold or another run).
pub fn pool_means(z: &[FeatureRow], y: &[f64], rows: &[usize], max: usize) -> (Vec<FeatureRow>, Vec<f64>) {
    let step = rows.len().div_ceil(max.max(1)).max(1);
    let mut out_z = Vec::with_capacity(rows.len() / step + 1);
    let mut out_y = Vec::with_capacity(rows.len() / step + 1);
    let mut start = 0;
    while start < rows.len() {
        let mut end = start + 1;
        while end < rows.len() && end - start < step && rows[end] == rows[end - 1] + 1 {
            end += 1;
        }
        let n = (end - start) as f64;
        let mut mean_z = [0.0; MAX_INPUTS];
        let mut mean_y = 0.0;
        for &i in &rows[start..end] {
            for (m, v) in mean_z.iter_mut().zip(&z[i]) {
                *m += v;
            }
            mean_y += y[i];
        }
        mean_z.iter_mut().for_each(|m| *m /= n);
        out_z.push(mean_z);
        out_y.push(mean_y / n);
        start = end;
    }
    (out_z, out_y)
}

#[cfg(test)]
#[allow(clippy::float_cmp, reason = "means of small integers are exact")]
mod tests {
    use super::*;

    #[test]
    fn pooled_means_average_consecutive_rows_and_never_span_a_gap() {
        let z: Vec<FeatureRow> = (0..10).map(|i| [i as f64; MAX_INPUTS]).collect();
        let y: Vec<f64> = (0..10).map(|i| 10.0 * i as f64).collect();
        // Rows 4 and 5 are held out: the pools stop at the jump from 3 to 6.
        let rows = [0, 1, 2, 3, 6, 7, 8, 9];
        let (pz, py) = pool_means(&z, &y, &rows, 4);
        assert_eq!(py, [5.0, 25.0, 65.0, 85.0]);
        assert_eq!(pz.iter().map(|r| r[0]).collect::<Vec<_>>(), [0.5, 2.5, 6.5, 8.5]);
        let (_, py) = pool_means(&z, &y, &rows, 3);
        assert_eq!(
            py,
            [10.0, 30.0, 70.0, 90.0],
            "pools of three cut short at the jump and the end"
        );
        let (_, all) = pool_means(&z, &y, &rows, 100);
        assert_eq!(
            all,
            rows.map(|i| 10.0 * i as f64),
            "under the cap every row is its own pool"
        );
    }
}
