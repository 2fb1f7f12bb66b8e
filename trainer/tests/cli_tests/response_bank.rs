//! `trainer fit --features response-bank` as a user meets it: a blob that
//! inspects, compensates and evaluates, and improves a run it never saw.

use crate::common::{compensate, eval_json, stderr, stdout, trainer};
use tempfile::TempDir;

#[test]
fn a_response_bank_fitted_on_one_simulated_run_improves_the_cluster_std_of_another() {
    let dir = TempDir::new().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_owned();
    for (seed, name) in [("1", "train.csv"), ("3", "unseen.csv")] {
        let o = trainer(&["simulate", "--profile", "ifog", "--seed", seed, "-o", &path(name)]);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let o = trainer(&[
        "fit",
        &path("train.csv"),
        "--features",
        "response-bank",
        "-o",
        &path("rb.bin"),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("model: thermal response bank, linear in its 8 inputs; 12 filters 10 s … 1.1 h on T, (T − T₀)², (T − T₀)³, static cubic in T; T₀ "),
        "{}",
        stdout(&o)
    );

    let o = trainer(&["inspect", "--model", &path("rb.bin"), "--json", "-"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["features"]["set"], "ResponseBank");
    assert_eq!(v["features"]["response_bank"]["taus_s"].as_array().unwrap().len(), 12);
    assert_eq!(v["inputs"], 8, "a static cubic and five responses");
    assert_eq!(v["centers"], 0);

    let o = compensate(
        dir.path().join("rb.bin").as_path(),
        dir.path().join("unseen.csv").as_path(),
        dir.path().join("out.csv").as_path(),
        &[],
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let rows = std::fs::read_to_string(dir.path().join("out.csv")).unwrap();
    assert!(rows.lines().filter(|l| !l.starts_with('#')).count() > 10_000);

    let v = eval_json(&path("rb.bin"), &path("unseen.csv"));
    let before = v[0]["cluster_std_before_dph"].as_f64().unwrap();
    let after = v[0]["cluster_std_after_dph"].as_f64().unwrap();
    assert!(after < 0.25 * before, "100-s cluster STD {before} → {after} °/h");
    assert_eq!(v[0]["flagged"]["input_clamped"], 0, "the unseen run stays in range");
}
