//! What a plan does at the ends of the range ([`Ends`]): the default soaks
//! both ends of a run of [`SHORT_RUN_S`] or more as long as leaves
//! [`DYNAMICS_S`] for the rest, within [`SHORT_END_SOAK_S`] …
//! [`MAX_END_SOAK_S`] ([`default_end_soak_s`]), a shorter run not at all;
//! `--plain` never; `--soak-ends` as long as a loop
//! [`SLOW_PLANT_FACTOR`] times slower than nominal needs to settle there.
//! Where the run has time for them besides (22.5 h over −40 … 60 °C), the
//! default soaks each interior band of the range too ([`shared_band_soak_s`]);
//! `--band-soaks` asks for them (refused without the time), `--no-band-soaks`
//! keeps the end soaks alone.
//!
//! Why (docs/decisions.md, "End soaks in the default plan"): a fit
//! identifies the settled bias at the ends from holds there, and a plan
//! that turns back before the loop gets there leaves the soak test's
//! extreme levels to the static curve's extrapolation. Measured over plan
//! draws on the simulator's gyros, 1.5-h soaks lowered the soak test's
//! settled spread after 12 h, 2-h soaks after 24 h and 3-h soaks lower still,
//! at about the same in-use accuracy; the slow plant's soaks of 4.5 h cost
//! accuracy in use.

use super::candidates::interior_bands;
use super::criterion::end_soak_s;
use super::limits::{PlanLimits, SLOW_PLANT_FACTOR};
use crate::describe::summary::sig;
use crate::fit::coverage::BAND_C;

/// Each end's longest soak in the default plan, s (3 h: longer soaks, as the
/// slow plant's, take more hours from the dynamics than the soak test gains).
pub const MAX_END_SOAK_S: f64 = 10_800.0;

/// Each end's shortest soak in the default plan, s (1.5 h: measured at 12 h).
pub const SHORT_END_SOAK_S: f64 = 5400.0;

/// The shortest run the default soaks the ends of, s (12 h: the length the
/// 1.5-h soaks were measured at; shorter runs keep their hours for the
/// dynamics).
pub const SHORT_RUN_S: f64 = 12.0 * 3600.0;

/// What the default keeps for the rest of the run besides its two end
/// soaks where the run is long enough, s: the 12 h the plain plan's dynamics
/// were validated on.
pub const DYNAMICS_S: f64 = 12.0 * 3600.0;

/// The shortest run whose default soaks each end [`MAX_END_SOAK_S`] besides
/// [`DYNAMICS_S`], s (18 h): shorter ones pool their end soaks
/// ([`Ends::pools_ends`]) and keep the candidate of the best D-criterion.
pub const FULL_END_SOAKS_RUN_S: f64 = DYNAMICS_S + 2.0 * MAX_END_SOAK_S;

/// The end-soak family of a plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ends {
    /// `trainer plan`'s default ([`default_end_soak_s`]): from
    /// [`SHORT_RUN_S`] on, soaks that leave [`DYNAMICS_S`] for the rest,
    /// within [`SHORT_END_SOAK_S`] … [`MAX_END_SOAK_S`]; else none. Where
    /// the run has time for them besides, a soak in each interior band
    /// ([`shared_band_soak_s`]).
    Default,
    /// `--no-band-soaks`: the default's end soaks, never band soaks (the
    /// default of before band soaks were, kept to compare with).
    EndsOnly,
    /// No end soaks (`--plain`): the draws as before end soaks existed.
    Plain,
    /// `--soak-ends`: soaks a loop [`SLOW_PLANT_FACTOR`] times slower than
    /// nominal settles in ([`end_soak_s`]).
    SlowPlant,
    /// `--band-soaks`: the default's end soaks and a soak in each interior
    /// band ([`shared_band_soak_s`]); refused where the run has no time for them.
    Bands,
}

impl Ends {
    /// Each end's soak under `limits`, s, `None` for none, once the limits
    /// are checked for this family (the slow plant's soaks need hours).
    pub fn end_soak_s(self, limits: &PlanLimits) -> Result<Option<f64>, String> {
        match self {
            Ends::Plain => limits.check().map(|()| None),
            Ends::Default | Ends::EndsOnly => limits.check().map(|()| default_end_soak_s(limits)),
            Ends::Bands => {
                let end_soak_s = Ends::Default.end_soak_s(limits)?;
                match end_soak_s.and_then(|s| shared_band_soak_s(limits, s)) {
                    Some(_) => Ok(end_soak_s),
                    None => Err(band_soaks_refusal(limits)),
                }
            }
            Ends::SlowPlant => limits.check_soaking_ends().map(|()| Some(end_soak_s(limits))),
        }
    }

