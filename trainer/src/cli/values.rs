//! The command line's names for the library's choices: clap's value enums
//! mirror `trainer`'s types, so the library needs no clap.

use clap::ValueEnum;
use trainer::fit::RbfInputs;
use trainer::simulate::Profile;

/// Model forms (`--method`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Gaussian RBF network (default); inputs chosen by `--features`.
    Rbf,
    /// Gaussian RBF on (T, ΔT): the IFOG paper's model before its modification.
    Rbf2,
    /// Cubic in T about the mid-range temperature, clamped: the PX4/ArduPilot form.
    Poly3,
    /// ε-SVR tuned by particle swarm (the RLG paper's method), deployed as an RBF network.
    SvrPso,
}

/// Inputs of the `rbf` method (`--features`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FeaturesArg {
    /// The thermal lag bank (default): mean coil temperature and filtered rates.
    LagBank,
    /// T, ΔT over three time scales and their first-order lag products.
    Multiscale,
    /// The multi-scale set with the second-order lag term ΔT₃².
    MultiscaleSecondOrder,
    /// Both multi-scale sets (and lagged forms), the better kept on validation.
    MultiscaleValidated,
    /// (T, ΔT, T×ΔT) with Gaussians over all three: the IFOG paper's network.
    Paper,
    /// The thermal response bank: a static cubic in T and five responses mixed from 12 filters (10 s … 1.1 h).
    ResponseBank,
}

impl FeaturesArg {
    /// The fixed inputs these features are; `None` for the banks (their
    /// filters are identified by the fit) and for multiscale-validated (two sets).
    pub fn rbf_inputs(self) -> Option<RbfInputs> {
        match self {
            FeaturesArg::Multiscale => Some(RbfInputs::Multiscale),
            FeaturesArg::MultiscaleSecondOrder => Some(RbfInputs::MultiscaleSecondOrder),
            FeaturesArg::Paper => Some(RbfInputs::Paper),
            FeaturesArg::LagBank | FeaturesArg::ResponseBank | FeaturesArg::MultiscaleValidated => None,
        }
    }
}

/// Temperature histories of `trainer simulate` (`--profile`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ProfileArg {
    /// Chamber, IFOG paper: 25 °C, down to 10 °C, hold, up to 40 °C, hold, back to 25 °C.
    Ifog,
    /// Chamber, RLG paper: 20 → −40 → 60 → −40 → 60 → 20 °C with holds.
    Cycle,
    /// Chamber or in use: random set points, ramp rates and holds.
    Random,
    /// Chamber: a designed multi-rate run across −40 … 60 °C (about 10.9 h).
    Designed,
    /// In use: powered on soaked cold, warms up on its own heat, then reaches ambient.
    ColdStart,
    /// In use: carried between a hangar and outside (near-instant air steps).
    AmbientSteps,
    /// In use: fast swings at 3 … 8 °C/min.
    Swings,
    /// In use: a 24-h day cycle.
    DayCycle,
    /// In use: a cold start followed by a seeded mix of steps, swings and slow drifts.
    Field,
    /// Chamber: a soak test, 3-h holds at 25, 0, 40, −20, 60, 20, −40, 10 °C, 1 °C/min between.
    Soak,
}

impl From<ProfileArg> for Profile {
    fn from(p: ProfileArg) -> Profile {
        match p {
            ProfileArg::Ifog => Profile::Ifog,
            ProfileArg::Cycle => Profile::Cycle,
            ProfileArg::Random => Profile::Random,
            ProfileArg::Designed => Profile::Designed,
            ProfileArg::ColdStart => Profile::ColdStart,
            ProfileArg::AmbientSteps => Profile::AmbientSteps,
            ProfileArg::Swings => Profile::Swings,
            ProfileArg::DayCycle => Profile::DayCycle,
            ProfileArg::Field => Profile::Field,
            ProfileArg::Soak => Profile::Soak,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_choice_maps_to_the_library_value_of_the_same_name() {
        for p in ProfileArg::value_variants() {
            let name = p.to_possible_value().unwrap().get_name().replace('-', "");
            assert_eq!(format!("{:?}", Profile::from(*p)).to_lowercase(), name);
        }
    }
}
