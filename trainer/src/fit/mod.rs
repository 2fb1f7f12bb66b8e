//! Model fitting: the methods `trainer fit` offers and the checks that a
//! recording can identify them at all.

pub mod coverage;
pub mod events;
pub mod lag_bank;
pub mod linalg;
pub mod ols;
pub mod poly;
pub mod pso;
pub mod rbf;
pub mod svr;
pub(crate) mod svr_data;
pub mod svr_pso;
pub mod thermometer_search;

use indicatif::{ProgressBar, ProgressStyle};
use rbf_core::model::SERIAL_CAPACITY;
use rbf_core::{FeatureSet, Model};

use crate::dataset::{Blocks, RunSet};

/// Least usable recording, s: a thermal model needs at least ten minutes.
pub const MIN_USABLE_S: f64 = 600.0;
/// Least loop-temperature span, °C, to identify a temperature dependence.
pub const MIN_TEMP_SPAN_C: f64 = 5.0;
/// Least ΔT span, °C/min, for models that use ΔT (the run must contain ramps).
pub const MIN_RATE_SPAN_C_PER_MIN: f64 = 0.2;

/// Inputs of the `rbf` method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum RbfFeatures {
    /// The default: the thermal lag bank (`FeatureSet::LagBank`): the mean
    /// coil temperature T̂ and the loop temperature's rates through up to six
    /// derivative filters from seconds to hours, their time constants, coil
    /// lags and Shupe gain identified from the runs ([`lag_bank`]) and chosen
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
    /// (`FeatureSet::MultiScaleLagged`, L from [`COIL_LAGS_MIN`]) and with a
    /// longer slowest window ([`rbf::SLOWEST_WINDOW_FACTORS`]), the best
    /// of those kept only when it validates clearly better than the
    /// first-order set ([`SECOND_ORDER_GAIN`]): it generalises to ramp rates
    /// and profiles it was not trained on. One pass over the data builds both
    /// sets' blocks (they share their filters and seven of eight inputs; the
    /// lagged blocks are derived from the second-order ones); the second
    /// search adds a quarter to a third to the fit time of one set.
    MultiscaleValidated,
    /// (T, ΔT, T×ΔT) with Gaussians over all three: the IFOG paper's network.
    Paper,
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
    /// [`rbf::SLOWEST_WINDOW_FACTORS`] for the second-order family.
    pub slowest_window_factor: f32,
    /// Contiguous folds per training run for validation when no `--validate`
    /// runs are given (never random rows: neighbouring samples correlate).
    pub folds: usize,
    /// Gyro serial number stored in the blob.
    pub serial: Option<String>,
    /// Show a progress bar.
    pub progress: bool,
    /// How `svr-pso` picks multi-point inputs: `None` = the subset of
    /// thermometers that validates best ([`thermometer_search`]), else the RLG
    /// paper's correlation rule.
    pub selection: Option<crate::gradients::Selection>,
    /// `svr-pso` on multi-point runs: these inputs instead of a selection.
    pub inputs: Option<Vec<rbf_core::features::Probe>>,
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
            inputs: None,
        }
    }
}

/// The second-order multi-scale set must validate at least this much better
/// (RMS ratio to the first-order set) to be chosen (`--features multiscale-validated`). The ΔT₃²
/// term is fitted on one training ramp rate and extrapolated to others: where
/// it does not clearly explain the training run it extrapolated badly, where
/// it does (cycle runs) it gained (figures: docs/benchmarks.md, "Measurements
/// behind design choices").
pub const SECOND_ORDER_GAIN: f64 = 0.9;

/// Coil lags L tried for [`FeatureSet::MultiScaleLagged`], minutes: the
/// Gaussians see T − L·ΔT₃. The mean coil temperature of the simulated gyros
/// lags the loop sensor by tens of minutes per °C/min of the slow rate.
pub const COIL_LAGS_MIN: [u16; 4] = [10, 20, 40, 80];

