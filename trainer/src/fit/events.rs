//! Validation folds that hold out whole thermal events.
//!
//! A model is used on temperature histories it never saw, so it is chosen by
//! how well it predicts a part of the training data it was not fitted on.
//! Neighbouring samples are nearly the same sample, and a ramp is explained
//! by its own hold, so the held-out parts are whole thermal events: a change
//! of temperature (ramp or step) with the hold that follows it. With several
//! training runs each run is a fold of its own (leave one run out): the
//! closest thing to a history the model has not seen.

/// Smoothing of the loop temperature before its rate is judged, s.
const SMOOTHING_S: f64 = 300.0;
/// A rate above this, °C/min, is a temperature change; below, a hold.
const MOVING_C_PER_MIN: f64 = 0.05;
/// Most folds leave-one-run-out makes (runs beyond it share folds).
pub const MAX_RUN_FOLDS: usize = 10;

/// Length of the means a held-out score is taken on, s: the cluster of the
/// 100-s cluster STD the in-use histories are judged by.
pub const SCORE_MEAN_S: f64 = crate::metrics::CLUSTER_S;

/// RMS of the [`SCORE_MEAN_S`] means of a residual over held-out rows, the
/// mean of each run removed: what the cluster STD of an unseen history
/// would see. `held[f]` are the rows fold `f` held out (ascending; a mean
/// never spans a break in them or two runs, and one with under half its
/// rows is dropped), `residual(f, row)` the residual there of the model
/// fitted without them. Rows are `row_s` apart; infinite below three means.
pub fn held_out_rms(held: &[&[usize]], run: &[usize], row_s: f64, residual: impl Fn(usize, usize) -> f64) -> f64 {
    let per_mean = (SCORE_MEAN_S / row_s).round().max(1.0) as usize;
    let mut means: Vec<(usize, f64)> = Vec::new();
    for (fold, rows) in held.iter().enumerate() {
        let mut chunk: Vec<usize> = Vec::new();
        let mut flush = |chunk: &mut Vec<usize>| {
            if chunk.len() * 2 >= per_mean {
                let r = chunk.iter().map(|&i| residual(fold, i)).sum::<f64>() / chunk.len() as f64;
                means.push((run[chunk[0]], r));
            }
            chunk.clear();
        };
        for &i in rows.iter() {
            let contiguous = chunk.last().is_none_or(|&l| l + 1 == i && run[l] == run[i]);
            if !contiguous || chunk.len() == per_mean {
                flush(&mut chunk);
            }
            chunk.push(i);
        }
        flush(&mut chunk);
    }
    let runs = means.iter().map(|m| m.0).max().map_or(0, |m| m + 1);
    let mut sse = 0.0;
    for r in 0..runs {
        let vals: Vec<f64> = means.iter().filter(|m| m.0 == r).map(|m| m.1).collect();
        if vals.is_empty() {
            continue;
        }
        let mean = vals.iter().sum::<f64>() / vals.len() as f64;
        sse += vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    }
    if means.len() < 3 {
        f64::INFINITY
    } else {
        (sse / means.len() as f64).sqrt()
    }
}

/// How the training blocks were split for validation.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub enum FoldKind {
    /// One fold per training run (leave one run out).
    Runs,
    /// Whole thermal events of each run held out in turn.
    Events,
    /// Contiguous stretches (a run without enough distinct events).
    Contiguous,
}

/// The validation split of some training rows: `folds[f]` are the rows held
/// out in fold `f`, in ascending order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Folds {
    /// Held-out rows per fold.
    pub held_out: Vec<Vec<usize>>,
    /// How they were made.
    pub kind: FoldKind,
    /// Thermal events found (over all runs).
    pub events: usize,
}

impl Folds {
    /// The rows fold `f` trains on: every row not held out in it.
    pub fn train_rows(&self, f: usize, rows: usize) -> Vec<usize> {
        let mut held = vec![false; rows];
        for &i in self.held_out.get(f).map_or(&[][..], Vec::as_slice) {
            if let Some(h) = held.get_mut(i) {
                *h = true;
            }
        }
        (0..rows).filter(|&i| !held[i]).collect()
    }
}

