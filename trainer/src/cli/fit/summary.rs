//! The fit summary `trainer fit` prints (and writes to fit.txt with --report): the
//! model in words, the structure choice, the lag bank's search, the training range.

use std::io::Write;

use rbf_core::{FeatureSet, Model};
use trainer::describe::gain_text;
use trainer::evaluation::evaluate::RunEvaluation;
use trainer::fit::coverage::InUse;
use trainer::fit::{self, BankReport, FitOptions, FitOutcome, FitReport, Method, SvrInputs};

use super::super::common::{describe_selection, rule_name};

/// How the fit was asked to choose, for the summary's wording.
pub struct FitHow {
    /// Whether --validate runs chose the hyper-parameters.
    pub with_validate_runs: bool,
    /// Contiguous folds per run otherwise.
    pub folds: usize,
    /// How svr-pso was asked to pick multi-point inputs.
    pub svr_inputs: Option<SvrInputs>,
}

impl FitHow {
    /// How `opts` asks to choose, with or without --validate runs.
    pub fn new(opts: &FitOptions, with_validate_runs: bool) -> FitHow {
        FitHow {
            with_validate_runs,
            folds: opts.folds,
            svr_inputs: match &opts.method {
                Method::SvrPso(svr) => Some(svr.inputs.clone()),
                _ => None,
            },
        }
    }
}

/// The default's structure choice, as `trainer fit` prints it: both
/// structures' training residuals and held-out scores beside the runs'
/// noise floor, or why the response bank was not tried.
pub(super) fn write_structure(out: &mut impl Write, s: &fit::response::StructureChoice) -> anyhow::Result<()> {
    // What the structure taken leaves, over the floor (the lag bank's where the response bank was not taken).
    let taken_std100_dph = match s.response_bank_std100_dph {
        Some(response) if s.response_bank => response,
        _ => s.lag_bank_std100_dph,
    };
    let floor = match s.noise_floor_std100_dph {
        Some(floor) => format!(
            "; the runs' noise floor {floor:.4e} °/h ({:.2}× of it left by the {})",
            taken_std100_dph / floor,
            if s.response_bank { "response bank" } else { "lag bank" }
        ),
        None => String::new(),
    };
    match (s.response_bank_std100_dph, s.response_bank_held_out_rms_dph) {
        (Some(response), Some(response_held_out)) => writeln!(
            out,
            "structure: residual STD100 on the training runs {:.4e} °/h with the lag bank, {response:.4e} °/h with the response bank (ratio {:.2}){floor}; held-out events {:.4e} and {response_held_out:.4e} °/h (the response bank is taken below a ratio of {} when it also predicts held-out events better): {}",
            s.lag_bank_std100_dph,
            response / s.lag_bank_std100_dph,
            s.lag_bank_held_out_rms_dph,
            fit::response::RESPONSE_BANK_MARGIN,
            if s.response_bank { "response bank" } else { "lag bank" }
        )?,
        _ => writeln!(
            out,
            "structure: lag bank; residual STD100 on the training runs {:.4e} °/h{floor}: no bank gets {} of it below {} of the floor, so the response bank was not tried",
            s.lag_bank_std100_dph,
            fit::response::RESPONSE_BANK_MARGIN,
            fit::response::NOISE_FLOOR_SHARE,
        )?,
    }
    Ok(())
}

/// The fit's choices as `trainer fit` prints them above its accuracy table.
pub fn write_summary(out: &mut impl Write, outcome: &FitOutcome, how: &FitHow) -> anyhow::Result<()> {
    writeln!(out, "model: {}", describe(&outcome.model))?;
    match &outcome.report {
        FitReport::Bank(bank) => write_bank_report(out, outcome, bank, how)?,
        FitReport::Rbf(choice) => write_choice(out, choice, how)?,
        FitReport::MultiscaleValidated { choice, sets } => {
            write_choice(out, choice, how)?;
            write_sets(out, &outcome.model, sets)?;
        }
        FitReport::SvrPso(choice) => write_svr(out, choice, how)?,
        FitReport::ResponseBank | FitReport::Poly3 => {}
    }
    Ok(())
}

