//! How much the response bank's regression weighs the blocks of the training
//! runs' settled levels (issue 48: the settled bias a soak test reads).
//!
//! The regression fits every 10-s block alike, so a chamber run's ramps
//! outnumber its holds and decide the static curve wherever the slow
//! responses can trade with it. Where the runs hold a settled level in every
//! 20-°C band of the range they cover (the 24-h plan's band soaks, or a soak
//! test fitted beside a plan), those levels pin the whole curve, and their
//! blocks (each plateau's 30-min window by the soak rule of `eval`,
//! [`crate::dataset::plateaus`]) count [`SETTLED_BLOCK_WEIGHT`] times. Where
//! they hold only the ends (the 12-h plan's cold start and hot-end soak), every
//! block counts once: weighed there, the ends pulled the curve against what
//! the ramps say of the middle.
//!
//! Measured 2026-12-01 with `bench/accuracy/soak_sweep.py` (25 plants, the
//! default plans of seeds 1–8, two soak tests each read less their noise-only
//! twin; docs/decisions.md, "Settled levels weighed where they span the
//! range"): weighing every plateau, whatever the bands, 3× / 10× / 30× put the
//! model's own soak error within 0.01 °/h after the 24-h plan on 48 / 53 / 48
//! instead of 42 of 160 bench trainings and 23 / 28 / 25 instead of 21 of 40
//! fast-twin ones, the in-use mean unchanged (95.3 / 96.5 %); after the
//! 12-h plan 10× lost (within 0.03 °/h: 50 → 47 bench, 21 → 17 fast twins).

use super::coverage::{USE_REACH_SHARE, bands_without_level_c};
use crate::dataset::plateaus::settled_windows;

/// How many times a settled block counts in the regression, where the runs'
/// settled levels span every 20-°C band (see the module documentation).
pub const SETTLED_BLOCK_WEIGHT: f64 = 10.0;

/// The weight of each block in the regression: [`SETTLED_BLOCK_WEIGHT`] in a
/// settled plateau's window where the runs' settled levels leave no 20-°C
/// band of their covered range without one, 1 elsewhere. The blocks are
/// given by their start `time_s` on their run's clock (s), their mean loop
/// temperature `temp_c` (°C) and their `run` (consecutive blocks of a run
/// together), each `block_s` long.
pub fn settled_block_weights(time_s: &[f64], temp_c: &[f64], run: &[usize], block_s: f64) -> Vec<f64> {
    let mut weight = vec![1.0; time_s.len()];
    let windows = settled_windows(time_s, temp_c, run, block_s);
    let levels: Vec<f64> = windows.iter().map(|w| w.temp_c).collect();
    let (lo, hi) = temp_c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &t| {
        (lo.min(t), hi.max(t))
    });
    if windows.is_empty() || !bands_without_level_c(&levels, lo, hi, USE_REACH_SHARE * (hi - lo)).is_empty() {
        return weight;
    }
    for ((w, &t), &r) in weight.iter_mut().zip(time_s).zip(run) {
        if windows.iter().any(|p| p.run == r && t >= p.start_s && t < p.end_s) {
            *w = SETTLED_BLOCK_WEIGHT;
        }
    }
    weight
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 10-s blocks of one run that holds each of `levels_c` for `hold_s`,
    /// 1 °C/min between them.
    fn held(levels_c: &[f64], hold_s: f64) -> (Vec<f64>, Vec<f64>) {
        let (mut time_s, mut temp_c) = (Vec::new(), Vec::new());
        let mut t = 0.0;
        let mut at = levels_c[0];
        for &level in levels_c {
            while (level - at).abs() > 1e-9 {
                at += (level - at).clamp(-1.0 / 6.0, 1.0 / 6.0);
                time_s.push(t);
                temp_c.push(at);
                t += 10.0;
            }
            let end = t + hold_s;
            while t < end {
                time_s.push(t);
                temp_c.push(level);
                t += 10.0;
            }
        }
        (time_s, temp_c)
    }

    #[test]
    fn settled_blocks_count_more_only_where_the_levels_span_every_band() {
        // Five 2-h holds 25 °C apart over -40 ... 60 °C: a level in every band.
        let (time_s, temp_c) = held(&[-40.0, -15.0, 10.0, 35.0, 60.0], 7200.0);
        let run = vec![0; time_s.len()];
        let w = settled_block_weights(&time_s, &temp_c, &run, 10.0);
        let is = |w: f64, v: f64| w.to_bits() == v.to_bits();
        let heavy = w.iter().filter(|&&w| is(w, SETTLED_BLOCK_WEIGHT)).count();
        // Each hold's 30-min window: 180 blocks of 10 s.
        assert_eq!(heavy, 5 * 180, "{heavy}");
        assert!(w.iter().all(|&w| is(w, 1.0) || is(w, SETTLED_BLOCK_WEIGHT)));
        // The last window ends with its hold: its blocks are the run's last 180.
        assert!(w[w.len() - 180..].iter().all(|&w| is(w, SETTLED_BLOCK_WEIGHT)));
        assert!(is(w[w.len() - 181], 1.0));

        // Only the ends held: the middle bands hold no level, every block counts once.
        let (time_s, temp_c) = held(&[-40.0, 60.0], 7200.0);
        let run = vec![0; time_s.len()];
        let w = settled_block_weights(&time_s, &temp_c, &run, 10.0);
        assert!(w.iter().all(|&w| is(w, 1.0)));
    }
}
