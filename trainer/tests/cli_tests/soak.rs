//! The soak test end to end: `simulate --profile soak` → `compensate` →
//! `eval --json`, the settled spread checked against plain arithmetic over
//! the compensated CSV (the rule of `trainer::dataset::plateaus`, written
//! out again here without the library).

use std::collections::BTreeMap;

use tempfile::TempDir;

use crate::common::{compensate, eval_json, fitted_model, simulated, stderr, trainer};

/// The soak profile's default levels, °C.
const LEVELS_C: [f64; 8] = [25.0, 0.0, 40.0, -20.0, 60.0, 20.0, -40.0, 10.0];

/// Settled plateaus of (time s, loop °C, residual °/h, input clamped 0/1)
/// rows sampled every `period_s`: (loop temperature °C, settled bias °/h,
/// share of the window clamped %) per plateau.
fn plateaus_by_hand(rows: &[Row], period_s: f64) -> Vec<(f64, f64, f64)> {
    // 60-s blocks from the first sample: (samples, Σ temp, Σ residual, gap).
    let t0 = rows[0].0;
    let mut blocks: BTreeMap<u64, (f64, f64, f64, bool)> = BTreeMap::new();
    let mut clamped: BTreeMap<u64, f64> = BTreeMap::new();
    let mut previous_t = f64::NAN;
    for &(t, temp, residual, clamp) in rows {
        let gap = t - previous_t > 2.0 * period_s;
        previous_t = t;
        let minute = ((t - t0) / 60.0).floor() as u64;
        *clamped.entry(minute).or_default() += clamp;
        let b = blocks.entry(minute).or_default();
        b.0 += 1.0;
        b.1 += temp;
        b.2 += residual;
        b.3 |= gap;
    }
    // Minute by minute from the first block: (Σ temp, Σ residual, samples) of the complete ones.
    let minutes = *blocks.keys().last().unwrap() as usize + 1;
    let mut at: Vec<Option<(f64, f64, f64)>> = vec![None; minutes];
    for (&m, b) in &blocks {
        if !b.3 && b.0 >= 0.5 * 60.0 / period_s {
            at[m as usize] = Some((b.1, b.2, b.0));
        }
    }
    let temp = |m: usize| at[m].map(|b| b.0 / b.2);
    let whole = |from: usize, to: usize| (from..=to).all(|m| at[m].is_some());
    // Steady: the loop moved ≤ 1.5 °C over the 10 minutes before, all complete.
    let steady: Vec<bool> = (0..minutes)
        .map(|k| k >= 10 && whole(k - 10, k) && (temp(k).unwrap() - temp(k - 10).unwrap()).abs() <= 1.5)
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < minutes {
        if !steady[i] {
            i += 1;
            continue;
        }
        let mut j = i;
        while j + 1 < minutes && steady[j + 1] {
            j += 1;
        }
        // The loop departs where it lies 0.015 °C off the line through its
        // last 10 min and twice as far as the least of the 5 min before. It
        // began to where the minutes before lie 0.003 °C off theirs and each
        // farther than the last (10 min back at most); the hold ends a minute
        // before that. No departure: the stretch's end, less 15 min where the
        // loop moved on.
        let off = |k: usize| {
            whole(k - 11, k).then(|| {
                (temp(k).unwrap() - (temp(k - 1).unwrap() + (temp(k - 1).unwrap() - temp(k - 11).unwrap()) / 10.0))
                    .abs()
            })
        };
        let mut departure = None;
        for k in i + 16..=(j + 10).min(minutes - 1) {
            let Some(now) = off(k) else { break };
            let Some(least) = (k - 5..k).map(off).try_fold(f64::INFINITY, |m, o| o.map(|o| m.min(o))) else {
                break;
            };
            if now > 0.015 && now > 2.0 * least {
                departure = Some(k);
                break;
            }
        }
        let onset = departure.map(|k| {
            let mut o = k;
            while o > i + 1 && o + 10 > k && matches!((off(o - 1), off(o)), (Some(b), Some(n)) if b > 0.003 && b < n) {
                o -= 1;
            }
            o
        });
        let moved_on = j + 1 < minutes && whole(j - 9, j + 1);
        let end = match onset {
            Some(o) => o as i64 - 2,
            None if moved_on => j as i64 - 15,
            None => j as i64,
        };
        if end - i as i64 + 1 >= 30 {
            let window = (end - 29) as usize..=end as usize;
            let (t, r, n) = window
                .clone()
                .filter_map(|m| at[m])
                .fold((0.0, 0.0, 0.0), |s, b| (s.0 + b.0, s.1 + b.1, s.2 + b.2));
            let c: f64 = window.map(|m| clamped[&(m as u64)]).sum();
            out.push((t / n, r / n, 100.0 * c / n));
        }
        i = departure.unwrap_or(j) + 1;
    }
    out
}

