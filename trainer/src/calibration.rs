//! One calibration's outcome and its summary rows: every figure a unit is judged on,
//! taken from its fit's JSON (`trainer fit --json`). The one source of those figures:
//! `trainer batch` writes the rows (one per unit and axis) into summary.json, summary.csv
//! and index.html, and [`crate::records`] stores each row in the calibration record.

use serde_json::{Value, json};

/// What became of one unit: passed its spec, failed it, or could not be calibrated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// Fitted and within every limit of the spec (or judged against none).
    Pass,
    /// Fitted, but a limit of the spec was missed.
    Fail,
    /// No model: an input at fault or the fit refused it.
    Error,
}

impl Status {
    /// `pass`, `fail` or `error`, as the summary and the records spell it.
    pub const fn as_str(self) -> &'static str {
        match self {
            Status::Pass => "pass",
            Status::Fail => "fail",
            Status::Error => "error",
        }
    }

    /// The status a spelling names (`None` for any other text).
    pub fn parse(text: &str) -> Option<Status> {
        [Status::Pass, Status::Fail, Status::Error]
            .into_iter()
            .find(|s| s.as_str() == text)
    }
}

/// One calibration as the batch and the records see it.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The unit's serial number.
    pub serial: String,
    /// Pass, fail or error.
    pub status: Status,
    /// For a fail, each limit missed; for an error, the input at fault; in words.
    pub reasons: Vec<String>,
    /// The fit's JSON (`trainer fit --json`), when the fit ran.
    pub fit: Option<Value>,
    /// Kept from an earlier run of the batch (`--resume`), not fitted again.
    pub resumed: bool,
}

impl Outcome {
    /// The outcome of a fit whose JSON is `fit`: pass, or fail with the spec's reasons.
    pub fn fitted(serial: &str, fit: Value, resumed: bool) -> Outcome {
        let reasons: Vec<String> = fit["acceptance"]["reasons"]
            .as_array()
            .map(|r| r.iter().filter_map(|x| x.as_str().map(str::to_owned)).collect())
            .unwrap_or_default();
        Outcome {
            serial: serial.to_owned(),
            status: if reasons.is_empty() { Status::Pass } else { Status::Fail },
            reasons,
            fit: Some(fit),
            resumed,
        }
    }

    /// A unit that could not be calibrated, and why.
    pub fn error(serial: &str, why: String) -> Outcome {
        Outcome {
            serial: serial.to_owned(),
            status: Status::Error,
            reasons: vec![why],
            fit: None,
            resumed: false,
        }
    }
}

/// The axis of a single-axis gyro's row (an IMU's axes are `x`, `y`, `z`).
pub const SINGLE_AXIS: &str = "single";

/// The axis of the row of a unit that could not be calibrated: its axes are not known.
pub const UNKNOWN_AXIS: &str = "-";

/// The summary rows of one unit, one per axis: serial, axis, status, reasons and every
/// figure of its fit that a batch is judged on (the holdout figures are the worst over the
/// unit's holdout runs of that axis). An axis of a multi-axis unit takes its own verdict.
pub fn rows(r: &Outcome) -> Vec<Value> {
    let Some(fit) = r.fit.as_ref() else {
        return vec![row(r, UNKNOWN_AXIS, None, &Value::Null, r.status, &r.reasons)];
    };
    let Some(axes) = fit["axes"].as_array() else {
        return vec![row(r, SINGLE_AXIS, None, fit, r.status, &r.reasons)];
    };
    axes.iter()
        .map(|figures| {
            let axis = figures["axis"].as_str().unwrap_or(UNKNOWN_AXIS);
            let reasons: Vec<String> = figures["acceptance"]["reasons"]
                .as_array()
                .map(|v| v.iter().filter_map(|x| x.as_str().map(str::to_owned)).collect())
                .unwrap_or_default();
            match r.status {
                // The unit's own error (a record not written) is every axis's.
                Status::Error => row(r, axis, Some(axis), figures, Status::Error, &r.reasons),
                _ if reasons.is_empty() => row(r, axis, Some(axis), figures, Status::Pass, &reasons),
                _ => row(r, axis, Some(axis), figures, Status::Fail, &reasons),
            }
        })
        .collect()
}