/// Folds over rows of loop temperature `temp_c` (one row per `row_s`
/// seconds, in time order within each run) from runs `run`: one per run when
/// there are several, else `folds` groups of whole thermal events.
pub fn thermal_folds(temp_c: &[f64], run: &[usize], row_s: f64, folds: usize) -> Folds {
    let runs = run.iter().max().map_or(0, |m| m + 1);
    let per_run: Vec<Vec<usize>> = (0..runs)
        .map(|r| (0..run.len()).filter(|&i| run[i] == r).collect())
        .filter(|rows: &Vec<usize>| !rows.is_empty())
        .collect();
    let event_starts: Vec<Vec<usize>> = per_run
        .iter()
        .map(|rows| {
            let temps: Vec<f64> = rows.iter().map(|&i| temp_c[i]).collect();
            event_starts(&temps, row_s)
        })
        .collect();
    let events = event_starts.iter().map(Vec::len).sum();
    if per_run.len() >= 2 {
        let n = per_run.len().min(MAX_RUN_FOLDS);
        let mut held_out = vec![Vec::new(); n];
        for (r, rows) in per_run.iter().enumerate() {
            held_out[r % n].extend_from_slice(rows);
        }
        held_out.iter_mut().for_each(|h| h.sort_unstable());
        return Folds {
            held_out,
            kind: FoldKind::Runs,
            events,
        };
    }
    let folds = folds.max(2);
    let Some(rows) = per_run.first() else {
        return Folds {
            held_out: Vec::new(),
            kind: FoldKind::Contiguous,
            events,
        };
    };
    let starts = &event_starts[0];
    if starts.len() >= folds {
        // Consecutive events grouped into folds of about equal duration.
        let mut held_out = vec![Vec::new(); folds];
        let bounds: Vec<usize> = starts.iter().copied().chain(std::iter::once(rows.len())).collect();
        for pair in bounds.windows(2) {
            let (lo, hi) = (pair[0], pair[1]);
            // By the event's middle: consecutive events, folds in time order.
            let f = ((lo + hi) / 2 * folds / rows.len()).min(folds - 1);
            held_out[f].extend_from_slice(&rows[lo..hi]);
        }
        // The stretch before the first event (the initial hold) joins the first fold.
        if let Some(&first) = starts.first() {
            held_out[0].extend_from_slice(&rows[..first]);
            held_out[0].sort_unstable();
        }
        held_out.retain(|h| !h.is_empty());
        if held_out.len() >= 2 {
            return Folds {
                held_out,
                kind: FoldKind::Events,
                events,
            };
        }
    }
    let held_out = (0..folds)
        .map(|f| rows[f * rows.len() / folds..(f + 1) * rows.len() / folds].to_vec())
        .filter(|h: &Vec<usize>| !h.is_empty())
        .collect();
    Folds {
        held_out,
        kind: FoldKind::Contiguous,
        events,
    }
}

