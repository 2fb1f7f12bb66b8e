//! `--method svr-pso`: the RLG paper's model (Li et al., Sensors 2015), an
//! ε-SVR with a Gaussian kernel ([`svr`]) whose σ, C and ε a particle
//! swarm ([`pso`]) tunes on contiguous validation folds, compiled into
//! the firmware's RBF network: an SVR's kernel expansion is a Gaussian RBF
//! network with one shared width, so the firmware runs it unchanged.
//!
//! Inputs: on runs with two or more thermometers (`temp_a` … `temp_h`), the
//! paper's multi-point inputs: every temperature and pairwise gradient is a
//! candidate, its 100-s block means are correlated with the bias
//! ([`crate::dataset::gradients`], the paper's Table 3). By default the thermometers
//! are then chosen by validation ([`super::thermometer_search`]: correlation
//! favours sensors whose lead over the coil does not carry to other ramp
//! rates); with a correlation rule ([`SvrInputs::Rule`]) the paper's
//! selection picks the inputs instead. rbf-core computes the inputs per
//! sample ([`rbf_core::FeatureSet::MultiPoint`]). On
//! single-thermometer runs, the IFOG paper's (T, ΔT, T×ΔT) (one ΔT window,
//! the middle of `--rate-window`'s list).
//!
//! Deployment: when the support vectors exceed the centre budget
//! (`--centers K`, else `--max-centers`, at most the firmware's
//! [`rbf_core::MAX_CENTERS`]), orthogonal least squares re-selects that many
//! of them as centres and the weights are refitted (ridge) on the training
//! blocks; [`SvrChoice`] reports what that costs on the validation folds.

pub mod pso;
pub mod svr;

use nalgebra::{DMatrix, DVector};
use rbf_core::features::{Probe, Probes};
use rbf_core::model::{ModelBody, ModelInfo};
use rbf_core::rbf::{RbfNetwork, RbfParams};
use rbf_core::{FeatureConfig, FeatureSet, MAX_CENTERS, MAX_INPUTS, Model};

use self::pso::PsoOptions;
use self::svr::{Svr, SvrParams};
use super::linalg::{FeatureRow, GramStats, InputShape, design, ridge_solve};
use super::scoring::cluster_rms;
use super::svr_data::SvrData;
use super::thermometer_search::{self, SubsetScore};
use super::{FitOptions, Progress, SvrInputs, SvrOptions, check_excitation, deploy_ranges, rbf, serial};
use crate::dataset::RunSet;
use crate::dataset::gradients::{self, Candidate, CorrelationTable, MultiBlocks};

/// The deployed network's centre budget.
fn center_budget(svr: &SvrOptions) -> usize {
    svr.centers.most().clamp(1, MAX_CENTERS)
}

/// SMO steps per solve before it settles for the best reached.
const MAX_SMO_STEPS: usize = 200_000;
/// Search box, log₁₀: σ (normalised units), C, and ε relative to the target's STD.
const LOG_SIGMA: (f64, f64) = (-1.0, 1.3);
const LOG_C: (f64, f64) = (-2.0, 3.0);
const LOG_EPSILON: (f64, f64) = (-4.0, -0.5);
/// Ridge strength when the weights of a reduced network are refitted.
const REFIT_RIDGE: f64 = 1e-7;

/// Length of the correlation analysis's blocks, s: the paper's 100 samples
/// at its 1 Hz.
const CORRELATION_BLOCK_S: f64 = 100.0;
/// Subsets of thermometers kept in the report of a validated choice.
const REPORTED_SUBSETS: usize = 8;

/// How the multi-point inputs were chosen.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct InputSelection {
    /// Correlation of every candidate with the bias (the paper's Table 3).
    pub table: CorrelationTable,
    /// The candidates chosen, in the model's input order.
    pub selected: Vec<Candidate>,
    /// The best subsets of thermometers by validation, best first, when the
    /// inputs were chosen that way (empty for a correlation rule or `--inputs`).
    pub ranking: Vec<SubsetScore>,
}

/// What the swarm chose and what deployment cost.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SvrChoice {
    /// The model's inputs with units.
    pub inputs: Vec<String>,
    /// Multi-point runs: the correlation analysis behind the inputs.
    pub selection: Option<InputSelection>,
    /// ΔT derivative-filter time constant, s (single-point inputs; 0 for multi-point).
    pub rate_window_s: f32,
    /// The SVR's hyper-parameters (σ in normalised units, ε in °/h).
    pub params: SvrParams,
    /// Support vectors of the final SVR.
    pub support_vectors: usize,
    /// Centres of the deployed network (≤ the firmware's capacity).
    pub centers: usize,
    /// Validation RMS of the SVR's 100-s cluster means on the PSO's folds
    /// (offset removed per fold), °/h.
    pub validation_rms_dph: f64,
    /// The same for the deployed network refitted on each fold's training part
    /// (equal to the SVR's when no reduction was needed), °/h: the swarm's fitness.
    pub deployed_validation_rms_dph: f64,
    /// Swarm settings.
    pub pso: PsoOptions,
    /// Swarm's best fitness after each iteration (validation RMS, °/h).
    pub pso_history: Vec<f64>,
}

