//! The in-use section's verdict: how far each forecast is from what was
//! measured, each plant's figures against the issue-32 targets
//! ([`PlantSummary`]), and the summary table over all plants.

/// What a training run is, for the targets that name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Training {
    /// A planned chamber run (`trainer plan`).
    Planned,
    /// The 1 °C/min cycle with 2-h holds.
    Cycle,
    /// The designed 10.9-h multi-rate run.
    Designed,
}

/// How far a forecast is from what was measured, as a factor of at least 1:
/// max(f/m, m/f). `None` where either is missing, not finite or not positive.
pub(super) fn forecast_factor(forecast_dph: Option<f64>, measured_dph: f64) -> Option<f64> {
    let f = forecast_dph?;
    let usable = |x: f64| x.is_finite() && x > 0.0;
    (usable(f) && usable(measured_dph)).then(|| (f / measured_dph).max(measured_dph / f))
}

/// The worst [`forecast_factor`] over `measured_dph`; `None` if any run has none.
pub(super) fn worst_forecast_factor(forecast_dph: Option<f64>, measured_dph: &[f64]) -> Option<f64> {
    measured_dph
        .iter()
        .map(|m| forecast_factor(forecast_dph, *m))
        .try_fold(1.0f64, |worst, f| Some(worst.max(f?)))
}

/// The issue-32 targets for gyros of designs nobody tuned on: trained on the
/// planned run, the in-use mean and worst 100-s cluster STD improvement, %;
/// trained on the cycle, the mean, %; the forecast within this factor of every
/// measured residual (planned and cycle trainings).
pub(super) const TARGET_PLANNED_MEAN_PCT: f64 = 93.0;
pub(super) const TARGET_PLANNED_WORST_PCT: f64 = 91.0;
pub(super) const TARGET_CYCLE_MEAN_PCT: f64 = 88.0;
pub(super) const TARGET_FORECAST_FACTOR: f64 = 1.5;

/// One plant's figures for the summary and the targets.
#[derive(Clone, Debug, Default)]
pub(super) struct PlantSummary {
    pub(super) name: String,
    /// Per training run: the default's mean and worst improvement, % (`None`: refused).
    pub(super) default_pct: Vec<(Training, Option<(f64, f64)>)>,
    /// Per training run: the worst forecast factor (`None`: no forecast).
    pub(super) forecast: Vec<(Training, Option<f64>)>,
    /// Per training run: the settled forecast's worst factor over the soak
    /// tests (`None`: the fit did not forecast it, or no soak reading).
    pub(super) settled_forecast: Vec<(Training, Option<f64>)>,
    /// The noise ceiling's mean and worst, %.
    pub(super) ceiling_pct: (f64, f64),
    /// The loop temperature's range on the planned run, °C.
    pub(super) planned_loop_c: (f64, f64),
}

impl PlantSummary {
    /// The mean and worst improvement after `training`, %: over several
    /// trainings of that kind (plans of other seeds), the mean of each;
    /// `None` when any was refused or none ran.
    pub(super) fn scores(&self, training: Training) -> Option<(f64, f64)> {
        let scores: Vec<(f64, f64)> = self
            .default_pct
            .iter()
            .filter(|(t, _)| *t == training)
            .map(|(_, s)| *s)
            .collect::<Option<_>>()?;
        let n = scores.len();
        (n > 0).then(|| {
            let (mean, worst) = scores.iter().fold((0.0, 0.0), |acc, s| (acc.0 + s.0, acc.1 + s.1));
            (mean / n as f64, worst / n as f64)
        })
    }

    /// The `index`-th training's scores, in column order ([`summary_table`]).
    fn scores_at(&self, index: usize) -> Option<(f64, f64)> {
        self.default_pct.get(index).and_then(|(_, s)| *s)
    }

