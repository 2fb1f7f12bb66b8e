//! Figures that tell one story (issue 49, item 10): a run gets the same MSD
//! and STD100 whichever command reports it, and a fit prints one held-out
//! figure, saying what the forecast rests on.

use crate::common::{fitted_model, stderr, stdout, trainer};
use tempfile::TempDir;

/// The figures of the table row of `run` in `printed`: everything after the
/// role and run name.
fn row_figures(printed: &str, run: &str) -> Vec<String> {
    let line = printed
        .lines()
        .find(|l| l.split_whitespace().nth(1) == Some(run))
        .unwrap_or_else(|| panic!("no row for {run} in {printed}"));
    line.split_whitespace().skip(2).map(str::to_owned).collect()
}

#[test]
fn a_training_run_gets_the_same_figures_from_fit_and_eval_and_one_held_out_figure() {
    let dir = TempDir::new().unwrap();
    let _ = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let model = dir.path().join("again.bin");
    let fit = trainer(&[
        "fit",
        "-q",
        "--block-s",
        "4",
        run.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
    ]);
    assert!(fit.status.success(), "{}", stderr(&fit));
    let fitted = stdout(&fit);
    let eval = trainer(&["eval", "--model", model.to_str().unwrap(), run.to_str().unwrap()]);
    assert!(eval.status.success(), "{}", stderr(&eval));
    assert_eq!(
        row_figures(&fitted, "train.csv"),
        row_figures(&stdout(&eval), "train.csv"),
        "{fitted}"
    );
    assert!(!fitted.contains("scored on the fit's"), "{fitted}");
    let held_out = fitted.matches("validation RMS").count() + fitted.matches("held-out RMS").count();
    assert_eq!(held_out, 1, "{fitted}");
    assert!(
        fitted.contains("(it chose the structure; the forecast above is made of the training residual"),
        "{fitted}"
    );
}

/// Wrong causes no more (issue 49, item 12): each refusal names what is wrong.
#[test]
fn a_refusal_names_the_cause_it_has() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let (m, run) = (model.to_str().unwrap(), dir.path().join("train.csv"));
    let r = run.to_str().unwrap();
    // A gzip file is not a file of CR-only line ends.
    let gz = crate::common::write(&dir, "run.csv.gz", &[0x1f, 0x8b, 0x08, 0x00, b'\r', 0x00, 0x03]);
    let o = trainer(&["eval", "--model", m, gz.to_str().unwrap()]);
    assert!(
        stderr(&o)
            .contains("run.csv.gz:1: the file is gzip-compressed, not CSV text; decompress it first (gunzip FILE)"),
        "{}",
        stderr(&o)
    );
    // A report into standard output, or into one of the runs.
    let o = trainer(&["report", "--model", m, r, "-o", "-"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("- (standard output) cannot take a directory of files"),
        "{}",
        stderr(&o)
    );
    assert!(!std::path::Path::new("-").exists());
    let again = dir.path().join("again.bin");
    let o = trainer(&["fit", "-q", r, "--report", r, "-o", again.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("train.csv: is an input of this command, not a directory to write"),
        "{}",
        stderr(&o)
    );
    // A stated sample rate is echoed as written.
    let text = std::fs::read_to_string(&run).unwrap();
    let restated = text.replace("# sample_rate_hz: 1\n", "# sample_rate_hz: 2.0001\n");
    let restated = crate::common::write(&dir, "restated.csv", restated.as_bytes());
    let o = trainer(&["eval", "--model", m, restated.to_str().unwrap()]);
    assert!(stderr(&o).contains("# sample_rate_hz: 2.0001 states"), "{}", stderr(&o));
}

/// The bias-instability rule (trainer::evaluation::allan, docs/methods.md)
/// against the truth: noise-only simulated runs of 4, 12 and 24 h, whose
/// bias instability is the simulator's (`# bias_instability_dph`). A floor
/// reads it within twice its stated uncertainty; a bound (no floor) is not
/// below it by more than that.
#[test]
fn the_bias_instability_of_noise_only_runs_is_read_within_its_uncertainty() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    for (hours, seed) in [
        ("4", "1"),
        ("4", "2"),
        ("12", "1"),
        ("12", "2"),
        ("24", "1"),
        ("24", "2"),
    ] {
        let run = dir.path().join(format!("noise{hours}-{seed}.csv"));
        let o = trainer(&[
            "simulate",
            "--noise-only",
            "--hours",
            hours,
            "--seed",
            seed,
            "-o",
            run.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let truth_dph: f64 = std::fs::read_to_string(&run)
            .unwrap()
            .lines()
            .find_map(|l| l.strip_prefix("# bias_instability_dph: "))
            .expect("the simulator states its bias instability")
            .parse()
            .unwrap();
        let o = trainer(&[
            "eval",
            "--model",
            model.to_str().unwrap(),
            run.to_str().unwrap(),
            "--allow-implausible",
            "--json",
            "-",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
        let a = &json[0]["allan_before"];
        let bi = a["bias_instability_dph"].as_f64().unwrap();
        let u = a["floor_uncertainty_pct"].as_f64().unwrap() / 100.0;
        let reached = a["floor_reached"].as_bool().unwrap();
        let case = format!(
            "{hours} h, seed {seed}: BI {bi:.3e} ±{:.0} % (floor {reached}), truth {truth_dph}",
            100.0 * u
        );
        assert!(
            a["floor_tau_s"].as_f64().unwrap() <= a["confident_tau_max_s"].as_f64().unwrap(),
            "{case}"
        );
        if reached {
            assert!((bi - truth_dph).abs() <= 2.0 * u * bi, "{case}");
        } else {
            assert!(truth_dph <= bi * (1.0 + 2.0 * u), "{case}");
        }
    }
}
