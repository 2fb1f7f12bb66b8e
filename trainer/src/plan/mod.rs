//! `trainer plan`: designing the chamber run the default model learns from.
//!
//! A plan is a sequence of [`Segment`]s (ramp to a target at a rate, hold)
//! after a power-on soak at its first temperature. Candidates are drawn from
//! a family that contains what the lag bank needs to see (a cold start whose
//! self-heating transient is recorded, levels across the range, full-rate
//! steps, bursts of swings, slow ramps, holds as long as the slowest coil
//! mode), and the one kept on a nominal plant is the best by the D-criterion
//! of the lag-bank regression ([`d_criterion`]), or from 18 h on by the sum
//! of its ranks by that and by how tightly the response bank's regression
//! pins the static curve a soak test reads ([`chosen`],
//! [`static_curve_variance`]). By default a run of 12 h
//! or more soaks each end of the range as long as leaves 12 h for the rest,
//! 1.5 … 3 h ([`ends`], [`candidate_soaking`]), and where the run has the
//! time besides (22.5 h over −40 … 60 °C) each interior 20-°C band of the
//! range once (`--no-band-soaks` keeps the end soaks alone); on request (`trainer plan
//! --soak-ends`) every candidate soaks there long enough for a loop
//! [`SLOW_PLANT_FACTOR`] times slower than nominal to settle ([`end_soak_s`]),
//! so the run reaches the asked range at the loop on plants other than the
//! nominal one, at the cost of dynamic excitation; `--plain` never soaks
//! the ends. Every way the plan predicts the loop range on both plants.
//! docs/plan.md argues the choice. Deterministic for a given seed.
//!
//! One module a job, each importing only those below it: [`limits`] (the
//! limits, segments and time arithmetic), [`candidates`], [`criterion`] (the
//! plan on the plant), [`ends`] (the end-soak family), this module ([`Plan`],
//! [`design`]) and [`plot`].

use std::fmt::Write as _;

use rand::SeedableRng;
use rand_pcg::Pcg64;

use crate::fit::coverage::BAND_C;
use crate::simulate::SimParams;

pub mod candidates;
pub mod criterion;
pub mod ends;
pub mod limits;
pub mod plot;
pub mod predict;
pub mod prediction;
pub mod spec;

use self::{candidates::*, criterion::*, ends::Ends, limits::*};

/// A designed profile: the segments, the score of the criterion and what it was chosen among.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The limits it meets.
    pub limits: PlanLimits,
    /// The first segment is the power-on soak (no ramp).
    pub segments: Vec<Segment>,
    /// D-criterion of the plan ([`d_criterion`]).
    pub criterion: f64,
    /// Median criterion of the candidates.
    pub median_criterion: f64,
    /// How loosely the plan pins the response bank's static curve
    /// ([`static_curve_variance`]; `None` where the bank could not be built).
    pub static_curve_variance: Option<f64>,
    /// Whether the D-criterion alone chose it (`--plain`, or a run under
    /// 18 h: [`design`]), not with the static-curve variance ([`chosen`]).
    pub chosen_by_d_alone: bool,
    /// Candidates drawn.
    pub candidates: usize,
    /// Seed of the draw.
    pub seed: u64,
    /// Lowest and highest loop temperature the nominal plant reads under the plan, °C.
    pub loop_range_c: (f64, f64),
    /// The same on a plant [`SLOW_PLANT_FACTOR`] times slower than nominal, °C.
    pub slow_loop_range_c: (f64, f64),
    /// Loop temperatures of the settled plateaus (the soak rule,
    /// [`crate::dataset::plateaus`]) the nominal plant reads under the plan, °C.
    pub settled_c: Vec<f64>,
    /// The same on the slow plant, °C.
    pub slow_settled_c: Vec<f64>,
    /// The end-soak family asked for.
    pub ends: Ends,
    /// Each end soak lasts at least this, s ([`Ends::end_soak_s`]); `None`
    /// without end soaks (the plan as before the end soaks).
    pub end_soak_s: Option<f64>,
    /// Each interior band's soak, s ([`Ends::band_soak_s`]); `None` without.
    pub band_soak_s: Option<f64>,
    /// The figures predicted after the default fit on the plan's run;
    /// `None` until predicted.
    pub prediction: Option<prediction::Prediction>,
}

impl Plan {
    /// Set points (time s, temperature °C), time from 0 strictly increasing.
    pub fn knots(&self) -> Vec<(f64, f64)> {
        knots(&self.segments)
    }

