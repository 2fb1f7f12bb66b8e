//! What a plan's run is predicted to give, on the nominal plant and the slow
//! one: the settled spread a soak test reads after the default fit on the
//! run, and the in-use 100-s cluster STD improvement of that fit.
//!
//! Nothing here is new arithmetic: each plant's [`TestBench`] simulates the
//! runs with [`crate::simulate`] at 1 Hz, fits the default model (the one
//! `trainer fit` fits) with [`crate::fit::fit`] and reads both figures with
//! [`crate::evaluation::evaluate::evaluate_run`] (the soak rule of
//! [`crate::dataset::plateaus`] for the settled spread). Every run has a
//! fixed seed ([`PLAN_RUN_SEED`], [`SOAK_SEEDS`], [`RANDOM_SEED`],
//! [`FIELD_SEED`]), so the prediction is deterministic.

use std::io::Cursor;
use std::path::Path;

use anyhow::Context;

use super::Plan;
use crate::evaluation::evaluate::evaluate_run;
use crate::fit::{FitOptions, Progress};
use crate::reading::run::RunReader;
use crate::reading::run::samples::Run;
use crate::simulate::profile::SOAK_LEVELS_C;
use crate::simulate::{ChamberRun, Profile, Schedule, SimParams};

/// The two soak tests the settled spread is read on, chamber levels in
/// order, °C (3-h holds, 1 °C/min between): the order, and another
/// order of other levels; the prediction is the worse of the two.
pub const SOAK_ORDERS_C: [[f64; 8]; 2] = [SOAK_LEVELS_C, [10.0, -40.0, 50.0, -10.0, 30.0, 60.0, -30.0, 0.0]];
/// Seed of the plan's simulated run (`trainer simulate`'s default).
pub const PLAN_RUN_SEED: u64 = 1;
/// Seeds of the two soak tests, in the order of [`SOAK_ORDERS_C`].
pub const SOAK_SEEDS: [u64; 2] = [2, 3];
/// Seed of the random in-use history.
pub const RANDOM_SEED: u64 = 4;
/// Seed of the field in-use history.
pub const FIELD_SEED: u64 = 5;
/// Set-point range of the random in-use history, °C.
pub const RANDOM_RANGE_C: (f64, f64) = (-20.0, 50.0);
/// Ramp-rate range of the random in-use history, °C/min.
pub const RANDOM_RAMP_RANGE_C_PER_MIN: (f64, f64) = (0.2, 3.0);
/// Length of the random in-use history, h.
pub const RANDOM_HOURS: f64 = 8.0;

pub use super::prediction::{PlantFigures, PlantKind, Prediction};

/// One plant's verification runs, simulated once and reused for every plan
/// judged on it: its two soak tests and its two in-use histories.
pub struct TestBench {
    /// Which plant.
    pub plant: PlantKind,
    params: SimParams,
    soaks: Vec<Run>,
    histories: Vec<Run>,
}

impl TestBench {
    /// Simulates the plant's soak tests and in-use histories (seconds in a release build).
    pub fn new(plant: PlantKind) -> anyhow::Result<Self> {
        let params = plant.params();
        let soaks = SOAK_ORDERS_C
            .iter()
            .zip(SOAK_SEEDS)
            .map(|(levels, seed)| {
                let run = ChamberRun {
                    soak_levels_c: levels.to_vec(),
                    params: params.clone(),
                    ..ChamberRun::with_profile(Profile::Soak, seed)
                };
                simulated(&run, "soak test")
            })
            .collect::<anyhow::Result<_>>()?;
        let random = ChamberRun {
            random_range_c: RANDOM_RANGE_C,
            ramp_range_c_per_min: RANDOM_RAMP_RANGE_C_PER_MIN,
            duration_s: Some(RANDOM_HOURS * 3600.0),
            params: params.clone(),
            ..ChamberRun::with_profile(Profile::Random, RANDOM_SEED)
        };
        let field = ChamberRun {
            params: params.clone(),
            ..ChamberRun::with_profile(Profile::Field, FIELD_SEED)
        };
        let histories = vec![
            simulated(&random, "random history")?,
            simulated(&field, "field history")?,
        ];
        Ok(TestBench {
            plant,
            params,
            soaks,
            histories,
        })
    }

    /// Both benches, simulated in parallel.
    pub fn both() -> anyhow::Result<[TestBench; 2]> {
        let [nominal, slow]: [anyhow::Result<TestBench>; 2] =
            crate::parallel::parallel_map(&PlantKind::BOTH, |&p| TestBench::new(p))
                .try_into()
                .map_err(|_| anyhow::anyhow!("two plants give two test benches"))?;
        Ok([nominal?, slow?])
    }

