//! Particle swarm optimisation as the RLG paper tunes its SVM with: inertia
//! weight falling linearly from 0.9 to 0.4 over the iterations (Shi &
//! Eberhart 1998), cognitive and social weights c1, c2, velocities clamped to
//! a share of each dimension's range, positions kept in the box.
//!
//! argmin's `ParticleSwarm` was considered: it implements SPSO 2011 with a
//! constant inertia weight and no velocity clamp, not the paper's schedule.
//! Deterministic for a seed: random numbers are drawn in a fixed order on
//! one thread; only the cost evaluations of a swarm run in parallel.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Swarm settings.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PsoOptions {
    /// Particles in the swarm.
    pub particles: usize,
    /// Iterations (velocity and position updates) after the initial swarm.
    pub iterations: usize,
    /// Inertia weight at the first and at the last iteration.
    pub inertia: (f64, f64),
    /// Cognitive weight (pull towards the particle's own best).
    pub c1: f64,
    /// Social weight (pull towards the swarm's best).
    pub c2: f64,
    /// Largest velocity per iteration, as a share of each dimension's range.
    pub max_velocity: f64,
    /// Random seed: the same seed gives the same result.
    pub seed: u64,
}

impl Default for PsoOptions {
    fn default() -> Self {
        PsoOptions {
            particles: 12,
            iterations: 15,
            inertia: (0.9, 0.4),
            c1: 2.0,
            c2: 2.0,
            max_velocity: 0.2,
            seed: 1,
        }
    }
}

/// What the swarm found.
#[derive(Clone, Debug, PartialEq)]
pub struct PsoResult {
    /// Best position.
    pub best: Vec<f64>,
    /// Its cost.
    pub best_cost: f64,
    /// The swarm's best cost after the initial swarm and after each iteration.
    pub history: Vec<f64>,
    /// Cost evaluations made.
    pub evaluations: usize,
}

/// Minimises `cost` over the box [`lower`, `upper`]. `evaluate` computes the
/// costs of a whole swarm (in parallel if it likes, results in order);
/// `on_iteration` is called after each swarm (progress bars). A NaN cost
/// counts as +∞.
pub fn minimise(
    lower: &[f64],
    upper: &[f64],
    opts: &PsoOptions,
    evaluate: impl Fn(&[Vec<f64>]) -> Vec<f64>,
    mut on_iteration: impl FnMut(),
) -> PsoResult {
    let dims = lower.len().min(upper.len());
    let range: Vec<f64> = (0..dims).map(|d| upper[d] - lower[d]).collect();
    let v_max: Vec<f64> = range.iter().map(|r| r * opts.max_velocity).collect();
    let mut rng = Pcg64::seed_from_u64(opts.seed);
    let n = opts.particles.max(1);
    let mut position: Vec<Vec<f64>> = (0..n)
        .map(|_| (0..dims).map(|d| lower[d] + rng.random::<f64>() * range[d]).collect())
        .collect();
    let mut velocity: Vec<Vec<f64>> = (0..n)
        .map(|_| {
            (0..dims)
                .map(|d| (2.0 * rng.random::<f64>() - 1.0) * v_max[d])
                .collect()
        })
        .collect();
    let clean = |c: f64| if c.is_nan() { f64::INFINITY } else { c };
    let mut cost: Vec<f64> = evaluate(&position).into_iter().map(clean).collect();
    let mut evaluations = n;
    let mut personal = position.clone();
    let mut personal_cost = cost.clone();
    let best_of = |costs: &[f64]| {
        costs
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i)
    };
    let mut g = best_of(&personal_cost);
    let mut global = personal[g].clone();
    let mut global_cost = personal_cost[g];
    let mut history = vec![global_cost];
    on_iteration();
    for it in 0..opts.iterations {
        let share = if opts.iterations > 1 {
            it as f64 / (opts.iterations - 1) as f64
        } else {
            0.0
        };
        let w = opts.inertia.0 + (opts.inertia.1 - opts.inertia.0) * share;
        for p in 0..n {
            for d in 0..dims {
                let (r1, r2) = (rng.random::<f64>(), rng.random::<f64>());
                let v = w * velocity[p][d]
                    + opts.c1 * r1 * (personal[p][d] - position[p][d])
                    + opts.c2 * r2 * (global[d] - position[p][d]);
                velocity[p][d] = v.clamp(-v_max[d], v_max[d]);
                position[p][d] = (position[p][d] + velocity[p][d]).clamp(lower[d], upper[d]);
            }
        }
        cost = evaluate(&position).into_iter().map(clean).collect();
        evaluations += n;
        for p in 0..n {
            if cost[p] < personal_cost[p] {
                personal_cost[p] = cost[p];
                personal[p].clone_from(&position[p]);
            }
        }
        g = best_of(&personal_cost);
        if personal_cost[g] < global_cost {
            global_cost = personal_cost[g];
            global.clone_from(&personal[g]);
        }
        history.push(global_cost);
        on_iteration();
    }
    PsoResult {
        best: global,
        best_cost: global_cost,
        history,
        evaluations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn serial(f: impl Fn(&[f64]) -> f64) -> impl Fn(&[Vec<f64>]) -> Vec<f64> {
        move |swarm: &[Vec<f64>]| swarm.iter().map(|p| f(p)).collect()
    }

    #[test]
    fn finds_the_minimum_of_a_shifted_bowl() {
        let f = |p: &[f64]| (p[0] - 1.5).powi(2) + 3.0 * (p[1] + 0.5).powi(2);
        let opts = PsoOptions {
            particles: 20,
            iterations: 60,
            ..PsoOptions::default()
        };
        let r = minimise(&[-5.0, -5.0], &[5.0, 5.0], &opts, serial(f), || {});
        assert!(
            (r.best[0] - 1.5).abs() < 1e-2 && (r.best[1] + 0.5).abs() < 1e-2,
            "{:?}",
            r.best
        );
        assert_eq!(r.history.len(), 61);
        assert!(
            r.history.windows(2).all(|w| w[1] <= w[0]),
            "the swarm's best never worsens"
        );
        assert_eq!(r.evaluations, 20 * 61);
    }

    #[test]
    fn same_seed_same_result_and_positions_stay_in_the_box() {
        let f = |p: &[f64]| {
            assert!(
                (-2.0..=2.0).contains(&p[0]) && (0.0..=1.0).contains(&p[1]),
                "{p:?} left the box"
            );
            -(p[0] * 3.0).sin() * p[1]
        };
        let opts = PsoOptions::default();
        let a = minimise(&[-2.0, 0.0], &[2.0, 1.0], &opts, serial(f), || {});
        let b = minimise(&[-2.0, 0.0], &[2.0, 1.0], &opts, serial(f), || {});
        assert_eq!(a, b);
        let other = PsoOptions { seed: 7, ..opts };
        let c = minimise(&[-2.0, 0.0], &[2.0, 1.0], &other, serial(f), || {});
        assert_ne!(a.history, c.history, "the seed matters");
    }

    #[test]
    fn nan_costs_never_win() {
        let f = |p: &[f64]| if p[0] < 0.0 { f64::NAN } else { p[0] };
        let r = minimise(&[-1.0], &[1.0], &PsoOptions::default(), serial(f), || {});
        assert!(r.best_cost.is_finite() && r.best[0] >= 0.0);
    }
}
