//! A plan's predicted figures on the nominal and the slow plant: what
//! `trainer plan` prints and writes after predicting them (the prediction
//! itself simulates, fits and evaluates in the module beside this one).

use super::criterion::slowed;
use super::limits::SLOW_PLANT_FACTOR;
use crate::simulate::SimParams;

/// The two plants a plan is judged on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlantKind {
    /// The documented gyro (`SimParams::default()`).
    Nominal,
    /// The documented gyro with every time constant [`SLOW_PLANT_FACTOR`]× nominal.
    Slow,
}

impl PlantKind {
    /// Both, nominal first.
    pub const BOTH: [PlantKind; 2] = [PlantKind::Nominal, PlantKind::Slow];

    /// The simulated gyro of this plant.
    pub fn params(self) -> SimParams {
        let nominal = SimParams::default();
        match self {
            PlantKind::Nominal => nominal,
            PlantKind::Slow => SimParams {
                plant: slowed(&nominal.plant, SLOW_PLANT_FACTOR),
                ..nominal
            },
        }
    }

    /// How the output names it.
    pub fn name(self) -> &'static str {
        match self {
            PlantKind::Nominal => "nominal plant",
            PlantKind::Slow => "slow plant",
        }
    }
}

/// The figures predicted on one plant.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PlantFigures {
    /// Which plant.
    pub plant: PlantKind,
    /// Spread of the settled bias after compensation, the worse of the two
    /// soak tests (the order and another), °/h; `None` when a soak test shows
    /// fewer than two plateaus (not on the simulator's gyros).
    pub settled_spread_dph: Option<f64>,
    /// Mean 100-s cluster STD improvement on the random and the field
    /// history, %.
    pub in_use_std100_gain_pct: f64,
}

/// A plan's predicted figures on both plants.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Prediction {
    /// On the documented gyro.
    pub nominal: PlantFigures,
    /// With every time constant [`SLOW_PLANT_FACTOR`]× nominal.
    pub slow: PlantFigures,
}

impl Prediction {
    /// The worse settled spread of the two plants, °/h; `None` when either has none.
    pub fn worse_settled_spread_dph(&self) -> Option<f64> {
        Some(self.nominal.settled_spread_dph?.max(self.slow.settled_spread_dph?))
    }

    /// The lower in-use improvement of the two plants, %.
    pub fn worse_in_use_std100_gain_pct(&self) -> f64 {
        self.nominal
            .in_use_std100_gain_pct
            .min(self.slow.in_use_std100_gain_pct)
    }

    /// Whether the settled spread meets `target_dph` on both plants.
    pub fn meets(&self, target_dph: f64) -> bool {
        self.worse_settled_spread_dph().is_some_and(|s| s <= target_dph)
    }

    /// The printed lines, one per plant.
    pub fn lines(&self) -> Vec<String> {
        [self.nominal, self.slow]
            .iter()
            .map(|f| {
                format!(
                    "predicted after the default fit on this run, {}: settled spread {} °/h (soak test, worse of two orders), in-use 100-s cluster STD improvement {:.1} % (mean of a random and a field history)",
                    f.plant.name(),
                    spread_text(f.settled_spread_dph),
                    f.in_use_std100_gain_pct
                )
            })
            .collect()
    }

    /// The `#` metadata lines of the plan file.
    pub fn metadata(&self) -> String {
        format!(
            "# predicted_settled_spread_dph: {},{} (nominal plant, slow plant; soak tests at {SOAK_DESCRIPTION} after the default fit on this run; docs/plan.md)\n# predicted_in_use_std100_gain_pct: {:.1},{:.1} (nominal plant, slow plant; mean of a random and a field history)\n",
            spread_text(self.nominal.settled_spread_dph),
            spread_text(self.slow.settled_spread_dph),
            self.nominal.in_use_std100_gain_pct,
            self.slow.in_use_std100_gain_pct
        )
    }
}

/// How the soak tests are described in the metadata.
const SOAK_DESCRIPTION: &str = "25,0,40,-20,60,20,-40,10 and 10,-40,50,-10,30,60,-30,0 °C, 3-h holds, 1 °C/min";

/// A settled spread as printed: four decimals, or `none` without plateaus.
fn spread_text(spread_dph: Option<f64>) -> String {
    spread_dph.map_or("none".to_owned(), |s| format!("{s:.4}"))
}
