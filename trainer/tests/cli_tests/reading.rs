//! What the engineer reads is right (issue 34): models described as they
//! are, clamped shares in the tables, plausibility checks that name the
//! mistake and the way around it.

use crate::common::{fitted_model, simulated, stderr, stdout, trainer, with_model, write};
use tempfile::TempDir;

#[test]
fn a_model_is_described_as_it_is_in_fit_inspect_and_report() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    // fit: the kind, its form and T₀; no zero term.
    let again = dir.path().join("again.bin");
    let fit = trainer(&["fit", run.to_str().unwrap(), "-o", again.to_str().unwrap()]);
    let fit_text = stdout(&fit);
    assert!(fit.status.success(), "{}", stderr(&fit));
    let model_line = fit_text.lines().find(|l| l.starts_with("model: ")).unwrap_or_default();
    assert!(
        model_line.starts_with("model: thermal lag bank, linear in its ") && model_line.contains("; T₀ "),
        "{fit_text}"
    );
    assert!(
        !fit_text.contains("no centres") && !fit_text.contains("0.000e0"),
        "{fit_text}"
    );
    // inspect: the same words, T₀ stated, no negative square.
    let text = stdout(&trainer(&["inspect", "--model", model.to_str().unwrap()]));
    assert!(
        text.contains("kind            thermal lag bank (stored as gaussian-rbf)\n"),
        "{text}"
    );
    assert!(text.contains("model           linear in its "), "{text}");
    assert!(
        text.contains("T₀              ") && text.contains(" °C (reference temperature)"),
        "{text}"
    );
    let square = text.lines().find(|l| l.contains("(T̂ − T₀)² [°C²]")).unwrap_or_default();
    assert!(square.contains(" 0 … "), "an even power's range starts at 0: {square}");
    let o = trainer(&["inspect", "--model", model.to_str().unwrap(), "--format", "json"]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["description"]["kind"], "thermal lag bank");
    let features = v["features"].as_object().unwrap();
    assert!(features.values().all(|x| !x.is_null()), "{features:?}");
    assert!(!features.contains_key("coil_lag_min"), "{features:?}");
    // report.md: the same kind and form.
    let out = dir.path().join("report");
    let o = with_model("report", &model, &run, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let form = text.lines().find_map(|l| l.strip_prefix("model           ")).unwrap();
    assert!(
        md.contains("- kind: thermal lag bank\n") && md.contains(&format!("- form: {form}\n")),
        "{md}"
    );
    assert!(md.contains("- reference temperature T₀: "), "{md}");
}

/// A 1-Hz run of `rows` rows: a ramp of `c_per_s` from 20 °C, `time_scale` s per second.
fn ramp_run(rows: usize, time_scale: f64, temp: impl Fn(f64) -> f64) -> String {
    let mut s = String::from("time_s,rate_dph,temp_c\n");
    for i in 0..rows {
        let t = i as f64;
        s.push_str(&format!(
            "{:.8},{:.4},{:.4}\n",
            t * time_scale,
            0.01 * (i % 7) as f64,
            temp(t)
        ));
    }
    s
}

#[test]
fn runs_in_fahrenheit_or_with_time_in_hours_are_refused_with_the_reason_and_a_way_around() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let model = model.to_str().unwrap();
    // A °C chamber ramp written in °F: 68 … 176 °F.
    let fahrenheit = write(&dir, "f.csv", ramp_run(3600, 1.0, |t| 68.0 + t * 0.03).as_bytes());
    // A 1 °C/min ramp with time_s in hours.
    let hours = write(
        &dir,
        "h.csv",
        ramp_run(3600, 1.0 / 3600.0, |t| 20.0 + t / 60.0).as_bytes(),
    );
    for (run, why) in [(&fahrenheit, "°F?"), (&hours, "time_s in hours")] {
        let out = dir.path().join("out.csv");
        for args in [
            vec!["eval", "--model", model, run.to_str().unwrap()],
            vec![
                "compensate",
                "--model",
                model,
                run.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
        ] {
            let o = trainer(&args);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stdout(&o));
            assert!(
                stderr(&o).contains(why) && stderr(&o).contains("--allow-implausible"),
                "{args:?}: {}",
                stderr(&o)
            );
            assert!(!out.exists(), "a refused compensate writes nothing");
            let o = trainer(&[&args[..], &["--allow-implausible"]].concat());
            assert!(o.status.success(), "{args:?} --allow-implausible: {}", stderr(&o));
            let _ = std::fs::remove_file(&out);
        }
    }
    // fit: a simulated chamber cycle (−40 … 60 °C) in °F.
    let cycle = dir.path().join("cycle.csv");
    simulated(
        &cycle,
        &["--profile", "cycle", "--hold-min", "30", "--sample-rate-hz", "0.2"],
    );
    let train = std::fs::read_to_string(&cycle).unwrap();
    let in_fahrenheit: String = train
        .lines()
        .map(|l| {
            let mut fields: Vec<String> = l.split(',').map(str::to_owned).collect();
            if let Some(c) = fields.get(2).and_then(|f| f.parse::<f64>().ok()) {
                fields[2] = format!("{:.4}", c * 1.8 + 32.0);
            }
            fields.join(",") + "\n"
        })
        .collect();
    let fahrenheit = write(&dir, "train_f.csv", in_fahrenheit.as_bytes());
    let o = trainer(&[
        "fit",
        "-q",
        fahrenheit.to_str().unwrap(),
        "-o",
        dir.path().join("f.bin").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("°F?") && stderr(&o).contains("--allow-implausible"),
        "{}",
        stderr(&o)
    );
    assert!(!dir.path().join("f.bin").exists());
}

