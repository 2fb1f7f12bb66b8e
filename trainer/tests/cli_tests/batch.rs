//! `trainer batch`: a manifest of units fitted and judged in parallel, a summary of
//! every unit with the failing ones first, exit 0/3/1, `--resume`, and bad manifests
//! refused with file, line and column before anything is written.

use crate::common::{inspect_json, short_chamber_run, short_chamber_run_with, stderr, stdout, trainer};
use tempfile::TempDir;

/// Two good units and one whose training run is cut short: exit 3, the good units'
/// blobs written with the batch and the digest of their runs in the provenance, the
/// broken one an error naming its file and line, listed first.
#[test]
fn a_batch_writes_every_good_unit_and_names_the_broken_one_first() {
    let dir = TempDir::new().unwrap();
    let runs = dir.path().join("runs");
    std::fs::create_dir(&runs).unwrap();
    for (name, seed) in [("u1", "1"), ("u2", "2"), ("h1", "11"), ("h2", "12"), ("h3", "13")] {
        short_chamber_run(&runs.join(format!("{name}.csv")), seed);
    }
    let whole = std::fs::read(runs.join("u2.csv")).unwrap();
    std::fs::write(runs.join("broken.csv"), &whole[..2000]).unwrap();
    std::fs::write(dir.path().join("spec.toml"), "[holdout]\nstd100_gain_min_pct = 1\n").unwrap();
    let manifest = dir.path().join("batch.toml");
    std::fs::write(
        &manifest,
        "batch = \"B-T\"\nspec = \"spec.toml\"\n\
         [[unit]]\nserial = \"FOG-1\"\ntrain = [\"runs/u1.csv\"]\nholdout = [\"runs/h1.csv\"]\n\
         [[unit]]\nserial = \"FOG-2\"\ntrain = [\"runs/u2.csv\"]\nholdout = [\"runs/h2.csv\"]\n\
         [[unit]]\nserial = \"FOG-3\"\ntrain = [\"runs/broken.csv\"]\nholdout = [\"runs/h3.csv\"]\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let o = trainer(&["batch", manifest.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["batch"], "B-T");
    let units = summary["units"].as_array().unwrap();
    assert_eq!(units[0]["serial"], "FOG-3", "failing units first");
    assert_eq!(units[0]["status"], "error");
    assert!(
        units[0]["reasons"][0].as_str().unwrap().contains("broken.csv:"),
        "{}",
        units[0]
    );
    for u in &units[1..] {
        assert_eq!(u["status"], "pass", "{u}");
        let serial = u["serial"].as_str().unwrap();
        let model = out.join(serial).join("model.bin");
        let inspected = inspect_json(&model);
        let p = &inspected["provenance"];
        assert_eq!((p["serial"].as_str(), p["batch"].as_str()), (Some(serial), Some("B-T")));
        let train = runs.join(if serial == "FOG-1" { "u1.csv" } else { "u2.csv" });
        assert_eq!(
            p["training_runs"][0]["sha256"],
            ::trainer::provenance::sha256_file(&train).unwrap().as_str()
        );
        assert!(out.join(serial).join("fit.json").exists());
    }
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), 4, "{csv}");
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .contains(",settled_forecast,training_settled_spread_dph,unmodelled_dynamics,"),
        "what the fit vouches for, per unit: {csv}"
    );
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(
        html.find("FOG-3").unwrap() < html.find("FOG-1").unwrap(),
        "failing first in the page"
    );
    // The same OUTDIR again: refused without --resume or --force; --resume keeps the good units.
    let o = trainer(&["batch", manifest.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    let o = trainer(&[
        "batch",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--resume",
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert_eq!(stderr(&o).matches("(unchanged, kept)").count(), 2, "{}", stderr(&o));
}

/// Each defect of a manifest is refused before any fit, naming the manifest's line.
#[test]
fn bad_manifests_are_refused_with_file_line_and_column_and_nothing_written() {
    let dir = TempDir::new().unwrap();
    short_chamber_run(&dir.path().join("a.csv"), "1");
    short_chamber_run(&dir.path().join("b.csv"), "2");
    let long = "X".repeat(40);
    let cases: [(&str, String, &str); 6] = [
        ("missing run", "batch = \"B\"\n[[unit]]\nserial = \"S1\"\ntrain = [\"nope.csv\"]\n".into(), ":4:10: training run nope.csv: no such file"),
        ("no training run", "batch = \"B\"\n[[unit]]\nserial = \"S1\"\n".into(), "has no training run"),
        ("long serial", format!("batch = \"B\"\n[[unit]]\nserial = \"{long}\"\ntrain = [\"a.csv\"]\n"), ":3:10: serial"),
        (
            "shared run",
            "batch = \"B\"\n[[unit]]\nserial = \"S1\"\ntrain = [\"a.csv\"]\n[[unit]]\nserial = \"S2\"\ntrain = [\"a.csv\"]\n".into(),
            "also the training run of unit S1",
        ),
        (
            "holdout is training",
            "batch = \"B\"\n[[unit]]\nserial = \"S1\"\ntrain = [\"a.csv\"]\nholdout = [\"a.csv\"]\n".into(),
            "also its training run",
        ),
        (
            "duplicate serial",
            "batch = \"B\"\n[[unit]]\nserial = \"S1\"\ntrain = [\"a.csv\"]\n[[unit]]\nserial = \"S1\"\ntrain = [\"b.csv\"]\n".into(),
            ":6:10: serial S1 is listed twice",
        ),
    ];
    for (what, text, needle) in cases {
        let manifest = dir.path().join("m.toml");
        std::fs::write(&manifest, text).unwrap();
        let out = dir.path().join("out");
        let o = trainer(&["batch", manifest.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "{what}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(needle) && stderr(&o).contains("m.toml"),
            "{what}: {}",
            stderr(&o)
        );
        assert!(!out.exists(), "{what}: nothing written");
    }
}

/// A three-axis unit is judged axis by axis: a summary row and a calibration record per
/// axis, the axis that misses a limit failing by name while the others pass (exit 3).
#[test]
fn a_three_axis_unit_is_judged_and_recorded_axis_by_axis() {
    let dir = TempDir::new().unwrap();
    for (name, seed) in [("imu_t.csv", "5"), ("imu_h.csv", "6")] {
        short_chamber_run_with(&dir.path().join(name), seed, &["--axes", "3"]);
    }
    // On these seeded runs the z axis's holdout leaves its training range most often.
    std::fs::write(dir.path().join("spec.toml"), "[holdout]\nclamped_max_pct = 0.01\n").unwrap();
    let manifest = dir.path().join("batch.toml");
    std::fs::write(
        &manifest,
        "batch = \"B-3\"\nspec = \"spec.toml\"\n[[unit]]\nserial = \"IMU-1\"\ntrain = [\"imu_t.csv\"]\nholdout = [\"imu_h.csv\"]\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let store = dir.path().join("cal.sqlite");
    let o = trainer(&[
        "batch",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--records",
        store.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let rows: Vec<(String, String)> = summary["units"]
        .as_array()
        .unwrap()
        .iter()
        .map(|u| {
            (
                u["axis"].as_str().unwrap().to_owned(),
                u["status"].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    assert_eq!(
        rows,
        [("z", "fail"), ("x", "pass"), ("y", "pass")].map(|(a, s)| (a.to_owned(), s.to_owned())),
        "a row per axis, the failing one first"
    );
    assert!(
        summary["units"][0]["reasons"][0]
            .as_str()
            .unwrap()
            .contains("clamped_max_pct"),
        "{}",
        summary["units"][0]
    );
    let o = trainer(&["history", "IMU-1", "--records", store.to_str().unwrap(), "--json"]);
    let records: Vec<serde_json::Value> = serde_json::from_str(&stdout(&o)).unwrap();
    let axes: Vec<(&str, &str)> = records
        .iter()
        .map(|r| (r["axis"].as_str().unwrap(), r["status"].as_str().unwrap()))
        .collect();
    assert_eq!(axes, [("x", "pass"), ("y", "pass"), ("z", "fail")], "a record per axis");
    assert!(
        records.iter().all(|r| r["model_crc32"] == records[0]["model_crc32"]),
        "one blob"
    );
}