    /// How long the gyro must soak unpowered at the first set point before
    /// power-on, s ([`pre_soak_s`] on the documented gyro's plant).
    pub fn pre_soak_s(&self) -> f64 {
        pre_soak_s(&SimParams::default().plant, self.segments[0].target_c)
    }

    /// The hot end's soak where the end soaks are pooled there, the
    /// power-on soak holding the cold end, s ([`Ends::pooled_hot_end_soak_s`]);
    /// `None` where they are not.
    pub fn pooled_hot_end_soak_s(&self) -> Option<f64> {
        self.ends.pooled_hot_end_soak_s(self.end_soak_s)
    }

    /// The hot end's soak, s: the pooled one, else each end's; `None` without end soaks.
    pub fn hot_end_soak_s(&self) -> Option<f64> {
        self.pooled_hot_end_soak_s().or(self.end_soak_s)
    }

    /// Length of the run, s.
    pub fn duration_s(&self) -> f64 {
        self.knots().last().map_or(0.0, |k| k.0)
    }

    /// How the plan was chosen among its candidates, in words.
    pub fn choice(&self) -> String {
        if self.chosen_by_d_alone {
            format!("best of {} candidates by the D-criterion", self.candidates)
        } else {
            format!(
                "chosen of {} candidates by the sum of its ranks by the D-criterion and by the static-curve variance",
                self.candidates
            )
        }
    }

    /// The `#` metadata lines every output format starts with.
    fn metadata(&self) -> String {
        let l = &self.limits;
        let mut s = String::new();
        let _ = writeln!(s, "# source: trainer plan (D-optimal chamber profile, docs/plan.md)");
        let _ = writeln!(s, "# min_c: {}", l.min_c);
        let _ = writeln!(s, "# max_c: {}", l.max_c);
        let _ = writeln!(s, "# max_rate_c_per_min: {}", l.max_rate_c_per_min);
        let _ = writeln!(s, "# hours: {}", l.hours);
        let _ = writeln!(s, "# seed: {}", self.seed);
        let _ = writeln!(
            s,
            "# criterion: D-optimal, (1/p)·ln det of the information matrix per 100-s mean of the lag-bank regression (p = {CRITERION_PARAMS}: a cubic in T; ΔT at τ {} s, each times 1, T, T²) on the nominal plant (trainer simulate's documented gyro)",
            CRITERION_TAUS_S.map(|t| format!("{t:.0}")).join("/")
        );
        let _ = writeln!(
            s,
            "# criterion_value: {:.4} ({}; median {:.4})",
            self.criterion,
            self.choice(),
            self.median_criterion
        );
        if let Some(v) = self.static_curve_variance {
            let _ = writeln!(
                s,
                "# static_curve_variance: {v:.4e} (the response bank's static curve at {STATIC_CURVE_LEVELS} levels over the limits, posterior variance about its mean per unit block-noise variance; lower pins a soak test's settled bias better)"
            );
        }
        let first = self.segments[0];
        let _ = writeln!(
            s,
            "# pre_soak: before 0 s, the gyro unpowered at {} °C for at least {:.0} min (the nominal plant's every node within {PRE_SOAK_WITHIN_C} °C of the air after {ROOM_C} °C)",
            first.target_c,
            self.pre_soak_s() / 60.0
        );
        let _ = writeln!(
            s,
            "# power_on: at 0 s, soaked at {} °C; held {:.0} min (cold start: the self-heating transient)",
            first.target_c,
            first.hold_s / 60.0
        );
        let _ = writeln!(s, "# duration_h: {:.3}", self.duration_s() / 3600.0);
        if let Some(end_soak_s) = self.end_soak_s {
            let each = if self.pooled_hot_end_soak_s().is_some() {
                "each end's share, both pooled at the hot end below"
            } else {
                "at each end of the range"
            };
            let _ = writeln!(
                s,
                "# end_soak_min: {:.1} ({each}: {})",
                end_soak_s / 60.0,
                self.ends.reason(&self.limits)
            );
            if let Some(hot_s) = self.pooled_hot_end_soak_s() {
                let _ = writeln!(
                    s,
                    "# hot_end_soak_min: {:.1} (both ends' share pooled at the hot end, the cold end held by the power-on soak at {} °C: the default of a run under {:.0} h)",
                    hot_s / 60.0,
                    self.limits.min_c,
                    ends::FULL_END_SOAKS_RUN_S / 3600.0
                );
            }
        }
        if let Some(band_soak_s) = self.band_soak_s {
            let _ = writeln!(
                s,
                "# band_soak_min: {:.1} (once in each interior {BAND_C:.0}-°C band of the range: what the run holds beyond {:.0} h and its end soaks, shared, {} … {} h)",
                band_soak_s / 60.0,
                ends::DYNAMICS_S / 3600.0,
                ends::SHORT_END_SOAK_S / 3600.0,
                ends::MAX_END_SOAK_S / 3600.0
            );
        }
        let levels = |l: &[f64]| l.iter().map(|t| format!("{t:.1}")).collect::<Vec<_>>().join(",");
        let _ = writeln!(
            s,
            "# predicted_settled_c: {} (nominal plant; soak rule of trainer eval)",
            levels(&self.settled_c)
        );
        let _ = writeln!(
            s,
            "# predicted_loop_c: {:.1},{:.1} (nominal plant; {:.1},{:.1} with every time constant {SLOW_PLANT_FACTOR}× nominal)",
            self.loop_range_c.0, self.loop_range_c.1, self.slow_loop_range_c.0, self.slow_loop_range_c.1
        );
        if let Some(prediction) = &self.prediction {
            s.push_str(&prediction.metadata());
        }
        s
    }