/// One compensated sample: time s, loop °C, rate_comp − ref °/h, 1 where its
/// model inputs were clamped to the training range (flag 1), else 0.
type Row = (f64, f64, f64, f64);

/// The rows of a compensated CSV at `path`.
fn compensated_rows(path: &std::path::Path) -> Vec<Row> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t, temp, rate_comp, reference, flags) = (
        col("time_s"),
        col("temp_c"),
        col("rate_comp_dph"),
        col("ref_dph"),
        col("flags"),
    );
    lines
        .map(|l| {
            let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            (f[t], f[temp], f[rate_comp] - f[reference], (f[flags] as u8 & 1) as f64)
        })
        .collect()
}

/// Max − min of `values`.
fn spread(values: &[f64]) -> f64 {
    values.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - values.iter().cloned().fold(f64::INFINITY, f64::min)
}

#[test]
fn a_soak_run_has_8_plateaus_at_its_levels_and_eval_s_settled_spread_is_the_arithmetic_one() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let soak = dir.path().join("soak.csv");
    simulated(&soak, &["--profile", "soak", "--seed", "3"]);
    let out = dir.path().join("soak-comp.csv");
    let o = compensate(&model, &soak, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let json = dir.path().join("eval.json");
    let o = trainer(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        soak.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        printed.contains("settled spread (max − min over 8 plateaus)"),
        "{printed}"
    );

    // The compensated CSV, by hand.
    let rows = compensated_rows(&out);
    let period_s = (rows.last().unwrap().0 - rows[0].0) / (rows.len() - 1) as f64;
    let by_hand = plateaus_by_hand(&rows, period_s);
    assert_eq!(by_hand.len(), 8, "{by_hand:?}");

    let v = crate::common::read_json(json);
    let plateaus = v[0]["plateaus"].as_array().unwrap();
    assert_eq!(plateaus.len(), 8, "{plateaus:#?}");
    for ((p, &(temp_c, bias_dph, clamped_pct)), level) in plateaus.iter().zip(&by_hand).zip(LEVELS_C) {
        let eval_temp = p["temp_c"].as_f64().unwrap();
        assert!((eval_temp - temp_c).abs() < 1e-9, "{p}: by hand {temp_c} °C");
        // The loop settles near the chamber: above it by the self-heating,
        // short of the far levels by what it still lags after 3 h (−36.5 °C
        // at −40, 57.8 at 60 on the documented gyro).
        assert!((eval_temp - level).abs() < 4.5, "{p} at {level} °C");
        // rate_comp_dph written in decimal: the sums agree to 1e-6 °/h.
        assert!(
            (p["bias_after_dph"].as_f64().unwrap() - bias_dph).abs() < 1e-6,
            "{p}: by hand {bias_dph}"
        );
        assert!(p["noise_dph"].as_f64().unwrap() > 0.0, "{p}");
        assert!(
            (p["outside_range_pct"].as_f64().unwrap() - clamped_pct).abs() < 1e-9,
            "{p}: by hand {clamped_pct} % of the window clamped"
        );
        let (start, end) = (
            p["window_start_s"].as_f64().unwrap(),
            p["window_end_s"].as_f64().unwrap(),
        );
        assert!((end - start - 1800.0).abs() < 1e-9, "{p}");
        assert!(p["steady_s"].as_f64().unwrap() >= 1800.0, "{p}");
    }
    let biases: Vec<f64> = by_hand.iter().map(|p| p.1).collect();
    let by_hand_spread = spread(&biases);
    let reported = v[0]["settled_spread_dph"].as_f64().unwrap();
    assert!(
        (reported - by_hand_spread).abs() < 1e-6,
        "eval {reported}, by hand {by_hand_spread}"
    );
    // The short training run leaves the soak's far levels outside its range.
    let inside: Vec<f64> = by_hand.iter().filter(|p| p.2 < 50.0).map(|p| p.1).collect();
    assert!(inside.len() >= 2 && inside.len() < 8, "{by_hand:?}");
    let in_range = v[0]["settled_spread_in_range_dph"].as_f64().unwrap();
    assert!(
        (in_range - spread(&inside)).abs() < 1e-6,
        "eval {in_range}, by hand {}",
        spread(&inside)
    );
    let before = v[0]["settled_spread_before_dph"].as_f64().unwrap();
    assert!(
        before > reported,
        "compensation narrows the spread: {before} → {reported}"
    );
}