/// The hyper-parameters a Gaussian RBF search chose over fixed inputs.
fn write_choice(out: &mut impl Write, c: &fit::rbf::RbfChoice, how: &FitHow) -> anyhow::Result<()> {
    writeln!(
        out,
        "chosen on {}: ΔT window {} s, {}ridge λ {:e}, {} centres; validation RMS {:.4e} °/h",
        if how.with_validate_runs {
            "--validate runs".into()
        } else {
            format!("{}-fold contiguous validation", how.folds.max(2))
        },
        c.rate_window_s,
        width_text(c),
        c.ridge,
        c.centers,
        c.validation_rms_dph
    )?;
    Ok(())
}

/// The Gaussian width, where there are Gaussians to speak of.
fn width_text(c: &fit::rbf::RbfChoice) -> String {
    if c.centers == 0 {
        String::new()
    } else {
        format!("width σ {} (normalised), ", c.width)
    }
}

/// The lag bank's fit: the structure choice, the forecast, the network
/// (unless the response bank replaced it) and the bank itself.
fn write_bank_report(
    out: &mut impl Write,
    outcome: &FitOutcome,
    bank: &BankReport,
    how: &FitHow,
) -> anyhow::Result<()> {
    if let Some(s) = &bank.structure {
        write_structure(out, s)?;
    }
    if let (Some(predicted), Some(factor), Some(training)) = (
        outcome.predicted_in_use_std100_dph(),
        outcome.excess_factor(),
        bank.training_std100_dph,
    ) {
        writeln!(
            out,
            "predicted residual STD100 in use {predicted:.4e} °/h ({})",
            forecast_basis(bank, training, factor)
        )?;
    }
    if !bank.response_bank_chosen() {
        // The bank's filters are its structure and its held-out figure is the
        // structure's, both printed below, not one window and one RMS.
        let c = &bank.choice;
        writeln!(
            out,
            "chosen on {}: {}ridge λ {:e}, {} centres",
            if how.with_validate_runs {
                "--validate runs".into()
            } else {
                format!("the same {} folds as the bank's structure", bank.search.fold_count)
            },
            width_text(c),
            c.ridge,
            c.centers,
        )?;
    }
    write_bank(out, &outcome.model, &bank.search)
}

/// What the in-use forecast is made of and what it holds for: the training
/// residual, its noise floor kept and the rest scaled by `factor`, for
/// temperature changes no faster than the runs' fastest.
fn forecast_basis(bank: &BankReport, training: f64, factor: f64) -> String {
    let parts = bank.noise_floor_std100_dph.map_or_else(
        || format!("×{factor} (the runs too short to tell its noise floor)"),
        |floor| format!("its white-noise floor {floor:.4e} °/h as it is, the rest ×{factor}"),
    );
    let rates = bank.search.coverage.rates.first().map_or(String::new(), |fast| {
        format!(
            "; for temperature changes within the runs' {:.1} … {:+.1} °C/min (τ {:.0} s)",
            fast.min_c_per_min, fast.max_c_per_min, fast.tau_s
        )
    });
    format!("the training residual {training:.4e} °/h on the fit's block means, warm-up left out: {parts}{rates}")
}

/// How `--features multiscale-validated` chose between the multi-scale sets.
fn write_sets(out: &mut impl Write, model: &Model, s: &fit::SetComparison) -> anyhow::Result<()> {
    let kept = model.features();
    let slowest_s = kept.windows_s()[2];
    let kept = match kept.set {
        FeatureSet::MultiScale => "first-order".to_owned(),
        FeatureSet::MultiScaleLagged { coil_lag_min } => {
            format!("second-order, coil lag {coil_lag_min} min, slowest window {slowest_s} s")
        }
        _ => format!("second-order, slowest window {slowest_s} s"),
    };
    writeln!(
        out,
        "feature sets: first-order validation RMS {:.4e} °/h, second-order (ΔT₃², coil lags {:?} min and slowest window ×{:?} tried) {:.4e} °/h (ratio {:.3}; kept when < {}): {}",
        s.first_order_rms_dph,
        fit::COIL_LAGS_MIN,
        fit::rbf::SLOWEST_WINDOW_FACTORS,
        s.second_order_rms_dph,
        s.second_order_rms_dph / s.first_order_rms_dph,
        fit::SECOND_ORDER_GAIN,
        kept
    )?;
    Ok(())
}