    /// The worst forecast factor over every planned and cycle training
    /// (`None` when any of them has none).
    pub(super) fn target_forecast(&self) -> Option<f64> {
        let judged: Vec<Option<f64>> = self
            .forecast
            .iter()
            .filter(|(k, _)| matches!(k, Training::Planned | Training::Cycle))
            .map(|(_, f)| *f)
            .collect();
        if judged.is_empty() {
            return None;
        }
        judged.into_iter().try_fold(1.0f64, |worst, f| Some(worst.max(f?)))
    }

    /// The targets this plant misses, in words; empty when it meets them all.
    /// A figure that is not a number (NaN) misses.
    pub(super) fn missed_targets(&self) -> Vec<String> {
        let below = |x: f64, target: f64| x.is_nan() || x < target;
        let mut missed = Vec::new();
        match self.scores(Training::Planned) {
            None => missed.push("planned: fit refused".to_owned()),
            Some((mean, worst)) => {
                if below(mean, TARGET_PLANNED_MEAN_PCT) {
                    missed.push(format!("planned mean {mean:.1} < {TARGET_PLANNED_MEAN_PCT}"));
                }
                if below(worst, TARGET_PLANNED_WORST_PCT) {
                    missed.push(format!("planned worst {worst:.1} < {TARGET_PLANNED_WORST_PCT}"));
                }
            }
        }
        match self.scores(Training::Cycle) {
            None => missed.push("cycle: fit refused".to_owned()),
            Some((mean, _)) if below(mean, TARGET_CYCLE_MEAN_PCT) => {
                missed.push(format!("cycle mean {mean:.1} < {TARGET_CYCLE_MEAN_PCT}"))
            }
            Some(_) => {}
        }
        match self.target_forecast() {
            None => missed.push("no forecast".to_owned()),
            Some(f) if f.is_nan() || f > TARGET_FORECAST_FACTOR => {
                missed.push(format!("forecast ×{f:.2} > {TARGET_FORECAST_FACTOR}"))
            }
            Some(_) => {}
        }
        missed
    }
}

