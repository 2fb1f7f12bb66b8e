//! The JSON report of `trainer fit` (`--json`): the fit's outcome, its runs' figures
//! and the model's feature configuration (which `trainer inspect --json` shares).

use rbf_core::{FeatureConfig, FeatureSet};
use trainer::describe::gain_symbol;
use trainer::evaluation::evaluate::RunEvaluation;
use trainer::fit::coverage::InUse;
use trainer::fit::vouch::SettledFloor;
use trainer::fit::{FitOutcome, FitReport};

use super::super::common::input_names;
use super::summary::settled_forecast_dph;

/// What a fit chose, as `trainer fit --json` writes it (one axis), for use
/// over `in_use`.
/// `floor`: the training runs' settled floor ([`trainer::fit::vouch`]).
pub(super) fn outcome_json(o: &FitOutcome, in_use: &InUse, floor: Option<&SettledFloor>) -> serde_json::Value {
    // Every key for every method (docs/cli.md), `null` where the method has no such figure.
    let (mut choice, mut sets, mut bank, mut structure, mut training_std100, mut svr) =
        (None, None, None, None, None, None);
    match &o.report {
        FitReport::Bank(b) => {
            choice = Some(&b.choice);
            bank = Some(&b.search);
            structure = b.structure.as_ref();
            training_std100 = b.training_std100_dph;
        }
        FitReport::Rbf(c) => choice = Some(c),
        FitReport::MultiscaleValidated { choice: c, sets: s } => (choice, sets) = (Some(c), Some(s)),
        FitReport::SvrPso(c) => svr = Some(c),
        FitReport::ResponseBank | FitReport::Poly3 => {}
    }
    let forecast = settled_forecast_dph(o, in_use, floor);
    serde_json::json!({
        "choice": choice,
        "feature_sets": sets,
        "lag_bank_search": bank,
        "structure": structure,
        "predicted_in_use_std100_dph": o.predicted_in_use_std100_dph(),
        "predicted_settled_spread_dph": forecast,
        "settled_forecast": settled_forecast(o, in_use, floor, forecast),
        // A floor under what a soak test of the unit reads, from the training runs' own settled levels.
        "training_settled_spread_dph": floor.map(|f| f.spread_dph),
        "training_settled_levels": floor.map(|f| f.levels),
        // The largest noise of those levels' means, °/h: what the settled forecast adds for a soak test's own noise.
        "training_settled_noise_dph": floor.map(|f| f.noise_dph),
        "residual_over_noise_floor": o.residual_over_noise_floor(),
        "unmodelled_dynamics": o.residual_over_noise_floor().map(trainer::fit::vouch::unmodelled),
        // What the runs lacked for `in_use` (the `missing:` lines); null for a method that does not say.
        "missing": o.bank_search().map(|b| b.coverage.missing(in_use, trainer::fit::coverage::model_range_c(&o.model))),
        "training_std100_dph": training_std100,
        "features": features_json(o.model.features()),
        "svr": svr,
    })
}

/// What `predicted_settled_spread_dph` (`forecast`) is made of, or why it is
/// null: the fit names the settled bias it cannot vouch for
/// (docs/decisions.md, "The settled curve after a planned run": no forecast
/// from a planned run alone held), and the floor under it where the training
/// runs give one.
fn settled_forecast(o: &FitOutcome, in_use: &InUse, floor: Option<&SettledFloor>, forecast: Option<f64>) -> String {
    let at_least = floor
        .map(|f| {
            format!(
                "; a soak test reads at least the training run's own settled spread, {:.4e} °/h over {} levels",
                f.spread_dph, f.levels
            )
        })
        .unwrap_or_default();
    let Some(search) = o.bank_search() else {
        return format!("not forecast: this method's fit does not read the runs' settled levels{at_least}");
    };
    if let (Some(dph), Some(f)) = (forecast, floor) {
        let factor = o.settled_floor_factor();
        let scaled = if factor > 1.0 {
            format!(" (× {factor}: a response bank that weighed its settled levels matches them closer than others)")
        } else {
            String::new()
        };
        return format!(
            "forecast: the runs hold a settled level in every 20-°C band; a soak test of other levels and order \
             reads about the training run's own settled spread, {:.4e} °/h over {} levels{scaled}, with eight levels' \
             noise ({} × {:.1e} °/h) in quadrature: {dph:.4e} °/h ({}; docs/methods.md)",
            f.spread_dph,
            f.levels,
            trainer::fit::vouch::SOAK_NOISE_RANGE_SD,
            f.noise_dph,
            trainer::fit::vouch::SETTLED_FORECAST_HELD
        );
    }
    let unsettled = search.coverage.unsettled_bands_c(in_use);
    if unsettled.is_empty() {
        "not forecast: the runs hold a settled level in every 20-°C band, but no one run holds two of them (the least a \
             floor needs)"
            .to_owned()
    } else {
        let bands: Vec<String> = unsettled.iter().map(|b| format!("{b:.0}")).collect();
        format!(
            "not forecast: no settled level in the 20-°C bands from {} °C (`missing:` says where to hold){at_least}",
            bands.join(", ")
        )
    }
}

/// The table's evaluations, as `trainer fit --json` writes them.
pub(super) fn runs_json(evals: &[(&str, RunEvaluation)]) -> serde_json::Value {
    evals
        .iter()
        .map(|(role, e)| serde_json::json!({"role": role, "evaluation": e}))
        .collect()
}

/// A model's inputs as `trainer inspect --json` and `trainer fit --json` give them.
pub fn features_json(f: &FeatureConfig) -> serde_json::Value {
    let mut v = serde_json::json!({
        "set": match f.set {
            FeatureSet::MultiPoint(_) => "MultiPoint".to_owned(),
            FeatureSet::MultiScaleLagged { .. } => "MultiScaleLagged".to_owned(),
            FeatureSet::LagBank(_) => "LagBank".to_owned(),
            FeatureSet::ResponseBank(_) => "ResponseBank".to_owned(),
            set => format!("{set:?}"),
        },
        "inputs": input_names(f.set),
        "rate_window_s": f.rate_window_s,
        "windows_s": f.filter_taus_s().as_slice(),
        "warmup_s": f.warmup_s(),
    });
    // Only what the set has: no `null` beside another set's real value.
    match f.set {
        FeatureSet::MultiScaleLagged { coil_lag_min } => v["coil_lag_min"] = serde_json::json!(coil_lag_min),
        FeatureSet::LagBank(b) => {
            v["lag_bank"] = serde_json::json!({
                "taus_s": b.taus(),
                "coil_lag_min": b.coil_lags(),
                "ref_c": b.ref_c,
                "gain_per_c": b.gain_per_c,
                "gain_per_c2": b.gain_per_c2,
                "gain_of": gain_symbol(b.gain_of),
                "static_degree": b.static_degree,
                "coil_range_c": [b.coil_min_c, b.coil_max_c],
            })
        }
        FeatureSet::ResponseBank(b) => {
            v["response_bank"] = serde_json::json!({
                "taus_s": b.taus(),
                "ref_c": b.ref_c,
                "temp_range_c": [b.range_min_c, b.range_max_c],
                "static_degree": b.static_degree,
                "weights": b.weights.iter().map(|row| &row[..b.filter_count()]).collect::<Vec<_>>(),
            })
        }
        _ => {}
    }
    v
}
