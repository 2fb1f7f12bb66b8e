//! Identifying the thermal lag bank ([`rbf_core::lag_bank`]) from chamber runs.
//!
//! The bias is modelled as a grey box with few parameters:
//!
//! ```text
//! b = f(T̂) + g(T̂)·Σ_k s_k·ΔT_k,   T̂ = T + Σ_k a_k·ΔT_k,   g = 1 + g₁(T̂ − T₀) + g₂(T̂ − T₀)²
//! ```
//!
//! f a cubic in T̂ (the static bias of the mean coil temperature), s_k the
//! rate weights (Shupe, stress and gradient terms, each linear in the coil's
//! rates), a_k the coil-lag weights that make T̂ a mixture of lags of the
//! loop temperature. The a_k and g enter nonlinearly: the whole structure is
//! fitted jointly by Levenberg–Marquardt with an analytic Jacobian on 10-s
//! means of the training blocks. What the chamber runs cannot pin down (which
//! filter time constants, whether the gain curves) is chosen by how well each
//! candidate predicts held-out thermal events ([`super::events`]) or the
//! `--validate` runs. The chosen structure becomes the model's feature
//! configuration; the RBF stage then fits the network on its exact inputs.

use nalgebra::{DMatrix, DVector};
use rbf_core::FeatureConfig;
use rbf_core::lag_bank::{BANK_FILTERS, GainOf, LagBank};

use super::coverage::{Coverage, settled_levels_c};
use super::events::{FoldKind, Folds, thermal_folds};
use super::{FitOptions, LagBankOptions, Progress};
use crate::dataset::{Blocks, RunSet};
use crate::parallel::parallel_map;

/// The two filter ladders whose blocks one pass over the data builds, s:
/// time constants 4× apart from 15 s and from 30 s. Every candidate is a
/// stretch of one of them.
pub const LADDERS_S: [&[f32]; 2] = [
    &[15.0, 60.0, 240.0, 960.0, 3840.0, 15360.0],
    &[30.0, 120.0, 480.0, 1920.0, 7680.0],
];

/// Candidate banks: (ladder, first filter, filters). 4× spacing spans the
/// coil's radial modes and the housing from seconds to hours without
/// filters so alike that their weights are not identified; which stretch
/// fits a gyro differs from unit to unit, so validation chooses. None
/// reaches the 15-s ladder's 4.3-h filter: chamber holds of an hour or two
/// never bring it near its steady state, so its weight is not identified,
/// and a slow in-use drift (a day cycle at 0.2 °C/min) drives it where no
/// training run went (on the bench's gyros it cost in-use accuracy there:
/// docs/decisions.md, "Measurements behind design choices").
pub const CANDIDATES: [(usize, usize, usize); 3] = [(1, 0, 5), (1, 0, 4), (0, 0, 5)];

/// Degrees of the Shupe gain g(T̂) tried: linear in T̂. A quadratic gain
/// validated better on held-out events of a chamber cycle (the same ramp
/// rate) and then extrapolated worse to fast in-use swings on the bench's
/// gyros; the fiber's gain drifts smoothly, so the simpler form is kept.
const GAIN_DEGREES: [usize; 1] = [1];
/// Length of the means the search fits on, s.
const SEARCH_MEAN_S: f64 = 10.0;
/// Length of the residual means validation scores, s (the cluster-STD window).
/// Temperature scale of the polynomial terms inside the fit, °C (conditioning only).
const TEMP_SCALE_C: f64 = 30.0;
/// Starting coil lags tried for the full fit (total over the filters), minutes.
const START_LAGS_MIN: [f64; 3] = [-0.1, -5.0, -20.0];
/// Residual, °/h per row, that a coil-lag weight of one filter time constant
/// (or a gain slope of [`GAIN_PRIOR_PER_C`]) costs ([`prior`]) when the
/// training runs hold too few thermal events to validate the lags on.
const LAG_PRIOR_DPH: f64 = 1e-3;
/// The gain slope the prior counts as one unit, per °C.
const GAIN_PRIOR_PER_C: f64 = 0.02;
/// Levenberg–Marquardt iterations at most.
const MAX_ITERATIONS: usize = 200;
/// Width of the band of T̂ the edge test ([`edge_test`]) holds out at each end
/// of the covered range, as a share of that range.
const EDGE_BAND_SHARE: f64 = 0.3;
/// The cubic is continued past an edge only where it predicts the held-out
/// band with at most this share of the tangent's RMS residual.
const EDGE_CUBIC_MAX_RATIO: f64 = 0.8;

/// The training data the search sees: 10-s means of the loop temperature,
/// every ladder filter's rate and the bias target.
#[derive(Clone, Debug, Default)]
struct LadderData {
    temp_c: Vec<f64>,
    /// Start of each mean on its run's clock, s.
    time_s: Vec<f64>,
    rates: Vec<[f64; BANK_FILTERS]>,
    y: Vec<f64>,
    run: Vec<usize>,
    /// Weight of the prior, °/h per row ([`prior`]); 0: none.
    lag_prior_dph: f64,
    /// Seconds of samples behind each mean, on average (10 s at 1 Hz and
    /// faster; more when a sample spans more than a block).
    mean_s: f64,
    /// Nominal length of each mean, s: [`SEARCH_MEAN_S`] rounded to whole
    /// blocks (the blocks of a long run are merged, [`Blocks::merge_pairs`]).
    row_s: f64,
}

