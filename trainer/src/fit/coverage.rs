//! What the training runs showed the lag bank, against what it needs to be
//! identified and to hold in use: settled levels across the range (the
//! static curve), fast changes of both signs at every filter's time scale
//! (the rate weights and coil lags), holds long enough for the slowest
//! filter (the slow lags apart from the static curve), thermal events to
//! validate on, and a power-on in the cold (the self-heating transient).
//! `trainer fit` prints it after its table and names what is missing, for
//! the range and rates of use it is told ([`InUse`]) or, told none, for the
//! range the loop covered, saying where the loop turned before it settled
//! (the chamber went further than the loop followed).

use serde::Serialize;

/// A 10-s mean counts as slow (near a level) below this rate at the 960-s
/// filter, °C/min: a sensor behind a housing of tens of minutes still
/// drifts this fast half an hour into a hold after a large step.
const SLOW_C_PER_MIN: f64 = 0.3;
/// A temperature band is covered by at least this long slow in it, s.
const LEVEL_S: f64 = 1200.0;
/// Width of the temperature bands, °C: a cubic static curve is bridged
/// safely across one band without a level, not across two.
pub const BAND_C: f64 = 20.0;
/// A long hold: a slow stretch at least this long, s (long enough for the
/// 960-s and 3840-s filters to read the slow decay apart from the static curve).
pub const LONG_HOLD_S: f64 = 2400.0;
/// The fastest filter should have seen changes at least this fast, °C/min:
/// an in-use air step of tens of °C reaches a sensor behind a housing of
/// tens of minutes faster than that, a 1-°C/min chamber ramp does not.
pub const FAST_C_PER_MIN: f64 = 1.0;
/// Thermal events below which validation falls back to contiguous folds.
const FEW_EVENTS: usize = 5;
/// A power-on counts as cold in the lowest this share of the covered range.
const COLD_SHARE: f64 = 0.25;

/// The loop range of use counts as covered when the runs came within this
/// share of its span of each end (a cubic static curve extrapolates safely
/// that far; `trainer plan` soaks until the loop comes this close).
pub const USE_REACH_SHARE: f64 = 0.05;

/// Readings within this of the coldest or hottest one are its end, °C.
const END_C: f64 = 1.0;

/// What the model will be used over, as far as the engineer says.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InUse {
    /// Loop-temperature range of use (lowest, highest), °C.
    pub range_c: Option<(f64, f64)>,
    /// Fastest loop-temperature change in use, either sign, °C/min.
    pub max_rate_c_per_min: Option<f64>,
}

/// One filter's covered rates.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RateCoverage {
    /// Filter time constant, s.
    pub tau_s: f64,
    /// Fastest rise the filter read, °C/min.
    pub max_c_per_min: f64,
    /// Fastest fall the filter read (negative), °C/min.
    pub min_c_per_min: f64,
}

/// What the training runs covered.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Coverage {
    /// Loop-temperature range of the 10-s means, °C.
    pub temp_range_c: (f64, f64),
    /// Lower edges of the 20-°C bands (from the coldest reading up) the runs stayed in slowly for 20 min or more, °C, ascending.
    pub bands_c: Vec<f64>,
    /// Lower edges of the bands within the covered range that they did not, °C.
    pub uncovered_c: Vec<f64>,
    /// Per filter, fastest to slowest.
    pub rates: Vec<RateCoverage>,
    /// Slow stretches at least [`LONG_HOLD_S`] long.
    pub long_holds: usize,
    /// Thermal events the event folds found.
    pub events: usize,
    /// Loop temperature at the power-on of the coldest run that starts cold and holds, °C.
    pub cold_start_c: Option<f64>,
    /// Slowest rate at the settling filter (≈ 960 s) within 1 °C of the
    /// coldest and of the hottest reading, °C/min: far from 0, the loop
    /// turned there before it settled, so the chamber went further than the
    /// loop followed.
    pub end_rates_c_per_min: (f64, f64),
    /// Loop temperatures of the runs' settled plateaus by the soak test's
    /// rule ([`crate::dataset::plateaus`]), °C, in time order: where the
    /// runs show the settled bias a soak test reads. Empty until
    /// [`settled_levels_c`] fills it.
    pub settled_c: Vec<f64>,
}

