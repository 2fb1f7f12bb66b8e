//! Orthogonal least squares forward selection of regressors
//! (Chen, Cowan & Grant, IEEE Trans. Neural Networks 2(2), 1991).
//!
//! Each step orthogonalises the remaining candidate columns against those
//! chosen so far (modified Gram–Schmidt) and picks the one with the largest
//! error-reduction ratio `(wᵀr)² / (wᵀw · yᵀy)`, where r is the residual of the
//! target. Fixed regressors (constant, linear terms) are projected out first.
//! Cost: O(steps × candidates × rows).

use nalgebra::{DMatrix, DVector};

/// Candidates whose orthogonalised norm² falls below this share of the
/// original are linearly dependent on what is chosen and are skipped.
const DEPENDENCE_TOLERANCE: f64 = 1e-10;

/// One OLS path: candidate columns in the order chosen, with their error-reduction ratios.
#[derive(Clone, Debug, PartialEq)]
pub struct Selection {
    /// Candidate column indices in selection order.
    pub order: Vec<usize>,
    /// Error-reduction ratio of each chosen column (share of yᵀy it explains).
    pub err: Vec<f64>,
}

/// Independent partial sums of the reductions below: a sum in one chain is
/// bound by the adder's latency, four chains run at its throughput. Fixed
/// lanes and a fixed final order, so results do not depend on the machine.
const LANES: usize = 4;

/// The lanes' total, (s₀ + s₁) + (s₂ + s₃).
fn lanes_total(lanes: [f64; LANES]) -> f64 {
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3])
}

/// aᵀb: element i goes to lane i mod [`LANES`].
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut lanes = [0.0f64; LANES];
    let (a4, b4) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (a_rest, b_rest) = (a4.remainder(), b4.remainder());
    for (x, y) in a4.zip(b4) {
        for ((sum, xi), yi) in lanes.iter_mut().zip(x).zip(y) {
            *sum += xi * yi;
        }
    }
    for ((sum, xi), yi) in lanes.iter_mut().zip(a_rest).zip(b_rest) {
        *sum += xi * yi;
    }
    lanes_total(lanes)
}

/// col ← col − along·q, returning (‖col‖², colᵀr) of the result, in one pass
/// with the lanes of [`dot`].
fn update_column(col: &mut [f64], along: f64, q: &[f64], r: &[f64]) -> (f64, f64) {
    let (mut n, mut d) = ([0.0f64; LANES], [0.0f64; LANES]);
    let step = |c: &mut f64, qi: f64, ri: f64, n: &mut f64, d: &mut f64| {
        *c -= along * qi;
        *n += *c * *c;
        *d += *c * ri;
    };
    let mut c4 = col.chunks_exact_mut(LANES);
    let (q4, r4) = (q.chunks_exact(LANES), r.chunks_exact(LANES));
    let (q_rest, r_rest) = (q4.remainder(), r4.remainder());
    for ((c, qc), rc) in (&mut c4).zip(q4).zip(r4) {
        for ((((ci, qi), ri), ni), di) in c.iter_mut().zip(qc).zip(rc).zip(&mut n).zip(&mut d) {
            step(ci, *qi, *ri, ni, di);
        }
    }
    let c_rest = c4.into_remainder();
    for ((((ci, qi), ri), ni), di) in c_rest.iter_mut().zip(q_rest).zip(r_rest).zip(&mut n).zip(&mut d) {
        step(ci, *qi, *ri, ni, di);
    }
    (lanes_total(n), lanes_total(d))
}

fn project_out(q: &[f64], v: &mut [f64]) {
    let along = dot(q, v);
    for (vi, qi) in v.iter_mut().zip(q) {
        *vi -= along * qi;
    }
}

fn norm_sq(v: &[f64]) -> f64 {
    dot(v, v)
}