impl LadderData {
    /// 10-s means of the blocks of a plain ladder bank (inputs [T, ΔT_1 …]),
    /// `block_s` asked for, never across a run boundary; blocks merged to
    /// more than 10 s stay on their own ([`Blocks::length_s`]).
    fn from_blocks(blocks: &Blocks, filters: usize, block_s: f64) -> LadderData {
        let length_s = blocks.length_s(block_s);
        let per_mean = (SEARCH_MEAN_S / length_s).round().max(1.0) as usize;
        let mut out = LadderData {
            row_s: per_mean as f64 * length_s,
            ..LadderData::default()
        };
        let mut start = 0;
        while start < blocks.len() {
            let mut end = start + 1;
            while end < blocks.len() && end - start < per_mean && blocks.run[end] == blocks.run[start] {
                end += 1;
            }
            let n = (end - start) as f64;
            let mean = |i: usize| blocks.x[start..end].iter().map(|r| r[i]).sum::<f64>() / n;
            let mut rates = [0.0; BANK_FILTERS];
            for (k, r) in rates.iter_mut().enumerate().take(filters) {
                *r = mean(1 + k);
            }
            out.temp_c.push(mean(0));
            out.time_s.push(blocks.time_s.get(start).copied().unwrap_or(f64::NAN));
            out.rates.push(rates);
            out.y.push(blocks.y[start..end].iter().sum::<f64>() / n);
            out.run.push(blocks.run[start]);
            start = end;
        }
        out.mean_s = blocks.usable_s / out.len().max(1) as f64;
        out
    }

    fn len(&self) -> usize {
        self.y.len()
    }
}

/// One candidate structure: which filters of which ladder, and the gain's degree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Structure {
    ladder: usize,
    first: usize,
    filters: usize,
    gain_degree: usize,
}

impl Structure {
    fn taus_s(&self) -> &'static [f32] {
        &LADDERS_S[self.ladder][self.first..self.first + self.filters]
    }

    /// Parameters: c0..c3, s_k, a_k, g₁ (.. g₂).
    fn params(&self) -> usize {
        4 + 2 * self.filters + self.gain_degree
    }

    fn label(&self) -> String {
        let taus: Vec<String> = self.taus_s().iter().map(|t| format!("{t:.0}")).collect();
        format!("τ {} s, gain degree {}", taus.join("/"), self.gain_degree)
    }
}

/// Fitted parameters of one structure (temperatures scaled by
/// [`TEMP_SCALE_C`]) and the range of T̂ its training rows covered.
#[derive(Clone, Debug)]
struct Fitted {
    p: Vec<f64>,
    range: CoilRange,
}

impl Fitted {
    fn new(s: &Structure, p: Vec<f64>, data: &LadderData, rows: &[usize]) -> Fitted {
        let range = coil_range(s, &p, data, rows);
        Fitted { p, range }
    }
}

/// The range of T̂ no extrapolation is needed within, °C.
type CoilRange = (f64, f64);
/// No limit: the rows a structure is fitted on lie within their own range.
const UNLIMITED: CoilRange = (f64::NEG_INFINITY, f64::INFINITY);

/// The estimated mean coil temperature T̂ at one row, °C.
fn coil_temp(s: &Structure, p: &[f64], temp_c: f64, rates: &[f64; BANK_FILTERS]) -> f64 {
    let n = s.filters;
    let d = &rates[s.first..s.first + n];
    temp_c + p[4 + n..4 + 2 * n].iter().zip(d).map(|(a, d)| a * d).sum::<f64>()
}

/// The range of T̂ over `rows`, °C.
fn coil_range(s: &Structure, p: &[f64], data: &LadderData, rows: &[usize]) -> CoilRange {
    rows.iter()
        .map(|&i| coil_temp(s, p, data.temp_c[i], &data.rates[i]))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| (lo.min(t), hi.max(t)))
}

/// The model's value and its Jacobian row at one data row; past `range`
/// the static cubic continues along its tangent, as the deployed bank does
/// ([`rbf_core::lag_bank`]).
fn predict_row(
    s: &Structure,
    p: &[f64],
    t0: f64,
    range: CoilRange,
    temp_c: f64,
    rates: &[f64; BANK_FILTERS],
    jac: Option<&mut [f64]>,
) -> f64 {
    let n = s.filters;
    let d = &rates[s.first..s.first + n];
    let (c, rest) = p.split_at(4);
    let (w, rest) = rest.split_at(n);
    let g = &rest[n..];
    let t_hat = coil_temp(s, p, temp_c, rates);
    let u = (t_hat - t0) / TEMP_SCALE_C;
    let uc = (t_hat.max(range.0).min(range.1) - t0) / TEMP_SCALE_C;
    let beyond = u - uc;
    let (p2, p3) = (uc * (uc + 2.0 * beyond), uc * uc * (uc + 3.0 * beyond));
    // The gain is of the coil's temperature ([`GainOf::Coil`]).
    let v = u;
    let gain = 1.0
        + g.iter()
            .enumerate()
            .map(|(j, gj)| gj * v.powi(j as i32 + 1))
            .sum::<f64>();
    let rate_sum: f64 = w.iter().zip(d).map(|(w, d)| w * d).sum();
    let value = c[0] + c[1] * u + c[2] * p2 + c[3] * p3 + gain * rate_sum;
    if let Some(jac) = jac {
        // A coil lag moves both the static curve's argument and the gain's.
        let gain_slope: f64 = g
            .iter()
            .enumerate()
            .map(|(j, gj)| (j + 1) as f64 * gj * v.powi(j as i32))
            .sum();
        let slope = (c[1] + uc * (2.0 * c[2] + 3.0 * uc * c[3]) + gain_slope * rate_sum) / TEMP_SCALE_C;
        jac[0] = 1.0;
        jac[1] = u;
        jac[2] = p2;
        jac[3] = p3;
        for k in 0..n {
            jac[4 + k] = gain * d[k];
            jac[4 + n + k] = slope * d[k];
        }
        for j in 0..g.len() {
            jac[4 + 2 * n + j] = v.powi(j as i32 + 1) * rate_sum;
        }
    }
    value
}