pub use crate::dataset::plateaus::settled_levels_c;

/// A lag-bank model's range of its static input, the mean coil temperature
/// T̂ (its first input), °C: where it is valid ([`Coverage::valid_range_c`]).
/// `None` for a model of another kind (the response bank the default may choose).
pub fn model_range_c(model: &rbf_core::Model) -> Option<(f64, f64)> {
    if !matches!(model.features().set, rbf_core::FeatureSet::LagBank(_)) {
        return None;
    }
    let (lo, hi) = model.input_range(0)?;
    Some((f64::from(lo), f64::from(hi)))
}

/// A range up to this share of a band over a multiple of [`BAND_C`] counts
/// no band more: its last band reaches its top (5 °C; a hot-end soak's loop
/// settles that far above the chamber's top with the electronics' heat, and
/// a sliver of a band above it would ask a settled level of its own).
pub const BAND_OVERHANG_SHARE: f64 = 0.25;

/// How many [`BAND_C`] bands `[edge, edge + 20)` from `lo` cover `lo … hi`:
/// at least one; the last holds `hi` and may reach [`BAND_OVERHANG_SHARE`]
/// of a band further ([`band_top_c`]).
pub fn band_count(lo: f64, hi: f64) -> usize {
    ((hi - lo) / BAND_C - BAND_OVERHANG_SHARE).ceil().max(1.0) as usize
}

/// The top of the band whose lower edge is `edge` in a range ending at
/// `hi`, °C: `edge` + [`BAND_C`], or `hi` for the last band ([`band_count`]);
/// never above `hi`.
pub fn band_top_c(edge: f64, hi: f64) -> f64 {
    let top = edge + BAND_C;
    if hi - top <= BAND_OVERHANG_SHARE * BAND_C {
        hi
    } else {
        top
    }
}

/// Lower edges of the [`BAND_C`] bands of `lo … hi` ([`band_count`]) that
/// hold none of `levels_c`, °C. The first band begins `end_slack_c` below
/// `lo` and the last ends that far above `hi`, inclusive: a level just past
/// an end of the range of use is that end's settled evidence.
/// Empty for an empty or unread (NaN) range.
pub fn bands_without_level_c(levels_c: &[f64], lo: f64, hi: f64, end_slack_c: f64) -> Vec<f64> {
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return Vec::new();
    }
    let bands = band_count(lo, hi);
    (0..bands)
        .map(|b| (b, lo + b as f64 * BAND_C))
        .filter(|&(b, edge)| {
            let from = if b == 0 { lo - end_slack_c } else { edge };
            let inside = |t: f64| t >= from && (t < edge + BAND_C || (b + 1 == bands && t <= hi + end_slack_c));
            !levels_c.iter().any(|&t| inside(t))
        })
        .map(|(_, edge)| edge)
        .collect()
}