/// Selects up to `max_terms` columns of `candidates` (rows × M) for target `y`,
/// after the `fixed` columns (rows × P), which are always in the model.
pub fn forward_select(
    candidates: &DMatrix<f64>,
    fixed: &DMatrix<f64>,
    y: &DVector<f64>,
    max_terms: usize,
) -> Selection {
    let y_energy = y.norm_squared().max(f64::MIN_POSITIVE);
    let mut residual: Vec<f64> = y.iter().copied().collect();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    for col in fixed.column_iter() {
        let mut v: Vec<f64> = col.iter().copied().collect();
        let original = norm_sq(&v);
        for q in &basis {
            project_out(q, &mut v);
        }
        let n = norm_sq(&v);
        if n > DEPENDENCE_TOLERANCE * original && n > 0.0 {
            let inv = n.sqrt().recip();
            v.iter_mut().for_each(|x| *x *= inv);
            basis.push(v);
        }
    }
    let mut columns: Vec<Vec<f64>> = candidates.column_iter().map(|c| c.iter().copied().collect()).collect();
    let original: Vec<f64> = columns.iter().map(|c| norm_sq(c)).collect();
    for q in &basis {
        project_out(q, &mut residual);
        columns.iter_mut().for_each(|c| project_out(q, c));
    }
    let mut active = vec![true; columns.len()];
    let mut selection = Selection {
        order: Vec::new(),
        err: Vec::new(),
    };
    // (‖col‖², colᵀr) of every column, kept current: each projection pass
    // below also sums them (in the same lanes and order as separate passes
    // would, so the results are bit for bit those of the textbook loop with
    // these sums, in half the passes).
    let mut stats: Vec<(f64, f64)> = columns.iter().map(|c| (norm_sq(c), dot(c, &residual))).collect();
    while selection.order.len() < max_terms {
        let mut best: Option<(usize, f64)> = None;
        for (m, &(n, d)) in stats.iter().enumerate() {
            if !active[m] || n <= DEPENDENCE_TOLERANCE * original[m] || n == 0.0 {
                continue;
            }
            let score = d * d / n;
            if best.is_none_or(|(_, s)| score > s) {
                best = Some((m, score));
            }
        }
        let Some((chosen, score)) = best else { break };
        active[chosen] = false;
        let n = stats[chosen].0;
        let q: Vec<f64> = columns[chosen].iter().map(|x| x / n.sqrt()).collect();
        project_out(&q, &mut residual);
        for (m, col) in columns.iter_mut().enumerate() {
            if !active[m] {
                continue;
            }
            let along = dot(&q, col);
            stats[m] = update_column(col, along, &q, &residual);
        }
        selection.order.push(chosen);
        selection.err.push(score / y_energy);
    }
    selection
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;

    fn gaussian(x: f64, c: f64, width: f64) -> f64 {
        (-(x - c).powi(2) / (2.0 * width * width)).exp()
    }

    #[test]
    fn recovers_the_centers_of_a_known_network_from_noiseless_data() {
        // y = 2 φ(x; −2) − 1.5 φ(x; 0.5) + 0.7 φ(x; 2.25), width 0.4: centres ≥ 4σ
        // apart (greedy selection cannot untangle heavily overlapping Gaussians).
        let width = 0.4;
        let true_centers = [(-2.0, 2.0), (0.5, -1.5), (2.25, 0.7)];
        let xs: Vec<f64> = (0..400).map(|i| -3.0 + 6.0 * i as f64 / 399.0).collect();
        let grid: Vec<f64> = (0..25).map(|i| -3.0 + 0.25 * i as f64).collect();
        let y = DVector::from_iterator(
            xs.len(),
            xs.iter().map(|&x| {
                true_centers
                    .iter()
                    .map(|&(c, w)| w * gaussian(x, c, width))
                    .sum::<f64>()
            }),
        );
        let candidates = DMatrix::from_fn(xs.len(), grid.len(), |r, c| gaussian(xs[r], grid[c], width));
        let fixed = DMatrix::from_element(xs.len(), 0, 0.0);
        let sel = forward_select(&candidates, &fixed, &y, 3);
        let mut chosen: Vec<f64> = sel.order.iter().map(|&m| grid[m]).collect();
        chosen.sort_by(f64::total_cmp);
        assert_eq!(chosen, vec![-2.0, 0.5, 2.25]);
        let explained: f64 = sel.err.iter().sum();
        assert!(
            (explained - 1.0).abs() < 1e-9,
            "three true centres explain all of y: {explained}"
        );
        // Least squares on the chosen columns gives back the true weights.
        let a = candidates.select_columns(&sel.order);
        let w = a.svd(true, true).solve(&y, 1e-12).unwrap();
        for (k, &m) in sel.order.iter().enumerate() {
            let truth = true_centers.iter().find(|c| c.0 == grid[m]).unwrap().1;
            assert!(
                (w[k] - truth).abs() < 1e-9,
                "weight of centre {}: {} vs {truth}",
                grid[m],
                w[k]
            );
        }
    }

    #[test]
    fn fixed_regressors_are_projected_out_and_duplicates_skipped() {
        let n = 50;
        let x: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        // y is a pure line: after the fixed [1, x] nothing is left to explain.
        let y = DVector::from_iterator(n, x.iter().map(|v| 3.0 + 2.0 * v));
        let fixed = DMatrix::from_fn(n, 2, |r, c| if c == 0 { 1.0 } else { x[r] });
        // Candidate 0 duplicates the fixed linear column; candidate 1 is x².
        let candidates = DMatrix::from_fn(n, 2, |r, c| if c == 0 { x[r] } else { x[r] * x[r] });
        let sel = forward_select(&candidates, &fixed, &y, 2);
        assert_eq!(sel.order, vec![1], "the duplicate of a fixed column is never chosen");
        assert!(sel.err[0] < 1e-20);
    }
}
