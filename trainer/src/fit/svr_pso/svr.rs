//! ε-support vector regression with a Gaussian kernel, solved by sequential
//! minimal optimisation: the dual of Vapnik's ε-SVR in LIBSVM's form (Chang &
//! Lin 2011, §2.4) with second-order working-set selection (Fan, Chen & Lin,
//! JMLR 6, 2005). Used by the RLG paper's method (`--method svr-pso`).
//!
//! The dual has 2l variables (α_i, α*_i); with z = (α, α*), s = (+1…, −1…):
//! minimise ½ zᵀQz + pᵀz subject to sᵀz = 0 and 0 ≤ z ≤ C, where
//! Q_tu = s_t s_u K(x_t, x_u) and p = (ε − y, ε + y). The model is
//! f(x) = Σ_i (α_i − α*_i) K(x_i, x) − ρ with K(a, b) = exp(−‖a − b‖²/2σ²):
//! a Gaussian RBF network with one shared width, which is how it is deployed.
//! The kernel matrix is computed once per fit (l ≤ a few thousand rows).
//!
//! Crates considered: smartcore's `SVR` (0.2 API) offers fit and predict but
//! not the expansion (support vectors, coefficients, ρ) that deployment
//! compiles into the firmware's network; linfa-svm solves the same dual but
//! brings ndarray and the linfa dataset and kernel crates into a trainer
//! built on nalgebra. This solver is LIBSVM's algorithm in ~200 lines, with
//! tests of its KKT conditions.

use crate::fit::linalg::{FeatureRow, GramStats, ridge_solve};

/// Ridge strength of the partially linear SVR's linear part (inputs normalised).
const LINEAR_RIDGE: f64 = 1e-6;

/// w₀ + Σ w_i x_i over the first `dims` inputs.
fn linear_part(w: &nalgebra::DVector<f64>, x: &FeatureRow, dims: usize) -> f64 {
    w[0] + (0..dims).map(|i| w[1 + i] * x[i]).sum::<f64>()
}

/// Hyper-parameters of one ε-SVR.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SvrParams {
    /// Gaussian kernel width σ, in the units of the inputs given.
    pub sigma: f64,
    /// Box constraint C (larger: less regularisation).
    pub c: f64,
    /// Half-width ε of the insensitive tube, in target units.
    pub epsilon: f64,
}

/// A fitted ε-SVR.
#[derive(Clone, Debug, PartialEq)]
pub struct Svr {
    /// Support vectors (rows with α_i ≠ α*_i), first `dims` entries used.
    pub support: Vec<FeatureRow>,
    /// α_i − α*_i of each support vector.
    pub coef: Vec<f64>,
    /// Constant term (−ρ).
    pub bias: f64,
    /// Weights of a linear part added to the expansion (empty: none; see
    /// [`Svr::fit_partially_linear`]).
    pub linear: Vec<f64>,
    /// Kernel width σ.
    pub sigma: f64,
    /// Inputs used.
    pub dims: usize,
    /// SMO iterations the solve took.
    pub iterations: usize,
}

/// Stopping tolerance on the maximal KKT violation (LIBSVM's default).
const KKT_TOLERANCE: f64 = 1e-3;
/// Curvature floor for non-positive-definite pairs (LIBSVM's τ).
const TAU: f64 = 1e-12;

fn kernel(a: &FeatureRow, b: &FeatureRow, dims: usize, gamma: f64) -> f64 {
    let d2: f64 = a.iter().zip(b).take(dims).map(|(x, y)| (x - y) * (x - y)).sum();
    (-gamma * d2).exp()
}