/// Sum of squared residuals over `rows`.
fn sse(s: &Structure, p: &[f64], t0: f64, data: &LadderData, rows: &[usize]) -> f64 {
    rows.iter()
        .map(|&i| (predict_row(s, p, t0, UNLIMITED, data.temp_c[i], &data.rates[i], None) - data.y[i]).powi(2))
        .sum()
}

/// What the joint fit minimises: the residuals over `rows` plus the prior.
fn cost(s: &Structure, p: &[f64], t0: f64, data: &LadderData, rows: &[usize]) -> f64 {
    sse(s, p, t0, data, rows) + prior(s, p, data, rows.len()).0
}

/// The soft prior on the coil lags and the gain, (its cost, per parameter
/// its curvature, 0 where none). Each lag weight in units of its filter's
/// time constant, β_k = a_k / τ_k, is held near the physically plausible
/// |β| ≲ 1 (T̂ a mixture of lags of T), and the gain's slope near
/// |g₁| ≲ [`GAIN_PRIOR_PER_C`] (the fiber's Shupe coefficient drifts by a
/// percent or two per °C), each by a cost of `data.lag_prior_dph`² per row
/// per unit². Used only where the runs hold too few thermal events to hold
/// any out: such runs barely identify the lags and otherwise give weights
/// of opposite sign and hours in size that cancel on the training run and
/// nowhere else, and a gain of T̂ times those lags is a product of rates a
/// faster ramp then meets at a size no training sample had. Where events
/// can be held out, validation judges the lags instead (a prior there
/// validated worse on independent plants; docs/methods.md).
fn prior(s: &Structure, p: &[f64], data: &LadderData, rows: usize) -> (f64, Vec<f64>) {
    let weight = rows as f64 * data.lag_prior_dph * data.lag_prior_dph;
    let mut curvature = vec![0.0; s.params()];
    if weight == 0.0 {
        return (0.0, curvature);
    }
    let mut cost = 0.0;
    let mut hold = |j: usize, per_unit: f64| {
        let units = p[j] * per_unit;
        cost += weight * units * units;
        curvature[j] = weight * per_unit * per_unit;
    };
    for (k, tau) in s.taus_s().iter().enumerate() {
        hold(4 + s.filters + k, 60.0 / f64::from(*tau));
    }
    // g₁ is fitted per TEMP_SCALE_C; g₂ per its square, held alike.
    for j in 0..s.gain_degree {
        hold(
            4 + 2 * s.filters + j,
            1.0 / (GAIN_PRIOR_PER_C * TEMP_SCALE_C).powi(j as i32 + 1),
        );
    }
    (cost, curvature)
}

/// Least squares of the linear parameters (c, s) with a and g held: the start of the joint fit.
fn linear_start(s: &Structure, lags_min: f64, t0: f64, data: &LadderData, rows: &[usize]) -> Option<Vec<f64>> {
    let n = s.filters;
    let mut p = vec![0.0; s.params()];
    p[4 + n..4 + 2 * n].iter_mut().for_each(|a| *a = lags_min / n as f64);
    let linear = 4 + n;
    let mut jac = vec![0.0; s.params()];
    let mut gram = DMatrix::<f64>::zeros(linear, linear);
    let mut aty = DVector::<f64>::zeros(linear);
    for &i in rows {
        predict_row(s, &p, t0, UNLIMITED, data.temp_c[i], &data.rates[i], Some(&mut jac));
        // The model is linear in (c, s): its Jacobian columns are the design.
        let row = DVector::from_column_slice(&jac[..linear]);
        gram += &row * row.transpose();
        aty += &row * data.y[i];
    }
    let trace = gram.trace() / linear as f64;
    for j in 0..linear {
        gram[(j, j)] += 1e-10 * trace;
    }
    let w = gram.cholesky()?.solve(&aty);
    p[..linear].copy_from_slice(w.as_slice());
    Some(p)
}