/// The second-order set's fit `second` against its variants at its window
/// and Gaussian width (centres and ridge searched), the one that validates
/// best: lagged by every coil lag of [`COIL_LAGS_MIN`], then, when the family
/// already validates better than the first-order set (`first_order_rms_dph`),
/// the same with the slowest window at the other factors of
/// [`rbf::SLOWEST_WINDOW_FACTORS`]. Lagged blocks are derived from the plain
/// set's, but a new slowest window needs its own blocks: a second pass over
/// streamed runs, made only where the family is in play (the 20-h run of
/// `cargo xtask bench-large-run` keeps the first-order set without it).
fn best_second_order_variant<T: RunSet + ?Sized, V: RunSet + ?Sized>(
    train: &T,
    validate: &V,
    second: (Model, rbf::RbfChoice),
    first_order_rms_dph: f64,
    opts: &FitOptions,
    progress: &Progress,
) -> anyhow::Result<(Model, rbf::RbfChoice)> {
    // One width: all six make the 20-h run's fit noticeably slower (`cargo
    // xtask bench-large-run`) for a marginal gain on one benchmark gyro.
    let (window, width) = (second.1.rate_window_s, [second.1.width]);
    let plain_and_lagged = || {
        std::iter::once(FeatureSet::MultiScaleSecondOrder)
            .chain(COIL_LAGS_MIN.map(|coil_lag_min| FeatureSet::MultiScaleLagged { coil_lag_min }))
    };
    let mut best = second;
    for slowest_window_factor in rbf::SLOWEST_WINDOW_FACTORS {
        let searched = slowest_window_factor.to_bits() == opts.slowest_window_factor.to_bits();
        let leads = best.1.validation_rms_dph < first_order_rms_dph;
        // A slowest window past the firmware's limit (1 day) is not offered.
        let usable = rbf::feature_config(FeatureSet::MultiScaleSecondOrder, window, slowest_window_factor).is_valid();
        let offered = searched || (leads && usable);
        if !offered {
            continue;
        }
        let at_window = FitOptions {
            rate_windows_s: vec![window],
            slowest_window_factor,
            ..opts.clone()
        };
        // The plain set at the searched factor is `second` itself.
        for set in plain_and_lagged().skip(usize::from(searched)) {
            let variant = rbf::fit_with_widths(train, validate, set, &at_window, &width, progress)?;
            if variant.1.validation_rms_dph < best.1.validation_rms_dph {
                best = variant;
            }
        }
    }
    Ok(best)
}

/// How `--features multiscale-validated` chose between the multi-scale sets
/// (the set kept is the model's, [`FitOutcome::model`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SetComparison {
    /// Validation RMS of the first-order set, °/h.
    pub first_order_rms_dph: f64,
    /// Validation RMS of the second-order set or, when one validates better,
    /// its best variant (lagged, [`COIL_LAGS_MIN`], or with a longer slowest
    /// window, [`rbf::SLOWEST_WINDOW_FACTORS`]), °/h.
    pub second_order_rms_dph: f64,
}

/// What was fitted and how it was chosen.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The deployable model.
    pub model: Model,
    /// The RBF hyper-parameters chosen (`rbf`, `rbf2`).
    pub choice: Option<rbf::RbfChoice>,
    /// The choice between the multi-scale sets (`--features multiscale-validated`).
    pub sets: Option<SetComparison>,
    /// The SVR's hyper-parameters and deployment (`svr-pso`).
    pub svr: Option<svr_pso::SvrChoice>,
    /// How the lag bank's structure was chosen (`--features lag-bank`).
    pub bank: Option<lag_bank::BankSearch>,
}

/// Fits `opts.method` on `train`, validating on `validate` (or k-fold when empty).
pub fn fit<T: RunSet + ?Sized, V: RunSet + ?Sized>(
    train: &T,
    validate: &V,
    opts: &FitOptions,
) -> anyhow::Result<FitOutcome> {
    if let Some(k) = opts.centers
        && !(1..=rbf_core::MAX_CENTERS).contains(&k)
    {
        anyhow::bail!(
            "{k} centres asked for: must be 1 ..= {} (firmware capacity)",
            rbf_core::MAX_CENTERS
        );
    }
    let progress = Progress::new(opts.progress);
    match opts.method {
        Method::Poly3 => Ok(FitOutcome {
            model: poly::fit(train, opts)?,
            choice: None,
            sets: None,
            svr: None,
            bank: None,
        }),
        Method::SvrPso => {
            if validate.count() > 0 {
                anyhow::bail!(
                    "svr-pso validates on contiguous folds of the training runs; it takes no validation runs"
                );
            }
            let (model, choice) = svr_pso::fit(train, opts, &progress)?;
            Ok(FitOutcome {
                model,
                choice: None,
                sets: None,
                svr: Some(choice),
                bank: None,
            })
        }
        Method::Rbf if opts.features == RbfFeatures::MultiscaleValidated => {
            // Both sets' blocks for every window in one pass over the data.
            let configs: Vec<_> = [FeatureSet::MultiScale, FeatureSet::MultiScaleSecondOrder]
                .into_iter()
                .flat_map(|set| {
                    let factor = opts.slowest_window_factor;
                    opts.rate_windows_s
                        .iter()
                        .map(move |&w| rbf::feature_config(set, w, factor))
                })
                .collect();
            train.prepare(&configs, opts.block_s)?;
            validate.prepare(&configs, opts.block_s)?;
            let first = rbf::fit(train, validate, FeatureSet::MultiScale, opts, &progress)?;
            // Searched in full: at the first set's width the second lost its
            // gain on the third gyro's cycle run (validation ratio above 0.9).
            let second = rbf::fit(train, validate, FeatureSet::MultiScaleSecondOrder, opts, &progress)?;
            let first_rms = first.1.validation_rms_dph;
            let second = best_second_order_variant(train, validate, second, first_rms, opts, &progress)?;
            let second_rms = second.1.validation_rms_dph;
            let keep_second = second_rms < SECOND_ORDER_GAIN * first_rms;
            let (model, choice) = if keep_second { second } else { first };
            Ok(FitOutcome {
                sets: Some(SetComparison {
                    first_order_rms_dph: first_rms,
                    second_order_rms_dph: second_rms,
                }),
                model,
                choice: Some(choice),
                svr: None,
                bank: None,
            })
        }
        Method::Rbf if opts.features == RbfFeatures::LagBank => {
            let (bank, search) = lag_bank::search(train, validate, opts, &progress)?;
            let config = rbf_core::FeatureConfig::lag_bank(bank);
            let (model, choice) = rbf::fit_configs(train, validate, &[config], opts, &rbf::WIDTHS, &progress)?;
            Ok(FitOutcome {
                model,
                choice: Some(choice),
                sets: None,
                svr: None,
                bank: Some(search),
            })
        }
        method => {
            let (model, choice) = rbf::fit(train, validate, method.feature_set(opts.features), opts, &progress)?;
            Ok(FitOutcome {
                model,
                choice: Some(choice),
                sets: None,
                svr: None,
                bank: None,
            })
        }
    }
}

