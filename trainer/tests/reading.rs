//! What the engineer reads is right (issue 34): models described as they
//! are, clamped shares in the tables, plausibility checks that name the
//! mistake and the way around it.

mod common;

use common::{fitted_model, stderr, stdout, trainer, write};
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
    let o = trainer(&[
        "report",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let form = text.lines().find_map(|l| l.strip_prefix("model           ")).unwrap();
    assert!(
        md.contains("- kind: thermal lag bank\n") && md.contains(&format!("- form: {form}\n")),
        "{md}"
    );
    assert!(md.contains("- reference temperature T₀: "), "{md}");
    let _ = write;
}