/// The summary: per plant the default's mean / worst improvement per
/// training run, the forecast's worst factor (planned and cycle), the noise
/// ceiling, the planned run's loop range and the targets missed; then over all plants.
/// `training`: each training run's kind and name, in column order.
pub(super) fn summary_table(plants: &[PlantSummary], training: &[(Training, &str)]) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let pair = |s: Option<(f64, f64)>| s.map_or("refused".to_owned(), |(m, w)| format!("{m:.1} / {w:.1}"));
    let factor = |f: Option<f64>| f.map_or("-".to_owned(), |f| format!("×{f:.2}"));
    let _ = writeln!(
        out,
        "\nin-use summary: the default's mean / worst improvement over the four in-use runs [%], trained on"
    );
    let _ = write!(out, "{:<18}", "plant");
    for (i, (kind, name)) in training.iter().enumerate() {
        let short = name.split(' ').next().unwrap_or_default();
        // Several trainings of a kind (plans of other seeds): numbered.
        let of_kind = training.iter().filter(|(k, _)| k == kind).count();
        let nth = training[..i].iter().filter(|(k, _)| k == kind).count() + 1;
        let label = if of_kind > 1 {
            format!("{short} {nth}")
        } else {
            short.to_owned()
        };
        let _ = write!(out, " {label:>15}");
    }
    let _ = writeln!(
        out,
        " {:>10} {:>15} {:>15}  targets (planned ≥ {TARGET_PLANNED_MEAN_PCT} / {TARGET_PLANNED_WORST_PCT}, cycle ≥ {TARGET_CYCLE_MEAN_PCT}, forecast within ×{TARGET_FORECAST_FACTOR})",
        "forecast", "noise ceiling", "planned loop °C"
    );
    for p in plants {
        let _ = write!(out, "{:<18}", p.name);
        for i in 0..training.len() {
            let _ = write!(out, " {:>15}", pair(p.scores_at(i)));
        }
        let missed = p.missed_targets();
        let _ = writeln!(
            out,
            " {:>10} {:>15} {:>15}  {}",
            factor(p.target_forecast()),
            pair(Some(p.ceiling_pct)),
            format!("{:.1} … {:.1}", p.planned_loop_c.0, p.planned_loop_c.1),
            if missed.is_empty() {
                "met".to_owned()
            } else {
                missed.join("; ")
            }
        );
    }
    // Over all plants: the mean of the means, the worst of the worsts.
    let overall = |scores: Vec<Option<(f64, f64)>>| -> Option<(f64, f64)> {
        let scores: Vec<(f64, f64)> = scores.into_iter().collect::<Option<_>>()?;
        let mean = scores.iter().map(|s| s.0).sum::<f64>() / scores.len().max(1) as f64;
        Some((mean, scores.iter().map(|s| s.1).fold(f64::INFINITY, f64::min)))
    };
    let _ = write!(out, "{:<18}", "all plants");
    for i in 0..training.len() {
        let _ = write!(
            out,
            " {:>15}",
            pair(overall(plants.iter().map(|p| p.scores_at(i)).collect()))
        );
    }
    let forecast = plants
        .iter()
        .map(PlantSummary::target_forecast)
        .try_fold(1.0f64, |worst, f| Some(worst.max(f?)));
    let missing = plants.iter().filter(|p| !p.missed_targets().is_empty()).count();
    let _ = writeln!(
        out,
        " {:>10} {:>15} {:>15}  {missing} of {} plants miss a target",
        factor(forecast),
        pair(overall(plants.iter().map(|p| Some(p.ceiling_pct)).collect())),
        "",
        plants.len()
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12
    }

    #[test]
    fn the_forecast_factor_is_symmetric_and_at_least_one() {
        let f = |forecast, measured| forecast_factor(Some(forecast), measured).unwrap();
        assert!(close(f(0.02, 0.01), 2.0));
        assert!(close(f(0.01, 0.02), 2.0), "too low counts as much as too high");
        assert!(close(f(0.0123, 0.0123), 1.0));
        // Nothing to compare: no forecast, a refused fit's NaN, a zero residual.
        assert_eq!(forecast_factor(None, 0.01), None);
        assert_eq!(forecast_factor(Some(0.01), f64::NAN), None);
        assert_eq!(forecast_factor(Some(0.01), 0.0), None);
        assert_eq!(forecast_factor(Some(-0.01), 0.01), None);
        // The worst over the runs, whichever side it is on; one run without a figure: none.
        let worst = worst_forecast_factor(Some(0.01), &[0.011, 0.004, 0.018]).unwrap();
        assert!(close(worst, 2.5), "{worst}");
        assert_eq!(worst_forecast_factor(Some(0.01), &[0.011, f64::NAN]), None);
        assert_eq!(worst_forecast_factor(None, &[0.01]), None);
    }

    /// A plant scored `planned` and `cycle` (mean, worst), forecast factors for both.
    fn plant(planned: Option<(f64, f64)>, cycle: Option<(f64, f64)>, forecast: [Option<f64>; 2]) -> PlantSummary {
        PlantSummary {
            name: "design 9".into(),
            default_pct: vec![
                (Training::Planned, planned),
                (Training::Cycle, cycle),
                (Training::Designed, Some((10.0, 5.0))),
            ],
            forecast: vec![
                (Training::Planned, forecast[0]),
                (Training::Cycle, forecast[1]),
                (Training::Designed, Some(9.0)),
            ],
            settled_forecast: Vec::new(),
            ceiling_pct: (97.0, 95.0),
            planned_loop_c: (-40.0, 55.0),
        }
    }

    #[test]
    fn the_targets_name_what_a_plant_misses_and_only_that() {
        let good = plant(Some((93.0, 91.0)), Some((88.0, 60.0)), [Some(1.5), Some(1.0)]);
        // At the targets is meeting them; the designed run is not judged.
        assert_eq!(good.missed_targets(), Vec::<String>::new());
        assert!(close(good.target_forecast().unwrap(), 1.5));
        let bad = plant(Some((92.9, 85.0)), Some((87.0, 80.0)), [Some(1.2), Some(1.8)]);
        assert_eq!(
            bad.missed_targets(),
            [
                "planned mean 92.9 < 93",
                "planned worst 85.0 < 91",
                "cycle mean 87.0 < 88",
                "forecast ×1.80 > 1.5"
            ]
        );
        let refused = plant(None, Some((f64::NAN, 0.0)), [None, Some(1.0)]);
        assert_eq!(
            refused.missed_targets(),
            ["planned: fit refused", "cycle mean NaN < 88", "no forecast"]
        );
    }

    #[test]
    fn plans_of_several_seeds_are_judged_by_their_means_and_the_worst_forecast() {
        let mut p = plant(Some((95.0, 93.0)), Some((90.0, 85.0)), [Some(1.2), Some(1.3)]);
        // A second plan's training, scored lower and forecast worse.
        p.default_pct.insert(1, (Training::Planned, Some((89.0, 87.0))));
        p.forecast.insert(1, (Training::Planned, Some(1.7)));
        let (mean, worst) = p.scores(Training::Planned).unwrap();
        assert!(close(mean, 92.0) && close(worst, 90.0), "{mean} {worst}");
        assert!(close(p.target_forecast().unwrap(), 1.7));
        assert_eq!(
            p.missed_targets(),
            [
                "planned mean 92.0 < 93",
                "planned worst 90.0 < 91",
                "forecast ×1.70 > 1.5"
            ]
        );
        // Its columns are numbered and keep each plan's own figures.
        let training = [
            (Training::Planned, "planned seed 1"),
            (Training::Planned, "planned seed 2"),
            (Training::Cycle, "cycle"),
            (Training::Designed, "designed"),
        ];
        let table = summary_table(std::slice::from_ref(&p), &training);
        let lines: Vec<&str> = table.lines().filter(|l| !l.is_empty()).collect();
        assert!(
            lines[1].contains("planned 1") && lines[1].contains("planned 2"),
            "{table}"
        );
        assert!(
            lines[2].contains("95.0 / 93.0") && lines[2].contains("89.0 / 87.0"),
            "{table}"
        );
        // One refused plan: no planned score.
        p.default_pct[1].1 = None;
        assert_eq!(p.scores(Training::Planned), None);
    }

    #[test]
    fn the_summary_shows_every_plant_its_misses_and_the_count() {
        let training = [
            (Training::Planned, "planned plan.csv"),
            (Training::Cycle, "cycle −40…60 °C, 1 °C/min, 2-h holds"),
            (Training::Designed, "designed 10.9 h, 5 °C/min"),
        ];
        let plants = [
            PlantSummary {
                name: "documented gyro".into(),
                ..plant(Some((95.0, 93.0)), Some((94.0, 92.0)), [Some(1.1), Some(1.3)])
            },
            plant(Some((90.0, 80.0)), Some((94.0, 92.0)), [Some(1.1), Some(1.3)]),
        ];
        let table = summary_table(&plants, &training);
        let lines: Vec<&str> = table.lines().filter(|l| !l.is_empty()).collect();
        assert!(lines[1].starts_with("plant") && lines[1].contains("planned") && lines[1].contains("designed"));
        assert!(
            lines[2].starts_with("documented gyro") && lines[2].ends_with("met"),
            "{table}"
        );
        assert!(
            lines[2].contains("95.0 / 93.0") && lines[2].contains("×1.30"),
            "{table}"
        );
        assert!(
            lines[3].ends_with("planned mean 90.0 < 93; planned worst 80.0 < 91"),
            "{table}"
        );
        assert!(lines[3].contains("-40.0 … 55.0"), "{table}");
        // Over all plants: the mean of the means, the worst of the worsts.
        assert!(lines[4].starts_with("all plants"), "{table}");
        assert!(
            lines[4].contains("92.5 / 80.0") && lines[4].contains("97.0 / 95.0"),
            "{table}"
        );
        assert!(lines[4].ends_with("1 of 2 plants miss a target"), "{table}");
    }
}