impl Coverage {
    /// Coverage of 10-s means: loop temperature `temp_c`, the filters'
    /// rates `rates[i][k]` (°C/min) at `taus_s`, run index per mean.
    /// `settle_filter` is the index of the filter read for settling (≈ 960 s).
    pub fn of_means(
        temp_c: &[f64],
        rates: &[&[f64]],
        run: &[usize],
        taus_s: &[f64],
        settle_filter: usize,
        mean_s: f64,
        events: usize,
    ) -> Coverage {
        let lo = temp_c.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = temp_c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        // The slowest the loop was near each extreme: a loop that settled
        // there was slow at some reading, one that turned was not.
        let rate_at = |extreme: f64| {
            temp_c
                .iter()
                .zip(rates)
                .filter(|(t, _)| (**t - extreme).abs() <= END_C)
                .map(|(_, r)| r[settle_filter])
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                .unwrap_or(0.0)
        };
        let end_rates_c_per_min = (rate_at(lo), rate_at(hi));
        let rate_cov = taus_s
            .iter()
            .enumerate()
            .map(|(k, &tau_s)| RateCoverage {
                tau_s,
                max_c_per_min: rates.iter().map(|r| r[k]).fold(0.0, f64::max),
                min_c_per_min: rates.iter().map(|r| r[k]).fold(0.0, f64::min),
            })
            .collect();
        // Settled stretches, never across a run boundary.
        let mut stretches: Vec<(usize, usize)> = Vec::new();
        let mut start: Option<usize> = None;
        for i in 0..=temp_c.len() {
            let settled = i < temp_c.len()
                && rates[i][settle_filter].abs() < SLOW_C_PER_MIN
                && start.is_none_or(|s| run[s] == run[i]);
            match (settled, start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    stretches.push((s, i));
                    start = (i < temp_c.len() && rates[i][settle_filter].abs() < SLOW_C_PER_MIN).then_some(i);
                }
                _ => {}
            }
        }
        let len_s = |&(s, e): &(usize, usize)| (e - s) as f64 * mean_s;
        // Bands from the coldest reading up; the hottest falls in the last.
        let bands = if hi > lo { band_count(lo, hi) } else { 1 };
        let band_of = |t: f64| (((t - lo) / BAND_C).floor().max(0.0) as usize).min(bands - 1);
        let mut dwell_s = vec![0.0; bands];
        for &(s, e) in &stretches {
            for &t in &temp_c[s..e] {
                if t.is_finite() {
                    dwell_s[band_of(t)] += mean_s;
                }
            }
        }
        let edge = |b: usize| lo + b as f64 * BAND_C;
        let bands_c: Vec<f64> = (0..bands).filter(|&b| dwell_s[b] >= LEVEL_S).map(edge).collect();
        let uncovered_c: Vec<f64> = (0..bands).filter(|&b| dwell_s[b] < LEVEL_S).map(edge).collect();
        let long_holds = stretches.iter().filter(|st| len_s(st) >= LONG_HOLD_S).count();
        // A cold power-on: a run whose first mean lies in the lowest quarter
        // and that does not ramp in its first settled stretch's place.
        let cold_limit = lo + COLD_SHARE * (hi - lo);
        let cold_start_c = (0..temp_c.len())
            .filter(|&i| i == 0 || run[i] != run[i - 1])
            .filter(|&i| temp_c[i] <= cold_limit)
            .filter(|&i| {
                stretches
                    .iter()
                    .any(|&(s, e)| s <= i + 1 && e > i && len_s(&(s, e)) >= LEVEL_S)
            })
            .map(|i| temp_c[i])
            .fold(None, |best: Option<f64>, t| Some(best.map_or(t, |b| b.min(t))));
        Coverage {
            temp_range_c: (lo, hi),
            bands_c,
            uncovered_c,
            rates: rate_cov,
            long_holds,
            events,
            cold_start_c,
            end_rates_c_per_min,
            settled_c: Vec::new(),
        }
    }

    /// Lower edges of the 20-°C bands of the range of use (or, told none,
    /// of the covered range) that hold no settled level ([`Self::settled_c`]), °C.
    /// A level within [`USE_REACH_SHARE`] of the range past either end
    /// counts for that end's band, as the range counts as reached from there.
    pub fn unsettled_bands_c(&self, in_use: &InUse) -> Vec<f64> {
        let (lo, hi) = in_use.range_c.unwrap_or(self.temp_range_c);
        bands_without_level_c(&self.settled_c, lo, hi, USE_REACH_SHARE * (hi - lo))
    }

    /// The loop temperatures the model is valid over, °C: the range of its
    /// static input (the mean coil temperature T̂, `model_range_c`, which lags
    /// the loop and so stops short of a chamber's ends) within the loop's
    /// range; the loop's range without one. A steady loop outside it reads a
    /// T̂ outside it: clamped (flag 1).
    pub fn valid_range_c(&self, model_range_c: Option<(f64, f64)>) -> (f64, f64) {
        let (lo, hi) = self.temp_range_c;
        model_range_c.map_or((lo, hi), |(m_lo, m_hi)| (m_lo.max(lo), m_hi.min(hi)))
    }

    /// What the lag bank needs for `in_use` and these runs lack, in words an
    /// engineer acts on; `model_range_c`: the fitted model's range of T̂, °C
    /// ([`model_range_c`]), which bounds where it is valid ([`Self::valid_range_c`]).
    pub fn missing(&self, in_use: &InUse, model_range_c: Option<(f64, f64)>) -> Vec<String> {
        let mut out = Vec::new();
        let (lo, hi) = self.temp_range_c;
        match in_use.range_c {
            Some((use_lo, use_hi)) => {
                let reach_c = USE_REACH_SHARE * (use_hi - use_lo);
                let (valid_lo, valid_hi) = self.valid_range_c(model_range_c);
                let short: Vec<String> = [
                    (valid_lo > use_lo + reach_c).then(|| format!("below {valid_lo:.1}")),
                    (valid_hi < use_hi - reach_c).then(|| format!("above {valid_hi:.1}")),
                ]
                .into_iter()
                .flatten()
                .collect();
                let valid = if (valid_lo, valid_hi) == (lo, hi) {
                    format!("the runs' loop read {lo:.1} … {hi:.1} °C")
                } else {
                    format!(
                        "the model is valid over {valid_lo:.1} … {valid_hi:.1} °C (its mean coil temperature T̂ on \
                         these runs; the loop read {lo:.1} … {hi:.1} °C)"
                    )
                };
                if !short.is_empty() {
                    out.push(format!(
                        "range of use {use_lo} … {use_hi} °C not covered: {valid}; {} °C the model extrapolates (flag 1); soak at each end of the range until the loop settles within {reach_c:.1} °C of it (`trainer plan` sizes the soaks)",
                        short.join(" and ")
                    ));
                }
            }
            None => {
                let (cold_rate, hot_rate) = self.end_rates_c_per_min;
                let turned: Vec<String> = [
                    (cold_rate < -SLOW_C_PER_MIN)
                        .then(|| format!("bottomed at {lo:.1} °C still falling {:.1} °C/min", -cold_rate)),
                    (hot_rate > SLOW_C_PER_MIN)
                        .then(|| format!("peaked at {hi:.1} °C still rising {hot_rate:.1} °C/min")),
                ]
                .into_iter()
                .flatten()
                .collect();
                if !turned.is_empty() {
                    out.push(format!(
                        "no settled end: the loop {} (τ 960 s): the chamber turned back before the loop followed it, so a range of use beyond is not covered; soak at the chamber's ends until the loop settles, and give the range of use (--use-range-c) to have it checked",
                        turned.join(" and ")
                    ));
                }
            }
        }
        if let (Some(use_rate), Some(fast)) = (in_use.max_rate_c_per_min, self.rates.first()) {
            let reached = fast.max_c_per_min.min(-fast.min_c_per_min);
            if reached < use_rate {
                out.push(format!(
                    "rates of use up to ±{use_rate} °C/min not covered: the loop's fastest fall/rise was {:.1}/{:+.1} °C/min (τ {:.0} s); faster changes extrapolate the rate weights; ramp and step both ways at the chamber's full rate",
                    fast.min_c_per_min, fast.max_c_per_min, fast.tau_s
                ));
            }
        }
        if !self.uncovered_c.is_empty() {
            out.push(format!(
                "no level in {} °C: the static curve there is only read while the temperature moves; hold there for {:.0} min or more",
                band_list(&self.uncovered_c, hi),
                LEVEL_S / 60.0
            ));
        }
        if let Some(fast) = self.rates.first() {
            if fast.max_c_per_min.max(-fast.min_c_per_min) < FAST_C_PER_MIN {
                out.push(format!(
                    "no fast change: the sensor never moved faster than {:.1} °C/min (τ {:.0} s); in use, steps and swings do, and leave more than the in-use forecast, which holds for changes this slow; ramp at the chamber's full rate",
                    fast.max_c_per_min.max(-fast.min_c_per_min),
                    fast.tau_s
                ));
            } else if fast.max_c_per_min.min(-fast.min_c_per_min) < 0.5 * FAST_C_PER_MIN {
                let which = if fast.max_c_per_min < -fast.min_c_per_min {
                    "heating"
                } else {
                    "cooling"
                };
                out.push(format!(
                    "no fast {which}: only one direction was fast; ramp the other way at the full rate too"
                ));
            }
        }
        let unsettled = self.unsettled_bands_c(in_use);
        if !unsettled.is_empty() {
            let hi = in_use.range_c.map_or(hi, |r| r.1);
            out.push(format!(
                "no settled level in {} °C (the loop steady {:.0} min by the soak rule of `eval`): the settled bias a soak test reads there is not identified from these runs, and the fit does not forecast its spread (`predicted_settled_spread_dph` null); hold the chamber at a level in each such band until the loop settles, an hour or more, or fit a soak test of the unit beside this run (docs/workflow.md, \"The soak test\")",
                band_list(&unsettled, hi),
                crate::dataset::plateaus::MIN_STEADY_S / 60.0
            ));
        }
        if self.long_holds == 0 {
            out.push(format!(
                "no long hold ({:.0} min slower than {SLOW_C_PER_MIN} °C/min): the slowest lags are not told apart from the static curve; hold an hour at least once after a fast change",
                LONG_HOLD_S / 60.0
            ));
        }
        if self.events < FEW_EVENTS {
            out.push(format!(
                "only {} thermal events (ramps or steps with their holds): too few to validate the structure on; add steps between levels",
                self.events
            ));
        }
        if self.cold_start_c.is_none() {
            out.push(format!(
                "no cold start: no run powers on in the coldest quarter of the range ({:.0} … {:.0} °C) and holds there; in use the gyro is switched on cold and self-heats: soak it cold unpowered, then power on and hold {:.0} min",
                lo,
                lo + COLD_SHARE * (hi - lo),
                LEVEL_S / 60.0 * 2.0
            ));
        }
        out
    }

    /// The coverage in a few lines, then what is missing for `in_use`
    /// ([`Self::missing`], the model's range of T̂ `model_range_c`).
    pub fn lines(&self, in_use: &InUse, model_range_c: Option<(f64, f64)>) -> Vec<String> {
        let rates: Vec<String> = self
            .rates
            .iter()
            .map(|r| format!("{:.0} s {:+.1}/{:+.1}", r.tau_s, r.min_c_per_min, r.max_c_per_min))
            .collect();
        let mut out = vec![
            format!(
                "coverage: T {:.1} … {:.1} °C; levels (20 min slower than {SLOW_C_PER_MIN} °C/min) in {} °C; {} thermal events; {} holds ≥ {:.0} min; {}",
                self.temp_range_c.0,
                self.temp_range_c.1,
                band_list(&self.bands_c, self.temp_range_c.1),
                self.events,
                self.long_holds,
                LONG_HOLD_S / 60.0,
                match self.cold_start_c {
                    Some(c) => format!("cold start at {c:.1} °C"),
                    None => "no cold start".to_owned(),
                }
            ),
            format!("coverage: fastest fall/rise per filter [°C/min]: {}", rates.join(", ")),
            format!(
                "coverage: settled levels (soak rule) at {} °C",
                if self.settled_c.is_empty() {
                    "none".to_owned()
                } else {
                    self.settled_c
                        .iter()
                        .map(|t| format!("{t:.1}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ),
        ];
        let missing = self.missing(in_use, model_range_c);
        if missing.is_empty() {
            let (valid_lo, valid_hi) = self.valid_range_c(model_range_c);
            let whose = if (valid_lo, valid_hi) == self.temp_range_c {
                "the loop's range on these runs"
            } else {
                "where the model is valid: its mean coil temperature T̂ on these runs"
            };
            out.push(match in_use.range_c {
                Some((use_lo, use_hi)) => {
                    format!("missing: nothing the lag bank needs for use over {use_lo} … {use_hi} °C")
                }
                None => format!(
                    "missing: nothing the lag bank needs for use within {valid_lo:.1} … {valid_hi:.1} °C, {whose} (--use-range-c checks the range of use)"
                ),
            });
        } else {
            out.extend(missing.into_iter().map(|m| format!("missing: {m}")));
        }
        out
    }
}

/// Bands by their lower edges as merged ranges: `-40 … -10, 20 … 30`.
fn band_list(edges: &[f64], hi: f64) -> String {
    if edges.is_empty() {
        return "none".to_owned();
    }
    let mut ranges: Vec<(f64, f64)> = Vec::new();
    for &e in edges {
        match ranges.last_mut() {
            Some(r) if (r.1 - e).abs() < 1e-9 => r.1 = e + BAND_C,
            _ => ranges.push((e, e + BAND_C)),
        }
    }
    for r in &mut ranges {
        r.1 = band_top_c(r.1 - BAND_C, hi);
    }
    ranges
        .iter()
        .map(|(a, b)| format!("{a:.0} … {b:.0}"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 10-s means of a history of (duration s, rate °C/min) pieces from `start`,
    /// with an idealised 960-s filter (the rate itself) and a 15-s filter.
    fn history(start: f64, pieces: &[(f64, f64)]) -> (Vec<f64>, Vec<[f64; 2]>) {
        let (mut t, mut temps, mut rates) = (start, Vec::new(), Vec::new());
        for &(dur, rate) in pieces {
            for _ in 0..(dur / 10.0) as usize {
                t += rate / 6.0;
                temps.push(t);
                rates.push([rate, rate]);
            }
        }
        (temps, rates)
    }

    fn coverage(start: f64, pieces: &[(f64, f64)], events: usize) -> Coverage {
        let (temps, rates) = history(start, pieces);
        let rows: Vec<&[f64]> = rates.iter().map(|r| &r[..]).collect();
        let run = vec![0; temps.len()];
        Coverage::of_means(&temps, &rows, &run, &[15.0, 960.0], 1, 10.0, events)
    }

    #[test]
    fn a_slow_warm_cycle_is_told_what_it_lacks() {
        // 25 °C, to −40 at 0.8 °C/min (what a 1-°C/min chamber ramp reaches
        // a lagging sensor at), hold 2 h, to 60, hold 2 h, back to 25.
        let c = coverage(
            25.0,
            &[
                (3600.0, 0.0),
                (4880.0, -0.8),
                (7200.0, 0.0),
                (7500.0, 0.8),
                (7200.0, 0.0),
                (2630.0, -0.8),
            ],
            3,
        );
        let missing = c.missing(&InUse::default(), None).join("\n");
        assert!(missing.contains("no fast change"), "{missing}");
        assert!(missing.contains("no cold start"), "{missing}");
        assert!(missing.contains("only 3 thermal events"), "{missing}");
        assert!(missing.contains("no level in -20 … 20 °C"), "{missing}");
        assert!(!missing.contains("no long hold"), "{missing}");
        assert_eq!(c.long_holds, 3);
    }

    /// A planned run: a cold start, fast steps both ways, holds at −40 and
    /// 60 °C, and (as its runs would show) a settled level in every 20-°C band.
    fn planned() -> Coverage {
        let mut c = coverage(
            -40.0,
            &[
                (3600.0, 0.0),
                (1200.0, 5.0),
                (2400.0, 0.0),
                (480.0, -5.0),
                (4000.0, 0.0),
                (960.0, -2.5),
                (1800.0, 0.0),
                (240.0, 5.0),
                (1800.0, 0.0),
                (480.0, 5.0),
                (1800.0, 0.0),
            ],
            8,
        );
        c.settled_c = vec![-39.0, -15.0, 5.0, 25.0, 59.0];
        c
    }

    #[test]
    fn settled_levels_are_the_holds_the_soak_rule_finds_and_the_bands_without_one_are_named() {
        // 10-s means: a 2-h hold at −40 °C, 1 °C/min to 20 °C, a 2-h hold,
        // 1 °C/min to 60 °C and a 20-min hold: two settled levels, none hot.
        let mut temp = vec![-40.0; 720];
        temp.extend((1..=360).map(|i| -40.0 + f64::from(i) / 6.0));
        temp.extend(vec![20.0; 720]);
        temp.extend((1..=240).map(|i| 20.0 + f64::from(i) / 6.0));
        temp.extend(vec![60.0; 120]);
        let time: Vec<f64> = (0..temp.len()).map(|i| i as f64 * 10.0).collect();
        let run = vec![0; temp.len()];
        let settled = settled_levels_c(&time, &temp, &run, 10.0);
        assert_eq!(settled.len(), 2, "{settled:?}");
        assert!(
            (settled[0] + 40.0).abs() < 1e-9 && (settled[1] - 20.0).abs() < 1e-9,
            "{settled:?}"
        );
        let mut c = planned();
        c.settled_c = settled;
        assert_eq!(c.unsettled_bands_c(&InUse::default()), [-20.0, 0.0, 40.0]);
        let missing = c.missing(&InUse::default(), None).join("\n");
        assert!(
            missing.contains("no settled level in -20 … 20, 40 … 60 °C")
                && missing.contains("predicted_settled_spread_dph")
                && missing.contains("or fit a soak test of the unit beside this run"),
            "{missing}"
        );
        // Told a range of use, the bands are the range's.
        let in_use = InUse {
            range_c: Some((-40.0, 20.0)),
            max_rate_c_per_min: None,
        };
        assert_eq!(c.unsettled_bands_c(&in_use), [-20.0]);
    }

    #[test]
    fn a_hot_end_settled_a_few_degrees_over_the_top_is_the_top_bands_level_not_a_band_of_its_own() {
        // The 24-h plan's levels on a gyro whose electronics lift the loop
        // 0.3 … 4.5 °C over a 60-°C chamber: one in each 20-°C band.
        let levels = [-39.3, -8.0, 10.2, 30.3, 60.3];
        for hi in [60.7, 64.5] {
            assert_eq!(band_count(-40.0, hi), 5, "{hi}");
            assert!((band_top_c(40.0, hi) - hi).abs() < 1e-12, "{hi}");
            assert!((band_top_c(20.0, hi) - 40.0).abs() < 1e-12, "{hi}");
            assert!(bands_without_level_c(&levels, -40.0, hi, 0.0).is_empty(), "{hi}");
        }
        // Past a quarter band over, the rest is a band of its own, which
        // takes the hot level and leaves 40 … 60 °C without one.
        assert_eq!(band_count(-40.0, 65.5), 6);
        assert_eq!(bands_without_level_c(&levels, -40.0, 65.5, 0.0), [40.0]);
        // Without the level at the hot end, its band is named to the range's top.
        let mut c = planned();
        c.temp_range_c = (-40.0, 64.5);
        c.settled_c = levels[..4].to_vec();
        let missing = c.missing(&InUse::default(), None).join("\n");
        assert!(missing.contains("no settled level in 40 … 64 °C"), "{missing}");
        // Told the range of use −40 … 60 °C, a level 0.3 °C past its end is its top band's.
        let in_use = InUse {
            range_c: Some((-40.0, 60.0)),
            max_rate_c_per_min: None,
        };
        c.settled_c = levels.to_vec();
        assert!(c.unsettled_bands_c(&in_use).is_empty());
        c.settled_c = vec![-40.4, -8.0, 10.2, 30.3, 60.3];
        assert!(c.unsettled_bands_c(&in_use).is_empty());
        c.settled_c = vec![-46.0, -8.0, 10.2, 30.3, 60.3];
        assert_eq!(c.unsettled_bands_c(&in_use), [-40.0]);
    }

    #[test]
    fn a_planned_run_with_a_cold_start_and_fast_steps_misses_nothing() {
        let c = planned();
        assert_eq!(
            c.missing(&InUse::default(), None),
            Vec::<String>::new(),
            "{:?}",
            c.lines(&InUse::default(), None)
        );
        assert_eq!(c.cold_start_c, Some(-40.0));
        assert!(
            c.lines(&InUse::default(), None)
                .last()
                .unwrap()
                .contains("nothing the lag bank needs")
        );
    }

    /// A designed run of 5-°C/min chamber ramps with short holds, as the
    /// loop reads it: it turns at −20 and 37 °C while still moving, never
    /// settling at the chamber's −40 … 60 °C.
    fn short_holds() -> Coverage {
        coverage(
            10.0,
            &[
                (2400.0, 0.0),
                (1500.0, -1.2),
                (900.0, 1.4),
                (1200.0, 0.0),
                (1500.0, 1.2),
                (600.0, 0.6),
                (600.0, -1.0),
                (1200.0, 0.0),
                (600.0, 0.8),
                (1200.0, 0.0),
            ],
            6,
        )
    }

    #[test]
    fn a_short_hold_run_is_told_its_loop_turned_before_the_chambers_ends() {
        let c = short_holds();
        let (lo, hi) = c.temp_range_c;
        assert!(
            (-21.0..=-19.0).contains(&lo) && (36.0..=38.0).contains(&hi),
            "{lo} … {hi}"
        );
        let lines = c.lines(&InUse::default(), None).join("\n");
        assert!(!lines.contains("missing: nothing"), "{lines}");
        assert!(lines.contains("missing: no settled end: the loop bottomed at -20.0 °C still falling 1.2 °C/min and peaked at 37.0 °C still rising 0.6 °C/min"), "{lines}");
        // Told the range of use, it names what the model extrapolates over.
        let in_use = InUse {
            range_c: Some((-40.0, 60.0)),
            max_rate_c_per_min: None,
        };
        let lines = c.lines(&in_use, None).join("\n");
        assert!(!lines.contains("missing: nothing"), "{lines}");
        assert!(
            lines.contains("missing: range of use -40 … 60 °C not covered: the runs' loop read -20.0 … 37.0 °C; below -20.0 and above 37.0 °C the model extrapolates"),
            "{lines}"
        );
        // Within 5 % of the span of each end counts as covered.
        let near = InUse {
            range_c: Some((-23.0, 40.0)),
            max_rate_c_per_min: None,
        };
        assert!(!c.lines(&near, None).join("\n").contains("range of use"));
    }

    #[test]
    fn rates_of_use_faster_than_the_runs_are_named() {
        let c = short_holds();
        let in_use = |r: f64| InUse {
            range_c: Some((-20.0, 37.0)),
            max_rate_c_per_min: Some(r),
        };
        let lines = c.lines(&in_use(3.0), None).join("\n");
        assert!(
            lines.contains("missing: rates of use up to ±3 °C/min not covered: the loop's fastest fall/rise was -1.2/+1.4 °C/min (τ 15 s)"),
            "{lines}"
        );
        assert!(!c.lines(&in_use(1.0), None).join("\n").contains("rates of use"));
    }

    #[test]
    fn a_run_that_settles_at_the_range_of_use_misses_nothing_for_it() {
        let c = planned();
        let in_use = InUse {
            range_c: Some((-40.0, 60.0)),
            max_rate_c_per_min: Some(1.0),
        };
        assert_eq!(
            c.lines(&in_use, None).last().map(String::as_str),
            Some("missing: nothing the lag bank needs for use over -40 … 60 °C")
        );
        assert_eq!(c.end_rates_c_per_min, (0.0, 0.0));
        // A wider range of use is not covered by it.
        let wider = InUse {
            range_c: Some((-55.0, 85.0)),
            max_rate_c_per_min: None,
        };
        assert!(
            c.lines(&wider, None)
                .join("\n")
                .contains("range of use -55 … 85 °C not covered")
        );
    }

    #[test]
    fn the_range_stated_valid_is_the_models_own_where_it_stops_short_of_the_loops() {
        // The loop reached −40 … 60 °C; the model's T̂, which lags it, only 39.2 at the top.
        let c = planned();
        let (lo, hi) = c.temp_range_c;
        let model = Some((lo, 39.2));
        let last = c.lines(&InUse::default(), model).pop().unwrap_or_default();
        assert!(
            last.contains(&format!("for use within {lo:.1} … 39.2 °C, where the model is valid")),
            "{last}"
        );
        let in_use = InUse {
            range_c: Some((lo, hi)),
            max_rate_c_per_min: None,
        };
        let lines = c.lines(&in_use, model).join("\n");
        assert!(
            lines.contains("not covered: the model is valid over")
                && lines.contains("above 39.2 °C the model extrapolates"),
            "{lines}"
        );
        assert!(!lines.contains("missing: nothing"), "{lines}");
    }
}