/// The SVR's inputs, its swarm's choice and its deployment.
fn write_svr(out: &mut impl Write, c: &fit::svr_pso::SvrChoice, how: &FitHow) -> anyhow::Result<()> {
    if let Some(sel) = &c.selection {
        let rule = match &how.svr_inputs {
            Some(SvrInputs::Named(_)) => "--inputs".to_owned(),
            Some(SvrInputs::Rule(rule)) => rule_name(*rule),
            Some(SvrInputs::BestSubset) | None => format!(
                "the best of {} subsets of thermometers on 3-fold contiguous validation",
                (1u32 << sel.table.names.len()) - 1
            ),
        };
        write!(out, "{}", describe_selection(&sel.table, &sel.selected, &rule))?;
        if !sel.ranking.is_empty() {
            writeln!(out, "validation RMS of the best subsets (°/h):")?;
            for s in &sel.ranking {
                let names: Vec<&str> = s.sensors.iter().map(|&k| sel.table.names[k].as_str()).collect();
                writeln!(out, "  {:.4e}  {}", s.validation_rms_dph, names.join(", "))?;
            }
        }
    }
    writeln!(out, "inputs: {}", c.inputs.join(", "))?;
    writeln!(
        out,
        "PSO on 3-fold contiguous validation of the deployed network ({} particles × {} iterations): ΔT window {} s, σ {:.4} (normalised), C {:.4e}, ε {:.3e} °/h; the SVR's own validation RMS {:.4e} °/h",
        c.pso.particles,
        c.pso.iterations,
        c.rate_window_s,
        c.params.sigma,
        c.params.c,
        c.params.epsilon,
        c.validation_rms_dph
    )?;
    writeln!(
        out,
        "{} support vectors → {} centres deployed (OLS, weights refitted); validation RMS of the deployed network {:.4e} °/h (the swarm's fitness)",
        c.support_vectors, c.centers, c.deployed_validation_rms_dph
    )?;
    Ok(())
}

/// The lag bank a fit identified, how it was chosen, and what the training runs covered.
pub(super) fn write_bank(
    out: &mut impl Write,
    model: &Model,
    search: &fit::lag_bank::BankSearch,
) -> anyhow::Result<()> {
    let FeatureSet::LagBank(bank) = model.features().set else {
        return Ok(());
    };
    let list = |v: &[f32], digits: usize| v.iter().map(|x| format!("{x:.digits$}")).collect::<Vec<_>>().join(", ");
    writeln!(
        out,
        "lag bank: τ [{}] s; coil lags a [{}] min (T̂ = T + Σ a·ΔT); Shupe gain {}; T₀ {} °C",
        list(bank.taus(), 0),
        list(bank.coil_lags(), 2),
        gain_text(&bank),
        trainer::describe::summary::sig(f64::from(bank.ref_c), 4),
    )?;
    let how = match search.folds {
        fit::events::FoldKind::Runs => format!("leave-one-run-out ({} folds)", search.fold_count),
        fit::events::FoldKind::Events => format!(
            "{} folds of whole thermal events ({} events found)",
            search.fold_count, search.events
        ),
        fit::events::FoldKind::Contiguous => format!(
            "{} contiguous folds (only {} thermal events found)",
            search.fold_count, search.events
        ),
    };
    writeln!(
        out,
        "structure chosen on {how} among {} candidates; held-out RMS of 100-s means {:.4e} °/h (it chose the \
         structure; the forecast above is made of the training residual, docs/methods.md \"The forecast\")",
        search.candidates.len(),
        search.held_out_rms_dph()
    )?;
    if search.lag_prior == fit::lag_bank::LagPrior::NoBankWithout {
        writeln!(
            out,
            "coil lags held near their filters' time constants by the soft prior: without it no candidate's lags \
             were ones the blob carries (hours of opposite sign, or over a day per °C/min)"
        )?;
    }
    let dims = model.features().dims();
    let mut covered = Vec::new();
    for i in 0..dims {
        let (Some(name), Some((lo, hi))) = (model.features().set.name(i), model.input_range(i)) else {
            continue;
        };
        if matches!(
            name,
            rbf_core::features::InputName::Bank(rbf_core::lag_bank::BankInput::CoilTemp { power: 2.. })
        ) {
            continue;
        }
        covered.push(format!("{name} {lo:.3} … {hi:.3}"));
    }
    writeln!(out, "training covered: {}", covered.join("; "))?;
    let x = &search.extrapolation;
    let end = |name: &str, e: &fit::lag_bank::EdgeTest| {
        if e.tangent_rms_dph.is_nan() {
            format!("{name}: too few means to test, tangent")
        } else {
            format!(
                "{name}: tangent {:.2e} / cubic {:.2e} °/h → {}",
                e.tangent_rms_dph,
                e.cubic_rms_dph,
                if e.reach_c > 0.0 {
                    format!("cubic for {:.1} °C", e.reach_c)
                } else {
                    "tangent".to_owned()
                }
            )
        }
    };
    writeln!(
        out,
        "extrapolation of the static cubic past T̂ {:.1} … {:.1} °C (edge test, outer {:.1} °C held out): {}; {}",
        x.covered_c.0,
        x.covered_c.1,
        x.band_c,
        end("below", &x.lower),
        end("above", &x.upper)
    )?;
    Ok(())
}