    /// Whether this family, its end soaks resolved to `end_soak_s`, pools
    /// them at the hot end: the run starts at the cold end, where the unit
    /// sits settled after its unpowered pre-soak and its power-on soak holds
    /// that end, and the hot end soaks both ends' share
    /// ([`Ends::pooled_hot_end_soak_s`]). The default's (`--no-band-soaks`' and
    /// `--band-soaks`' too, not `--soak-ends`') where each end's soak is
    /// shorter than [`MAX_END_SOAK_S`]: runs under 18 h.
    ///
    /// Why (docs/decisions.md, "End soaks in the default plan"): a 1.5-h
    /// soak at the end of a ramp across the range leaves the loop short of
    /// both ends, and self-heating lifts the soak test's hot levels above
    /// the air. Over sixteen 12-h draws on the bench's plants, pooled soaks
    /// put more trainings within both targets (soak spread and in use).
    pub fn pools_ends(self, end_soak_s: Option<f64>) -> bool {
        matches!(self, Ends::Default | Ends::EndsOnly | Ends::Bands) && end_soak_s.is_some_and(|s| s < MAX_END_SOAK_S)
    }

    /// The hot end's soak, s, where this family pools end soaks of
    /// `end_soak_s` ([`Ends::pools_ends`]): both ends' share, at most
    /// [`MAX_END_SOAK_S`]; `None` where it does not pool them.
    pub fn pooled_hot_end_soak_s(self, end_soak_s: Option<f64>) -> Option<f64> {
        end_soak_s
            .filter(|_| self.pools_ends(end_soak_s))
            .map(|s| (2.0 * s).min(MAX_END_SOAK_S))
    }

    /// Each interior band's soak under `limits` once the end soak is
    /// `end_soak_s`, s, `None` for none: the default's and `--band-soaks`'
    /// ([`shared_band_soak_s`]); the other families hold none.
    pub fn band_soak_s(self, limits: &PlanLimits, end_soak_s: Option<f64>) -> Option<f64> {
        match (self, end_soak_s) {
            (Ends::Default | Ends::Bands, Some(end_soak_s)) => shared_band_soak_s(limits, end_soak_s),
            _ => None,
        }
    }

    /// The family as `trainer plan` names it, given the soaks it resolved to.
    pub fn name(self, end_soak_s: Option<f64>, band_soak_s: Option<f64>) -> String {
        let bands = band_soak_s.map_or(String::new(), |s| format!(", {}-h band soaks", hours(s)));
        match (self, end_soak_s, self.pooled_hot_end_soak_s(end_soak_s)) {
            (_, None, _) => "plain".to_owned(),
            (Ends::SlowPlant, Some(_), _) => "--soak-ends".to_owned(),
            (_, _, Some(hot_s)) => format!("{}-h hot-end soak, cold start at the cold end{bands}", hours(hot_s)),
            (_, Some(s), None) => format!("{}-h end soaks{bands}", hours(s)),
        }
    }

    /// Why each end holds as long as it does, for the plan's metadata.
    pub fn reason(self, limits: &PlanLimits) -> String {
        match self {
            Ends::SlowPlant => format!(
                "a loop {SLOW_PLANT_FACTOR}× slower than nominal comes within {:.1} °C of where it settles",
                limits.reach_c()
            ),
            _ => format!(
                "the default of a run of {:.0} h or more: as long as leaves {:.0} h for the rest, {} … {} h",
                SHORT_RUN_S / 3600.0,
                DYNAMICS_S / 3600.0,
                SHORT_END_SOAK_S / 3600.0,
                MAX_END_SOAK_S / 3600.0
            ),
        }
    }
}

/// The default's soak at each end under `limits`, s, in whole minutes: in a
/// run of [`SHORT_RUN_S`] or more, as long as leaves [`DYNAMICS_S`] for the
/// rest of the run, at least [`SHORT_END_SOAK_S`] and at most
/// [`MAX_END_SOAK_S`] (1.5 h up to 15 h, 2 h at 16 h, 3 h from 18 h);
/// `None` in a shorter run.
pub fn default_end_soak_s(limits: &PlanLimits) -> Option<f64> {
    let run_s = limits.hours * 3600.0;
    (run_s >= SHORT_RUN_S).then(|| {
        let leaving_dynamics_s = ((run_s - DYNAMICS_S) / 2.0 / 60.0).floor() * 60.0;
        leaving_dynamics_s.clamp(SHORT_END_SOAK_S, MAX_END_SOAK_S)
    })
}

/// `s` seconds in hours for a name, to three significant digits (100 min
/// is "1.67", 90 min "1.5", 3 h "3").
fn hours(s: f64) -> String {
    sig(s / 3600.0, 3)
}