/// Indices (into `temp_c`) where thermal events start: the first row of each
/// temperature change that follows a hold, the temperature smoothed over
/// [`SMOOTHING_S`] first so that sensor noise is no event.
fn event_starts(temp_c: &[f64], row_s: f64) -> Vec<usize> {
    if temp_c.is_empty() || row_s.is_nan() || row_s <= 0.0 {
        return Vec::new();
    }
    let alpha = (row_s / SMOOTHING_S).min(1.0);
    let mut smooth = temp_c[0];
    let mut previous = smooth;
    let mut starts = Vec::new();
    let mut moving = false;
    // A change must last a minute to count (not a sensor glitch).
    let confirm_rows = ((60.0 / row_s).ceil() as usize).max(1);
    let mut candidate: Option<(usize, usize)> = None;
    for (i, &t) in temp_c.iter().enumerate() {
        smooth += alpha * (t - smooth);
        let rate_c_per_min = (smooth - previous) / row_s * 60.0;
        previous = smooth;
        let now_moving = rate_c_per_min.abs() > MOVING_C_PER_MIN;
        match (moving, now_moving, candidate) {
            (false, true, None) => candidate = Some((i, 1)),
            (false, true, Some((start, n))) => {
                if n + 1 >= confirm_rows {
                    starts.push(start);
                    moving = true;
                    candidate = None;
                } else {
                    candidate = Some((start, n + 1));
                }
            }
            (false, false, _) => candidate = None,
            (true, false, _) => moving = false,
            (true, true, _) => {}
        }
    }
    starts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 1-s rows of a profile: holds and ramps (°C, minutes).
    fn profile(steps: &[(f64, f64)], start_c: f64) -> Vec<f64> {
        let mut t = vec![start_c; 1800];
        let mut cur = start_c;
        for &(target, hold_min) in steps {
            let n = ((target - cur).abs() * 60.0) as usize; // 1 °C/min
            t.extend((1..=n).map(|i| cur + (target - cur) * i as f64 / n as f64));
            t.extend(std::iter::repeat_n(target, (hold_min * 60.0) as usize));
            cur = target;
        }
        t
    }

    #[test]
    fn every_ramp_after_a_hold_starts_an_event() {
        let t = profile(&[(-20.0, 60.0), (40.0, 60.0), (10.0, 60.0)], 20.0);
        let starts = event_starts(&t, 1.0);
        assert_eq!(starts.len(), 3, "{starts:?}");
        // Each found within two minutes of the ramp's start.
        for (s, expected) in starts.iter().zip([1800, 1800 + 2400 + 3600, 1800 + 6000 + 3600 + 3600]) {
            assert!(s.abs_diff(expected) < 120, "{s} vs {expected}");
        }
    }

    #[test]
    fn a_single_run_is_split_into_whole_events() {
        let t = profile(
            &[(-20.0, 60.0), (40.0, 60.0), (10.0, 60.0), (30.0, 60.0), (0.0, 60.0)],
            20.0,
        );
        let folds = thermal_folds(&t, &vec![0; t.len()], 1.0, 5);
        assert_eq!(folds.kind, FoldKind::Events);
        assert_eq!(folds.events, 5);
        assert_eq!(folds.held_out.len(), 5);
        let all: usize = folds.held_out.iter().map(Vec::len).sum();
        assert_eq!(all, t.len(), "every row is held out exactly once");
        // The ramp to 40 °C (two minutes in: detection lags by the smoothing) and its hold are held out together.
        let ramp_start = 1800 + 2400 + 3600 + 120;
        let fold = folds.held_out.iter().position(|h| h.contains(&ramp_start)).unwrap();
        assert!(folds.held_out[fold].contains(&(ramp_start + 60 * 60 + 3000)));
        let train = folds.train_rows(fold, t.len());
        assert_eq!(train.len() + folds.held_out[fold].len(), t.len());
    }

    #[test]
    fn several_runs_are_left_out_one_at_a_time() {
        let t: Vec<f64> = (0..300).map(|i| i as f64).collect();
        let run: Vec<usize> = (0..300).map(|i| i / 100).collect();
        let folds = thermal_folds(&t, &run, 1.0, 5);
        assert_eq!(folds.kind, FoldKind::Runs);
        assert_eq!(
            folds.held_out,
            vec![(0..100).collect::<Vec<_>>(), (100..200).collect(), (200..300).collect()]
        );
    }

    #[test]
    fn a_run_without_enough_events_falls_back_to_contiguous_folds() {
        let t = profile(&[(40.0, 120.0)], 20.0);
        let folds = thermal_folds(&t, &vec![0; t.len()], 1.0, 4);
        assert_eq!(folds.kind, FoldKind::Contiguous);
        assert_eq!(folds.held_out.len(), 4);
        assert_eq!(folds.held_out[0][0], 0);
    }
}