/// One line naming the model as it is ([`trainer::describe`]): kind, form,
/// T₀, and the ΔT windows of a set that is not a lag bank (whose filters
/// the bank's own line lists).
pub(super) fn describe(model: &Model) -> String {
    let f = model.features();
    let windows: Vec<String> = f
        .filter_taus_s()
        .iter()
        .map(|t| trainer::describe::summary::sig(f64::from(*t), 4))
        .collect();
    let d = trainer::describe::describe(model);
    match f.set {
        FeatureSet::LagBank(_) | FeatureSet::ResponseBank(_) => d.line(),
        _ if windows.is_empty() => d.line(),
        _ => format!("{}; ΔT windows {} s", d.line(), windows.join(", ")),
    }
}

/// The loop temperature's range over the training runs, °C: the lag bank
/// search's coverage (10-s means), or the model's first input's training
/// range where that input is the loop temperature; `None` otherwise.
pub(super) fn training_loop_range_c(outcome: &FitOutcome) -> Option<(f64, f64)> {
    if let Some(search) = outcome.bank_search() {
        return Some(search.coverage.temp_range_c);
    }
    match outcome.model.features().set {
        FeatureSet::Temp
        | FeatureSet::TempRate
        | FeatureSet::TempRateProduct
        | FeatureSet::MultiScale
        | FeatureSet::MultiScaleSecondOrder => {
            let (lo, hi) = outcome.model.input_range(0)?;
            Some((f64::from(lo), f64::from(hi)))
        }
        // A response bank's range is the loop temperature's over its training runs.
        FeatureSet::ResponseBank(b) => Some((f64::from(b.range_min_c), f64::from(b.range_max_c))),
        _ => None,
    }
}

/// The floor under a soak test's settled spread from the training runs'
/// evaluations in `evals` (those of `axis`, for a multi-axis fit;
/// [`fit::vouch::settled_floor`]).
pub(super) fn training_settled_floor(
    evals: &[(&str, RunEvaluation)],
    axis: Option<&'static str>,
) -> Option<fit::vouch::SettledFloor> {
    fit::vouch::settled_floor(
        evals
            .iter()
            .filter(|(role, e)| *role == "train" && e.axis == axis)
            .filter_map(|(_, e)| e.settled.as_ref()),
    )
}

/// The settled spread a soak test of the unit is forecast to read
/// ([`fit::vouch::settled_forecast_dph`]): where the runs of `outcome` hold a
/// settled level in every 20-°C band of the range of use (never for a method
/// that does not read them).
pub(super) fn settled_forecast_dph(
    outcome: &FitOutcome,
    in_use: &InUse,
    floor: Option<&fit::vouch::SettledFloor>,
) -> Option<f64> {
    let every_band_settled = outcome
        .bank_search()
        .is_some_and(|s| s.coverage.unsettled_bands_c(in_use).is_empty());
    fit::vouch::settled_forecast_dph(floor, every_band_settled, outcome.settled_floor_factor())
}

/// What the fit vouches for, as `trainer fit` prints it below the coverage
/// lines ([`fit::vouch::lines`]).
pub(super) fn write_vouching(
    out: &mut impl Write,
    outcome: &FitOutcome,
    in_use: &InUse,
    floor: Option<&fit::vouch::SettledFloor>,
) -> anyhow::Result<()> {
    let forecast = settled_forecast_dph(outcome, in_use, floor);
    for line in fit::vouch::lines(floor, forecast, outcome.residual_over_noise_floor()) {
        writeln!(out, "{line}")?;
    }
    Ok(())
}
