//! The default multi-point input choice of `--method svr-pso`: which
//! thermometers the model reads, chosen by validation instead of by
//! correlation alone.
//!
//! The RLG paper keeps every temperature and gradient whose block means
//! correlate with the bias at |r| ≥ 0.9 ([`crate::dataset::gradients`], still
//! available as `--select-threshold` / `--select-top`). Correlation favours
//! sensors that *lead* the fiber coil, such as chamber air or the mounting
//! plate: on a 1 °C/min cycle their lead stands in for the Shupe rate term,
//! but the lead grows with the ramp rate, so a model on them does not carry
//! to other rates (simulated 8-thermometer runs trained on a 1 °C/min cycle
//! lose much of their improvement on a 5 °C/min cycle and a random profile;
//! figures: docs/benchmarks.md), and the candidates
//! that pass are often near copies of one another.
//!
//! Here every non-empty subset of the thermometers (at most 255) is scored
//! on the swarm's own contiguous folds by a fast stand-in for the SVR: a
//! ridge network of Gaussians at farthest-point centres plus a linear part,
//! over a few widths and ridge strengths, the best kept. Every gradient
//! between a subset's thermometers lies in the span of that linear part, so
//! a subset stands for its temperatures and all their gradients. The
//! smallest subset within `PARSIMONY` of the lowest validation error
//! becomes the SVR's inputs.

use nalgebra::DVector;
use rbf_core::MAX_INPUTS;

use super::Progress;
use super::linalg::{FeatureRow, GramStats, InputShape, design, farthest_points, ridge_solve};
use super::rbf::PARSIMONY;
use super::scoring::cluster_rms;
use super::svr_data::SvrData;
use crate::parallel::parallel_map;

/// Gaussian centres of the stand-in network.
const CENTERS: usize = 32;
/// Widths (normalised units) and ridge strengths the stand-in tries.
const WIDTHS: [f64; 4] = [0.5, 1.0, 2.0, 4.0];
const RIDGES: [f64; 2] = [1e-6, 1e-4];

/// One subset of thermometers and how well it predicts the bias.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SubsetScore {
    /// The thermometers, as indices into the data's sensors (the
    /// correlation matrix's rows), ascending.
    pub sensors: Vec<usize>,
    /// Validation RMS of the stand-in network's 100-s cluster means on the
    /// contiguous folds (offset removed per fold, best width and ridge), °/h.
    pub validation_rms_dph: f64,
}

/// Every non-empty subset of the `data.dims` thermometers whose temperatures
/// are `data`'s inputs, best first (ties: fewer thermometers first).
pub(super) fn rank(data: &SvrData, progress: &Progress) -> Vec<SubsetScore> {
    let m = data.dims.min(MAX_INPUTS);
    let masks: Vec<u32> = (1..1u32 << m).collect();
    progress.start("choosing thermometers", masks.len() as u64);
    let mut scores = parallel_map(&masks, |&mask| {
        let sensors: Vec<usize> = (0..m).filter(|k| mask & (1 << k) != 0).collect();
        let validation_rms_dph = score(data, &sensors);
        progress.inc();
        SubsetScore {
            sensors,
            validation_rms_dph,
        }
    });
    progress.finish();
    scores.sort_by(|a, b| {
        a.validation_rms_dph
            .total_cmp(&b.validation_rms_dph)
            .then(a.sensors.len().cmp(&b.sensors.len()))
    });
    scores
}

/// The subset to use from a [`rank`]ing: the fewest thermometers whose
/// score is within [`PARSIMONY`] of the best (`None` for no finite score).
pub(super) fn choose(ranking: &[SubsetScore]) -> Option<&SubsetScore> {
    let best = ranking.first()?.validation_rms_dph;
    if !best.is_finite() {
        return None;
    }
    ranking
        .iter()
        .filter(|s| s.validation_rms_dph <= best * PARSIMONY)
        .min_by_key(|s| s.sensors.len())
}

/// The stand-in network's validation RMS on the inputs `columns` of `data`
/// (the best over [`WIDTHS`] × [`RIDGES`] of the mean over folds), °/h;
/// +∞ if no setting can be solved.
fn score(data: &SvrData, columns: &[usize]) -> f64 {
    let dims = columns.len();
    let z: Vec<FeatureRow> = data
        .x
        .iter()
        .map(|row| {
            let mut r = [0.0; MAX_INPUTS];
            for (slot, &c) in r.iter_mut().zip(columns) {
                *slot = row[c];
            }
            r
        })
        .collect();
    let shape = InputShape { dims, kernel: dims };
    let settings = WIDTHS.len() * RIDGES.len();
    let mut totals = vec![0.0; settings];
    for fold in &data.folds {
        let centers: Vec<FeatureRow> = farthest_points(&z, &fold.train, dims, CENTERS)
            .into_iter()
            .map(|i| z[i])
            .collect();
        let target = DVector::from_iterator(fold.train.len(), fold.train.iter().map(|&i| data.y[i]));
        for (w, &width) in WIDTHS.iter().enumerate() {
            let stats = GramStats::new(&design(&z, &fold.train, shape, &centers, width), &target);
            let held_out = design(&z, &fold.validate, shape, &centers, width);
            for (r, &ridge) in RIDGES.iter().enumerate() {
                let rms = match ridge_solve(&stats, held_out.ncols(), ridge) {
                    Some(weights) => {
                        let predicted = &held_out * weights;
                        cluster_rms(
                            fold.validate.iter().zip(predicted.iter()).map(|(&i, p)| data.y[i] - p),
                            data.per_cluster,
                        )
                    }
                    None => f64::INFINITY,
                };
                totals[w * RIDGES.len() + r] += rms;
            }
        }
    }
    totals.into_iter().fold(f64::INFINITY, f64::min) / data.folds.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::Blocks;

    /// Blocks of four thermometers over ten temperature cycles: b is a with
    /// reading noise, c leads a (it sees the cause first), d is unrelated.
    /// The bias is a nonlinear function of a and of the c − a gradient.
    fn blocks() -> Blocks {
        let mut blocks = Blocks {
            dims: 4,
            ..Blocks::default()
        };
        let noise = |k: f64| ((k * 12.9898).sin() * 43_758.547).fract() - 0.5;
        for k in 0..3000 {
            let t = k as f64;
            let a = 20.0 * (t / 50.0).sin();
            let b = a + 2.0 * noise(t);
            let c = 20.0 * ((t + 5.0) / 50.0).sin();
            let d = 5.0 * (t / 173.0).sin();
            let mut x = [0.0; MAX_INPUTS];
            x[..4].copy_from_slice(&[a, b, c, d]);
            blocks.x.push(x);
            blocks.y.push(0.002 * a * a + 0.5 * (c - a));
            blocks.run.push(0);
        }
        blocks
    }

    #[test]
    fn the_thermometers_that_determine_the_bias_rank_first() {
        let data = SvrData::new(&blocks(), 1.0).unwrap();
        let ranking = rank(&data, &Progress::new(false));
        assert_eq!(ranking.len(), 15, "every non-empty subset of 4");
        assert_eq!(choose(&ranking).unwrap().sensors, [0, 2], "{:?}", &ranking[..4]);
        let single_a = ranking.iter().find(|s| s.sensors == [0]).unwrap();
        assert!(
            single_a.validation_rms_dph > 5.0 * ranking[0].validation_rms_dph,
            "a alone misses the gradient: {single_a:?} vs {:?}",
            ranking[0]
        );
        assert!(
            ranking
                .windows(2)
                .all(|w| w[0].validation_rms_dph <= w[1].validation_rms_dph)
        );
    }
}
