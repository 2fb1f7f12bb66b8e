//! The acceptance spec: the limits a unit is sold against, read from TOML, and the
//! verdict on one unit's fit (`trainer fit --spec FILE`, every unit of `trainer batch`).
//!
//! ```toml
//! [holdout]                            # every holdout run
//! std100_gain_min_pct = 85             # 100-s cluster STD improvement, %
//! clamped_max_pct = 5                  # samples clamped to the training range, %
//! std100_after_max_dph = 0.02          # 100-s cluster STD after, °/h
//! msd_after_max_dph2 = 1e-4            # MSD after, (°/h)²
//! bias_instability_after_max_dph = 0.005
//! settled_spread_max_dph = 0.01        # spread of the settled bias after (runs with plateaus)
//! [forecast]
//! in_use_std100_max_dph = 0.02         # the fit's predicted_in_use_std100_dph
//! [coverage]
//! use_range_c = [-40, 60]              # `missing:` must be empty for this range of use
//! ```
//! Every key is optional; an unknown key (a misspelt limit, a limit in another unit) is
//! refused by name, as is a limit of the wrong sign, each with the spec's file, line and column.

use std::path::Path;

use serde::Deserialize;
use toml::Spanned;

use crate::evaluation::evaluate::RunEvaluation;
use crate::text::{self, line_col};

/// Limits on every holdout run.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct HoldoutLimits {
    /// Least 100-s cluster STD improvement, %.
    pub std100_gain_min_pct: Option<Spanned<f64>>,
    /// Largest share of samples clamped to the training range, %.
    pub clamped_max_pct: Option<Spanned<f64>>,
    /// Largest 100-s cluster STD after compensation, °/h.
    pub std100_after_max_dph: Option<Spanned<f64>>,
    /// Largest MSD after compensation, (°/h)².
    pub msd_after_max_dph2: Option<Spanned<f64>>,
    /// Largest bias instability (Allan floor) after compensation, °/h.
    pub bias_instability_after_max_dph: Option<Spanned<f64>>,
    /// Largest spread of the settled bias after compensation, °/h (runs with plateaus).
    pub settled_spread_max_dph: Option<Spanned<f64>>,
}

/// Limits on the fit's forecast for in-use histories.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ForecastLimits {
    /// Largest forecast 100-s cluster STD in use, °/h.
    pub in_use_std100_max_dph: Option<Spanned<f64>>,
}

/// What the training runs must cover.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CoverageLimits {
    /// Range of use, °C: nothing may be `missing:` for it.
    pub use_range_c: Option<Spanned<[f64; 2]>>,
}

/// An acceptance spec.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Limits on every holdout run.
    #[serde(default)]
    pub holdout: HoldoutLimits,
    /// Limits on the forecast.
    #[serde(default)]
    pub forecast: ForecastLimits,
    /// Coverage.
    #[serde(default)]
    pub coverage: CoverageLimits,
}

impl Spec {
    /// Reads and checks the spec at `path`.
    pub fn read(path: &Path) -> anyhow::Result<Spec> {
        let source = std::fs::read_to_string(path)
            .map_err(|e| anyhow::anyhow!("{}: cannot read acceptance spec: {e}", text::path(path)))?;
        Spec::parse(&source, &text::path(path))
    }