#[test]
fn a_run_without_holds_has_a_null_spread_and_says_so() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("swings.csv");
    simulated(&run, &["--profile", "swings", "--hours", "2"]);
    let o = trainer(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--json",
        "-",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(v[0]["settled_spread_dph"].is_null(), "{}", v[0]);
    assert!(v[0]["plateaus"].as_array().is_some_and(|p| p.len() < 2), "{}", v[0]);
    let text = stderr(&o);
    assert!(
        text.contains("no settled plateau (the loop never steady for 30 min)") || text.contains("one settled plateau"),
        "{text}"
    );
}

#[test]
fn soak_levels_and_hold_set_the_plateaus_and_need_the_soak_profile() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("soak2.csv");
    let path = run.to_str().unwrap();
    let o = trainer(&["simulate", "--soak-levels-c", "-10,30", "-o", path]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("--profile soak"), "{}", stderr(&o));
    let o = trainer(&[
        "simulate",
        "--profile",
        "soak",
        "--soak-levels-c",
        "30,20,25",
        "--soak-hold-h",
        "2",
        "-o",
        path,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = eval_json(model.to_str().unwrap(), path);
    let temps: Vec<f64> = v[0]["plateaus"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["temp_c"].as_f64().unwrap())
        .collect();
    assert_eq!(temps.len(), 3, "{temps:?}");
    assert!(
        temps[1] < temps[2] && temps[2] < temps[0],
        "in the asked order: {temps:?}"
    );
    assert!(
        temps
            .iter()
            .zip([30.0, 20.0, 25.0])
            .all(|(t, level)| (t - level).abs() < 3.0),
        "{temps:?}"
    );
}

#[test]
fn a_fit_on_a_run_settled_in_every_band_forecasts_a_soak_s_spread_as_its_own_levels_and_eval_agrees() {
    // Three 2-h holds settle the loop in every 20-°C band the run covers: the
    // runs' own settled spread, with eight levels' noise in quadrature, is
    // then the forecast of a soak test's (the planned run without it keeps it
    // null: `plan::a_plan_runs_through_the_simulator_and_a_fit_reports_its_coverage`).
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("soak3.csv");
    let path = run.to_str().unwrap();
    let o = trainer(&[
        "simulate",
        "--profile",
        "soak",
        "--soak-levels-c",
        "30,0,50",
        "--soak-hold-h",
        "2",
        "--sample-rate-hz",
        "1",
        "-o",
        path,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let model = dir.path().join("soak3.bin");
    let fit_json = dir.path().join("fit.json");
    let o = trainer(&[
        "fit",
        path,
        "-o",
        model.to_str().unwrap(),
        "--json",
        fit_json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        printed.contains("settled: the training run's own 3 settled levels")
            && printed.contains("a soak test of this unit is forecast to read"),
        "{printed}"
    );
    let fit = crate::common::read_json(&fit_json);
    assert_eq!(fit["training_settled_levels"], 3, "{fit}");
    let floor = fit["training_settled_spread_dph"].as_f64().unwrap();
    let level_noise = fit["training_settled_noise_dph"].as_f64().unwrap();
    assert!(level_noise > 0.0, "{fit}");
    let forecast = fit["predicted_settled_spread_dph"].as_f64().unwrap();
    // The documented gyro takes the lag bank here, whose own spread counts as
    // it is (a response bank that weighed its levels takes it
    // `WEIGHED_RESPONSE_BANK_FLOOR_FACTOR` times: vouch's unit tests).
    assert_eq!(fit["structure"]["response_bank"], false, "{fit}");
    let expected = floor.hypot(::trainer::fit::vouch::SOAK_NOISE_RANGE_SD * level_noise);
    assert!(
        (forecast - expected).abs() <= 1e-12 * expected && forecast > floor,
        "forecast {forecast}, floor {floor} with eight levels' noise {expected}"
    );
    assert!(
        fit["settled_forecast"]
            .as_str()
            .unwrap()
            .starts_with("forecast: the runs hold a settled level in every 20-°C band"),
        "{fit}"
    );
    assert!(fit["residual_over_noise_floor"].as_f64().unwrap() > 0.0, "{fit}");

    // `eval` of the same model on the same run reads the same spread.
    let v = eval_json(model.to_str().unwrap(), path);
    let eval_spread = v[0]["settled_spread_dph"].as_f64().unwrap();
    assert!((eval_spread - floor).abs() < 1e-12, "fit {floor}, eval {eval_spread}");
}

#[test]
fn eval_s_settled_spread_agrees_with_the_chamber_s_clock_through_a_lagging_loop() {
    // A soak of other levels and order on `--unit 1`, whose loop shows a
    // ramp minutes late: each hold's window must end within a few minutes of
    // the chamber's hold end (not in the next ramp), and the spread must be
    // the one read over each hold's last 30 min by the chamber's clock, to
    // within the noise of the plateaus' means.
    const LEVELS: [f64; 4] = [15.0, 35.0, 20.0, 30.0];
    const HOLD_S: f64 = 3.0 * 3600.0;
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let soak = dir.path().join("soak.csv");
    simulated(
        &soak,
        &[
            "--unit",
            "1",
            "--profile",
            "soak",
            "--soak-levels-c",
            "15,35,20,30",
            "--seed",
            "5",
        ],
    );
    let out = dir.path().join("soak-comp.csv");
    let o = compensate(&model, &soak, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = compensated_rows(&out);
    // The chamber's hold ends: a hold, then 1 °C/min to the next level and its hold.
    let mut hold_ends_s = vec![HOLD_S];
    for pair in LEVELS.windows(2) {
        let last = *hold_ends_s.last().unwrap();
        hold_ends_s.push(last + (pair[1] - pair[0]).abs() * 60.0 + HOLD_S);
    }
    let clock: Vec<f64> = hold_ends_s
        .iter()
        .map(|&end| {
            let window: Vec<f64> = rows
                .iter()
                .filter(|r| r.0 >= end - 1800.0 && r.0 < end)
                .map(|r| r.2)
                .collect();
            window.iter().sum::<f64>() / window.len() as f64
        })
        .collect();

    let v = eval_json(model.to_str().unwrap(), soak.to_str().unwrap());
    let plateaus = v[0]["plateaus"].as_array().unwrap();
    assert_eq!(plateaus.len(), LEVELS.len(), "{plateaus:#?}");
    for (p, end) in plateaus.iter().zip(&hold_ends_s) {
        let window_end = p["window_end_s"].as_f64().unwrap();
        assert!(
            window_end >= end - 180.0 && window_end <= end + 120.0,
            "window ends at {window_end} s, the chamber's hold at {end} s: {p}"
        );
    }
    let noise = plateaus
        .iter()
        .map(|p| p["noise_dph"].as_f64().unwrap())
        .fold(0.0, f64::max);
    let reported = v[0]["settled_spread_dph"].as_f64().unwrap();
    let by_clock = spread(&clock);
    assert!(
        (reported - by_clock).abs() <= 2.0 * noise,
        "eval {reported} °/h, the chamber's clock {by_clock} °/h, a plateau's noise up to {noise} °/h"
    );
}
