//! What `fit` is asked for: the model form, its inputs and the search's settings.

use rbf_core::FeatureSet;
use rbf_core::model::SERIAL_CAPACITY;

/// Inputs of the `rbf` method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum RbfFeatures {
    /// The default: the thermal lag bank (`FeatureSet::LagBank`): the mean
    /// coil temperature T̂ and the loop temperature's rates through up to five
    /// derivative filters from seconds to hours, their time constants, coil
    /// lags and Shupe gain identified from the runs ([`lag_bank`](super::lag_bank)) and chosen
    /// on held-out thermal events; Gaussians and a cubic over T̂, the rates
    /// linear. Generalises to temperature histories unlike the chamber's.
    LagBank,
    /// T, ΔT over three time scales, T×ΔT₁, T×ΔT₂, T×ΔT₃ and T²×ΔT₂
    /// (`FeatureSet::MultiScale`: first-order lag terms); Gaussians over T, the
    /// ΔT terms linear (the Shupe effect's form).
    Multiscale,
    /// T, ΔT over three time scales, T×ΔT₂, T×ΔT₃, T²×ΔT₂ and ΔT₃²
    /// (`FeatureSet::MultiScaleSecondOrder`): with the second-order lag term.
    MultiscaleSecondOrder,
    /// Both multi-scale sets fitted, the second-order one also
    /// with Gaussians over the lag-corrected temperature T − L·ΔT₃
    /// (`FeatureSet::MultiScaleLagged`, L from [`COIL_LAGS_MIN`](super::COIL_LAGS_MIN)) and with a
    /// longer slowest window ([`rbf::SLOWEST_WINDOW_FACTORS`](super::rbf::SLOWEST_WINDOW_FACTORS)), the best
    /// of those kept only when it validates clearly better than the
    /// first-order set ([`SECOND_ORDER_GAIN`](super::SECOND_ORDER_GAIN)): it generalises to ramp rates
    /// and profiles it was not trained on. One pass over the data builds both
    /// sets' blocks (they share their filters and seven of eight inputs; the
    /// lagged blocks are derived from the second-order ones); the second
    /// search adds a quarter to a third to the fit time of one set.
    MultiscaleValidated,
    /// (T, ΔT, T×ΔT) with Gaussians over all three: the IFOG paper's network.
    Paper,
    /// The thermal response bank (`FeatureSet::ResponseBank`): a static
    /// cubic in T about T₀ and five responses mixed from twelve derivative
    /// filters (10 s … 1.1 h), fitted by [`response`](super::response).
    ResponseBank,
}

/// The model forms `trainer fit` can produce.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum Method {
    /// Gaussian RBF network (default); inputs chosen by `--features`.
    Rbf,
    /// Gaussian RBF on (T, ΔT): the IFOG paper's model before its modification.
    Rbf2,
    /// Cubic in T about the mid-range temperature, clamped: the PX4/ArduPilot form.
    Poly3,
    /// ε-SVR with a Gaussian kernel on (T, ΔT, T×ΔT), σ, C and ε tuned by
    /// particle swarm on contiguous folds (the RLG paper's method), compiled
    /// into the same RBF network (support vectors reduced by OLS to the
    /// centre budget, `centers` else `max_centers`, when there are more).
    SvrPso,
}

impl Method {
    /// The feature set the method uses (`features` applies to `rbf`).
    pub fn feature_set(self, features: RbfFeatures) -> FeatureSet {
        match self {
            Method::Rbf if features == RbfFeatures::Paper => FeatureSet::TempRateProduct,
            Method::Rbf if features == RbfFeatures::Multiscale => FeatureSet::MultiScale,
            // A placeholder: the bank's structure is identified by the fit.
            Method::Rbf if features == RbfFeatures::LagBank => {
                FeatureSet::LagBank(rbf_core::lag_bank::LagBank::plain(&[60.0], 25.0).unwrap_or_else(|| unreachable!()))
            }
            // A placeholder: the bank is identified by the fit.
            Method::Rbf if features == RbfFeatures::ResponseBank => FeatureSet::ResponseBank(
                rbf_core::response_bank::ResponseBank::new(&[10.0], 25.0, -1000.0, 1000.0, 4)
                    .unwrap_or_else(|| unreachable!()),
            ),
            // The validated choice's second candidate; `fit` tries both.
            Method::Rbf => FeatureSet::MultiScaleSecondOrder,
            Method::Rbf2 => FeatureSet::TempRate,
            Method::Poly3 => FeatureSet::Temp,
            Method::SvrPso => FeatureSet::TempRateProduct,
        }
    }
}

/// Everything `fit` needs besides the data.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Model form.
    pub method: Method,
    /// Inputs of the `rbf` method.
    pub features: RbfFeatures,
    /// Block length for averaging, s.
    pub block_s: f64,
    /// Fixed number of centres, or `None` to choose on validation.
    pub centers: Option<usize>,
    /// Most centres considered when choosing.
    pub max_centers: usize,
    /// ΔT filter time constants to choose from, s (the fastest of the three
    /// multi-scale windows, which are 1, 16 and 256 times it).
    pub rate_windows_s: Vec<f32>,
    /// Factor on the slowest multi-scale window (256 × the fastest × this);
    /// `--features multiscale-validated` also tries
    /// [`rbf::SLOWEST_WINDOW_FACTORS`](super::rbf::SLOWEST_WINDOW_FACTORS) for the second-order family.
    pub slowest_window_factor: f32,
    /// Contiguous folds per training run for validation when no `--validate`
    /// runs are given (never random rows: neighbouring samples correlate).
    pub folds: usize,
    /// Gyro serial number stored in the blob.
    pub serial: Option<String>,
    /// Show a progress bar.
    pub progress: bool,
    /// How `svr-pso` picks multi-point inputs: `None` = the subset of
    /// thermometers that validates best ([`thermometer_search`](super::thermometer_search)), else the RLG
    /// paper's correlation rule.
    pub selection: Option<crate::dataset::gradients::Selection>,
    /// `svr-pso` on multi-point runs: these inputs instead of a selection.
    pub inputs: Option<Vec<rbf_core::features::Probe>>,
    /// The default's choice: the response bank instead of the lag bank where
    /// the lag bank misses its training runs (off when the lag bank is asked for).
    pub structure_choice: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            method: Method::Rbf,
            features: RbfFeatures::LagBank,
            block_s: 1.0,
            centers: None,
            max_centers: 32,
            rate_windows_s: vec![15.0, 60.0, 240.0],
            slowest_window_factor: 1.0,
            folds: 5,
            serial: None,
            progress: false,
            selection: None,
            structure_choice: true,
            inputs: None,
        }
    }
}

/// The serial number as stored in the blob, refusing one that does not fit.
pub(crate) fn serial(opts: &FitOptions) -> anyhow::Result<Option<heapless::String<SERIAL_CAPACITY>>> {
    opts.serial
        .as_deref()
        .map(|s| {
            heapless::String::try_from(s).map_err(|_| anyhow::anyhow!("serial {s:?}: at most {SERIAL_CAPACITY} bytes"))
        })
        .transpose()
}