    /// Parses and checks a spec; errors start with `name:line:column:`.
    pub fn parse(source: &str, name: &str) -> anyhow::Result<Spec> {
        let spec: Spec = toml::from_str(source).map_err(|e| {
            let (line, col) = e.span().map_or((1, 1), |s| line_col(source, s.start));
            anyhow::anyhow!("{name}:{line}:{col}: acceptance spec refused: {}", e.message())
        })?;
        let at = |span: std::ops::Range<usize>, why: String| {
            let (line, col) = line_col(source, span.start);
            anyhow::anyhow!("{name}:{line}:{col}: acceptance spec refused: {why}")
        };
        let h = &spec.holdout;
        for (key, limit) in [
            ("std100_gain_min_pct", &h.std100_gain_min_pct),
            ("clamped_max_pct", &h.clamped_max_pct),
        ] {
            if let Some(v) = limit
                && !(v.get_ref().is_finite() && (0.0..=100.0).contains(v.get_ref()))
            {
                return Err(at(
                    v.span(),
                    format!("{key} = {}: a share in % from 0 to 100", v.get_ref()),
                ));
            }
        }
        for (key, limit) in [
            ("std100_after_max_dph", &h.std100_after_max_dph),
            ("msd_after_max_dph2", &h.msd_after_max_dph2),
            ("bias_instability_after_max_dph", &h.bias_instability_after_max_dph),
            ("settled_spread_max_dph", &h.settled_spread_max_dph),
            ("in_use_std100_max_dph", &spec.forecast.in_use_std100_max_dph),
        ] {
            if let Some(v) = limit
                && !(v.get_ref().is_finite() && *v.get_ref() > 0.0)
            {
                return Err(at(
                    v.span(),
                    format!(
                        "{key} = {}: a largest value must be above 0 (°/h or (°/h)², as its name says)",
                        v.get_ref()
                    ),
                ));
            }
        }
        if let Some(r) = &spec.coverage.use_range_c {
            let [lo, hi] = *r.get_ref();
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(at(
                    r.span(),
                    format!("use_range_c = [{lo}, {hi}]: [MIN, MAX] in °C, MIN below MAX"),
                ));
            }
        }
        Ok(spec)
    }

    /// The range of use the coverage must hold, °C.
    pub fn use_range_c(&self) -> Option<(f64, f64)> {
        self.coverage
            .use_range_c
            .as_ref()
            .map(|r| (r.get_ref()[0], r.get_ref()[1]))
    }
}

/// What the verdict is judged on.
#[derive(Clone, Debug)]
pub struct Judged<'a> {
    /// The unit's holdout runs, evaluated.
    pub holdout: Vec<&'a RunEvaluation>,
    /// The fit's forecast of the in-use 100-s cluster STD, °/h (`None`: the method gives none).
    pub forecast_in_use_std100_dph: Option<f64>,
    /// What the training runs lack for the spec's range of use (`None`: the method
    /// does not assess coverage).
    pub missing: Option<Vec<String>>,
}

/// A unit's verdict: passed, or the limits it missed in words.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Verdict {
    /// Every limit missed, in words (empty: the unit passes).
    pub reasons: Vec<String>,
}

impl Verdict {
    /// True when no limit was missed.
    pub fn passed(&self) -> bool {
        self.reasons.is_empty()
    }
}

/// A figure below its least value, or not a number (a figure that cannot be computed
/// does not meet a limit).
fn misses_min(value: f64, min: f64) -> bool {
    value.is_nan() || value < min
}

/// A figure above its largest value, or not a number.
fn misses_max(value: f64, max: f64) -> bool {
    value.is_nan() || value > max
}