/// Fits the RLG paper's model on `train` (PSO fitness on contiguous folds).
pub fn fit<T: RunSet + ?Sized>(
    train: &T,
    opts: &FitOptions,
    svr: &SvrOptions,
    progress: &Progress,
) -> anyhow::Result<(Model, SvrChoice)> {
    let (features, selection) = choose_inputs(train, opts, svr, progress)?;
    // Multi-point inputs get a linear part: gradients grow in proportion to
    // the ramp rate, and it carries the model past the training ramps. On the
    // single-point (T, ΔT, T×ΔT) it extrapolates worse than the paper's pure
    // ε-SVR, so that stays pure (figures: docs/decisions.md, "Measurements
    // behind design choices").
    let partially_linear = selection.is_some();
    let set = features.set;
    let window = features.rate_window_s;
    let blocks = train.block_means(&features, opts.block_s)?;
    if selection.is_none() {
        check_excitation(&blocks, set, svr.centers.fixed(), opts.block_s)?;
    }
    let data = SvrData::new(&blocks, opts.block_s)?;
    let SvrData { norm, x, y, dims, .. } = &data;
    let dims = *dims;
    let params_at = |p: &[f64]| SvrParams {
        sigma: 10f64.powf(p[0]),
        c: 10f64.powf(p[1]),
        epsilon: 10f64.powf(p[2]) * data.y_std,
    };
    let budget = center_budget(svr);
    // The swarm tunes what is deployed: the network within the firmware's
    // centre budget. Tuned on the SVR alone it drifted to wide kernels and
    // C at the box edge, whose hundreds of near-dependent support vectors
    // OLS could not reduce: the deployed network then validated far worse
    // than the SVR it was reduced from (docs/decisions.md, "Measurements
    // behind design choices").
    let score = |params: SvrParams| data.validation_rms(params, Some(budget), partially_linear);
    let pso_opts = PsoOptions::default();
    progress.start("tuning σ, C, ε (PSO)", pso_opts.iterations as u64 + 1);
    let lower = [LOG_SIGMA.0, LOG_C.0, LOG_EPSILON.0];
    let upper = [LOG_SIGMA.1, LOG_C.1, LOG_EPSILON.1];
    let result = pso::minimise(
        &lower,
        &upper,
        &pso_opts,
        |swarm| crate::parallel::parallel_map(swarm, |p| score(params_at(p))),
        || progress.inc(),
    );
    progress.finish();
    if !result.best_cost.is_finite() {
        anyhow::bail!("no SVR could be fitted (singular or empty data)");
    }
    let params = params_at(&result.best);
    let svr = fit_svr(x, y, dims, params, partially_linear);
    let deployed = deployable(&svr, x, y, budget)?;
    // What the reduction cost, on the same folds: the SVR's own error.
    let validation_rms_dph = if svr.support.len() > budget {
        data.validation_rms(params, None, partially_linear)
    } else {
        result.best_cost
    };
    let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let flat_centers: Vec<f32> = deployed
        .support
        .iter()
        .flat_map(|c| c[..dims].iter().map(|&v| v as f32))
        .collect();
    let net = RbfNetwork::new(&RbfParams {
        offset: &to_f32(&norm.offset),
        scale: &to_f32(&norm.scale),
        kernel_inputs: dims,
        centers: &flat_centers,
        widths: &vec![params.sigma as f32; deployed.support.len()],
        weights: &to_f32(&deployed.coef),
        linear: &to_f32(&deployed.linear),
        constant: deployed.bias as f32,
    })
    .map_err(|e| anyhow::anyhow!("the compiled SVR is not deployable: {e}"))?;
    let info = ModelInfo { serial: serial(opts)? };
    let model = Model::new(features, &deploy_ranges(&blocks), ModelBody::Rbf(net), info)
        .map_err(|e| anyhow::anyhow!("the compiled SVR is not deployable: {e}"))?;
    let choice = SvrChoice {
        inputs: set.names().map(|n| n.to_string()).collect(),
        selection,
        rate_window_s: window,
        params,
        support_vectors: svr.support.len(),
        centers: deployed.support.len(),
        validation_rms_dph,
        deployed_validation_rms_dph: result.best_cost,
        pso: pso_opts,
        pso_history: result.history,
    };
    Ok((model, choice))
}

