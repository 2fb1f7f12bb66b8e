//! A model described as it is, from the model itself: its kind, its form,
//! its inputs with units and its reference temperature T₀. `trainer fit`,
//! `trainer inspect` and report.md print these same words. Its [`summary`]
//! gives the tidy numbers and counts those words are made of.

pub mod summary;

use rbf_core::Model;
use rbf_core::features::FeatureSet;
use rbf_core::lag_bank::{GainOf, LagBank};
use rbf_core::model::ModelBody;
use rbf_core::response_bank::ResponseBank;
use serde::Serialize;

use crate::describe::summary::{count, sig};

/// What a model is, in words.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelDescription {
    /// The model's kind, e.g. `thermal lag bank`: what its inputs are.
    pub kind: String,
    /// How the bias follows from the inputs, e.g. `linear in its 8 inputs`.
    pub form: String,
    /// The inputs with their units, in the model's order.
    pub inputs: Vec<String>,
    /// Reference temperature T₀ of the model's powers and gains, °C; absent
    /// when no input is taken about one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ref_temp_c: Option<f32>,
    /// The unit of the bias the model gives.
    pub bias_unit: &'static str,
}

impl ModelDescription {
    /// One line: kind, form and T₀ (`thermal lag bank, linear in its 8 inputs; …; T₀ 10 °C`).
    pub fn line(&self) -> String {
        let t0 = self
            .ref_temp_c
            .map_or(String::new(), |t| format!("; T₀ {} °C", sig(f64::from(t), 4)));
        format!("{}, {}{t0}", self.kind, self.form)
    }
}

/// The description of `model`, one arm per feature set: a new kind of model is one arm more.
pub fn describe(model: &Model) -> ModelDescription {
    let set = model.features().set;
    let kind = match set {
        FeatureSet::Temp => "static curve of the loop temperature T (PX4/ArduPilot form)".to_owned(),
        FeatureSet::TempRate => "IFOG paper's model before its modification, (T, ΔT)".to_owned(),
        FeatureSet::TempRateProduct => "IFOG paper's model, (T, ΔT, T×ΔT)".to_owned(),
        FeatureSet::MultiScale => "multi-scale rates, first order".to_owned(),
        FeatureSet::MultiScaleSecondOrder => "multi-scale rates, second order".to_owned(),
        FeatureSet::MultiScaleLagged { coil_lag_min } => {
            format!("multi-scale rates, second order, coil lag {coil_lag_min} min")
        }
        FeatureSet::MultiPoint(probes) => format!(
            "multi-point temperatures ({})",
            count(probes.len() as u64, "thermometer input", "thermometer inputs")
        ),
        FeatureSet::LagBank(_) => "thermal lag bank".to_owned(),
        FeatureSet::ResponseBank(_) => "thermal response bank".to_owned(),
    };
    let (form, body_ref_c) = match model.body() {
        ModelBody::Rbf(net) => {
            let names: Vec<String> = set.names().map(|n| n.to_string()).collect();
            let kernel = &names[..net.kernel_inputs().min(names.len())];
            let linear = match net.linear().len() {
                0 => String::new(),
                n if n == names.len() => format!("linear in its {}", count(n as u64, "input", "inputs")),
                n => format!("linear in {}", count(n as u64, "input", "inputs")),
            };
            let form = match (net.centers_used(), linear.is_empty()) {
                (0, true) => "a constant".to_owned(),
                (0, false) => linear,
                (k, linear_empty) => format!(
                    "Gaussian RBF, {} over ({}){}",
                    count(k as u64, "centre", "centres"),
                    kernel.join(", "),
                    if linear_empty {
                        String::new()
                    } else {
                        format!(", plus {linear}")
                    }
                ),
            };
            (form, None)
        }
        ModelBody::Poly3(p) => ("cubic in (T − T₀)".to_owned(), Some(p.ref_temp_c)),
    };
    let (form, ref_temp_c) = match set {
        FeatureSet::LagBank(bank) => (format!("{form}; {}", bank_form(&bank)), Some(bank.ref_c)),
        FeatureSet::ResponseBank(bank) => (format!("{form}; {}", response_bank_form(&bank)), Some(bank.ref_c)),
        _ => (form, body_ref_c),
    };
    ModelDescription {
        kind,
        form,
        inputs: set.names().map(|n| n.to_string()).collect(),
        ref_temp_c,
        bias_unit: "°/h",
    }
}

/// A response bank's filters and static curve: `12 filters 10 s … 1.1 h on
/// T, (T − T₀)², (T − T₀)³, static cubic in T`.
pub fn response_bank_form(bank: &ResponseBank) -> String {
    let taus = bank.taus();
    let span = |s: f32| {
        let s = f64::from(s);
        if s >= 3600.0 {
            format!("{} h", sig(s / 3600.0, 3))
        } else {
            format!("{} s", sig(s, 3))
        }
    };
    format!(
        "{} {} … {} on T, (T − T₀)², (T − T₀)³, static {} in T",
        count(taus.len() as u64, "filter", "filters"),
        taus.first().map_or_else(String::new, |&t| span(t)),
        taus.last().map_or_else(String::new, |&t| span(t)),
        ["linear", "quadratic", "cubic", "quartic"]
            .get(bank.static_inputs().wrapping_sub(1))
            .unwrap_or(&"curve"),
    )
}

/// The temperature a bank's gain is of: `T̂` or `T`.
pub fn gain_symbol(of: GainOf) -> &'static str {
    match of {
        GainOf::Coil => "T̂",
        GainOf::Loop => "T",
    }
}

/// A lag bank's coil temperature and Shupe gain, with its terms that are not zero:
/// `T̂ = T + Σ a_k·ΔT_k over 5 filters, g = 1 + 6.23e-3·(T̂ − T₀)`.
pub fn bank_form(bank: &LagBank) -> String {
    format!(
        "T̂ = T + Σ a_k·ΔT_k over {}, Shupe gain {}",
        count(bank.filter_count() as u64, "filter", "filters"),
        gain_text(bank)
    )
}

/// A bank's Shupe gain with only its non-zero terms: `g = 1`, `g = 1 + 6.226e-3·(T̂ − T₀)`.
pub fn gain_text(bank: &LagBank) -> String {
    let of = gain_symbol(bank.gain_of);
    let mut g = "g = 1".to_owned();
    for (coefficient, power) in [(bank.gain_per_c, ""), (bank.gain_per_c2, "²")] {
        if coefficient != 0.0 {
            let sign = if coefficient < 0.0 { '−' } else { '+' };
            g.push_str(&format!(" {sign} {:.3e}·({of} − T₀){power}", coefficient.abs()));
        }
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_gain_shows_only_its_terms_that_are_not_zero() {
        let mut bank = LagBank {
            taus_s: [0.0; rbf_core::lag_bank::BANK_FILTERS],
            filters: 1,
            coil_lag_min: [0.0; rbf_core::lag_bank::BANK_FILTERS],
            ref_c: 10.0,
            gain_per_c: 6.226e-3,
            gain_per_c2: 0.0,
            static_degree: 3,
            coil_min_c: -30.0,
            coil_max_c: 50.0,
            gain_of: GainOf::Coil,
        };
        assert_eq!(gain_text(&bank), "g = 1 + 6.226e-3·(T̂ − T₀)");
        bank.gain_per_c = 0.0;
        bank.gain_per_c2 = -2e-5;
        assert_eq!(gain_text(&bank), "g = 1 − 2.000e-5·(T̂ − T₀)²");
    }
}