    /// The figures of `plan` on this plant: its run simulated, the default
    /// model fitted on it, the model evaluated on the soak tests and the histories.
    pub fn judge(&self, plan: &Plan) -> anyhow::Result<PlantFigures> {
        let run = ChamberRun {
            params: self.params.clone(),
            ..ChamberRun::planned(Schedule::from_knots(plan.knots()), "trainer plan", PLAN_RUN_SEED)
        };
        let training = [simulated(&run, "plan's run")?];
        let outcome = crate::fit::fit(&training, &[] as &[Run], &FitOptions::default())
            .with_context(|| format!("the default fit on the plan's run ({})", self.plant.name()))?;
        let model = &outcome.model;
        let spreads: Vec<Option<f64>> = self
            .soaks
            .iter()
            .map(|soak| evaluate_run(model, soak).settled.and_then(|s| s.settled_spread_dph))
            .collect();
        let settled_spread_dph = spreads.iter().copied().try_fold(0.0f64, |worst, s| Some(worst.max(s?)));
        let gains: Vec<f64> = self
            .histories
            .iter()
            .map(|h| evaluate_run(model, h).cluster_std_improvement_pct)
            .collect();
        Ok(PlantFigures {
            plant: self.plant,
            settled_spread_dph,
            in_use_std100_gain_pct: gains.iter().sum::<f64>() / gains.len() as f64,
        })
    }
}

/// `plan`'s figures on both `benches` (nominal, slow), judged in parallel;
/// `progress` counts one step per plant.
pub fn predict(plan: &Plan, benches: &[TestBench; 2], progress: &Progress) -> anyhow::Result<Prediction> {
    let [nominal, slow]: [anyhow::Result<PlantFigures>; 2] = crate::parallel::parallel_map(benches, |b| {
        let figures = b.judge(plan);
        progress.inc();
        figures
    })
    .try_into()
    .map_err(|_| anyhow::anyhow!("two test benches give two judgements"))?;
    Ok(Prediction {
        nominal: nominal?,
        slow: slow?,
    })
}

/// A simulated run read back as `trainer fit` and `trainer eval` read a
/// recorded one (the same reader, from memory), named `name` in messages.
fn simulated(run: &ChamberRun, name: &str) -> anyhow::Result<Run> {
    let reader = RunReader::from_reader(Path::new(name), Cursor::new(run.to_csv().into_bytes()))?;
    Ok(Run::read(reader)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::limits::SLOW_PLANT_FACTOR;

    #[test]
    fn the_slow_plant_is_the_nominal_one_with_every_time_constant_longer() {
        let (n, s) = (PlantKind::Nominal.params(), PlantKind::Slow.params());
        assert_eq!(n, SimParams::default());
        let ratio = s.plant.tau_coil_outer_s / n.plant.tau_coil_outer_s;
        assert!((ratio - SLOW_PLANT_FACTOR).abs() < 1e-12, "{ratio}");
        assert_eq!(s.gyro, n.gyro);
    }

    #[test]
    fn the_same_plan_gets_the_same_figures_and_a_soak_spread_on_the_plant() {
        // Fixed seeds: the prediction is a function of the plan; and the
        // soak tests hold plateaus, so a spread is read.
        let limits = super::super::limits::PlanLimits {
            min_c: -40.0,
            max_c: 60.0,
            max_rate_c_per_min: 5.0,
            hours: 6.0,
        };
        let plan = super::super::design(&limits, 1, 4, super::super::ends::Ends::Default).unwrap();
        let bench = TestBench::new(PlantKind::Nominal).unwrap();
        let a = bench.judge(&plan).unwrap();
        let b = bench.judge(&plan).unwrap();
        let spread = a.settled_spread_dph.expect("eight plateaus a soak test");
        assert_eq!(spread.to_bits(), b.settled_spread_dph.unwrap().to_bits());
        assert_eq!(a.in_use_std100_gain_pct.to_bits(), b.in_use_std100_gain_pct.to_bits());
        // Compensated: well below the raw bias's 1.4–2 °/h span, above the soak's noise.
        assert!((0.005..1.0).contains(&spread), "{spread}");
    }

    #[test]
    fn a_prediction_meets_a_target_only_when_both_plants_do() {
        let figures = |plant, spread| PlantFigures {
            plant,
            settled_spread_dph: spread,
            in_use_std100_gain_pct: 90.0,
        };
        let p = Prediction {
            nominal: figures(PlantKind::Nominal, Some(0.01)),
            slow: figures(PlantKind::Slow, Some(0.03)),
        };
        assert!(p.meets(0.03) && !p.meets(0.02));
        assert_eq!(p.worse_settled_spread_dph(), Some(0.03));
        let none = Prediction {
            slow: figures(PlantKind::Slow, None),
            ..p
        };
        assert!(!none.meets(1.0), "no plateaus: no claim");
        assert!(none.metadata().contains("predicted_settled_spread_dph: 0.0100,none"));
    }
}