impl SvrData {
    /// Mean over the folds of the validation RMS (100-s clusters, offset
    /// removed per fold) of the SVR fitted on each fold's training part, °/h;
    /// with `budget`, of the network deployed within that many centres (+∞
    /// where it cannot be built). The PSO's fitness and the cost of deployment.
    fn validation_rms(&self, params: SvrParams, budget: Option<usize>, partially_linear: bool) -> f64 {
        let (x, y) = (&self.x, &self.y);
        self.folds
            .iter()
            .map(|f| {
                let (fx, fy) = pick(x, y, &f.train);
                let svr = fit_svr(&fx, &fy, self.dims, params, partially_linear);
                let model = match budget {
                    None => svr,
                    Some(budget) => match deployable(&svr, &fx, &fy, budget) {
                        Ok(net) => net,
                        Err(_) => return f64::INFINITY,
                    },
                };
                cluster_rms(
                    f.validate.iter().map(|&i| y[i] - model.predict(&x[i])),
                    self.per_cluster,
                )
            })
            .sum::<f64>()
            / self.folds.len() as f64
    }
}

/// The ε-SVR, or its partially linear form ([`Svr::fit_partially_linear`]).
fn fit_svr(x: &[FeatureRow], y: &[f64], dims: usize, params: SvrParams, partially_linear: bool) -> Svr {
    if partially_linear {
        Svr::fit_partially_linear(x, y, dims, params, MAX_SMO_STEPS)
    } else {
        Svr::fit(x, y, dims, params, MAX_SMO_STEPS)
    }
}

/// The model's inputs: multi-point ones (named, chosen by validation or by a
/// correlation rule) where every training run has two or more thermometers,
/// else (T, ΔT, T×ΔT).
fn choose_inputs<T: RunSet + ?Sized>(
    train: &T,
    opts: &FitOptions,
    svr: &SvrOptions,
    progress: &Progress,
) -> anyhow::Result<(FeatureConfig, Option<InputSelection>)> {
    let thermometers = train.thermometers()?;
    if thermometers.len() < 2 {
        anyhow::ensure!(
            !matches!(svr.inputs, SvrInputs::Named(_)),
            "named multi-point inputs given, but the training runs do not all have two or more \
             of the thermometer columns temp_a … temp_h"
        );
        let windows = &svr.rate_windows_s;
        let window = windows.get(windows.len() / 2).copied().unwrap_or(60.0);
        let features = rbf::feature_config(FeatureSet::TempRateProduct, window, 1.0);
        train.prepare(&[features], opts.block_s)?;
        return Ok((features, None));
    }
    // Every thermometer's block means, computed by rbf-core as the firmware
    // would (TMP117 resolution, faults held); gradients are their differences.
    let sensors: Vec<usize> = thermometers.iter().collect();
    let all_temps: Vec<Probe> = sensors.iter().map(|&i| Probe::Temp(i as u8)).collect();
    let temps_config =
        FeatureConfig::multipoint(Probes::new(&all_temps).ok_or_else(|| anyhow::anyhow!("no thermometer to read"))?);
    train.prepare(&[temps_config], opts.block_s)?;
    let temps = train.block_means(&temps_config, opts.block_s)?;
    check_excitation(&temps, FeatureSet::Temp, svr.centers.fixed(), opts.block_s)?;
    let group = (CORRELATION_BLOCK_S / temps.length_s(opts.block_s)).round().max(1.0) as usize;
    let table = gradients::correlations(&MultiBlocks::from_blocks(&temps, &sensors, group));
    let mut ranking = Vec::new();
    let (selected, probes) = match &svr.inputs {
        SvrInputs::Named(given) => {
            for p in given {
                anyhow::ensure!(
                    p.thermometers().is_subset(thermometers),
                    "input {p}: the training runs lack that thermometer"
                );
            }
            let selected = given.iter().filter_map(|p| Candidate::of_probe(*p, &sensors)).collect();
            (selected, given.clone())
        }
        SvrInputs::BestSubset => {
            let all = thermometer_search::rank(&SvrData::new(&temps, opts.block_s)?, progress);
            let best = thermometer_search::choose(&all)
                .ok_or_else(|| anyhow::anyhow!("no subset of the thermometers predicts the bias (singular data)"))?;
            let selected: Vec<Candidate> = best.sensors.iter().map(|&k| Candidate { i: k, j: k }).collect();
            let probes = selected.iter().map(|c| c.probe(&sensors)).collect();
            ranking = all.into_iter().take(REPORTED_SUBSETS).collect();
            (selected, probes)
        }
        &SvrInputs::Rule(rule) => {
            let mut selected = gradients::select(&table, rule);
            selected.truncate(MAX_INPUTS);
            anyhow::ensure!(
                !selected.is_empty(),
                "no temperature or gradient passes the correlation rule {rule:?}; \
                 see `trainer correlate` for the correlations"
            );
            let probes = selected.iter().map(|c| c.probe(&sensors)).collect();
            (selected, probes)
        }
    };
    let features = FeatureConfig::multipoint(
        Probes::new(&probes).ok_or_else(|| anyhow::anyhow!("the selected inputs do not form a valid set"))?,
    );
    train.prepare(&[features], opts.block_s)?;
    Ok((
        features,
        Some(InputSelection {
            table,
            selected,
            ranking,
        }),
    ))
}

