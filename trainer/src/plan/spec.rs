//! `trainer plan --settled-spread-dph X`: the shortest run predicted to meet
//! a settled-spread spec on both plants ([`predict`](super::predict)).
//!
//! The lengths tried are whole hours from the shortest the limits allow up to
//! `--hours` (and `--hours` itself when it is not whole). At each length the
//! plain plan, from 12 h the default's end soaks (and band soaks where they
//! fit, [`Ends::Default`]) and,
//! where the length holds them, the `--soak-ends` plan are designed and
//! predicted; the length's pick is the family that meets the spec (the better
//! in use when both do), else the one of lower settled spread. The lengths
//! are scanned from the shortest up and the first that meets the spec is the
//! answer: the predicted spread does not fall monotonically with the hours
//! (docs/plan.md, "What each extra hour buys": a longer plain plan may turn
//! back from an end sooner), so a bisection could skip the shortest length
//! that meets it. The price: a spec that cannot be met is known only after
//! every length up to `--hours`.

use super::ends::{Ends, default_end_soak_s};
use super::limits::PlanLimits;
use super::predict::{Prediction, TestBench, predict};
use super::{Plan, design};
use crate::fit::Progress;

/// One length's plan, as the search chose its family, and its prediction.
#[derive(Clone, Debug)]
pub struct Tried {
    /// The plan (its `ends` and `end_soak_s` say the family).
    pub plan: Plan,
    /// Its figures on both plants.
    pub prediction: Prediction,
}

impl Tried {
    /// The family, as the output names it.
    pub fn family(&self) -> String {
        self.plan.ends.name(self.plan.end_soak_s, self.plan.band_soak_s)
    }
}

/// What the search found.
#[derive(Clone, Debug)]
pub struct SpecOutcome {
    /// The settled spread asked for on both plants, °/h.
    pub target_dph: f64,
    /// The shortest length that meets it, `None` when none within `--hours` does.
    pub met: Option<Tried>,
    /// Without `met`: the length of lowest predicted settled spread tried.
    pub best: Tried,
    /// Every length tried, shortest first: (hours, family, worse settled spread °/h).
    pub tried: Vec<(f64, String, Option<f64>)>,
}

impl SpecOutcome {
    /// The plan to write: the one that meets the spec.
    pub fn plan(&self) -> Option<&Tried> {
        self.met.as_ref()
    }

    /// The line saying what the search did.
    pub fn summary(&self) -> String {
        let tried: Vec<String> = self
            .tried
            .iter()
            .map(|(h, family, s)| format!("{h} h {family} {}", s.map_or("none".to_owned(), |s| format!("{s:.4}"))))
            .collect();
        let tried = tried.join(", ");
        match &self.met {
            Some(t) => format!(
                "--settled-spread-dph {}: met on both plants by the {} h {} plan (predicted {:.4} °/h at worst), the shortest found (tried, worse plant's spread in °/h: {tried})",
                self.target_dph,
                t.plan.limits.hours,
                t.family(),
                t.prediction.worse_settled_spread_dph().unwrap_or(f64::NAN)
            ),
            None => format!(
                "--settled-spread-dph {}: no plan within --hours {} is predicted to meet it on both plants; the best tried, the {} h {} plan, gives {} °/h on the nominal plant and {} °/h on the slow plant ({:.1} / {:.1} % in use) (tried, worse plant's spread in °/h: {tried}); where the unit is soaked anyway, fit its soak test beside the planned run (docs/workflow.md, \"The soak test\")",
                self.target_dph,
                self.tried.last().map_or(0.0, |t| t.0),
                self.best.plan.limits.hours,
                self.best.family(),
                spread(self.best.prediction.nominal.settled_spread_dph),
                spread(self.best.prediction.slow.settled_spread_dph),
                self.best.prediction.nominal.in_use_std100_gain_pct,
                self.best.prediction.slow.in_use_std100_gain_pct,
            ),
        }
    }
}

/// A spread as printed.
fn spread(s: Option<f64>) -> String {
    s.map_or("none".to_owned(), |s| format!("{s:.4}"))
}

/// The lengths the search may try within `limits`, h: whole hours from the
/// shortest the limits allow up to `limits.hours`, and `limits.hours`
/// itself when it is not whole.
pub fn lengths_h(limits: &PlanLimits) -> Vec<f64> {
    let shortest = limits.shortest_hours().ceil().max(1.0);
    let mut out: Vec<f64> = (shortest as u32..=limits.hours.floor() as u32).map(f64::from).collect();
    if out.last().is_none_or(|&h| h < limits.hours) {
        out.push(limits.hours);
    }
    out
}

