//! What `fit` is asked for: the method, each with only its own options, and
//! the settings every method shares (blocks, folds, serial, progress).

use rbf_core::FeatureSet;
use rbf_core::features::Probe;
use rbf_core::model::SERIAL_CAPACITY;
use rbf_core::thermometer::ThermometerSet;

use crate::dataset::gradients::Selection;

/// How many Gaussian centres a network may have (`--centers K` or `--max-centers K`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CenterBudget {
    /// Exactly K centres (fewer where OLS finds fewer independent ones).
    Fixed(usize),
    /// K ≤ this many, chosen on validation.
    UpTo(usize),
}

impl CenterBudget {
    /// The budget a search has without `--centers` or `--max-centers`.
    pub const DEFAULT: CenterBudget = CenterBudget::UpTo(32);

    /// The fixed K, if one was asked for.
    pub fn fixed(self) -> Option<usize> {
        match self {
            CenterBudget::Fixed(k) => Some(k),
            CenterBudget::UpTo(_) => None,
        }
    }

    /// The most centres the budget allows.
    pub fn most(self) -> usize {
        match self {
            CenterBudget::Fixed(k) | CenterBudget::UpTo(k) => k,
        }
    }

    /// The budget within `cap` centres: a search bounded by it, a fixed K
    /// above it refused (`Err(K)`).
    pub fn capped(self, cap: usize) -> Result<CenterBudget, usize> {
        match self {
            CenterBudget::Fixed(k) if k > cap => Err(k),
            CenterBudget::Fixed(k) => Ok(CenterBudget::Fixed(k)),
            CenterBudget::UpTo(max) => Ok(CenterBudget::UpTo(max.min(cap))),
        }
    }
}

/// The search of a Gaussian RBF network over a fixed feature set: its
/// centre budget and the ΔT filters it chooses among.
#[derive(Clone, Debug, PartialEq)]
pub struct RbfSearch {
    /// Centres fixed or searched.
    pub centers: CenterBudget,
    /// ΔT filter time constants to choose from, s (the fastest of the three
    /// multi-scale windows, which are 1, 16 and 256 times it).
    pub rate_windows_s: Vec<f32>,
    /// Factor on the slowest multi-scale window (256 × the fastest × this);
    /// [`Method::MultiscaleValidated`] also tries
    /// [`rbf::SLOWEST_WINDOW_FACTORS`](super::rbf::SLOWEST_WINDOW_FACTORS) for the second-order family.
    pub slowest_window_factor: f32,
}

impl Default for RbfSearch {
    fn default() -> Self {
        RbfSearch {
            centers: CenterBudget::DEFAULT,
            rate_windows_s: vec![15.0, 60.0, 240.0],
            slowest_window_factor: 1.0,
        }
    }
}

/// The fixed feature sets a plain RBF search fits ([`Method::Rbf`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RbfInputs {
    /// (T, ΔT): the IFOG paper's model before its modification (`--method rbf2`).
    TempRate,
    /// (T, ΔT, T×ΔT) with Gaussians over all three: the IFOG paper's network
    /// (`--features paper`).
    Paper,
    /// T, ΔT over three time scales, T×ΔT₁, T×ΔT₂, T×ΔT₃ and T²×ΔT₂
    /// (`FeatureSet::MultiScale`: first-order lag terms); Gaussians over T, the
    /// ΔT terms linear (the Shupe effect's form).
    Multiscale,
    /// T, ΔT over three time scales, T×ΔT₂, T×ΔT₃, T²×ΔT₂ and ΔT₃²
    /// (`FeatureSet::MultiScaleSecondOrder`): with the second-order lag term.
    MultiscaleSecondOrder,
}

impl RbfInputs {
    /// The feature set these inputs are.
    pub fn feature_set(self) -> FeatureSet {
        match self {
            RbfInputs::TempRate => FeatureSet::TempRate,
            RbfInputs::Paper => FeatureSet::TempRateProduct,
            RbfInputs::Multiscale => FeatureSet::MultiScale,
            RbfInputs::MultiscaleSecondOrder => FeatureSet::MultiScaleSecondOrder,
        }
    }
}

/// The thermal lag bank's options ([`Method::LagBank`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LagBankOptions {
    /// Gaussians over the mean coil temperature T̂: none unless asked for
    /// (`--centers K`).
    pub centers: Option<usize>,
    /// The default's choice: the response bank instead of the lag bank where
    /// the lag bank misses its training runs (off when the lag bank is asked
    /// for, or Gaussians are).
    pub structure_choice: bool,
}

/// How `svr-pso` picks its multi-point inputs.
#[derive(Clone, Debug, PartialEq)]
pub enum SvrInputs {
    /// The subset of thermometers that validates best ([`thermometer_search`](super::thermometer_search)).
    BestSubset,
    /// The RLG paper's correlation rule.
    Rule(Selection),
    /// These inputs (`--inputs`).
    Named(Vec<Probe>),
}

/// The ε-SVR's options ([`Method::SvrPso`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SvrOptions {
    /// The deployed network's centre budget (support vectors reduced by OLS to it).
    pub centers: CenterBudget,
    /// ΔT windows given, s: single-point runs use the middle one.
    pub rate_windows_s: Vec<f32>,
    /// Multi-point runs: how the inputs are picked.
    pub inputs: SvrInputs,
}