/// One row: `figures` the fit's (or one axis's) JSON, the holdout evaluations those of
/// `holdout_axis` (`None`: every holdout run).
fn row(
    r: &Outcome,
    axis: &str,
    holdout_axis: Option<&str>,
    figures: &Value,
    status: Status,
    reasons: &[String],
) -> Value {
    let fit = r.fit.as_ref();
    let holdouts: Vec<&Value> = fit
        .and_then(|f| f["runs"].as_array())
        .map(|runs| {
            runs.iter()
                .filter(|x| x["role"] == "holdout")
                .map(|x| &x["evaluation"])
                .filter(|e| holdout_axis.is_none_or(|axis| e["axis"] == axis))
                .collect()
        })
        .unwrap_or_default();
    let worst = |key: &str, max: bool| {
        let values = holdouts.iter().filter_map(|e| e[key].as_f64());
        if max {
            values.reduce(f64::max)
        } else {
            values.reduce(f64::min)
        }
    };
    let clamped = holdouts
        .iter()
        .filter_map(|e| Some(100.0 * e["flagged"]["input_clamped"].as_f64()? / e["samples"].as_f64()?))
        .reduce(f64::max);
    let bias_instability = holdouts
        .iter()
        .filter_map(|e| e["allan_after"]["bias_instability_dph"].as_f64())
        .reduce(f64::max);
    let figure = |key: &str| fit.map(|_| figures[key].clone());
    json!({
        "serial": r.serial,
        "axis": axis,
        "status": status.as_str(),
        "reasons": reasons,
        "model_kind": fit.map(|f| f["method"].clone()),
        "training_std100_dph": figure("training_std100_dph"),
        "holdout_std100_before_dph": worst("cluster_std_before_dph", true),
        "holdout_std100_after_dph": worst("cluster_std_after_dph", true),
        "holdout_std100_gain_pct": worst("cluster_std_improvement_pct", false),
        "forecast_in_use_std100_dph": figure("predicted_in_use_std100_dph"),
        "forecast_settled_spread_dph": figure("predicted_settled_spread_dph"),
        "clamped_pct": clamped,
        "bias_instability_after_dph": bias_instability,
        "missing": figure("missing"),
        "settled_forecast": figure("settled_forecast"),
        "training_settled_spread_dph": figure("training_settled_spread_dph"),
        "unmodelled_dynamics": figure("unmodelled_dynamics"),
        "blob_bytes": fit.map(|f| f["blob_bytes"].clone()),
        "resumed": r.resumed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_row_takes_the_worst_holdout_and_the_spec_s_reasons_make_a_fail() {
        let fit = json!({
            "method": "lag-bank",
            "acceptance": {"status": "fail", "reasons": ["h2.csv: gain 80 % below 85 %"]},
            "runs": [
                {"role": "train", "evaluation": {"cluster_std_after_dph": 9.0}},
                {"role": "holdout", "evaluation": {"cluster_std_after_dph": 0.01, "cluster_std_improvement_pct": 95.0,
                 "samples": 1000.0, "flagged": {"input_clamped": 10.0}}},
                {"role": "holdout", "evaluation": {"cluster_std_after_dph": 0.03, "cluster_std_improvement_pct": 80.0,
                 "samples": 1000.0, "flagged": {"input_clamped": 50.0}}},
            ],
        });
        let rows = rows(&Outcome::fitted("FOG-1", fit, false));
        assert_eq!(rows.len(), 1);
        let r = &rows[0];
        assert_eq!(
            (r["status"].as_str(), r["axis"].as_str()),
            (Some("fail"), Some(SINGLE_AXIS))
        );
        assert_eq!(r["reasons"][0], "h2.csv: gain 80 % below 85 %");
        assert_eq!(
            r["holdout_std100_after_dph"], 0.03,
            "the worst holdout, not the training run"
        );
        assert_eq!(r["holdout_std100_gain_pct"], 80.0);
        assert_eq!(r["clamped_pct"], 5.0);
        assert_eq!(Status::parse("error"), Some(Status::Error));
        assert_eq!(Status::parse("ok"), None);
    }
}