    /// Whether a loop of this range reaches both ends of the asked range
    /// (within [`PlanLimits::reach_c`]).
    pub fn reaches(&self, loop_range_c: (f64, f64)) -> bool {
        let reach_c = self.limits.reach_c();
        loop_range_c.0 <= self.limits.min_c + reach_c && loop_range_c.1 >= self.limits.max_c - reach_c
    }

    /// What the plan predicts at the loop, in a line or more: the range on
    /// the nominal plant and on the slow one, and a warning for each that
    /// stays short of an end of the asked range by more than
    /// [`PlanLimits::reach_c`], saying by how much and what closes the gap.
    pub fn loop_range_lines(&self) -> Vec<String> {
        let (min_c, max_c) = (self.limits.min_c, self.limits.max_c);
        let (lo, hi) = self.loop_range_c;
        let (slo, shi) = self.slow_loop_range_c;
        let soaks = match (self.end_soak_s, self.pooled_hot_end_soak_s()) {
            (_, Some(hot_s)) => format!(
                "a soak of {:.1} min or more at the hot end, the cold end held by the power-on soak",
                hot_s / 60.0
            ),
            (Some(s), None) => format!("soaks of {:.1} min or more at each end", s / 60.0),
            (None, None) => "no end soaks: --soak-ends adds them".to_owned(),
        };
        let slow_soak_min = end_soak_s(&self.limits) / 60.0;
        let mut out = vec![format!(
            "predicted loop range: {lo:.1} … {hi:.1} °C on the nominal plant, {slo:.1} … {shi:.1} °C with every time constant {SLOW_PLANT_FACTOR}× nominal (asked {min_c} … {max_c} °C; {soaks})"
        )];
        out.push(self.settled_line());
        for (name, range) in [
            ("the nominal plant", self.loop_range_c),
            ("the slow plant", self.slow_loop_range_c),
        ] {
            if self.reaches(range) {
                continue;
            }
            let short: Vec<String> = [(range.0 - min_c, min_c), (max_c - range.1, max_c)]
                .into_iter()
                .filter(|&(gap, _)| gap > self.limits.reach_c())
                .map(|(gap, end)| format!("{gap:.1} °C short of {end} °C"))
                .collect();
            let remedy = match (self.ends, self.end_soak_s) {
                (_, None) => format!(
                    "--soak-ends closes the gap, at a cost: it holds each end {slow_soak_min:.0} min or more out of the {} h, time \
                     the other ramps and steps no longer get (fewer thermal events to fit the lags on); more --hours \
                     may close it too",
                    self.limits.hours
                ),
                (Ends::SlowPlant, Some(_)) => {
                    "its self-heating or lags keep it from the ends; more --hours may close the gap".to_owned()
                }
                (_, Some(_)) => format!(
                    "--soak-ends holds each end {slow_soak_min:.0} min instead, at a cost in dynamic excitation; more --hours may close it too"
                ),
            };
            out.push(format!(
                "warning: on {name} the loop is predicted to reach only {:.1} … {:.1} °C, {} (more than the {:.1} °C a fit counts as reached): {remedy}",
                range.0,
                range.1,
                short.join(" and "),
                self.limits.reach_c()
            ));
        }
        out
    }