/// Levenberg–Marquardt from `p` on `rows`; returns the parameters and their cost.
///
/// Why not the `levenberg-marquardt` crate: it is MINPACK's `lmder`, which
/// takes the whole rows × parameters Jacobian and factors it by QR, with its
/// own trust-region step and column scaling. This fit sums JᵀJ row by row
/// (up to 32,768 blocks per ladder, for every structure, fold and start in
/// parallel) and steps by Marquardt's diagonal on a cost that includes the
/// prior ([`prior`]), so the crate would hold each fit's Jacobian in memory
/// and walk other steps: the fitted lags, and so every lag-bank blob, would
/// change in their last bits, where the same inputs must give the same blob.
/// (Not measured against it; a trial would be judged by `cargo xtask
/// bench-accuracy --in-use --designs 16` and the blobs' bytes.)
fn levenberg_marquardt(s: &Structure, mut p: Vec<f64>, t0: f64, data: &LadderData, rows: &[usize]) -> (Vec<f64>, f64) {
    let m = s.params();
    let mut current = cost(s, &p, t0, data, rows);
    let mut lambda = 1e-3;
    let mut jac = vec![0.0; m];
    for _ in 0..MAX_ITERATIONS {
        let mut jtj = DMatrix::<f64>::zeros(m, m);
        let mut jtr = DVector::<f64>::zeros(m);
        for &i in rows {
            let r = predict_row(s, &p, t0, UNLIMITED, data.temp_c[i], &data.rates[i], Some(&mut jac)) - data.y[i];
            let row = DVector::from_column_slice(&jac);
            jtj.syger(1.0, &row, &row, 1.0);
            jtr += &row * r;
        }
        let (_, curvature) = prior(s, &p, data, rows.len());
        for (j, c) in curvature.iter().enumerate() {
            jtj[(j, j)] += c;
            jtr[j] += c * p[j];
        }
        jtj.fill_upper_triangle_with_lower_triangle();
        let diag: Vec<f64> = (0..m).map(|j| jtj[(j, j)].max(1e-12)).collect();
        let mut improved = false;
        while lambda < 1e12 {
            let mut a = jtj.clone();
            for j in 0..m {
                a[(j, j)] += lambda * diag[j];
            }
            let Some(chol) = a.cholesky() else {
                lambda *= 4.0;
                continue;
            };
            let step = chol.solve(&(-&jtr));
            let trial: Vec<f64> = p.iter().zip(step.iter()).map(|(a, b)| a + b).collect();
            let trial_cost = cost(s, &trial, t0, data, rows);
            if trial_cost.is_finite() && trial_cost < current {
                let gain = (current - trial_cost) / current.max(f64::MIN_POSITIVE);
                p = trial;
                current = trial_cost;
                lambda = (lambda / 3.0).max(1e-12);
                improved = gain > 1e-10;
                break;
            }
            lambda *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (p, current)
}

/// The best of several starts on `rows`.
fn fit_structure(s: &Structure, t0: f64, data: &LadderData, rows: &[usize], starts: &[f64]) -> Option<Fitted> {
    starts
        .iter()
        .filter_map(|&lags| linear_start(s, lags, t0, data, rows))
        .map(|p| levenberg_marquardt(s, p, t0, data, rows))
        .filter(|(_, c)| c.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(p, _)| Fitted::new(s, p, data, rows))
}

/// The held-out score of `fits` (each fitted without its held-out rows):
/// [`super::events::held_out_rms`] of the residuals on those rows.
fn score(s: &Structure, fits: &[(Fitted, Vec<usize>)], t0: f64, data: &LadderData) -> f64 {
    let held: Vec<&[usize]> = fits.iter().map(|(_, rows)| rows.as_slice()).collect();
    super::events::held_out_rms(&held, &data.run, data.row_s, |fold, i| {
        let fitted = &fits[fold].0;
        data.y[i] - predict_row(s, &fitted.p, t0, fitted.range, data.temp_c[i], &data.rates[i], None)
    })
}

/// One candidate's result in the search.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CandidateScore {
    /// The candidate: time constants and gain degree.
    pub label: String,
    /// Validation RMS of 100-s means of the residual, °/h.
    pub validation_rms_dph: f64,
}

/// What the lag-bank search chose and why.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BankSearch {
    /// Every candidate's validation score, in the order tried.
    pub candidates: Vec<CandidateScore>,
    /// Index of the chosen candidate.
    pub chosen: usize,
    /// How validation held data out.
    pub folds: FoldKind,
    /// Number of folds (or validation runs).
    pub fold_count: usize,
    /// Thermal events found in the training runs.
    pub events: usize,
    /// What the training runs covered of what the bank needs.
    pub coverage: Coverage,
    /// How far past each end of the covered range of T̂ the static cubic is
    /// followed before it continues along its tangent.
    pub extrapolation: Extrapolation,
    /// Whether, and why, the soft prior held the coil lags (`prior`).
    pub lag_prior: LagPrior,
}

/// Whether the soft prior on the coil lags and the gain (`prior`) was applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LagPrior {
    /// Not applied: validation on held-out events or runs judged the lags.
    None,
    /// The runs hold too few thermal events to validate the lags on.
    FewEvents,
    /// Without it no candidate's lags were ones the blob carries (hours of
    /// opposite sign, or over a day per °C/min), so the search ran again with it.
    NoBankWithout,
}

