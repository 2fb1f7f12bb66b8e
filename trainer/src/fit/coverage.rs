//! What the training runs showed the lag bank, against what it needs to be
//! identified and to hold in use: settled levels across the range (the
//! static curve), fast changes of both signs at every filter's time scale
//! (the rate weights and coil lags), holds long enough for the slowest
//! filter (the slow lags apart from the static curve), thermal events to
//! validate on, and a power-on in the cold (the self-heating transient).
//! `trainer fit` prints it after its table and names what is missing.

use serde::Serialize;

/// A 10-s mean counts as settled below this rate at the 960-s filter, °C/min.
const SETTLED_C_PER_MIN: f64 = 0.05;
/// A level is a settled stretch at least this long, s.
const LEVEL_S: f64 = 1200.0;
/// A hold this long lets the slowest coil mode settle (`plan::LONG_HOLD_S`), s.
pub const LONG_HOLD_S: f64 = 3840.0;
/// Gap between settled levels (or from a level to the end of the range)
/// the static cubic is asked to bridge without data, °C.
const LEVEL_GAP_C: f64 = 25.0;
/// The fastest filter should have seen changes at least this fast, °C/min:
/// in use, air steps and swings of 3 … 8 °C/min reach the sensor at this
/// rate or more.
pub const FAST_C_PER_MIN: f64 = 2.0;
/// Thermal events below which validation falls back to contiguous folds.
const FEW_EVENTS: usize = 5;
/// A power-on counts as cold in the lowest this share of the covered range.
const COLD_SHARE: f64 = 0.25;

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
    /// Temperatures of the settled levels (≥ 20 min), °C, ascending.
    pub levels_c: Vec<f64>,
    /// Per filter, fastest to slowest.
    pub rates: Vec<RateCoverage>,
    /// Settled stretches at least [`LONG_HOLD_S`] long.
    pub long_holds: usize,
    /// Thermal events the event folds found.
    pub events: usize,
    /// Loop temperature at the power-on of the coldest run that starts cold and holds, °C.
    pub cold_start_c: Option<f64>,
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
                && rates[i][settle_filter].abs() < SETTLED_C_PER_MIN
                && start.is_none_or(|s| run[s] == run[i]);
            match (settled, start) {
                (true, None) => start = Some(i),
                (false, Some(s)) => {
                    stretches.push((s, i));
                    start = (i < temp_c.len() && rates[i][settle_filter].abs() < SETTLED_C_PER_MIN).then_some(i);
                }
                _ => {}
            }
        }
        let len_s = |&(s, e): &(usize, usize)| (e - s) as f64 * mean_s;
        let mut levels_c: Vec<f64> = stretches
            .iter()
            .filter(|st| len_s(st) >= LEVEL_S)
            .map(|&(s, e)| temp_c[s..e].iter().sum::<f64>() / (e - s) as f64)
            .collect();
        levels_c.sort_by(f64::total_cmp);
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
            levels_c,
            rates: rate_cov,
            long_holds,
            events,
            cold_start_c,
        }
    }

    /// What the lag bank needs and these runs lack, in words an engineer acts on.
    pub fn missing(&self) -> Vec<String> {
        let mut out = Vec::new();
        let (lo, hi) = self.temp_range_c;
        // Gaps: from the range's ends to the nearest level and between levels.
        let mut edges = vec![lo];
        edges.extend(&self.levels_c);
        edges.push(hi);
        let gaps: Vec<String> = edges
            .windows(2)
            .filter(|w| w[1] - w[0] > LEVEL_GAP_C)
            .map(|w| format!("{:.0} … {:.0} °C", w[0], w[1]))
            .collect();
        if self.levels_c.is_empty() {
            out.push(format!(
                "no settled level (a hold of {:.0} min): the static curve is read only during ramps; hold at several temperatures",
                LEVEL_S / 60.0
            ));
        } else if !gaps.is_empty() {
            out.push(format!(
                "no settled level in {}: hold there for {:.0} min or more",
                gaps.join(", "),
                LEVEL_S / 60.0
            ));
        }
        if let Some(fast) = self.rates.first() {
            if fast.max_c_per_min.max(-fast.min_c_per_min) < FAST_C_PER_MIN {
                out.push(format!(
                    "no fast change: the sensor never moved faster than {:.1} °C/min (τ {:.0} s); in use, steps and swings do; ramp at the chamber's full rate",
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
        if self.long_holds == 0 {
            out.push(format!(
                "no hold of {:.0} min: the slowest lags are not told apart from the static curve; hold that long at least once after a fast change",
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

    /// The coverage in a few lines, then what is missing.
    pub fn lines(&self) -> Vec<String> {
        let levels: Vec<String> = self.levels_c.iter().map(|l| format!("{l:.0}")).collect();
        let rates: Vec<String> = self
            .rates
            .iter()
            .map(|r| format!("{:.0} s {:+.1}/{:+.1}", r.tau_s, r.min_c_per_min, r.max_c_per_min))
            .collect();
        let mut out = vec![
            format!(
                "coverage: T {:.1} … {:.1} °C; settled levels [{}] °C; {} thermal events; {} holds ≥ {:.0} min; {}",
                self.temp_range_c.0,
                self.temp_range_c.1,
                levels.join(", "),
                self.events,
                self.long_holds,
                LONG_HOLD_S / 60.0,
                match self.cold_start_c {
                    Some(c) => format!("cold start at {c:.1} °C"),
                    None => "no cold start".to_owned(),
                }
            ),
            format!("coverage: fastest fall/rise per filter [°C/min]: {}", rates.join(", ")),
        ];
        let missing = self.missing();
        if missing.is_empty() {
            out.push("missing: nothing the lag bank needs".to_owned());
        } else {
            out.extend(missing.into_iter().map(|m| format!("missing: {m}")));
        }
        out
    }
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
        // 20 °C, 1 °C/min to −40, hold 2 h, to 60, hold 2 h, back to 20.
        let c = coverage(
            20.0,
            &[
                (3600.0, 0.0),
                (3600.0, -1.0),
                (7200.0, 0.0),
                (6000.0, 1.0),
                (7200.0, 0.0),
                (2400.0, -1.0),
            ],
            3,
        );
        let missing = c.missing().join("\n");
        assert!(missing.contains("no fast change"), "{missing}");
        assert!(missing.contains("no cold start"), "{missing}");
        assert!(missing.contains("only 3 thermal events"), "{missing}");
        assert!(
            missing.contains("no settled level in -40 … 20 °C, 20 … 60 °C"),
            "{missing}"
        );
        assert!(!missing.contains("no hold of"), "{missing}");
        assert_eq!(c.long_holds, 2);
    }

    #[test]
    fn a_planned_run_with_a_cold_start_and_fast_steps_misses_nothing() {
        let c = coverage(
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
        assert_eq!(c.missing(), Vec::<String>::new(), "{:?}", c.lines());
        assert_eq!(c.cold_start_c, Some(-40.0));
        assert!(c.lines().last().unwrap().contains("nothing the lag bank needs"));
    }
}