impl Svr {
    /// Fits an ε-SVR to (x, y) (`dims` inputs per row), at most `max_iterations`
    /// SMO steps (the result is then the best reached, still feasible).
    pub fn fit(x: &[FeatureRow], y: &[f64], dims: usize, params: SvrParams, max_iterations: usize) -> Svr {
        let l = x.len().min(y.len());
        let gamma = 1.0 / (2.0 * params.sigma * params.sigma);
        // The kernel matrix, row-major l × l.
        let mut k = vec![0.0f64; l * l];
        for i in 0..l {
            for j in 0..=i {
                let v = kernel(&x[i], &x[j], dims, gamma);
                k[i * l + j] = v;
                k[j * l + i] = v;
            }
        }
        let n = 2 * l;
        let sign = |t: usize| if t < l { 1.0 } else { -1.0 };
        let row = |t: usize| t % l;
        let c = params.c;
        let mut alpha = vec![0.0f64; n];
        // Gradient of the dual at α = 0: p.
        let mut grad: Vec<f64> = (0..n)
            .map(|t| {
                if t < l {
                    params.epsilon - y[t]
                } else {
                    params.epsilon + y[t - l]
                }
            })
            .collect();
        let upper = |a: f64| a >= c;
        let lower = |a: f64| a <= 0.0;
        let mut iterations = 0;
        while iterations < max_iterations {
            // i: the most violating variable in I_up (largest −s_t G_t).
            let mut g_max = f64::NEG_INFINITY;
            let mut i = None;
            for t in 0..n {
                let movable = if sign(t) > 0.0 {
                    !upper(alpha[t])
                } else {
                    !lower(alpha[t])
                };
                if movable && -sign(t) * grad[t] >= g_max {
                    g_max = -sign(t) * grad[t];
                    i = Some(t);
                }
            }
            let Some(i) = i else { break };
            // j: the second-order choice in I_low.
            let (si, ri) = (sign(i), row(i));
            let mut g_max2 = f64::NEG_INFINITY;
            let mut j = None;
            let mut best_obj = f64::INFINITY;
            for t in 0..n {
                let st = sign(t);
                let movable = if st > 0.0 { !lower(alpha[t]) } else { !upper(alpha[t]) };
                if !movable {
                    continue;
                }
                let v = st * grad[t];
                g_max2 = g_max2.max(v);
                let grad_diff = g_max + v;
                if grad_diff > 0.0 {
                    // K_ii + K_tt − 2K_it, whatever the signs (K_ii = 1).
                    let quad = (2.0 - 2.0 * k[ri * l + row(t)]).max(TAU);
                    let obj = -(grad_diff * grad_diff) / quad;
                    if obj <= best_obj {
                        best_obj = obj;
                        j = Some(t);
                    }
                }
            }
            if g_max + g_max2 < KKT_TOLERANCE {
                break;
            }
            let Some(j) = j else { break };
            iterations += 1;
            let (sj, rj) = (sign(j), row(j));
            let q_ij = si * sj * k[ri * l + rj];
            let (old_i, old_j) = (alpha[i], alpha[j]);
            // α of one point and α* of another (signs differ), or both alike.
            if (i < l) != (j < l) {
                let quad = (2.0 + 2.0 * q_ij).max(TAU);
                let delta = (-grad[i] - grad[j]) / quad;
                let diff = alpha[i] - alpha[j];
                alpha[i] += delta;
                alpha[j] += delta;
                if diff > 0.0 {
                    if alpha[j] < 0.0 {
                        alpha[j] = 0.0;
                        alpha[i] = diff;
                    }
                } else if alpha[i] < 0.0 {
                    alpha[i] = 0.0;
                    alpha[j] = -diff;
                }
                if diff > 0.0 {
                    if alpha[i] > c {
                        alpha[i] = c;
                        alpha[j] = c - diff;
                    }
                } else if alpha[j] > c {
                    alpha[j] = c;
                    alpha[i] = c + diff;
                }
            } else {
                let quad = (2.0 - 2.0 * q_ij).max(TAU);
                let delta = (grad[i] - grad[j]) / quad;
                let sum = alpha[i] + alpha[j];
                alpha[i] -= delta;
                alpha[j] += delta;
                if sum > c {
                    if alpha[i] > c {
                        alpha[i] = c;
                        alpha[j] = sum - c;
                    }
                } else if alpha[j] < 0.0 {
                    alpha[j] = 0.0;
                    alpha[i] = sum;
                }
                if sum > c {
                    if alpha[j] > c {
                        alpha[j] = c;
                        alpha[i] = sum - c;
                    }
                } else if alpha[i] < 0.0 {
                    alpha[i] = 0.0;
                    alpha[j] = sum;
                }
            }
            let (di, dj) = (alpha[i] - old_i, alpha[j] - old_j);
            for (t, g) in grad.iter_mut().enumerate() {
                let st = sign(t);
                let rt = row(t);
                *g += st * (si * di * k[ri * l + rt] + sj * dj * k[rj * l + rt]);
            }
        }
        // ρ: the mean of s_t G_t over free variables, else the middle of the bounds.
        let (mut ub, mut lb, mut sum_free, mut free) = (f64::INFINITY, f64::NEG_INFINITY, 0.0, 0usize);
        for t in 0..n {
            let yg = sign(t) * grad[t];
            let positive = sign(t) > 0.0;
            if upper(alpha[t]) {
                if positive {
                    lb = lb.max(yg);
                } else {
                    ub = ub.min(yg);
                }
            } else if lower(alpha[t]) {
                if positive {
                    ub = ub.min(yg);
                } else {
                    lb = lb.max(yg);
                }
            } else {
                free += 1;
                sum_free += yg;
            }
        }
        let rho = if free > 0 {
            sum_free / free as f64
        } else {
            (ub + lb) / 2.0
        };
        let (mut support, mut coef) = (Vec::new(), Vec::new());
        for i in 0..l {
            let beta = alpha[i] - alpha[i + l];
            if beta != 0.0 {
                support.push(x[i]);
                coef.push(beta);
            }
        }
        Svr {
            support,
            coef,
            bias: if rho.is_finite() { -rho } else { 0.0 },
            linear: Vec::new(),
            sigma: params.sigma,
            dims,
            iterations,
        }
    }