    /// The settled levels the plan gives (the soak rule of `trainer eval`),
    /// and the 20-°C bands of the asked range it leaves without one on the
    /// nominal plant: there the fit that follows forecasts no soak spread.
    fn settled_line(&self) -> String {
        let list = |levels: &[f64]| {
            if levels.is_empty() {
                "none".to_owned()
            } else {
                levels.iter().map(|t| format!("{t:.1}")).collect::<Vec<_>>().join(", ")
            }
        };
        let (min_c, max_c) = (self.limits.min_c, self.limits.max_c);
        let bare: Vec<String> =
            crate::fit::coverage::bands_without_level_c(&self.settled_c, min_c, max_c, self.limits.reach_c())
                .iter()
                .map(|lo| format!("{lo:.0} … {:.0}", crate::fit::coverage::band_top_c(*lo, max_c)))
                .collect();
        let verdict = if bare.is_empty() {
            "one in every 20-°C band of the asked range".to_owned()
        } else {
            format!(
                "none in {} °C: a soak test's settled bias there is not identified from this run (more --hours hold more levels; docs/plan.md)",
                bare.join(", ")
            )
        };
        format!(
            "predicted settled levels (soak rule): {} °C on the nominal plant, {} °C on the slow plant; {verdict}",
            list(&self.settled_c),
            list(&self.slow_settled_c)
        )
    }

    /// The set-point CSV `trainer simulate --chamber-profile` reads.
    pub fn set_points_csv(&self) -> String {
        let mut s = self.metadata();
        s.push_str("time_s,chamber_c\n");
        for (t, c) in self.knots() {
            let _ = writeln!(s, "{t:.0},{c}");
        }
        s
    }

    /// The segment table chamber controllers take: set point, ramp and hold minutes.
    pub fn segments_csv(&self) -> String {
        let mut s = self.metadata();
        let _ = writeln!(
            s,
            "# segment 1 is the power-on soak: no ramp; before it, the pre-soak above (unpowered, {:.0} min)",
            self.pre_soak_s() / 60.0
        );
        s.push_str("segment,target_c,ramp_min,hold_min\n");
        for (i, g) in self.segments.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{},{},{}",
                i + 1,
                g.target_c,
                ramp_minutes(g.ramp_s),
                minutes(g.hold_s)
            );
        }
        s
    }
}

/// A hold in minutes: every hold of a plan is a whole number of minutes.
fn minutes(s: f64) -> String {
    format!("{:.0}", s / 60.0)
}

/// A ramp in minutes: every ramp is a whole number of tenths of a minute,
/// so one decimal is exact.
fn ramp_minutes(s: f64) -> String {
    format!("{:.1}", s / 60.0)
}

/// Whether [`design`] keeps the candidate of the highest D-criterion alone
/// rather than the one [`chosen`] with the static-curve variance: with
/// `--plain` (the plans of before end soaks), and in a run shorter than the
/// dynamics' 12 h and two full end soaks (18 h): after 12-h plans the
/// choice lowered the soak spread but cost accuracy in use, after 24-h ones
/// it did not (docs/decisions.md, "The plan chosen for the static curve").
fn by_d_alone(limits: &PlanLimits, ends: Ends) -> bool {
    ends == Ends::Plain || limits.hours * 3600.0 < ends::FULL_END_SOAKS_RUN_S
}