/// Judges `unit` against `spec`.
pub fn judge(spec: &Spec, unit: &Judged<'_>) -> Verdict {
    let mut reasons = Vec::new();
    let h = &spec.holdout;
    let any_holdout_limit = [
        &h.std100_gain_min_pct,
        &h.clamped_max_pct,
        &h.std100_after_max_dph,
        &h.msd_after_max_dph2,
        &h.bias_instability_after_max_dph,
        &h.settled_spread_max_dph,
    ]
    .iter()
    .any(|l| l.is_some());
    if any_holdout_limit && unit.holdout.is_empty() {
        reasons.push("the spec sets holdout limits but the unit has no holdout run".to_owned());
    }
    let value = |l: &Option<Spanned<f64>>| l.as_ref().map(|v| *v.get_ref());
    for e in &unit.holdout {
        let run = &e.run;
        if let Some(min) = value(&h.std100_gain_min_pct)
            && misses_min(e.cluster_std_improvement_pct, min)
        {
            reasons.push(format!(
                "{run}: 100-s STD gain {:.1} % below std100_gain_min_pct {min} %",
                e.cluster_std_improvement_pct
            ));
        }
        if let Some(max) = value(&h.clamped_max_pct)
            && misses_max(e.clamped_pct(), max)
        {
            reasons.push(format!(
                "{run}: {:.1} % of samples clamped, above clamped_max_pct {max} %",
                e.clamped_pct()
            ));
        }
        if let Some(max) = value(&h.std100_after_max_dph)
            && misses_max(e.cluster_std_after_dph, max)
        {
            reasons.push(format!(
                "{run}: 100-s STD after {:.4} °/h above std100_after_max_dph {max} °/h",
                e.cluster_std_after_dph
            ));
        }
        if let Some(max) = value(&h.msd_after_max_dph2)
            && misses_max(e.msd_after_dph2, max)
        {
            reasons.push(format!(
                "{run}: MSD after {:.3e} (°/h)² above msd_after_max_dph2 {max:e}",
                e.msd_after_dph2
            ));
        }
        if let Some(max) = value(&h.bias_instability_after_max_dph)
            && misses_max(e.allan_after.bias_instability_dph, max)
        {
            reasons.push(format!(
                "{run}: bias instability after {:.4} °/h above bias_instability_after_max_dph {max} °/h",
                e.allan_after.bias_instability_dph
            ));
        }
        if let Some(max) = value(&h.settled_spread_max_dph) {
            match e.settled.as_ref().and_then(|s| s.settled_spread_dph) {
                Some(spread) if spread <= max => {}
                Some(spread) => reasons.push(format!(
                    "{run}: settled-bias spread {spread:.4} °/h above settled_spread_max_dph {max} °/h"
                )),
                None => {}
            }
        }
    }
    if let Some(max) = value(&spec.forecast.in_use_std100_max_dph) {
        match unit.forecast_in_use_std100_dph {
            Some(f) if f <= max => {}
            Some(f) => reasons.push(format!(
                "forecast in-use 100-s STD {f:.4} °/h above in_use_std100_max_dph {max} °/h"
            )),
            None => reasons.push("the spec limits the forecast but this fit method gives none".to_owned()),
        }
    }
    if let Some((lo, hi)) = spec.use_range_c() {
        match &unit.missing {
            Some(missing) if missing.is_empty() => {}
            Some(missing) => reasons.push(format!(
                "the training runs lack, for use over {lo} … {hi} °C: {}",
                missing.join("; ")
            )),
            None => {
                reasons.push("the spec sets a range of use but this fit method does not assess coverage".to_owned())
            }
        }
    }
    Verdict { reasons }
}

/// The error a command returns when a unit missed its spec: the process exits 3
/// (after every output is written).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Rejected(pub String);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_keys_and_limits_of_the_wrong_sign_are_refused_with_file_line_and_column() {
        let e = Spec::parse("[holdout]\nstd100_after_max_mdph = 20\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("s.toml:2:1:") && e.contains("std100_after_max_mdph"),
            "{e}"
        );
        let e = Spec::parse("[holdout]\nstd100_after_max_dph = -0.02\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("s.toml:2:24:") && e.contains("above 0"), "{e}");
        let e = Spec::parse("[holdout]\nclamped_max_pct = 500\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("0 to 100"), "{e}");
        let e = Spec::parse("[coverage]\nuse_range_c = [60, -40]\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("MIN below MAX"), "{e}");
        let e = Spec::parse("[forecast]\nin_use_std100_max_dph = \"0.02\"\n", "s.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("s.toml:2:"), "{e}");
        assert_eq!(
            Spec::parse("", "s.toml").unwrap(),
            Spec::default(),
            "every limit is optional"
        );
    }

    #[test]
    fn without_a_holdout_run_or_a_forecast_the_limits_on_them_fail_by_name() {
        let spec = Spec::parse(
            "[holdout]\nstd100_gain_min_pct = 85\n[forecast]\nin_use_std100_max_dph = 0.02\n[coverage]\nuse_range_c = [-40, 60]\n",
            "s",
        )
        .unwrap();
        let v = judge(
            &spec,
            &Judged {
                holdout: vec![],
                forecast_in_use_std100_dph: Some(0.03),
                missing: Some(vec!["no cold start".to_owned()]),
            },
        );
        assert!(!v.passed());
        let all = v.reasons.join("\n");
        assert!(all.contains("no holdout run"), "{all}");
        assert!(all.contains("in_use_std100_max_dph 0.02"), "{all}");
        assert!(all.contains("no cold start"), "{all}");
        let ok = judge(
            &Spec::default(),
            &Judged {
                holdout: vec![],
                forecast_in_use_std100_dph: None,
                missing: None,
            },
        );
        assert!(ok.passed(), "an empty spec passes every unit that fits");
    }
}