/// The default's (and `--band-soaks`') soak in each interior band of the
/// range ([`interior_bands`]) once each end soaks `end_soak_s`, s, in whole
/// minutes: what the run holds beyond [`DYNAMICS_S`] and its end soaks,
/// shared among the bands, at most [`MAX_END_SOAK_S`]; `None` when that
/// is shorter than [`SHORT_END_SOAK_S`] or the range has no interior band
/// (2 h each at 24 h over −40 … 60 °C, from 27 h on 3 h).
///
/// Why by default where they fit (docs/decisions.md, "Band soaks"): the
/// soak test reads the settled bias across the range. Over twelve 24-h plan
/// draws they lowered the soak spread of gyros that settle within a 3-h
/// hold, as the handed-out designs do, at better in-use accuracy; on the
/// simulator's slower designs they were neutral on the mean, some gaining
/// and some (near the 0.01-°/h aim) losing.
pub fn shared_band_soak_s(limits: &PlanLimits, end_soak_s: f64) -> Option<f64> {
    let bands = interior_bands(limits);
    let spare_s = limits.hours * 3600.0 - DYNAMICS_S - 2.0 * end_soak_s;
    if bands == 0 || spare_s <= 0.0 {
        return None;
    }
    let each_s = (spare_s / bands as f64 / 60.0).floor() * 60.0;
    (each_s >= SHORT_END_SOAK_S).then_some(each_s.min(MAX_END_SOAK_S))
}

