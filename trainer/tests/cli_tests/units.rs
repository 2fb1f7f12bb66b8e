//! Inputs wrong in a way the reader cannot see line by line (issue 49, item
//! 11): a run listed twice under any role, a rate or a time column in other
//! units, options the fit would ignore. Every command that reads a run
//! refuses them with the reason.

use crate::common::{fitted_model, stderr, trainer, write};
use tempfile::TempDir;

/// The fixture's training run with each data row's fields changed by `edit`
/// (index of the row, header names, fields).
fn rewritten(dir: &TempDir, name: &str, edit: impl Fn(usize, &[&str], &mut Vec<String>)) -> std::path::PathBuf {
    let text = std::fs::read_to_string(dir.path().join("train.csv")).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let mut out = header.join(",") + "\n";
    for (i, line) in lines.enumerate() {
        let mut fields: Vec<String> = line.split(',').map(str::to_owned).collect();
        edit(i, &header, &mut fields);
        out += &(fields.join(",") + "\n");
    }
    write(dir, name, out.as_bytes())
}

/// Runs `eval`, `compensate` and `fit` on `run` and asserts each refuses it
/// with a message holding `expected`.
fn every_command_refuses(dir: &TempDir, model: &std::path::Path, run: &std::path::Path, expected: &str) {
    let (m, r) = (model.to_str().unwrap(), run.to_str().unwrap());
    let out = dir.path().join("out.csv");
    let fitted = dir.path().join("refit.bin");
    for args in [
        vec!["eval", "--model", m, r],
        vec!["compensate", "--model", m, r, "-o", out.to_str().unwrap()],
        vec!["fit", "-q", r, "-o", fitted.to_str().unwrap()],
    ] {
        let o = trainer(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expected), "{args:?}: {}", stderr(&o));
        assert!(!out.exists() && !fitted.exists());
    }
}

#[test]
fn a_rate_in_rad_per_s_beside_a_reference_in_deg_per_h_is_refused_everywhere() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = rewritten(&dir, "rads.csv", |_, header, fields| {
        let i = header.iter().position(|h| *h == "rate_dph").unwrap();
        let dph: f64 = fields[i].parse().unwrap();
        fields[i] = format!("{:e}", dph.to_radians() / 3600.0);
    });
    every_command_refuses(
        &dir,
        &model,
        &run,
        "rad/s? the rate and the reference must both be in °/h",
    );
}

#[test]
fn a_time_column_in_milliseconds_or_minutes_is_refused_everywhere() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    // 50 Hz logged in ms: a step of 20 "s".
    let ms = rewritten(&dir, "ms.csv", |i, _, fields| fields[0] = format!("{}", i * 20));
    every_command_refuses(&dir, &model, &ms, "is time_s in milliseconds?");
    // 1 Hz logged in minutes: the loop's ramps read 60 times too fast.
    let minutes = rewritten(&dir, "min.csv", |i, _, fields| {
        fields[0] = format!("{:.6}", i as f64 / 60.0)
    });
    // (fit: its own refusal, the run too short to warm up in seconds.)
    every_command_refuses(&dir, &model, &minutes, "hours or minutes");
}

#[test]
fn a_run_listed_twice_is_refused_in_every_role_and_command() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let train = dir.path().join("train.csv");
    // Another run: one reading differs from the training run's.
    let other = rewritten(&dir, "other.csv", |i, header, fields| {
        if i == 0 {
            let rate = header.iter().position(|h| *h == "rate_dph").unwrap();
            fields[rate] = "0.5".into();
        }
    });
    let copy = dir.path().join("copy.csv");
    std::fs::copy(&other, &copy).unwrap();
    let (t, o, c, m) = (
        train.to_str().unwrap(),
        other.to_str().unwrap(),
        copy.to_str().unwrap(),
        model.to_str().unwrap(),
    );
    let fitted = dir.path().join("refit.bin");
    let f = fitted.to_str().unwrap();
    let report = dir.path().join("report");
    for (args, expected) in [
        (
            vec!["fit", "-q", t, "--validate", o, "--validate", c, "-o", f],
            "copy.csv: the --validate run is a copy of --validate run",
        ),
        (
            vec!["fit", "-q", t, "--validate", o, "--holdout", c, "-o", f],
            "copy.csv: the --holdout run is a copy of --validate run",
        ),
        (
            vec!["eval", "--model", m, o, c],
            "the evaluated run is a copy of evaluated run",
        ),
        (
            vec!["report", "--model", m, o, c, "-o", report.to_str().unwrap()],
            "the evaluated run is a copy of evaluated run",
        ),
    ] {
        let out = trainer(&args);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {}", stderr(&out));
        assert!(stderr(&out).contains(expected), "{args:?}: {}", stderr(&out));
        assert!(!fitted.exists() && !report.exists());
    }
}

#[test]
fn options_the_fit_would_ignore_are_refused_naming_why() {
    let dir = TempDir::new().unwrap();
    let _ = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let fitted = dir.path().join("refit.bin");
    let (r, f) = (run.to_str().unwrap(), fitted.to_str().unwrap());
    for (extra, expected) in [
        (
            vec!["--dt-window-s", "60"],
            "--dt-window-s would be ignored: the thermal lag bank (the default) identifies its own filters",
        ),
        (
            vec!["--features", "response-bank", "--dt-window-s", "60"],
            "the response bank has its 12 filters fixed",
        ),
        (
            vec!["--inputs", "temp_a"],
            "--inputs would be ignored: it names the multi-point inputs of --method svr-pso",
        ),
        (
            vec!["--centers", "64", "--max-centers", "1"],
            "--max-centers bounds the search for K, which --centers fixes",
        ),
    ] {
        let mut args = vec!["fit", "-q", r, "-o", f];
        args.extend(&extra);
        let o = trainer(&args);
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {}", stderr(&o));
        assert!(stderr(&o).contains(expected), "{extra:?}: {}", stderr(&o));
        assert!(!fitted.exists());
    }
}