/// The edge test's verdict at both ends of the covered range of T̂.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Extrapolation {
    /// The range of T̂ the training runs covered, °C.
    pub covered_c: (f64, f64),
    /// Width of the band held out at each end, °C.
    pub band_c: f64,
    /// Below the covered range.
    pub lower: EdgeTest,
    /// Above it.
    pub upper: EdgeTest,
}

/// One end's edge test: the band beyond that end held out, the structure
/// refitted on the rest, the band predicted both ways.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct EdgeTest {
    /// RMS residual on the band with the cubic's tangent past the refit's edge, °/h
    /// (NaN: too few rows on either side to test).
    pub tangent_rms_dph: f64,
    /// RMS residual on the band with the cubic itself, °/h.
    pub cubic_rms_dph: f64,
    /// How far past the covered range the deployed cubic is followed, °C
    /// (the band's width where the cubic won, else 0).
    pub reach_c: f64,
}

impl BankSearch {
    /// The chosen candidate's validation RMS of 100-s means on the held-out
    /// folds, °/h (what chose the structure; the in-use forecast is
    /// [`super::forecast`]'s).
    pub fn held_out_rms_dph(&self) -> f64 {
        self.candidates
            .get(self.chosen)
            .map_or(f64::NAN, |c| c.validation_rms_dph)
    }
}

/// Plain banks over each ladder: the configurations whose blocks the search reads.
pub fn ladder_configs() -> Vec<FeatureConfig> {
    LADDERS_S
        .iter()
        .filter_map(|taus| LagBank::plain(taus, 0.0).map(FeatureConfig::lag_bank))
        .collect()
}