#[test]
fn a_holdout_that_is_a_training_run_or_a_copy_of_one_is_refused() {
    let dir = TempDir::new().unwrap();
    let _ = fitted_model(&dir);
    let train = dir.path().join("train.csv");
    let copy = dir.path().join("copy.csv");
    std::fs::copy(&train, &copy).unwrap();
    let model = dir.path().join("m.bin");
    for (holdout, how) in [(&train, "the same file as"), (&copy, "a copy of")] {
        let o = trainer(&[
            "fit",
            "-q",
            train.to_str().unwrap(),
            "--holdout",
            holdout.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(1));
        assert!(
            stderr(&o).contains(&format!("the --holdout run is {how} training run")),
            "{}",
            stderr(&o)
        );
        assert!(!model.exists());
    }
}

#[test]
fn a_run_listed_twice_is_refused_by_its_rows_whatever_its_metadata_and_line_ends() {
    let dir = TempDir::new().unwrap();
    let _ = fitted_model(&dir);
    let train = dir.path().join("train.csv");
    let text = std::fs::read_to_string(&train).unwrap();
    // The same rows without the `#` lines, with CRLF line ends.
    let rows: String = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| format!("{l}\r\n"))
        .collect();
    assert!(text.starts_with('#') && rows.len() != text.len());
    let stripped = write(&dir, "stripped.csv", rows.as_bytes());
    let model = dir.path().join("m.bin");
    let fit = |args: &[&str]| {
        let mut all = vec!["fit", "-q"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["-o", model.to_str().unwrap()]);
        trainer(&all)
    };
    let (t, s) = (train.to_str().unwrap(), stripped.to_str().unwrap());
    for (args, expected) in [
        (vec![t, t], "the training run is the same file as training run"),
        (vec![t, s], "the training run is the same rows as training run"),
        (
            vec![t, "--validate", s],
            "the --validate run is the same rows as training run",
        ),
    ] {
        let o = fit(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        assert!(stderr(&o).contains(expected), "{args:?}: {}", stderr(&o));
        assert!(!model.exists());
    }
}

#[test]
fn a_header_with_another_delimiter_names_it_and_every_missing_column() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = write(&dir, "semi.csv", b"time_s;rate_dph;temp_c\n0;1;20\n1;1;20\n");
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), run.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let e = stderr(&o);
    assert!(
        e.contains("semi.csv:1: header has no required columns time_s and rate_dph")
            && e.contains("separated by ';', not by commas"),
        "{e}"
    );
}

#[test]
fn help_describes_the_default_the_command_uses() {
    let fit = stdout(&trainer(&["fit", "--help"]));
    let opening = fit[..fit.find("Usage:").unwrap()]
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert!(opening.contains("The default is the thermal lag bank"), "{opening}");
    assert!(
        !fit.contains("Features (T [°C], ΔT [°C/min], T×ΔT) are computed"),
        "{fit}"
    );
    let blocks = stdout(&trainer(&["blocks", "--help"]))
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert!(!blocks.contains("multiscale-validated, the fit's default"), "{blocks}");
    assert!(blocks.contains("lag-bank, the fit's default"), "{blocks}");
    let dir = TempDir::new().unwrap();
    let run = write(&dir, "r.csv", b"time_s,rate_dph,temp_c\n0,1,20\n1,1,20\n");
    let o = trainer(&[
        "blocks",
        run.to_str().unwrap(),
        "--features",
        "lag-bank",
        "-o",
        dir.path().join("b.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("pass the fitted model with --model"),
        "{}",
        stderr(&o)
    );
}