/// Designs and predicts the plans of one length, every family the length
/// allows, and keeps the one the spec prefers.
fn try_length(
    limits: &PlanLimits,
    hours: f64,
    seed: u64,
    candidates: usize,
    target_dph: f64,
    benches: &[TestBench; 2],
    progress: &Progress,
) -> anyhow::Result<Tried> {
    let at = PlanLimits { hours, ..*limits };
    let mut families = vec![Ends::Plain];
    if default_end_soak_s(&at).is_some() {
        families.push(Ends::Default);
    }
    if at.check_soaking_ends().is_ok() {
        families.push(Ends::SlowPlant);
    }
    let mut tried = Vec::new();
    for ends in families {
        let mut plan = design(&at, seed, candidates, ends).map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
        let prediction = predict(&plan, benches, progress)?;
        plan.prediction = Some(prediction);
        tried.push(Tried { plan, prediction });
    }
    let key = |t: &Tried| {
        let meets = t.prediction.meets(target_dph);
        let spread = t.prediction.worse_settled_spread_dph().unwrap_or(f64::INFINITY);
        // Meeting first; then, among those that meet, better in use; else lower spread.
        (
            meets,
            if meets {
                t.prediction.worse_in_use_std100_gain_pct()
            } else {
                -spread
            },
        )
    };
    tried
        .into_iter()
        .max_by(|a, b| {
            let (ka, kb) = (key(a), key(b));
            ka.0.cmp(&kb.0).then(ka.1.total_cmp(&kb.1))
        })
        .ok_or_else(|| anyhow::anyhow!("no plan family at {hours} h"))
}

/// The shortest plan within `limits` (lengths by [`lengths_h`]) predicted to
/// give a settled spread of at most `target_dph` on both plants, found by
/// the scan the module describes. `progress` counts one step per plan and
/// plant predicted.
pub fn design_for_settled_spread(
    limits: &PlanLimits,
    seed: u64,
    candidates: usize,
    target_dph: f64,
    benches: &[TestBench; 2],
    progress: &Progress,
) -> anyhow::Result<SpecOutcome> {
    anyhow::ensure!(
        target_dph.is_finite() && target_dph > 0.0,
        "--settled-spread-dph {target_dph}: must be a positive number of °/h"
    );
    limits.check().map_err(|e| anyhow::anyhow!("cannot plan: {e}"))?;
    let lengths = lengths_h(limits);
    // Up to three families and two plants a length.
    progress.start("plan for the spec", 6 * lengths.len() as u64);
    let mut tried: Vec<(usize, Tried)> = Vec::new();
    let mut met = None;
    for (i, &hours) in lengths.iter().enumerate() {
        let t = try_length(limits, hours, seed, candidates, target_dph, benches, progress)?;
        let meets = t.prediction.meets(target_dph);
        tried.push((i, t));
        if meets {
            met = Some(i);
            break;
        }
    }
    progress.finish();
    tried.sort_by_key(|t| t.0);
    let summary = tried
        .iter()
        .map(|(_, t)| (t.plan.limits.hours, t.family(), t.prediction.worse_settled_spread_dph()))
        .collect();
    let met = met.and_then(|i| tried.iter().find(|t| t.0 == i).map(|t| t.1.clone()));
    let best = tried
        .iter()
        .map(|t| &t.1)
        .min_by(|a, b| {
            let s = |t: &Tried| t.prediction.worse_settled_spread_dph().unwrap_or(f64::INFINITY);
            s(a).total_cmp(&s(b))
        })
        .cloned()
        .ok_or_else(|| anyhow::anyhow!("no length tried"))?;
    Ok(SpecOutcome {
        target_dph,
        met,
        best,
        tried: summary,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_run_in_whole_hours_from_the_shortest_allowed_to_the_budget() {
        let limits = PlanLimits {
            min_c: -40.0,
            max_c: 60.0,
            max_rate_c_per_min: 5.0,
            hours: 12.5,
        };
        let l = lengths_h(&limits);
        assert_eq!(l.first().copied(), Some(limits.shortest_hours().ceil()));
        assert_eq!(l.last().copied(), Some(12.5));
        assert!(l.windows(2).all(|w| w[1] > w[0]));
        let whole = PlanLimits { hours: 12.0, ..limits };
        assert_eq!(lengths_h(&whole).last().copied(), Some(12.0));
        assert!(lengths_h(&whole).iter().all(|h| h.fract() == 0.0));
    }
}