/// The model forms `trainer fit` can produce, each with its own options.
#[derive(Clone, Debug, PartialEq)]
pub enum Method {
    /// The thermal lag bank (`FeatureSet::LagBank`), the default: the mean
    /// coil temperature T̂ and the loop temperature's rates through up to five
    /// derivative filters from seconds to hours, their time constants, coil
    /// lags and Shupe gain identified from the runs ([`lag_bank`](super::lag_bank)) and chosen
    /// on held-out thermal events; Gaussians and a cubic over T̂, the rates
    /// linear. Generalises to temperature histories unlike the chamber's.
    LagBank(LagBankOptions),
    /// The thermal response bank (`FeatureSet::ResponseBank`): a static
    /// cubic in T about T₀ and five responses mixed from twelve derivative
    /// filters (10 s … 1.1 h), fitted by [`response`](super::response).
    ResponseBank,
    /// A Gaussian RBF network over fixed inputs.
    Rbf {
        /// The network's inputs.
        inputs: RbfInputs,
        /// Its search.
        search: RbfSearch,
    },
    /// Both multi-scale sets fitted, the second-order one also with
    /// Gaussians over the lag-corrected temperature T − L·ΔT₃
    /// (`FeatureSet::MultiScaleLagged`, L from [`COIL_LAGS_MIN`](super::COIL_LAGS_MIN)) and with a
    /// longer slowest window ([`rbf::SLOWEST_WINDOW_FACTORS`](super::rbf::SLOWEST_WINDOW_FACTORS)), the best
    /// of those kept only when it validates clearly better than the
    /// first-order set ([`SECOND_ORDER_GAIN`](super::SECOND_ORDER_GAIN)): it generalises to ramp rates
    /// and profiles it was not trained on. One pass over the data builds both
    /// sets' blocks (they share their filters and seven of eight inputs; the
    /// lagged blocks are derived from the second-order ones).
    MultiscaleValidated(RbfSearch),
    /// Cubic in T about the mid-range temperature, clamped: the PX4/ArduPilot form.
    Poly3,
    /// ε-SVR with a Gaussian kernel on (T, ΔT, T×ΔT) or multi-point inputs,
    /// σ, C and ε tuned by particle swarm on contiguous folds (the RLG paper's
    /// method), compiled into the same RBF network.
    SvrPso(SvrOptions),
}

impl Default for Method {
    fn default() -> Self {
        Method::LagBank(LagBankOptions {
            centers: None,
            structure_choice: true,
        })
    }
}

impl Method {
    /// The method's name in `trainer fit --json` (`"method"`): the form,
    /// `Rbf` for every Gaussian network and bank (their inputs are in `features`).
    pub fn name(&self) -> &'static str {
        match self {
            Method::Rbf {
                inputs: RbfInputs::TempRate,
                ..
            } => "Rbf2",
            Method::LagBank(_) | Method::ResponseBank | Method::Rbf { .. } | Method::MultiscaleValidated(_) => "Rbf",
            Method::Poly3 => "Poly3",
            Method::SvrPso(_) => "SvrPso",
        }
    }

    /// The method with at most `cap` centres per network (a three-axis
    /// firmware holds fewer than one axis's); `Err(K)` for a fixed K above it.
    pub fn with_center_cap(mut self, cap: usize) -> Result<Method, usize> {
        match &mut self {
            Method::LagBank(bank) => {
                if let Some(k) = bank.centers.filter(|&k| k > cap) {
                    return Err(k);
                }
            }
            Method::Rbf { search, .. } | Method::MultiscaleValidated(search) => {
                search.centers = search.centers.capped(cap)?;
            }
            Method::SvrPso(svr) => svr.centers = svr.centers.capped(cap)?,
            Method::ResponseBank | Method::Poly3 => {}
        }
        Ok(self)
    }

    /// The thermometers the method's single-point model reads: the loop's,
    /// and whatever else its feature set names.
    pub fn thermometers(&self) -> ThermometerSet {
        let set = match self {
            Method::LagBank(_) | Method::ResponseBank | Method::Poly3 => FeatureSet::Temp,
            Method::Rbf { inputs, .. } => inputs.feature_set(),
            Method::MultiscaleValidated(_) => FeatureSet::MultiScaleSecondOrder,
            Method::SvrPso(_) => FeatureSet::TempRateProduct,
        };
        set.thermometers().union(ThermometerSet::LOOP)
    }
}

/// Everything `fit` needs besides the data: the method and what every method shares.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Model form and its own options.
    pub method: Method,
    /// Block length for averaging, s.
    pub block_s: f64,
    /// Contiguous folds per training run for validation when no `--validate`
    /// runs are given (never random rows: neighbouring samples correlate).
    pub folds: usize,
    /// Gyro serial number stored in the blob.
    pub serial: Option<String>,
    /// Show a progress bar.
    pub progress: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            method: Method::default(),
            block_s: 1.0,
            folds: 5,
            serial: None,
            progress: false,
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