/// Chooses and identifies the lag bank for `train` (validated on `validate`
/// when given, else on held-out thermal events).
pub fn search<T: RunSet + ?Sized, V: RunSet + ?Sized>(
    train: &T,
    validate: &V,
    opts: &FitOptions,
    own: &LagBankOptions,
    progress: &Progress,
) -> anyhow::Result<(LagBank, BankSearch)> {
    let configs = ladder_configs();
    train.prepare(&configs, opts.block_s)?;
    validate.prepare(&configs, opts.block_s)?;
    let mut ladders = Vec::new();
    for (config, taus) in configs.iter().zip(LADDERS_S) {
        let blocks = train.block_means(config, opts.block_s)?;
        super::check_excitation(&blocks, config.set, own.centers, opts.block_s)?;
        let data = LadderData::from_blocks(&blocks, taus.len(), opts.block_s);
        let val = if validate.count() > 0 {
            let b = validate.block_means(config, opts.block_s)?;
            Some(LadderData::from_blocks(&b, taus.len(), opts.block_s))
        } else {
            None
        };
        ladders.push((data, val));
    }
    let (t_lo, t_hi) = ladders[0]
        .0
        .temp_c
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
            (lo.min(t), hi.max(t))
        });
    // T₀ on a 0.5 °C grid: the blob stores it in f32, the fit uses the same value.
    let t0 = (0.5 * (t_lo + t_hi) * 2.0).round() / 2.0;
    let folds: Vec<Folds> = ladders
        .iter()
        .map(|(d, _)| thermal_folds(&d.temp_c, &d.run, d.row_s, opts.folds))
        .collect();
    let coverage = {
        let data = &ladders[0].0;
        let rates: Vec<&[f64]> = data.rates.iter().map(|r| &r[..LADDERS_S[0].len()]).collect();
        let taus: Vec<f64> = LADDERS_S[0].iter().map(|&t| f64::from(t)).collect();
        // The 960-s filter tells a settled level from a ramp.
        let mut coverage = Coverage::of_means(&data.temp_c, &rates, &data.run, &taus, 3, data.mean_s, folds[0].events);
        coverage.settled_c = settled_levels_c(&data.time_s, &data.temp_c, &data.run, data.row_s);
        coverage
    };
    let mut lag_prior = LagPrior::None;
    for ((data, val), f) in ladders.iter_mut().zip(&folds) {
        if val.is_none() && f.kind == FoldKind::Contiguous {
            data.lag_prior_dph = LAG_PRIOR_DPH;
            lag_prior = LagPrior::FewEvents;
        }
    }
    let structures: Vec<Structure> = CANDIDATES
        .iter()
        .flat_map(|&(ladder, first, filters)| {
            GAIN_DEGREES.iter().map(move |&gain_degree| Structure {
                ladder,
                first,
                filters,
                gain_degree,
            })
        })
        .collect();
    // Every candidate fitted and scored on `ladders`, and the best the blob can carry.
    let identify = |ladders: &[(LadderData, Option<LadderData>)]| {
        progress.start("lag-bank structure", structures.len() as u64);
        let results = parallel_map(&structures, |s| {
            let (data, val) = &ladders[s.ladder];
            let all: Vec<usize> = (0..data.len()).collect();
            let full = fit_structure(s, t0, data, &all, &START_LAGS_MIN);
            let score = match (&full, val) {
                (None, _) => f64::INFINITY,
                (Some(full), Some(val)) => {
                    let rows: Vec<usize> = (0..val.len()).collect();
                    score(s, &[(full.clone(), rows)], t0, val)
                }
                (Some(full), None) => {
                    // Each fold starts from the full fit's solution (one start).
                    let f = &folds[s.ladder];
                    let fits: Vec<(Fitted, Vec<usize>)> = (0..f.held_out.len())
                        .filter_map(|k| {
                            let rows = f.train_rows(k, data.len());
                            let (p, c) = levenberg_marquardt(s, full.p.clone(), t0, data, &rows);
                            c.is_finite()
                                .then(|| (Fitted::new(s, p, data, &rows), f.held_out[k].clone()))
                        })
                        .collect();
                    score(s, &fits, t0, data)
                }
            };
            progress.inc();
            (full, score)
        });
        progress.finish();
        let chosen = results
            .iter()
            .enumerate()
            // Only banks the blob can carry: a candidate whose identified coil
            // lags exceed a day per °C/min is passed over, not deployed.
            .filter(|(i, (f, sc))| {
                sc.is_finite() && f.as_ref().is_some_and(|f| to_bank(&structures[*i], f, t0).is_some())
            })
            .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
            .map(|(i, _)| i);
        (results, chosen)
    };
    let (mut results, mut chosen) = identify(&ladders);
    if chosen.is_none() && ladders.iter().any(|(d, _)| d.lag_prior_dph == 0.0) {
        // Without the prior every candidate's lags ran to hours of opposite
        // sign or past what the blob carries (a loop sensor deep in the coil,
        // design 1 of the simulator, after some plans): the soft prior holds
        // each lag near its filter's time constant, as for runs too short to
        // validate on, and the structure choice below still weighs the
        // response bank against it.
        for (data, _) in &mut ladders {
            data.lag_prior_dph = LAG_PRIOR_DPH;
        }
        lag_prior = LagPrior::NoBankWithout;
        (results, chosen) = identify(&ladders);
    }
    let chosen = chosen.ok_or_else(|| {
        anyhow::anyhow!(
            "no lag-bank structure could be identified from the training runs (singular data, or coil lags over a day)"
        )
    })?;
    let s = structures[chosen];
    // The chosen bank's blocks are cut from its ladder's; the other ladder's
    // are not read again.
    let unused: Vec<FeatureConfig> = (0..configs.len())
        .filter(|&l| l != s.ladder)
        .map(|l| configs[l])
        .collect();
    train.release(&unused, opts.block_s);
    validate.release(&unused, opts.block_s);
    let mut fitted = results[chosen].0.clone().expect("chosen among fitted candidates");
    let extrapolation = edge_test(&s, &fitted, t0, &ladders[s.ladder].0);
    // Followed past the covered range at most to the blob's limit: with coil
    // lags of hours the estimated coil temperature spans hundreds of °C, and
    // a band's width past it would leave a bank no blob carries.
    let limit_c = f64::from(rbf_core::lag_bank::MAX_TEMP_C);
    fitted.range = (
        (fitted.range.0 - extrapolation.lower.reach_c).max(-limit_c),
        (fitted.range.1 + extrapolation.upper.reach_c).min(limit_c),
    );
    let bank = to_bank(&s, &fitted, t0).ok_or_else(|| {
        anyhow::anyhow!("the identified lag bank is out of the firmware's range (coil lags over a day per °C/min)")
    })?;
    let (fold_kind, fold_count) = if validate.count() > 0 {
        (FoldKind::Runs, validate.count())
    } else {
        (folds[s.ladder].kind.clone(), folds[s.ladder].held_out.len())
    };
    Ok((
        bank,
        BankSearch {
            candidates: structures
                .iter()
                .zip(&results)
                .map(|(s, (_, sc))| CandidateScore {
                    label: s.label(),
                    validation_rms_dph: *sc,
                })
                .collect(),
            chosen,
            folds: fold_kind,
            fold_count,
            events: folds[s.ladder].events,
            coverage,
            extrapolation,
            lag_prior,
        },
    ))
}

/// The edge test: how far past the covered range of T̂ the static cubic is
/// trusted. At each end, the outer [`EDGE_BAND_SHARE`] of the range is held
/// out, the structure refitted on the rest (from the full fit), and the band
/// predicted twice: with the cubic continuing along its tangent past the
/// refit's edge (the deployed default) and with the cubic itself. Where the
/// cubic predicts the band with at most [`EDGE_CUBIC_MAX_RATIO`] of the
/// tangent's residual, the deployed cubic is followed one band's width past
/// that end. A chamber run that never soaks the coil at its extremes (short
/// holds, a slow coil) leaves in-use temperatures 10–20 °C outside the range;
/// whether the cubic holds there differs from gyro to gyro, and this is the
/// part of the training data that can tell.
fn edge_test(s: &Structure, full: &Fitted, t0: f64, data: &LadderData) -> Extrapolation {
    let (lo, hi) = full.range;
    let band = EDGE_BAND_SHARE * (hi - lo);
    let t_hat: Vec<f64> = (0..data.len())
        .map(|i| coil_temp(s, &full.p, data.temp_c[i], &data.rates[i]))
        .collect();
    let end = |upper: bool| -> EdgeTest {
        let inside = |t: f64| if upper { t <= hi - band } else { t >= lo + band };
        let (rows, held): (Vec<usize>, Vec<usize>) = (0..data.len()).partition(|&i| inside(t_hat[i]));
        let untested = EdgeTest {
            tangent_rms_dph: f64::NAN,
            cubic_rms_dph: f64::NAN,
            reach_c: 0.0,
        };
        // A band of under ten 10-s means is no evidence either way.
        if held.len() < 10 || rows.len() < s.params() * 4 {
            return untested;
        }
        let (p, cost) = levenberg_marquardt(s, full.p.clone(), t0, data, &rows);
        if !cost.is_finite() {
            return untested;
        }
        let refit = Fitted::new(s, p, data, &rows);
        let rms = |range: CoilRange| {
            let sse: f64 = held
                .iter()
                .map(|&i| {
                    (data.y[i] - predict_row(s, &refit.p, t0, range, data.temp_c[i], &data.rates[i], None)).powi(2)
                })
                .sum();
            (sse / held.len() as f64).sqrt()
        };
        let (tangent, cubic) = (rms(refit.range), rms(UNLIMITED));
        EdgeTest {
            tangent_rms_dph: tangent,
            cubic_rms_dph: cubic,
            reach_c: if cubic <= EDGE_CUBIC_MAX_RATIO * tangent {
                band
            } else {
                0.0
            },
        }
    };
    Extrapolation {
        covered_c: (lo, hi),
        band_c: band,
        lower: end(false),
        upper: end(true),
    }
}