/// Training data that cannot identify a model: what is missing (see
/// [`check_excitation`]; `trainer fit` adds the causes it finds in the runs,
/// [`crate::diagnose::with_causes`]).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Unidentifiable(pub String);

/// Least spread of the block-mean bias target, °/h: below it the rate
/// column carries no gyro signal (a real gyro's noise alone is larger).
pub const MIN_TARGET_SPREAD_DPH: f64 = 1e-9;

/// Refuses training data that cannot identify a model of `set`, saying what is missing.
pub fn check_excitation(blocks: &Blocks, set: FeatureSet, opts: &FitOptions) -> anyhow::Result<()> {
    let mut missing = Vec::new();
    if blocks.usable_s < MIN_USABLE_S {
        missing.push(format!(
            "the training runs hold {:.0} s of usable samples; at least {MIN_USABLE_S:.0} s are needed",
            blocks.usable_s
        ));
    }
    if blocks.is_empty() {
        return Err(
            Unidentifiable("no usable samples in the training runs (all warming up or sensor faults)".into()).into(),
        );
    }
    let (y_lo, y_hi) = blocks
        .y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &y| {
            (lo.min(y), hi.max(y))
        });
    if y_hi - y_lo < MIN_TARGET_SPREAD_DPH {
        missing.push(format!(
            "the bias target rate_dph − ref_dph is {} °/h in every block: no excitation to fit (is rate_dph the gyro output?)",
            crate::sampling::sig(y_lo)
        ));
    }
    let (lo, hi) = blocks.block_range(0);
    if hi - lo < MIN_TEMP_SPAN_C {
        missing.push(format!(
            "loop temperature spans only {:.2} °C ({lo:.2} … {hi:.2} °C); at least {MIN_TEMP_SPAN_C} °C is needed",
            hi - lo
        ));
    }
    if set != FeatureSet::Temp {
        let first_rate = match set {
            FeatureSet::LagBank(bank) => bank.static_inputs(),
            _ => 1,
        };
        let (lo, hi) = blocks.block_range(first_rate);
        if hi - lo < MIN_RATE_SPAN_C_PER_MIN {
            missing.push(format!(
                "ΔT spans only {:.3} °C/min; at least {MIN_RATE_SPAN_C_PER_MIN} °C/min is needed (the run needs temperature ramps)",
                hi - lo
            ));
        }
    }
    let parameters = 1 + set.dims() + opts.centers.unwrap_or(1);
    if blocks.len() < 10 * parameters {
        missing.push(format!(
            "{} blocks of {} s is too few for {parameters} parameters",
            blocks.len(),
            opts.block_s
        ));
    }
    if missing.is_empty() {
        Ok(())
    } else {
        Err(Unidentifiable(format!(
            "the training data cannot identify a thermal model: {}. Record a chamber run with temperature holds and ramps.",
            missing.join("; ")
        ))
        .into())
    }
}

/// Clamp ranges for deployment: the per-sample feature range seen in training.
pub(crate) fn deploy_ranges(blocks: &Blocks) -> Vec<(f32, f32)> {
    blocks
        .sample_range
        .iter()
        .map(|&(lo, hi)| (lo as f32, hi as f32))
        .collect()
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

/// A progress bar that is silent when disabled or not on a terminal.
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar, hidden unless `visible`.
    pub fn new(visible: bool) -> Self {
        Progress {
            bar: if visible {
                ProgressBar::new(0)
            } else {
                ProgressBar::hidden()
            },
        }
    }

    /// Starts a stage of `total` steps.
    pub fn start(&self, stage: &str, total: u64) {
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.set_style(
            ProgressStyle::with_template("{msg:>20} [{bar:30}] {pos}/{len} ({eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        self.bar.set_message(stage.to_owned());
    }

    /// One step done.
    pub fn inc(&self) {
        self.bar.inc(1);
    }

    /// The stage is over.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