/// Why `--band-soaks` is refused under `limits`: the run is too short.
fn band_soaks_refusal(limits: &PlanLimits) -> String {
    let bands = interior_bands(limits);
    if bands == 0 {
        return format!(
            "--band-soaks: the range {} … {} °C has no {BAND_C:.0}-°C band between the two at its ends to soak",
            limits.min_c, limits.max_c
        );
    }
    let needs_h = (DYNAMICS_S + 2.0 * MAX_END_SOAK_S + bands as f64 * SHORT_END_SOAK_S) / 3600.0;
    format!(
        "--band-soaks: a {} h run has no time for them: {:.0} h of dynamics besides the end soaks and {} h in each \
         of the range's {bands} interior {BAND_C:.0}-°C bands: the run needs --hours {needs_h} or more",
        limits.hours,
        DYNAMICS_S / 3600.0,
        SHORT_END_SOAK_S / 3600.0
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::plan::limits::TEST_LIMITS as LIMITS;

    #[test]
    fn the_default_soaks_the_ends_of_a_twelve_hour_run_and_longer_where_twelve_hours_remain_besides() {
        let at = |hours: f64| Ends::Default.end_soak_s(&PlanLimits { hours, ..LIMITS });
        assert_eq!(at(11.9), Ok(None));
        assert_eq!(at(12.0), Ok(Some(SHORT_END_SOAK_S)));
        assert_eq!(at(15.0), Ok(Some(SHORT_END_SOAK_S)));
        // Between, what leaves 12 h, in whole minutes.
        assert_eq!(at(16.0), Ok(Some(7200.0)));
        assert_eq!(at(17.01), Ok(Some(150.0 * 60.0)));
        assert_eq!(at(18.0), Ok(Some(MAX_END_SOAK_S)));
        assert_eq!(at(24.0), Ok(Some(MAX_END_SOAK_S)));
        assert_eq!(Ends::Plain.end_soak_s(&PlanLimits { hours: 24.0, ..LIMITS }), Ok(None));
        // The slow plant's soak is longer than the default's on these limits.
        let slow = Ends::SlowPlant.end_soak_s(&LIMITS).unwrap().unwrap();
        assert!(slow > MAX_END_SOAK_S, "{slow}");
        // Limits no plan meets are refused by every family.
        let bad = PlanLimits { hours: 1.0, ..LIMITS };
        for ends in [Ends::Default, Ends::EndsOnly, Ends::Plain, Ends::SlowPlant] {
            assert!(ends.end_soak_s(&bad).is_err(), "{ends:?}");
        }
    }

    #[test]
    fn families_are_named_by_what_they_resolved_to() {
        assert_eq!(Ends::Default.name(None, None), "plain");
        assert_eq!(Ends::Default.name(Some(MAX_END_SOAK_S), None), "3-h end soaks");
        // Under 3 h each, pooled at the hot end, at most 3 h there.
        assert_eq!(
            Ends::Default.name(Some(SHORT_END_SOAK_S), None),
            "3-h hot-end soak, cold start at the cold end"
        );
        assert_eq!(
            Ends::EndsOnly.name(Some(9000.0), None),
            "3-h hot-end soak, cold start at the cold end"
        );
        assert_eq!(
            Ends::Default.name(Some(MAX_END_SOAK_S), Some(7200.0)),
            "3-h end soaks, 2-h band soaks"
        );
        assert_eq!(Ends::SlowPlant.name(Some(16_000.0), None), "--soak-ends");
        // Hours of a third or two thirds read to two decimals, not to f64's last digit.
        assert_eq!(
            Ends::Default.name(Some(MAX_END_SOAK_S), Some(6000.0)),
            "3-h end soaks, 1.67-h band soaks"
        );
    }

    #[test]
    fn end_soaks_shorter_than_three_hours_are_pooled_at_the_hot_end_except_for_the_slow_plant() {
        for ends in [Ends::Default, Ends::EndsOnly, Ends::Bands] {
            assert!(ends.pools_ends(Some(SHORT_END_SOAK_S)), "{ends:?}");
            assert!(ends.pools_ends(Some(MAX_END_SOAK_S - 60.0)), "{ends:?}");
            assert!(!ends.pools_ends(Some(MAX_END_SOAK_S)), "{ends:?}");
            assert!(!ends.pools_ends(None), "{ends:?}");
        }
        // --soak-ends asks each end held until the slow plant settles there.
        assert!(!Ends::SlowPlant.pools_ends(Some(SHORT_END_SOAK_S)));
        assert!(!Ends::Plain.pools_ends(Some(SHORT_END_SOAK_S)));
        // The hot end soaks both shares, at most 3 h; unpooled, none is pooled there.
        let bits = |s: Option<f64>| s.map(f64::to_bits);
        assert_eq!(
            bits(Ends::Default.pooled_hot_end_soak_s(Some(SHORT_END_SOAK_S))),
            bits(Some(2.0 * SHORT_END_SOAK_S))
        );
        assert_eq!(
            bits(Ends::Default.pooled_hot_end_soak_s(Some(7200.0))),
            bits(Some(MAX_END_SOAK_S))
        );
        assert_eq!(Ends::SlowPlant.pooled_hot_end_soak_s(Some(7200.0)), None);
        assert_eq!(Ends::Default.pooled_hot_end_soak_s(Some(MAX_END_SOAK_S)), None);
        assert_eq!(Ends::Default.pooled_hot_end_soak_s(None), None);
    }

    #[test]
    fn band_soaks_share_what_the_run_keeps_beyond_twelve_hours_of_dynamics_and_its_end_soaks() {
        let at = |hours: f64| {
            let limits = PlanLimits { hours, ..LIMITS };
            let ends = Ends::Default.end_soak_s(&limits).unwrap();
            Ends::Bands.band_soak_s(&limits, ends)
        };
        // −40 … 60 °C: three interior bands (−20 … 0, 0 … 20, 20 … 40 °C).
        assert_eq!(at(12.0), None);
        assert_eq!(at(22.4), None, "less than 1.5 h a band");
        assert_eq!(at(22.5), Some(SHORT_END_SOAK_S));
        assert_eq!(at(24.0), Some(7200.0));
        assert_eq!(at(36.0), Some(MAX_END_SOAK_S));
        // A range of two bands has no interior one.
        let narrow = PlanLimits {
            min_c: 0.0,
            max_c: 40.0,
            hours: 36.0,
            ..LIMITS
        };
        assert_eq!(Ends::Bands.band_soak_s(&narrow, Some(MAX_END_SOAK_S)), None);
        // The default holds them where they fit, --no-band-soaks never, and
        // --band-soaks refuses a run without time for them.
        let day = PlanLimits { hours: 24.0, ..LIMITS };
        assert_eq!(Ends::Default.band_soak_s(&day, Some(MAX_END_SOAK_S)), Some(7200.0));
        assert_eq!(Ends::EndsOnly.band_soak_s(&day, Some(MAX_END_SOAK_S)), None);
        assert_eq!(Ends::EndsOnly.end_soak_s(&day), Ends::Default.end_soak_s(&day));
        assert_eq!(
            Ends::Default.band_soak_s(&PlanLimits { hours: 22.0, ..LIMITS }, Some(MAX_END_SOAK_S)),
            None
        );
        let refusal = Ends::Bands
            .end_soak_s(&PlanLimits { hours: 22.0, ..LIMITS })
            .unwrap_err();
        assert!(refusal.contains("needs --hours 22.5 or more"), "{refusal}");
        assert!(
            Ends::Bands
                .end_soak_s(&narrow)
                .unwrap_err()
                .contains("no 20-°C band between")
        );
        assert_eq!(
            Ends::Bands.end_soak_s(&PlanLimits { hours: 24.0, ..LIMITS }),
            Ok(Some(MAX_END_SOAK_S))
        );
        let long = PlanLimits { hours: 36.0, ..LIMITS };
        assert_eq!(Ends::SlowPlant.band_soak_s(&long, Some(MAX_END_SOAK_S)), None);
        assert_eq!(Ends::Plain.band_soak_s(&long, None), None);
    }
}