/// The deployable bank of a fitted structure: time constants, coil lags and
/// gain in the blob's units, the static part as T̂ and its powers.
fn to_bank(s: &Structure, fitted: &Fitted, t0: f64) -> Option<LagBank> {
    let n = s.filters;
    let mut bank = LagBank::plain(s.taus_s(), t0 as f32)?;
    for (dst, a) in bank.coil_lag_min.iter_mut().zip(&fitted.p[4 + n..4 + 2 * n]) {
        *dst = *a as f32;
    }
    let g = &fitted.p[4 + 2 * n..];
    bank.gain_per_c = g.first().map_or(0.0, |g1| (g1 / TEMP_SCALE_C) as f32);
    bank.gain_per_c2 = g.get(1).map_or(0.0, |g2| (g2 / (TEMP_SCALE_C * TEMP_SCALE_C)) as f32);
    bank.static_degree = rbf_core::lag_bank::MAX_STATIC_DEGREE;
    bank.gain_of = GainOf::Coil;
    (bank.coil_min_c, bank.coil_max_c) = (fitted.range.0 as f32, fitted.range.1 as f32);
    bank.is_valid().then_some(bank)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows of a synthetic gyro whose bias is exactly the bank's structure.
    /// Past `static_range` the truth's static cubic continues along its
    /// tangent (as a deployed bank past its covered range).
    fn synthetic(s: &Structure, truth: &[f64], t0: f64, static_range: CoilRange) -> LadderData {
        let mut data = LadderData {
            row_s: SEARCH_MEAN_S,
            ..LadderData::default()
        };
        let mut filters = [0.0f64; BANK_FILTERS];
        let taus = LADDERS_S[s.ladder];
        let mut temp = 20.0;
        for i in 0..20_000 {
            // A slow triangle wave with holds: ramps of 1 °C/min.
            let phase = (i / 900) % 8;
            let step = match phase {
                0 | 1 => 1.0 / 6.0,
                4 | 5 => -1.0 / 6.0,
                _ => 0.0,
            };
            temp += step;
            let mut rates = [0.0; BANK_FILTERS];
            for (k, tau) in taus.iter().enumerate() {
                let tau = f64::from(*tau);
                let r = (temp - filters[k]) / (tau + 10.0);
                filters[k] += 10.0 * r;
                rates[k] = r * 60.0;
            }
            data.y.push(predict_row(s, truth, t0, static_range, temp, &rates, None));
            data.temp_c.push(temp);
            data.rates.push(rates);
            data.run.push(0);
        }
        data
    }

    /// The 30 s … 1920 s filters of the second ladder with a linear gain.
    const FOUR_FILTERS: Structure = Structure {
        ladder: 1,
        first: 0,
        filters: 4,
        gain_degree: 1,
    };

    #[test]
    fn the_joint_fit_recovers_a_structure_from_noise_free_data() {
        let s = FOUR_FILTERS;
        // c, s (°/h per °C/min), a (min), g₁; coil lags of a physical size
        // (|a_k| below one filter time constant), which the lag prior leaves alone.
        let truth = [
            0.1, 0.05, 0.02, -0.01, 0.2, 0.1, -0.05, 0.02, -0.25, -1.0, -4.0, -10.0, 0.3,
        ];
        let data = synthetic(&s, &truth, 20.0, UNLIMITED);
        let rows: Vec<usize> = (0..data.len()).collect();
        let fitted = fit_structure(&s, 20.0, &data, &rows, &START_LAGS_MIN).unwrap();
        let bias_rms = (data.y.iter().map(|y| y * y).sum::<f64>() / data.len() as f64).sqrt();
        let rms = (sse(&s, &fitted.p, 20.0, &data, &rows) / data.len() as f64).sqrt();
        assert!(rms < 1e-3 * bias_rms, "residual RMS {rms} of a {bias_rms} °/h bias");
        // On ramps the total coil lag is what the data pins down (the 15-s
        // filter's share of it barely shows); the slowest lag on its own too.
        let (total, want_total): (f64, f64) = (fitted.p[8..12].iter().sum(), truth[8..12].iter().sum());
        assert!(
            (total - want_total).abs() < 0.02 * want_total.abs(),
            "total lag {total} min, truth {want_total} min"
        );
        assert!(
            (fitted.p[11] - truth[11]).abs() < 0.05 * truth[11].abs(),
            "slowest lag {} min",
            fitted.p[11]
        );
    }

    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "the reach is the band's width itself or exactly 0: exactness is what this test guards"
    )]
    fn the_edge_test_follows_the_cubic_only_where_the_held_out_band_does() {
        let s = FOUR_FILTERS;
        // A strongly curved static part (c₂, c₃ in units of 30 °C) on the
        // synthetic triangle wave, 20 … 320 °C.
        let truth = [
            0.1, 0.5, 0.3, 0.05, 0.2, 0.1, -0.05, 0.02, -0.25, -1.0, -4.0, -10.0, 0.3,
        ];
        let rows = |data: &LadderData| (0..data.len()).collect::<Vec<_>>();
        // A true cubic everywhere: both held-out bands are the cubic's, so
        // it is followed one band past both ends.
        let cubic = synthetic(&s, &truth, 150.0, UNLIMITED);
        let full = fit_structure(&s, 150.0, &cubic, &rows(&cubic), &START_LAGS_MIN).unwrap();
        let x = edge_test(&s, &full, 150.0, &cubic);
        assert!((x.band_c - 0.3 * (x.covered_c.1 - x.covered_c.0)).abs() < 1e-9);
        for end in [&x.lower, &x.upper] {
            assert!(end.cubic_rms_dph < 0.1 * end.tangent_rms_dph, "{x:?}");
            assert_eq!(end.reach_c, x.band_c, "{x:?}");
        }
        // A curve that straightens out in the upper band: the cubic would
        // overshoot there, so the upper end keeps the tangent.
        let edge = (f64::NEG_INFINITY, x.covered_c.1 - x.band_c);
        let straightening = synthetic(&s, &truth, 150.0, edge);
        let full = fit_structure(&s, 150.0, &straightening, &rows(&straightening), &START_LAGS_MIN).unwrap();
        let x = edge_test(&s, &full, 150.0, &straightening);
        assert!(x.upper.tangent_rms_dph < x.upper.cubic_rms_dph, "{x:?}");
        assert_eq!(x.upper.reach_c, 0.0, "{x:?}");
    }

    #[test]
    fn the_analytic_jacobian_is_the_model_s_derivative() {
        let s = Structure {
            gain_degree: 2,
            ..FOUR_FILTERS
        };
        // Curved static part, sizeable lags and a curved gain of T̂: every
        // cross term (a lag moving both the cubic's and the gain's argument) shows.
        let p = [
            0.1, 0.4, 0.3, -0.2, 0.2, 0.1, -0.05, 0.02, -0.5, -2.0, -6.0, -15.0, 0.3, -0.2,
        ];
        let rates = [0.8, 0.6, 0.4, 0.2, 0.0, 0.0, 0.0, 0.0];
        for temp_c in [-30.0, 5.0, 47.0] {
            let mut jac = [0.0; 14];
            predict_row(&s, &p, 20.0, UNLIMITED, temp_c, &rates, Some(&mut jac));
            for (j, analytic) in jac.iter().enumerate() {
                let h = 1e-6 * p[j].abs().max(1.0);
                let at = |d: f64| {
                    let mut q = p;
                    q[j] += d;
                    predict_row(&s, &q, 20.0, UNLIMITED, temp_c, &rates, None)
                };
                let numeric = (at(h) - at(-h)) / (2.0 * h);
                assert!(
                    (analytic - numeric).abs() <= 1e-6 * numeric.abs().max(1.0),
                    "∂/∂p[{j}] at {temp_c} °C: analytic {analytic}, numeric {numeric}"
                );
            }
        }
    }

    #[test]
    fn the_deployed_bank_carries_the_fitted_lags_and_gain_in_blob_units() {
        let s = Structure {
            ladder: 0,
            first: 1,
            filters: 3,
            gain_degree: 2,
        };
        let p = vec![0.0, 1.0, 0.0, 0.0, 0.1, 0.2, 0.3, -2.0, -6.0, -12.0, 0.6, 0.9];
        let bank = to_bank(
            &s,
            &Fitted {
                p,
                range: (-10.0, 40.0),
            },
            22.5,
        )
        .unwrap();
        assert_eq!(bank.taus(), &[60.0, 240.0, 960.0]);
        assert_eq!(bank.coil_lags(), &[-2.0, -6.0, -12.0]);
        assert!((bank.gain_per_c - 0.02).abs() < 1e-9);
        assert!((bank.gain_per_c2 - 0.001).abs() < 1e-9);
        assert!((bank.ref_c - 22.5).abs() < 1e-6);
        assert_eq!(bank.static_degree, 3);
        assert_eq!((bank.coil_min_c, bank.coil_max_c), (-10.0, 40.0));
        assert_eq!(bank.gain_of, GainOf::Coil, "the gain the search fitted is of T̂");
    }
}