/// Designs a plan within `limits`: of `candidates` draws from `seed`, the
/// one [`chosen`] by its D-criterion and its static-curve variance on the
/// documented gyro's plant (by the D-criterion alone with `--plain` and under 18 h); where `ends`
/// resolves to end soaks ([`Ends::end_soak_s`]), drawn by
/// [`candidate_soaking`], else by [`candidate`] (the draws are then the
/// same as before end soaks existed).
pub fn design(limits: &PlanLimits, seed: u64, candidates: usize, ends: Ends) -> Result<Plan, String> {
    let end_soak_s = ends.end_soak_s(limits)?;
    let band_soak_s = ends.band_soak_s(limits, end_soak_s);
    let pooled_hot_end_soak_s = ends.pooled_hot_end_soak_s(end_soak_s);
    let plant = SimParams::default().plant;
    let d_alone = by_d_alone(limits, ends);
    let indices: Vec<u64> = (0..candidates.max(1) as u64).collect();
    let mut scored = crate::parallel::parallel_map(&indices, |&i| {
        let mut rng = Pcg64::seed_from_u64(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(i));
        let segments = match end_soak_s {
            Some(s) => candidate_soaking(limits, s, pooled_hot_end_soak_s, band_soak_s, &mut rng),
            None => candidate(limits, &mut rng),
        };
        let temps = loop_temps(&segments, &plant);
        // The variance only where it takes part in the choice (the kept plan's is stated below).
        let variance = if d_alone {
            None
        } else {
            static_curve_variance(&temps, limits)
        };
        (segments, (d_criterion(&temps, limits), variance))
    });
    let mut d_scores: Vec<f64> = scored.iter().map(|s| s.1.0).collect();
    d_scores.sort_by(f64::total_cmp);
    let median_criterion = d_scores[d_scores.len() / 2];
    let scores: Vec<(f64, Option<f64>)> = scored.iter().map(|s| s.1).collect();
    let kept =
        chosen(&scores, d_alone).ok_or_else(|| "no candidate plan has an invertible information matrix".to_owned())?;
    let (segments, (criterion, variance)) = scored.swap_remove(kept);
    let nominal = loop_temps(&segments, &plant);
    let static_curve_variance = if d_alone {
        static_curve_variance(&nominal, limits)
    } else {
        variance
    };
    let slow = loop_temps(&segments, &slowed(&plant, SLOW_PLANT_FACTOR));
    let loop_range_c = range_of(&nominal);
    let slow_loop_range_c = range_of(&slow);
    // loop_temps reads the loop every second from 0 s.
    let settled = |temps: &[f64]| {
        let time_s: Vec<f64> = (0..temps.len()).map(|i| i as f64).collect();
        crate::dataset::plateaus::settled_levels_c(&time_s, temps, &vec![0; temps.len()], 1.0)
    };
    Ok(Plan {
        limits: *limits,
        segments,
        criterion,
        median_criterion,
        static_curve_variance,
        chosen_by_d_alone: d_alone,
        candidates: candidates.max(1),
        seed,
        loop_range_c,
        slow_loop_range_c,
        settled_c: settled(&nominal),
        slow_settled_c: settled(&slow),
        ends,
        end_soak_s,
        band_soak_s,
        prediction: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use super::limits::TEST_LIMITS as LIMITS;

    #[test]
    fn candidates_keep_every_limit_and_end_within_the_budget() {
        let soak_s = end_soak_s(&LIMITS);
        for (seed, soak_ends) in (0..40).flat_map(|seed| [(seed, false), (seed, true)]) {
            let mut rng = Pcg64::seed_from_u64(seed);
            let segments = if soak_ends {
                candidate_soaking(&LIMITS, soak_s, None, None, &mut rng)
            } else {
                candidate(&LIMITS, &mut rng)
            };
            let k = knots(&segments);
            assert_eq!(k[0].0.to_bits(), 0.0f64.to_bits(), "seed {seed}: starts at 0");
            assert!(k.last().unwrap().0 <= 12.0 * 3600.0, "seed {seed}: {:?}", k.last());
            for w in k.windows(2) {
                assert!(w[1].0 > w[0].0, "seed {seed}: time not increasing {w:?}");
                let rate = (w[1].1 - w[0].1).abs() / (w[1].0 - w[0].0) * 60.0;
                assert!(rate < 5.0, "seed {seed}: {rate} °C/min");
            }
            assert!(k.iter().all(|&(_, c)| (-40.0..=60.0).contains(&c)));
        }
    }

    #[test]
    fn a_pooled_candidate_starts_at_the_cold_end_and_soaks_the_hot_end_both_shares_within_the_budget() {
        let soak_s = ends::SHORT_END_SOAK_S;
        for seed in 0..40 {
            let mut rng = Pcg64::seed_from_u64(seed);
            let segments = candidate_soaking(&LIMITS, soak_s, Some(2.0 * soak_s), None, &mut rng);
            // Soaked unpowered at the cold end before power-on: its power-on soak holds that end.
            assert_eq!(
                segments[0].target_c.to_bits(),
                LIMITS.min_c.to_bits(),
                "seed {seed}: {segments:?}"
            );
            let hot_s = segments
                .iter()
                .filter(|g| (g.target_c - LIMITS.max_c).abs() < 0.006)
                .map(|g| g.hold_s)
                .fold(0.0, f64::max);
            assert!(hot_s >= 2.0 * soak_s, "seed {seed}: hot end {hot_s} s: {segments:?}");
            let k = knots(&segments);
            assert!(
                k.last().unwrap().0 <= LIMITS.hours * 3600.0,
                "seed {seed}: {:?}",
                k.last()
            );
            for w in k.windows(2) {
                let rate = (w[1].1 - w[0].1).abs() / (w[1].0 - w[0].0) * 60.0;
                assert!(w[1].0 > w[0].0 && rate < 5.0, "seed {seed}: {w:?}");
            }
        }
    }

    #[test]
    fn a_band_soaking_candidate_soaks_each_interior_band_once_and_each_end_within_the_limits() {
        let limits = PlanLimits { hours: 24.0, ..LIMITS };
        let end_soak_s = Ends::Default.end_soak_s(&limits).unwrap().unwrap();
        let band_soak_s = Ends::Bands.band_soak_s(&limits, Some(end_soak_s)).unwrap();
        for seed in 0..40 {
            let mut rng = Pcg64::seed_from_u64(seed);
            let segments = candidate_soaking(&limits, end_soak_s, None, Some(band_soak_s), &mut rng);
            let k = knots(&segments);
            assert!(k.last().unwrap().0 <= 24.0 * 3600.0, "seed {seed}: {:?}", k.last());
            for w in k.windows(2) {
                let rate = (w[1].1 - w[0].1).abs() / (w[1].0 - w[0].0) * 60.0;
                assert!(w[1].0 > w[0].0 && rate < 5.0, "seed {seed}: {w:?}");
            }
            // The longest hold at set points in lo … hi, s (the last hold may be cut by the budget's end).
            let longest = |lo: f64, hi: f64| {
                segments
                    .iter()
                    .filter(|g| g.target_c >= lo && g.target_c < hi)
                    .map(|g| g.hold_s)
                    .fold(0.0, f64::max)
            };
            // In the middle of each band, where the loop settles within it.
            for centre in [-10.0, 10.0, 30.0] {
                let middle = longest(centre - 5.0, centre + 5.0);
                assert!(
                    middle >= band_soak_s,
                    "seed {seed}: band about {centre} °C: {segments:?}"
                );
            }
            assert!(longest(60.0, 60.1) >= end_soak_s, "seed {seed}: hot end: {segments:?}");
            let starts_cold = segments[0].target_c <= -39.99;
            assert!(
                starts_cold || longest(-40.0, -39.99) >= end_soak_s,
                "seed {seed}: cold end: {segments:?}"
            );
        }
    }

    #[test]
    fn the_criterion_prefers_a_rich_profile_to_a_slow_cycle() {
        let plant = SimParams::default().plant;
        let cycle = vec![
            Segment {
                target_c: 20.0,
                ramp_s: 0.0,
                hold_s: 3600.0,
            },
            Segment {
                target_c: -40.0,
                ramp_s: 3601.0,
                hold_s: 7200.0,
            },
            Segment {
                target_c: 60.0,
                ramp_s: 6001.0,
                hold_s: 7200.0,
            },
            Segment {
                target_c: 20.0,
                ramp_s: 2401.0,
                hold_s: 10_000.0,
            },
        ];
        let slow = d_criterion(&loop_temps(&cycle, &plant), &LIMITS);
        let plan = design(&LIMITS, 1, 8, Ends::Default).unwrap();
        assert!(plan.criterion > slow + 1.0, "plan {} vs cycle {slow}", plan.criterion);
        assert!(plan.criterion >= plan.median_criterion);
    }

    /// A history of holds at `levels_c` (each `hold_s`), ramped at 5 °C/min between, from a soak at the first.
    fn holds(levels_c: &[f64], hold_s: f64) -> Vec<Segment> {
        let mut at = levels_c[0];
        levels_c
            .iter()
            .map(|&target_c| {
                let ramp_s = ramp_seconds((target_c - at).abs(), 5.0);
                at = target_c;
                Segment {
                    target_c,
                    ramp_s,
                    hold_s,
                }
            })
            .collect()
    }

    #[test]
    fn settled_holds_across_the_range_pin_the_static_curve_better_than_fast_swings_without_them() {
        let plant = SimParams::default().plant;
        // 12 h each: five 2.2-h holds across the range, or 32 swings between the ends held 2 min.
        let soak = holds(&[-40.0, 60.0, 10.0, -15.0, 35.0], 2.2 * 3600.0);
        let swings: Vec<f64> = (0..32).map(|i| if i % 2 == 0 { -40.0 } else { 60.0 }).collect();
        let swings = holds(&swings, 120.0);
        let held = static_curve_variance(&loop_temps(&soak, &plant), &LIMITS).unwrap();
        let swung = static_curve_variance(&loop_temps(&swings, &plant), &LIMITS).unwrap();
        assert!(held > 0.0 && held < 0.5 * swung, "holds {held:e}, swings {swung:e}");
    }

    #[test]
    fn a_plan_keeps_the_least_sum_of_ranks_by_d_and_by_static_curve_variance_or_the_best_d_when_plain() {
        // Ranks by D: 1, 2, 0; by the variance: 2, 0, 1 (sums 3, 2, 1).
        let scores = [(-9.0, Some(5.0)), (-8.8, Some(9.0)), (-8.9, Some(4.0))];
        assert_eq!(chosen(&scores, false), Some(2));
        assert_eq!(chosen(&scores, true), Some(1));
        // Equal sums go to the higher D; no variance ranks last by it.
        assert_eq!(chosen(&[(-9.0, Some(1.0)), (-8.0, Some(2.0))], false), Some(1));
        assert_eq!(
            chosen(&[(-8.0, None), (-9.0, Some(2.0)), (-10.0, Some(3.0))], false),
            Some(1)
        );
        // A singular information matrix is never kept, whatever its variance.
        assert_eq!(
            chosen(&[(f64::NEG_INFINITY, Some(0.1)), (-9.0, Some(9.0))], false),
            Some(1)
        );
        assert_eq!(chosen(&[(f64::NEG_INFINITY, Some(0.1))], false), None);
    }

    #[test]
    fn a_day_long_plan_says_how_it_was_chosen_and_a_short_or_plain_one_keeps_the_best_d_criterion() {
        let day = PlanLimits { hours: 24.0, ..LIMITS };
        let plan = design(&day, 1, 8, Ends::Default).unwrap();
        assert!(!plan.chosen_by_d_alone && plan.static_curve_variance.is_some_and(|v| v > 0.0));
        let text = plan.metadata();
        assert!(
            text.contains("by the sum of its ranks by the D-criterion and by the static-curve variance"),
            "{text}"
        );
        assert!(text.contains("# static_curve_variance: "), "{text}");
        // --plain, and a run too short for the dynamics and two full end soaks: the D-criterion alone.
        for (limits, ends) in [
            (day, Ends::Plain),
            (PlanLimits { hours: 17.9, ..LIMITS }, Ends::Default),
        ] {
            let plain = design(&limits, 1, 8, ends).unwrap();
            assert!(plain.chosen_by_d_alone && plain.metadata().contains("best of 8 candidates by the D-criterion"));
        }
    }

    #[test]
    fn the_same_seed_gives_the_same_plan() {
        for ends in [Ends::Default, Ends::SlowPlant] {
            let a = design(&LIMITS, 7, 6, ends).unwrap();
            let b = design(&LIMITS, 7, 6, ends).unwrap();
            assert_eq!(a.set_points_csv(), b.set_points_csv());
            assert_ne!(
                a.set_points_csv(),
                design(&LIMITS, 8, 6, ends).unwrap().set_points_csv()
            );
        }
    }

    #[test]
    fn segment_tables_hold_whole_degrees_and_whole_minutes_of_hold_after_a_stated_pre_soak() {
        for (seed, ends) in [(1, Ends::Default), (3, Ends::Plain), (7, Ends::SlowPlant)] {
            let plan = design(&LIMITS, seed, 4, ends).unwrap();
            let table = plan.segments_csv();
            for row in table.lines().filter(|l| !l.starts_with('#')).skip(1) {
                let f: Vec<&str> = row.split(',').collect();
                for v in [f[1], f[3]] {
                    assert!(!v.contains('.'), "seed {seed}: {row}: not a whole number");
                }
            }
            let pre = table
                .lines()
                .find(|l| l.starts_with("# pre_soak: "))
                .expect("a pre-soak line");
            assert!(pre.contains(" min "), "{pre}");
        }
        // The nominal plant, from the lab to -40 °C: hours, not minutes; a
        // start at the lab's temperature needs none.
        let plant = SimParams::default().plant;
        let cold = pre_soak_s(&plant, -40.0);
        assert!((3600.0..86_400.0).contains(&cold) && cold % 60.0 == 0.0, "{cold}");
        assert!(pre_soak_s(&plant, ROOM_C) < 60.0 + 1e-9);
    }

    #[test]
    fn the_designed_segments_themselves_hold_whole_degrees_and_minutes_within_the_checks() {
        // The plan's values, not only their printing: a hold of 1.3 min
        // printed as 1 would put the table and the set points at odds.
        for (seed, ends) in [
            (1, Ends::Default),
            (2, Ends::Default),
            (5, Ends::Plain),
            (7, Ends::SlowPlant),
            (9, Ends::SlowPlant),
        ] {
            let plan = design(&LIMITS, seed, 4, ends).unwrap();
            for g in &plan.segments {
                assert!(g.target_c.fract() == 0.0, "seed {seed}: set point {}", g.target_c);
                assert!(g.hold_s % 60.0 == 0.0, "seed {seed}: hold {} s", g.hold_s);
                assert!(g.ramp_s % 6.0 == 0.0, "seed {seed}: ramp {} s", g.ramp_s);
            }
            // The limits still hold after the rounding.
            for w in plan.segments.windows(2) {
                let rate_c_per_min = (w[1].target_c - w[0].target_c).abs() / (w[1].ramp_s / 60.0);
                assert!(rate_c_per_min <= LIMITS.max_rate_c_per_min, "seed {seed}: {w:?}");
            }
            assert!(
                plan.segments
                    .iter()
                    .all(|g| (LIMITS.min_c..=LIMITS.max_c).contains(&g.target_c))
            );
            assert!(plan.duration_s() <= LIMITS.hours * 3600.0, "seed {seed}");
            assert!(plan.pre_soak_s() % 60.0 == 0.0 && plan.pre_soak_s() > 0.0);
        }
    }

    #[test]
    fn the_default_plan_soaks_both_ends_three_hours_in_a_long_run_and_pools_its_one_and_a_half_at_the_hot_end_in_twelve()
     {
        for (hours, soak_s, written) in [
            (
                24.0,
                ends::MAX_END_SOAK_S,
                "# end_soak_min: 180.0 (at each end of the range: the default",
            ),
            (
                12.0,
                ends::SHORT_END_SOAK_S,
                "# end_soak_min: 90.0 (each end's share, both pooled at the hot end below: the default",
            ),
        ] {
            let limits = PlanLimits { hours, ..LIMITS };
            let plan = design(&limits, 1, 4, Ends::Default).unwrap();
            assert_eq!(plan.end_soak_s, Some(soak_s));
            // Pooled under 18 h: the run starts at the cold end and the hot end soaks both shares.
            let pooled = hours < 18.0;
            assert_eq!(plan.pooled_hot_end_soak_s().is_some(), pooled, "{hours} h");
            let hot_soak_s = if pooled { 2.0 * soak_s } else { soak_s };
            if pooled {
                assert_eq!(
                    plan.segments[0].target_c.to_bits(),
                    limits.min_c.to_bits(),
                    "{:?}",
                    plan.segments
                );
                assert!(
                    plan.set_points_csv()
                        .contains("# hot_end_soak_min: 180.0 (both ends' share pooled"),
                    "{}",
                    plan.set_points_csv()
                );
            }
            let held_at = |end_c: f64| {
                plan.segments
                    .iter()
                    .filter(|g| (g.target_c - end_c).abs() < 0.006)
                    .map(|g| g.hold_s)
                    .fold(0.0, f64::max)
            };
            // The cold end's soak may be the power-on soak: the unit is soaked there before it.
            let cold_start = (plan.segments[0].target_c - limits.min_c).abs() < 0.006;
            assert!(cold_start || held_at(limits.min_c) >= soak_s, "{:?}", plan.segments);
            assert!(held_at(limits.max_c) >= hot_soak_s, "{:?}", plan.segments);
            assert!(plan.set_points_csv().contains(written), "{hours} h");
            assert_eq!(design(&limits, 1, 4, Ends::Plain).unwrap().end_soak_s, None);
        }
        // Under 12 h the default is the plain draw.
        let short = PlanLimits { hours: 10.0, ..LIMITS };
        assert_eq!(
            design(&short, 1, 4, Ends::Default).unwrap().segments,
            design(&short, 1, 4, Ends::Plain).unwrap().segments
        );
    }

    #[test]
    fn ramps_are_rounded_up_to_stay_under_the_limit() {
        // Whole minutes: exact in f64.
        let secs = |delta: f64, rate: f64| ramp_seconds(delta, rate).to_bits();
        assert_eq!(secs(100.0, 5.0), 1206.0f64.to_bits());
        assert_eq!(secs(10.0, 3.0), 204.0f64.to_bits());
        assert_eq!(secs(7.0, 3.0), 144.0f64.to_bits());
        assert_eq!(ramp_minutes(90.0), "1.5");
        assert_eq!(minutes(3600.0), "60");
    }
}
