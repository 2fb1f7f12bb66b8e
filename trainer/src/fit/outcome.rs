//! What a fit gives: the model and the report of the method that ran.

use rbf_core::Model;

use super::{forecast, lag_bank, rbf, response, svr_pso};

/// How [`Method::MultiscaleValidated`](super::Method::MultiscaleValidated)
/// chose between the multi-scale sets (the set kept is the model's, [`FitOutcome::model`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SetComparison {
    /// Validation RMS of the first-order set, °/h.
    pub first_order_rms_dph: f64,
    /// Validation RMS of the second-order set or, when one validates better,
    /// its best variant (lagged, [`COIL_LAGS_MIN`](super::COIL_LAGS_MIN), or with a longer slowest
    /// window, [`rbf::SLOWEST_WINDOW_FACTORS`]), °/h.
    pub second_order_rms_dph: f64,
}

/// What the lag bank's fit chose ([`Method::LagBank`](super::Method::LagBank)).
#[derive(Clone, Debug)]
pub struct BankReport {
    /// The lag bank network's ridge and centres.
    pub choice: rbf::RbfChoice,
    /// How the bank's structure was chosen.
    pub search: lag_bank::BankSearch,
    /// The default's choice between the lag bank and the response bank
    /// (`None` when the structure was not chosen: the lag bank asked for,
    /// Gaussians asked for, or runs too short to score).
    pub structure: Option<response::StructureChoice>,
    /// The deployed bank's residual 100-s cluster STD on the training runs,
    /// °/h (`None` for runs too short for it).
    pub training_std100_dph: Option<f64>,
    /// The part of the lag bank's training residual white noise explains,
    /// °/h ([`forecast::white_noise_std100`]; `None` where the runs hold
    /// too few adjacent blocks to tell): the gyro's, whichever bank deploys.
    pub noise_floor_std100_dph: Option<f64>,
}

impl BankReport {
    /// Whether the default deployed the response bank instead of the lag bank.
    pub fn response_bank_chosen(&self) -> bool {
        self.structure.as_ref().is_some_and(|s| s.response_bank)
    }

    /// The forecast's factor for a deployed response bank: smaller where its
    /// regression weighed the runs' settled levels
    /// ([`forecast::WEIGHED_RESPONSE_BANK_EXCESS_FACTOR`]), and the more
    /// hours it fitted ([`forecast::response_bank_excess_factor`]).
    pub fn response_bank_excess_factor(&self) -> f64 {
        forecast::response_bank_excess_factor(
            self.response_bank_weighed_settled_levels(),
            self.structure
                .as_ref()
                .and_then(|s| s.response_bank_training_hours)
                .unwrap_or(0.0),
        )
    }

    /// Whether the response bank's regression weighed the runs' settled
    /// levels ([`super::settled_blocks`]); false where it was not identified.
    pub fn response_bank_weighed_settled_levels(&self) -> bool {
        self.structure
            .as_ref()
            .and_then(|s| s.response_bank_settled_levels_weighed)
            .unwrap_or(false)
    }
}

/// The report of the method that ran: one variant per [`Method`](super::Method).
#[derive(Clone, Debug)]
pub enum FitReport {
    /// The thermal lag bank (or the response bank the default chose in its place).
    Bank(BankReport),
    /// The thermal response bank, asked for.
    ResponseBank,
    /// A Gaussian RBF network over fixed inputs: the hyper-parameters chosen.
    Rbf(rbf::RbfChoice),
    /// Both multi-scale sets: the kept set's hyper-parameters and the comparison.
    MultiscaleValidated {
        /// The kept set's hyper-parameters.
        choice: rbf::RbfChoice,
        /// Both sets' validation scores.
        sets: SetComparison,
    },
    /// The cubic in T.
    Poly3,
    /// The SVR's hyper-parameters and deployment.
    SvrPso(svr_pso::SvrChoice),
}

/// What was fitted and how it was chosen.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The deployable model.
    pub model: Model,
    /// What the method that ran chose.
    pub report: FitReport,
}

impl FitOutcome {
    /// The residual 100-s cluster STD the fit forecasts for in-use histories
    /// unlike its training runs, °/h: the deployed bank's training residual,
    /// its noise floor as it is and the rest times its structure's factor
    /// ([`forecast::in_use_std100`]); `None` for the other methods.
    pub fn predicted_in_use_std100_dph(&self) -> Option<f64> {
        let FitReport::Bank(bank) = &self.report else {
            return None;
        };
        let training = forecast::TrainingResidual {
            std100_dph: bank.training_std100_dph?,
            noise_floor_std100_dph: bank.noise_floor_std100_dph,
        };
        Some(forecast::in_use_std100(training, self.excess_factor()?)).filter(|v| v.is_finite())
    }

    /// The deployed bank's residual 100-s cluster STD on its training runs
    /// over the runs' white-noise floor ([`super::vouch`]); `None` for the
    /// other methods and where the runs were too short to tell the floor.
    pub fn residual_over_noise_floor(&self) -> Option<f64> {
        let FitReport::Bank(bank) = &self.report else {
            return None;
        };
        Some(bank.training_std100_dph? / bank.noise_floor_std100_dph?).filter(|r| r.is_finite())
    }

    /// The factor the settled forecast applies to the training runs' own
    /// settled spread ([`super::vouch::settled_forecast_dph`]):
    /// [`super::vouch::WEIGHED_RESPONSE_BANK_FLOOR_FACTOR`] where the deployed
    /// model is a response bank whose regression weighed the runs' settled
    /// levels, 1 elsewhere.
    pub fn settled_floor_factor(&self) -> f64 {
        match &self.report {
            FitReport::Bank(bank) if bank.response_bank_chosen() && bank.response_bank_weighed_settled_levels() => {
                super::vouch::WEIGHED_RESPONSE_BANK_FLOOR_FACTOR
            }
            _ => 1.0,
        }
    }

    /// The factor [`Self::predicted_in_use_std100_dph`] applies to the
    /// model error above the noise floor; `None` for the methods it does
    /// not forecast.
    pub fn excess_factor(&self) -> Option<f64> {
        match &self.report {
            FitReport::Bank(bank) if bank.response_bank_chosen() => Some(bank.response_bank_excess_factor()),
            FitReport::Bank(_) => Some(forecast::LAG_BANK_EXCESS_FACTOR),
            _ => None,
        }
    }

    /// The lag bank's search, for the fits that ran it.
    pub fn bank_search(&self) -> Option<&lag_bank::BankSearch> {
        match &self.report {
            FitReport::Bank(bank) => Some(&bank.search),
            _ => None,
        }
    }

    /// The Gaussian network's hyper-parameters, for the fits that searched one.
    pub fn rbf_choice(&self) -> Option<&rbf::RbfChoice> {
        match &self.report {
            FitReport::Bank(BankReport { choice, .. })
            | FitReport::Rbf(choice)
            | FitReport::MultiscaleValidated { choice, .. } => Some(choice),
            FitReport::ResponseBank | FitReport::Poly3 | FitReport::SvrPso(_) => None,
        }
    }
}