/// The SVR's expansion within `budget` centres: itself when it fits, else
/// at most `budget` of its support vectors chosen by OLS, with the
/// coefficients and constant refitted on (x, y).
fn deployable(svr: &Svr, x: &[FeatureRow], y: &[f64], budget: usize) -> anyhow::Result<Svr> {
    if svr.support.len() <= budget {
        return Ok(svr.clone());
    }
    let rows: Vec<usize> = (0..x.len()).collect();
    let dims = svr.dims;
    let shape = InputShape { dims, kernel: dims };
    // design(): [1, linear terms, Gaussians]; the constant and the linear
    // part (if the SVR has one) are kept and refitted with the chosen Gaussians.
    let a = design(x, &rows, shape, &svr.support, svr.sigma);
    let fixed_count = 1 + if svr.linear.is_empty() { 0 } else { dims };
    let fixed = a.columns(0, fixed_count).clone_owned();
    let candidates = a.columns(1 + dims, svr.support.len()).clone_owned();
    let target = DVector::from_column_slice(y);
    let order = super::ols::forward_select(&candidates, &fixed, &target, budget).order;
    let centers: Vec<FeatureRow> = order.iter().map(|&m| svr.support[m]).collect();
    let mut reduced = DMatrix::zeros(x.len(), fixed_count + centers.len());
    for c in 0..fixed_count {
        reduced.set_column(c, &fixed.column(c));
    }
    for (k, &m) in order.iter().enumerate() {
        reduced.set_column(fixed_count + k, &candidates.column(m));
    }
    let stats = GramStats::new(&reduced, &target);
    let w = ridge_solve(&stats, fixed_count + centers.len(), REFIT_RIDGE)
        .ok_or_else(|| anyhow::anyhow!("the reduced network's weights are singular"))?;
    Ok(Svr {
        support: centers,
        coef: w.as_slice()[fixed_count..].to_vec(),
        bias: w[0],
        linear: w.as_slice()[1..fixed_count].to_vec(),
        ..svr.clone()
    })
}

fn pick(x: &[FeatureRow], y: &[f64], rows: &[usize]) -> (Vec<FeatureRow>, Vec<f64>) {
    (
        rows.iter().map(|&i| x[i]).collect(),
        rows.iter().map(|&i| y[i]).collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::scoring::offset_free_rms;

    #[test]
    fn a_large_expansion_is_reduced_to_the_firmware_capacity_and_still_fits() {
        // sin over 2 inputs with a narrow kernel and a thin tube: far more
        // support vectors than the firmware holds.
        let mut x = Vec::new();
        for i in 0..20 {
            for j in 0..15 {
                let mut r = [0.0; rbf_core::MAX_INPUTS];
                r[0] = -2.0 + 0.2 * i as f64;
                r[1] = -1.5 + 0.2 * j as f64;
                x.push(r);
            }
        }
        let y: Vec<f64> = x.iter().map(|r| r[0].sin() * r[1].cos()).collect();
        let params = SvrParams {
            sigma: 0.4,
            c: 100.0,
            epsilon: 1e-3,
        };
        let svr = Svr::fit(&x, &y, 2, params, MAX_SMO_STEPS);
        assert!(svr.support.len() > MAX_CENTERS, "{} support vectors", svr.support.len());
        let net = deployable(&svr, &x, &y, MAX_CENTERS).unwrap();
        assert_eq!(net.support.len(), MAX_CENTERS);
        let rms = offset_free_rms(x.iter().zip(&y).map(|(r, t)| t - net.predict(r)));
        assert!(rms < 0.02, "reduced network RMS {rms}");
    }
}