    /// A partially linear ε-SVR (Smola, Frieß & Schölkopf, NIPS 1998): a
    /// least-squares linear part in the inputs, and an ε-SVR of what it leaves.
    /// Outside the training range the Gaussians fade and the linear part
    /// carries on: a faster ramp than any in training still gets the
    /// proportional share of a rate-driven bias.
    pub fn fit_partially_linear(
        x: &[FeatureRow],
        y: &[f64],
        dims: usize,
        params: SvrParams,
        max_iterations: usize,
    ) -> Svr {
        let n = x.len().min(y.len());
        let a = nalgebra::DMatrix::from_fn(n, 1 + dims, |r, c| if c == 0 { 1.0 } else { x[r][c - 1] });
        let target = nalgebra::DVector::from_column_slice(&y[..n]);
        let stats = GramStats::new(&a, &target);
        let Some(w) = ridge_solve(&stats, 1 + dims, LINEAR_RIDGE) else {
            return Svr::fit(x, y, dims, params, max_iterations);
        };
        let residual: Vec<f64> = (0..n).map(|r| y[r] - linear_part(&w, &x[r], dims)).collect();
        let mut svr = Svr::fit(x, &residual, dims, params, max_iterations);
        svr.bias += w[0];
        svr.linear = w.as_slice()[1..].to_vec();
        svr
    }

    /// The regression function at `x`.
    pub fn predict(&self, x: &FeatureRow) -> f64 {
        let gamma = 1.0 / (2.0 * self.sigma * self.sigma);
        let linear: f64 = self.linear.iter().zip(x).map(|(w, v)| w * v).sum();
        linear
            + self.bias
            + self
                .support
                .iter()
                .zip(&self.coef)
                .map(|(s, b)| b * kernel(s, x, self.dims, gamma))
                .sum::<f64>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(v: f64) -> FeatureRow {
        let mut r = [0.0; rbf_core::MAX_INPUTS];
        r[0] = v;
        r
    }

    #[test]
    fn fits_a_smooth_function_within_its_tube() {
        // y = sin(x) on [−3, 3]: with a small ε and a large C the fit stays
        // within about ε of every training point and between them.
        let x: Vec<FeatureRow> = (0..121).map(|i| row(-3.0 + 0.05 * i as f64)).collect();
        let y: Vec<f64> = x.iter().map(|r| r[0].sin()).collect();
        let params = SvrParams {
            sigma: 0.8,
            c: 100.0,
            epsilon: 0.01,
        };
        let svr = Svr::fit(&x, &y, 1, params, 100_000);
        let worst = x
            .iter()
            .zip(&y)
            .map(|(r, t)| (svr.predict(r) - t).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.01 + 2e-3, "worst training error {worst}");
        let between = (svr.predict(&row(0.525)) - 0.525f64.sin()).abs();
        assert!(between < 0.02, "error between samples {between}");
        // The tube makes the expansion sparse: points strictly inside carry no weight.
        assert!(svr.support.len() < x.len(), "{} support vectors", svr.support.len());
    }

    #[test]
    fn the_dual_solution_meets_its_constraints() {
        let x: Vec<FeatureRow> = (0..60).map(|i| row(i as f64 * 0.1)).collect();
        // A noisy line: many points on the box bound C.
        let y: Vec<f64> = x
            .iter()
            .enumerate()
            .map(|(i, r)| 0.5 * r[0] + if i % 2 == 0 { 0.3 } else { -0.3 })
            .collect();
        let params = SvrParams {
            sigma: 1.0,
            c: 0.5,
            epsilon: 0.05,
        };
        let svr = Svr::fit(&x, &y, 1, params, 100_000);
        // Σ(α − α*) = 0 and |α − α*| ≤ C.
        let sum: f64 = svr.coef.iter().sum();
        assert!(sum.abs() < 1e-9, "equality constraint: {sum}");
        assert!(svr.coef.iter().all(|b| b.abs() <= params.c + 1e-12));
        // Points well outside the tube sit on the bound with the residual's sign.
        for (s, b) in svr.support.iter().zip(&svr.coef) {
            let i = (s[0] / 0.1).round() as usize;
            let residual = y[i] - svr.predict(s);
            if residual.abs() > params.epsilon + 0.05 {
                assert!((b.abs() - params.c).abs() < 1e-9, "x = {}: coefficient {b}", s[0]);
                assert_eq!(*b > 0.0, residual > 0.0, "x = {}: sign", s[0]);
            }
        }
    }

    #[test]
    fn a_wide_tube_gives_the_constant_fit() {
        let x: Vec<FeatureRow> = (0..20).map(|i| row(i as f64)).collect();
        let y: Vec<f64> = x.iter().map(|r| 2.0 + 0.01 * r[0]).collect();
        let params = SvrParams {
            sigma: 1.0,
            c: 1.0,
            epsilon: 1.0,
        };
        let svr = Svr::fit(&x, &y, 1, params, 1000);
        assert!(svr.support.is_empty());
        assert!((svr.predict(&row(5.0)) - 2.1).abs() <= 1.0);
    }
}
