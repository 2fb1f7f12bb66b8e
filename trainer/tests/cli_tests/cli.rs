//! The `trainer` binary as a user meets it: exit codes, messages naming file,
//! line and column, files written.

use std::path::Path;

use crate::common::{
    compensate, fit_ok, fitted_model, inspect_json, shared_data, short_chamber_run, simulated, stderr, stdout, trainer,
    with_model, write,
};
use tempfile::TempDir;

/// `trainer blocks RUN --block-s 60 -o OUT` with `args`, which must succeed; the CSV written.
fn blocks_csv(run: &Path, out: &Path, args: &[&str]) -> String {
    let fixed = [
        "blocks",
        run.to_str().unwrap(),
        "--block-s",
        "60",
        "-o",
        out.to_str().unwrap(),
    ];
    let o = trainer(&[&fixed[..], args].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::read_to_string(out).unwrap()
}

/// Data rows of a recorded-run file (no metadata, blank lines or header).
fn data_rows(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .skip(1)
        .collect()
}

const GOOD_HEADER: &str = "# sample_rate_hz: 1\ntime_s,rate_dph,temp_c\n";

#[test]
fn malformed_runs_are_refused_naming_file_line_and_column() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let cases: &[(&str, &str, &str)] = &[
        (
            "not_a_number",
            "0,1,20\n1,1.2.3,20\n",
            ":4: column rate_dph (field 2): \"1.2.3\" is not a number",
        ),
        (
            "nan",
            "0,1,20\n1,2,20\n2,NaN,20\n",
            ":5: column rate_dph (field 2): \"NaN\" is not a finite number",
        ),
        (
            "infinite_temp",
            "0,1,20\n1,2,inf\n",
            ":4: column temp_c (field 3): \"inf\" is not a finite number",
        ),
        (
            "time_back",
            "0,1,20\n1,2,20\n1,2,20\n",
            ":5: column time_s (field 1): 1 does not increase",
        ),
        ("short_row", "0,1,20\n1,2\n", ":4: row has 2 fields, the header has 3"),
        (
            "empty_field",
            "0,1,20\n1,,20\n",
            ":4: column rate_dph (field 2): field is empty",
        ),
    ];
    let out = dir.path().join("out.csv");
    for (name, rows, expected) in cases {
        let run = write(&dir, &format!("{name}.csv"), format!("{GOOD_HEADER}{rows}").as_bytes());
        for args in [
            vec![
                "compensate",
                "--model",
                model.to_str().unwrap(),
                run.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            vec!["eval", "--model", model.to_str().unwrap(), run.to_str().unwrap()],
            vec![
                "fit",
                "-q",
                run.to_str().unwrap(),
                "-o",
                dir.path().join("x.bin").to_str().unwrap(),
            ],
        ] {
            let o = trainer(&args);
            assert_eq!(o.status.code(), Some(1), "{name} {}: {}", args[0], stderr(&o));
            let message = stderr(&o);
            assert!(
                message.contains(&format!("{name}.csv{expected}")),
                "{name} {}: got {message}",
                args[0]
            );
            assert!(!message.contains("panicked"), "{message}");
        }
    }
}

#[test]
fn header_problems_are_refused_at_the_header_line() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let cases: &[(&str, &[u8], &str)] = &[
        (
            "no_time",
            b"# a: b\nrate_dph,temp_c\n1,2\n",
            "no_time.csv:2: header has no required column time_s",
        ),
        (
            "no_temp",
            b"time_s,rate_dph\n0,1\n",
            "no_temp.csv:1: header has no column temp_c",
        ),
        (
            "dup",
            b"time_s,rate_dph,temp_c,rate_dph\n",
            "dup.csv:1: column rate_dph appears twice",
        ),
        ("empty", b"", "empty.csv:1: no header line"),
        (
            "latin1",
            b"time_s,rate_dph,temp_c\n0,1,2\n1,2,\xb0\n",
            "latin1.csv:3: line is not valid UTF-8",
        ),
        (
            "bad_flag",
            b"time_s,rate_dph,temp_c,temp_fault\n0,1,20,2\n",
            "bad_flag.csv:2: column temp_fault (field 4): \"2\" is not 0 or 1",
        ),
    ];
    let out = dir.path().join("out.csv");
    for (name, content, expected) in cases {
        let run = write(&dir, &format!("{name}.csv"), content);
        let o = compensate(&model, &run, &out, &[]);
        assert_eq!(o.status.code(), Some(1), "{name}");
        assert!(stderr(&o).contains(expected), "{name}: {}", stderr(&o));
    }
}

#[test]
fn original_bmi270_terminal_logs_get_a_clear_error() {
    let original = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/bmi270/BMI_270_hot_test.csv");
    if !original.exists() {
        // The shared/ folder sits beside the checkout on project machines; the
        // converted copies in examples/ are covered by the next test.
        eprintln!("skipping: {} not present", original.display());
        return;
    }
    let dir = TempDir::new().unwrap();
    let model = dir.path().join("m.bin");
    let o = trainer(&["fit", "-q", original.to_str().unwrap(), "-o", model.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("BMI_270_hot_test.csv:1: header has no required columns time_s and rate_dph"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn converted_bmi270_logs_are_read_but_cannot_identify_a_model() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let hot = shared_data("bmi270/bmi270_hot_z.csv");
    let o = trainer(&[
        "fit",
        "-q",
        hot.to_str().unwrap(),
        "-o",
        dir.path().join("m.bin").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    let message = stderr(&o);
    assert!(message.contains("at least 600 s are needed"), "{message}");
    assert!(message.contains("at least 5 °C is needed"), "{message}");
    assert!(!dir.path().join("m.bin").exists(), "a refused fit writes no model");

    // compensate accepts them: one output row per input row.
    let out = dir.path().join("hot_comp.csv");
    let o = compensate(&model, &hot, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (input, output) = (
        std::fs::read_to_string(&hot).unwrap(),
        std::fs::read_to_string(&out).unwrap(),
    );
    assert_eq!(data_rows(&input).len(), data_rows(&output).len());
}

#[test]
fn tolerable_variants_are_accepted_row_for_row() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let rows = "0,1.5,20\n1,1.6,20.1\n2,1.7,20.2\n";
    let variants: &[(&str, String)] = &[
        ("bom", format!("\u{feff}time_s,rate_dph,temp_c\n{rows}")),
        (
            "crlf",
            format!(
                "# sample_rate_hz: 1\r\ntime_s,rate_dph,temp_c\r\n{}",
                rows.replace('\n', "\r\n")
            ),
        ),
        (
            "extra_columns",
            "note,temp_c,time_s,rate_dph,x\na,20,0,1.5,\nb,20.1,1,1.6,q\nc,20.2,2,1.7,\n".to_owned(),
        ),
        ("no_metadata", format!("time_s,rate_dph,temp_c\n{rows}")),
        (
            "comments_between",
            "time_s,rate_dph,temp_c\n0,1.5,20\n# operator opened the door\n\n1,1.6,20.1\n".to_owned(),
        ),
    ];
    for (name, content) in variants {
        let run = write(&dir, &format!("{name}.csv"), content.as_bytes());
        let out = dir.path().join(format!("{name}_out.csv"));
        let o = compensate(&model, &run, &out, &[]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let text = std::fs::read_to_string(&out).unwrap();
        let data = data_rows(&text);
        assert_eq!(
            data.len(),
            data_rows(content).len(),
            "{name}: one output row per input row"
        );
        for line in data {
            let fields: Vec<&str> = line.split(',').collect();
            let n = fields.len();
            let flags: u8 = fields[n - 1].parse().unwrap();
            let bias: f32 = fields[n - 3].parse().unwrap();
            assert!(bias.is_finite(), "{name}: {line}");
            assert!(flags & 4 == 0, "{name}: model applied: {line}");
        }
    }
}

#[test]
fn corrupt_blobs_are_refused_with_the_reason() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let good = std::fs::read(&model).unwrap();
    let run = write(&dir, "run.csv", format!("{GOOD_HEADER}0,1,20\n").as_bytes());
    let mut flipped = good.clone();
    flipped[20] ^= 0x04;
    let mut version = good.clone();
    version[4] = 7;
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("flip", flipped, "CRC mismatch"),
        ("truncated", good[..good.len() - 3].to_vec(), "truncated"),
        ("text", b"hello, this is not a model".to_vec(), "bad magic"),
        ("empty", Vec::new(), "truncated"),
        ("version", version, "unsupported format version 7"),
    ];
    let out = dir.path().join("out.csv");
    for (name, bytes, reason) in cases {
        let blob = write(&dir, &format!("{name}.bin"), &bytes);
        for args in [
            vec![
                "compensate",
                "--model",
                blob.to_str().unwrap(),
                run.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            vec!["inspect", blob.to_str().unwrap()],
        ] {
            let o = trainer(&args);
            assert_eq!(o.status.code(), Some(1), "{name}");
            let message = stderr(&o);
            assert!(
                message.contains("model refused") && message.contains(reason),
                "{name}: {message}"
            );
        }
    }
}

#[test]
fn the_validated_choice_keeps_the_second_order_set_only_when_it_validates_clearly_better() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("cycle.csv");
    let sim = [
        "simulate",
        "--profile",
        "cycle",
        "--ramp",
        "2",
        "--rate-hz",
        "0.2",
        "--seed",
        "5",
    ];
    let o = trainer(&[&sim[..], &["-o", run.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let (model, json) = (dir.path().join("m.bin"), dir.path().join("fit.json"));
    let o = trainer(&[
        "fit",
        "--features",
        "multiscale-validated",
        run.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = stdout(&o);
    assert!(
        printed.contains("feature sets: first-order validation RMS"),
        "{printed}"
    );
    let fit = crate::common::read_json(&json);
    let sets = &fit["feature_sets"];
    let (first, second) = (
        sets["first_order_rms_dph"].as_f64().unwrap(),
        sets["second_order_rms_dph"].as_f64().unwrap(),
    );
    // The second-order family is the plain set or one of its lagged forms.
    let chosen = &fit["features"];
    let second_kept = chosen["set"] == "MultiScaleSecondOrder" || chosen["set"] == "MultiScaleLagged";
    assert_eq!(
        second_kept,
        second < trainer::fit::SECOND_ORDER_GAIN * first,
        "first {first}, second {second}, chosen {chosen}"
    );
    // Only the second-order family tries longer slowest windows.
    let windows: Vec<f64> = serde_json::from_value(chosen["windows_s"].clone()).unwrap();
    let factors: &[f32] = match second_kept {
        true => &trainer::fit::rbf::SLOWEST_WINDOW_FACTORS,
        false => &[1.0],
    };
    assert!(
        factors
            .iter()
            .any(|&f| (windows[2] / windows[0] - f64::from(256.0 * f)).abs() < 1e-3),
        "{windows:?}"
    );
    // The printed choice names the second-order family's slowest window.
    let slowest = format!("slowest window {} s", windows[2]);
    assert_eq!(printed.contains(&slowest), second_kept, "{slowest}: {printed}");
    let o = trainer(&["inspect", "--json", "-", model.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(&v["features"], chosen, "the blob holds the chosen set, lag and windows");
    // An explicit set is fitted alone.
    let o = fit_ok(&["--force", "--features", "multiscale-second-order"], &run, &model);
    assert!(!stdout(&o).contains("feature sets:"));
    let o = trainer(&["inspect", "--json", "-", model.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["features"]["set"], "MultiScaleSecondOrder");
}

#[test]
fn blocks_with_a_coil_lag_move_input_0_back_by_the_lag_and_refuse_other_sets() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("cycle_verify_5cpm.csv");
    let write_blocks = |name: &str, extra: &[&str]| -> Vec<Vec<f64>> {
        let args = [
            &["--features", "multiscale-second-order", "--rate-window-s", "15"],
            extra,
        ]
        .concat();
        let text = blocks_csv(&run, &dir.path().join(name), &args);
        assert!(text.starts_with("# features: "), "{text:.200}");
        text.lines()
            .skip(2)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect()
    };
    let plain = write_blocks("plain.csv", &[]);
    let lagged = write_blocks("lagged.csv", &["--coil-lag-min", "40"]);
    assert!(plain.len() > 100);
    assert_eq!(plain.len(), lagged.len());
    for (p, l) in plain.iter().zip(&lagged) {
        // Columns: run, x0 … x7, target. x3 is ΔT₃ in °C/min.
        assert!(
            (l[1] - (p[1] - 40.0 * p[4])).abs() < 1e-9 * p[1].abs().max(1.0),
            "{p:?} {l:?}"
        );
        assert_eq!(l[2..], p[2..]);
    }
    let o = trainer(&[
        "blocks",
        run.to_str().unwrap(),
        "--features",
        "paper",
        "--coil-lag-min",
        "40",
        "-o",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("--coil-lag-min needs --features multiscale-second-order"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_slow_fastest_window_is_not_offered_a_slowest_window_past_one_day() {
    // 300 s × 256 × 1.25 would be 96,000 s: past the firmware's limit, so
    // the second-order family (which leads on this run) keeps 256τ.
    let dir = TempDir::new().unwrap();
    let model = dir.path().join("m.bin");
    let run = shared_data("cycle_train_1cpm.csv");
    let args = [
        "fit",
        run.to_str().unwrap(),
        "--features",
        "multiscale-validated",
        "--rate-window-s",
        "300",
        "-q",
        "-o",
    ];
    let o = trainer(&[&args[..], &[model.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = trainer(&["inspect", "--json", "-", model.to_str().unwrap()]);
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["features"]["windows_s"], serde_json::json!([300.0, 4800.0, 76800.0]));
}

#[test]
fn blocks_of_a_model_are_the_blocks_of_its_own_inputs() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("cycle_verify_5cpm.csv");
    let (model, explicit, of_model) = (
        dir.path().join("m.bin"),
        dir.path().join("explicit.csv"),
        dir.path().join("of_model.csv"),
    );
    let fit = [
        "fit",
        run.to_str().unwrap(),
        "--features",
        "multiscale-second-order",
        "--rate-window-s",
        "60",
        "--centers",
        "4",
        "-q",
        "-o",
        model.to_str().unwrap(),
    ];
    let o = trainer(&fit);
    assert!(o.status.success(), "{}", stderr(&o));
    let explicit = blocks_csv(
        &run,
        &explicit,
        &["--features", "multiscale-second-order", "--rate-window-s", "60"],
    );
    let of_model = blocks_csv(&run, &of_model, &["--model", model.to_str().unwrap()]);
    assert!(explicit.lines().count() > 100);
    assert_eq!(of_model, explicit, "same set, windows and lag, same blocks");
    // A model's inputs are not mixed with explicit ones.
    let o = trainer(&[
        "blocks",
        run.to_str().unwrap(),
        "--model",
        model.to_str().unwrap(),
        "--rate-window-s",
        "15",
        "-o",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}

#[test]
fn inspect_reports_header_shapes_ranges_and_crc() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let o = trainer(&["inspect", "--json", "-", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v["crc"], "ok");
    assert_eq!(v["kind"], "gaussian-rbf");
    // The default, the lag bank: T̂, its square and cube, and one Shupe rate
    // per filter; the filters' time constants rise from seconds to hours and
    // are the ΔT windows the firmware runs.
    assert_eq!(v["features"]["set"], "LagBank");
    assert_eq!(
        v["features"]["lag_bank"]["gain_of"], "T̂",
        "the Shupe gain is of the coil's temperature"
    );
    let taus: Vec<f64> = v["features"]["lag_bank"]["taus_s"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect();
    assert!((4..=5).contains(&taus.len()), "{taus:?}");
    assert!(taus.windows(2).all(|w| w[1] > w[0]) && taus[0] >= 15.0 && taus[taus.len() - 1] <= 7680.0);
    assert_eq!(v["inputs"].as_u64().unwrap() as usize, 3 + taus.len());
    assert_eq!(v["features"]["windows_s"], v["features"]["lag_bank"]["taus_s"]);
    assert_eq!(v["features"]["inputs"][0], "T̂ [°C]");
    assert_eq!(
        v["blob_bytes"].as_u64().unwrap(),
        std::fs::metadata(&model).unwrap().len()
    );
    // The first range is that of the mean coil temperature T̂ over the
    // training run's used samples, a lagged (or led) copy of the loop
    // temperature: within a few degrees of its range. The bank follows its
    // cubic over that range (from 10-s means, the ranges from samples) and,
    // where the edge test trusts the cubic, up to one held-out band (0.3 of
    // the range) past an end.
    let train = std::fs::read_to_string(dir.path().join("train.csv")).unwrap();
    let temps: Vec<f64> = data_rows(&train)
        .iter()
        .map(|l| l.split(',').nth(2).unwrap().parse().unwrap())
        .collect();
    let (lo, hi) = temps
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let t_range = &v["training_ranges"][0];
    let (t_min, t_max) = (t_range["min"].as_f64().unwrap(), t_range["max"].as_f64().unwrap());
    let covered = &v["features"]["lag_bank"]["coil_range_c"];
    let (cubic_min, cubic_max) = (covered[0].as_f64().unwrap(), covered[1].as_f64().unwrap());
    let band = 0.3 * (t_max - t_min) + 0.5;
    assert!(
        cubic_min < t_min + 0.5 && cubic_min > t_min - band,
        "{t_range} vs {covered}"
    );
    assert!(
        cubic_max > t_max - 0.5 && cubic_max < t_max + band,
        "{t_range} vs {covered}"
    );
    assert!(
        (t_min - lo).abs() < 5.0 && (t_max - hi).abs() < 5.0,
        "{t_range} vs loop {lo} … {hi}"
    );
    // 30-min holds do not settle a coil that lags its sensor by about as long
    // (the identified lags add up to that): T̂ spans only part of the loop's range.
    assert!(t_max - t_min > 0.5 * (hi - lo), "{t_range} vs loop {lo} … {hi}");
    let text = stdout(&trainer(&["inspect", model.to_str().unwrap()]));
    assert!(text.contains("CRC-32          ok (0x"), "{text}");
}

/// Every blob `fit` writes holds its provenance (format 4): the digest of each training
/// run is `sha256sum`'s, the CRC-32 is the blob's trailer as "0x…", in text, JSON and TOML.
#[test]
fn a_fitted_blob_carries_its_provenance_and_inspect_shows_it_with_the_crc() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let expected = ::trainer::provenance::sha256_file(&run).unwrap();
    let blob = std::fs::read(&model).unwrap();
    let crc = u32::from_le_bytes(blob[blob.len() - 4..].try_into().unwrap());
    let json = inspect_json(&model);
    assert_eq!(json["format_version"], 4);
    assert_eq!(json["crc32"], format!("{crc:#010x}"));
    let p = &json["provenance"];
    assert_eq!(p["training_runs"][0]["file"], "train.csv");
    assert_eq!(p["training_runs"][0]["sha256"], expected.as_str());
    assert_eq!(p["trainer_version"], env!("CARGO_PKG_VERSION"));
    assert!(p["fitted_utc"].as_str().unwrap().ends_with('Z'), "{p}");
    assert!(p["spec_sha256"].is_null() && p["batch"].is_null(), "{p}");
    let text = stdout(&trainer(&["inspect", "--model", model.to_str().unwrap()]));
    assert!(
        text.contains(&format!("training run    train.csv sha256 {expected}")),
        "{text}"
    );
    let toml = stdout(&trainer(&[
        "inspect",
        "--model",
        model.to_str().unwrap(),
        "--format",
        "toml",
    ]));
    assert!(
        toml.contains(&expected) && toml.contains(&format!("{crc:#010x}")),
        "{toml}"
    );
}

/// A blob written before provenance existed (format 2) still loads and says so.
#[test]
fn a_format_2_blob_still_loads_and_shows_no_provenance() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let (decoded, _) = ::trainer::blobfile::read_model(&model).unwrap();
    let old = dir.path().join("old.bin");
    std::fs::write(&old, ::trainer::blobfile::encode_model(&decoded, None).unwrap()).unwrap();
    let o = trainer(&["inspect", "--model", old.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("provenance      none"), "{}", stdout(&o));
    let json: serde_json::Value = serde_json::from_str(&stdout(&trainer(&[
        "inspect",
        "--model",
        old.to_str().unwrap(),
        "--format",
        "json",
    ])))
    .unwrap();
    assert!(json["provenance"].is_null() && json["format_version"] == 2, "{json}");
    let run = dir.path().join("train.csv");
    let o = trainer(&["eval", "--model", old.to_str().unwrap(), run.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn help_teaches_units_and_methods() {
    let fit_help = stdout(&trainer(&["fit", "--help"]));
    for needle in [
        "°C/min",
        "orthogonal least squares",
        "rbf2",
        "poly3",
        "--validate",
        "contiguous",
    ] {
        assert!(fit_help.contains(needle), "fit --help lacks {needle:?}");
    }
    let compensate_help = stdout(&trainer(&["compensate", "--help"]));
    assert!(compensate_help.contains("temp_fault") && compensate_help.contains("flags"));
}

#[test]
fn fit_rejects_bad_options_and_writes_nothing() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let out = dir.path().join("m.bin");
    for (args, reason) in [
        (
            vec!["--centers", "65"],
            "invalid value '65' for '--centers <K>': 65 is not in 1..=64",
        ),
        (vec!["--max-centers", "0"], "invalid value '0' for '--max-centers <K>'"),
        (
            vec!["--folds", "0"],
            "invalid value '0' for '--folds <N>': 0 is not in 2..=20",
        ),
        (vec!["--folds", "1"], "invalid value '1' for '--folds <N>'"),
        (vec!["--folds", "100000"], "invalid value '100000' for '--folds <N>'"),
        (vec!["--block-s", "0"], "--block-s"),
        (vec!["--rate-window-s=-3"], "--dt-window-s"),
        (
            vec!["--serial", "a-serial-number-far-longer-than-thirty-two-bytes"],
            "--serial",
        ),
    ] {
        let mut all = vec!["fit", "-q", run.to_str().unwrap(), "-o", out.to_str().unwrap()];
        all.extend(args);
        let o = trainer(&all);
        assert_eq!(o.status.code(), Some(1), "{reason}");
        assert!(stderr(&o).contains(reason), "{reason}: {}", stderr(&o));
        assert!(!out.exists());
    }
}

#[test]
fn decode_turns_a_uart_capture_into_csv_and_reports_damage() {
    use gyro_wire::frame::{self, MAX_FRAME_LEN, OutputFrame};
    let dir = TempDir::new().unwrap();
    let mut capture = vec![0x42, 0x17]; // the capture started mid-frame: a partial frame first
    for seq in 0..5u32 {
        let f = OutputFrame {
            seq,
            rate_dph: 10.0 + seq as f32,
            bias_dph: 0.5,
            rate_comp_dph: 9.5 + seq as f32,
            temp_c: 25.0,
            flags: if seq == 3 { 2 } else { 0 },
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = frame::encode(&f, &mut buf).unwrap();
        let mut bytes = buf[..n].to_vec();
        if seq == 1 {
            bytes.truncate(3); // damaged on the link
            bytes.push(0);
        }
        capture.extend(bytes);
    }
    capture.insert(2, 0); // end of the partial frame
    let frames = write(&dir, "frames.bin", &capture);
    let out = dir.path().join("frames.csv");
    let o = trainer(&["decode", frames.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("2 damaged frame(s) skipped"), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "seq,rate_dph,bias_dph,rate_comp_dph,temp_c,flags");
    assert_eq!(
        &lines[1..],
        [
            "0,10,0.5,9.5,25,0",
            "2,12,0.5,11.5,25,0",
            "3,13,0.5,12.5,25,2",
            "4,14,0.5,13.5,25,0"
        ]
    );
}

#[test]
fn report_writes_svg_and_png_plots_json_and_markdown() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let out = dir.path().join("report");
    let o = with_model("report", &model, &run, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    for stem in ["train_rate", "train_allan", "bias_surface"] {
        let png = std::fs::read(out.join(format!("{stem}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{stem}.png is a PNG");
        assert!(png.len() > 10_000, "{stem}.png has content");
        let svg = std::fs::read_to_string(out.join(format!("{stem}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("<polyline") || svg.contains("<circle"),
            "{stem}.svg draws"
        );
    }
    let json = crate::common::read_json(out.join("report.json"));
    let e = &json["runs"][0];
    assert!(e["cluster_std_improvement_pct"].as_f64().unwrap() > 50.0, "{e}");
    assert!(e["allan_after"]["adev_dph"].as_array().unwrap().len() >= 8);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains("| train |") && md.contains("![rate](train_rate.svg)"),
        "{md}"
    );
    // The model is listed, and every run says how many samples were clamped.
    assert!(
        md.contains("## Model") && md.contains("- kind: thermal lag bank") && md.contains("- form: linear in its "),
        "{md}"
    );
    assert!(md.contains("- centres: ") && md.contains("  - T̂ [°C]: "), "{md}");
    let clamped = e["flagged"]["input_clamped"].as_u64().unwrap();
    let samples = e["samples"].as_u64().unwrap();
    let cell = format!("| {clamped} ({:.1} %) |", 100.0 * clamped as f64 / samples as f64);
    assert!(md.contains(&cell), "{cell} in {md}");
    // Allan plots shade confidence bands; the bias surface has a colour bar.
    let allan = std::fs::read_to_string(out.join("train_allan.svg")).unwrap();
    assert!(allan.contains("<polygon") && allan.contains("IEEE 952"), "Allan bands");
    let surface = std::fs::read_to_string(out.join("bias_surface.svg")).unwrap();
    // The default model's bias is drawn where the runs went, over its own inputs.
    assert!(
        surface.contains("model bias [°/h]")
            && surface.contains("where the runs went")
            && surface.contains("dashed: training range")
            && surface.contains("mean coil temperature T-hat [°C]"),
        "colour bar axis, the path and the training range, the lag bank's inputs (T̂ in words: the PNG font draws no combining hat)"
    );
}

#[test]
fn fit_never_overwrites_a_model_without_force() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let original = std::fs::read(&model).unwrap();
    let run = shared_data("ifog_verify_3cpm.csv");
    let fit = |extra: &[&str]| {
        let mut args = vec!["fit", "-q", "--centers", "4", "--block-s", "1"];
        args.extend(extra);
        args.extend([run.to_str().unwrap(), "-o", model.to_str().unwrap()]);
        trainer(&args)
    };
    let o = fit(&[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("exists; pass --force to overwrite it"),
        "{}",
        stderr(&o)
    );
    assert_eq!(
        std::fs::read(&model).unwrap(),
        original,
        "the refused fit left the model alone"
    );

    let o = fit(&["--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(std::fs::read(&model).unwrap(), original, "--force replaced the model");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "no temporary files left behind: {leftovers:?}");
}

#[test]
fn correlate_prints_the_gradient_matrix_of_a_multi_point_run_and_its_selection() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("multi.csv");
    let run_s = run.to_str().unwrap();
    let o = trainer(&[
        "simulate",
        "--profile",
        "cycle",
        "--ramp",
        "2",
        "--hours",
        "3",
        "--seed",
        "3",
        "--multi",
        "-o",
        run_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = trainer(&["correlate", run_s, "--select-top", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    // Eight rows of the matrix, one per thermometer, and the selection line.
    for name in ["temp_a", "temp_d", "temp_h"] {
        assert!(
            text.lines().any(|l| l.trim_start().starts_with(name)),
            "{name} row missing:\n{text}"
        );
    }
    let selected = text.lines().last().unwrap();
    assert!(selected.starts_with("selected (top 2 by |r|): "), "{selected}");
    assert_eq!(selected.matches("(r = ").count(), 2, "{selected}");
    // Marked in the matrix: a temperature once, a gradient in both triangles.
    let marks: usize = text.lines().skip(1).map(|l| l.matches('*').count()).sum();
    let expected: usize = selected
        .split("), ")
        .map(|name| if name.contains('−') { 2 } else { 1 })
        .sum();
    assert_eq!(marks, expected, "{text}");
    // A single-point run cannot give gradients.
    let single = shared_data("ifog_verify_3cpm.csv");
    let o = trainer(&["correlate", single.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("gradients need at least two"), "{}", stderr(&o));
}

#[test]
fn simulate_params_describe_another_gyro_and_bad_files_are_refused_with_their_place() {
    let dir = TempDir::new().unwrap();
    let run = |name: &str, params: Option<&Path>| {
        let out = dir.path().join(name);
        let mut args = vec!["simulate", "--hours", "1", "--seed", "9", "-o", out.to_str().unwrap()];
        if let Some(p) = params {
            args.extend(["--params", p.to_str().unwrap()]);
        }
        (trainer(&args), out)
    };
    let (o, default_run) = run("default.csv", None);
    assert!(o.status.success(), "{}", stderr(&o));
    // A field left out keeps its default: an empty object is the default gyro, bit for bit.
    let empty = write(&dir, "empty.json", b"{}");
    let (o, same_run) = run("same.csv", Some(&empty));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&default_run).unwrap(), std::fs::read(&same_run).unwrap());
    // A slower housing and a larger Shupe gain: another run, its parameters in the header.
    let other = write(
        &dir,
        "other.json",
        br#"{"plant": {"tau_top_s": 2400, "tau_coil_layer_s": 400}, "gyro": {"shupe_dph_per_c_per_min": 0.6}}"#,
    );
    let (o, other_run) = run("other.csv", Some(&other));
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&other_run).unwrap();
    let header = text
        .lines()
        .find(|l| l.starts_with("# simulator_params: "))
        .expect("params recorded");
    assert!(
        header.contains("\"tau_top_s\":2400.0") && header.contains("\"shupe_dph_per_c_per_min\":0.6"),
        "{header}"
    );
    assert_ne!(
        data_rows(&text),
        data_rows(&std::fs::read_to_string(&default_run).unwrap())
    );
    // Syntax errors and unknown fields name file, line and column; impossible values the field.
    for (content, expected) in [
        (
            "{\n  \"plant\": {\"tau_top_s\": 2400,}\n}",
            "bad.json:2:31: trailing comma",
        ),
        ("{\"gyro\": {\"shupe\": 1}}", "bad.json:1:17: unknown field `shupe`"),
        (
            "{\"plant\": {\"tau_base_s\": 1}}",
            "bad.json: every time constant must be at least 5 s",
        ),
        (
            "{\"gyro\": {\"arw_deg_per_sqrt_h\": -1}}",
            "bad.json: arw_deg_per_sqrt_h must be ≥ 0",
        ),
    ] {
        let bad = write(&dir, "bad.json", content.as_bytes());
        let (o, out) = run("bad.csv", Some(&bad));
        assert_eq!(o.status.code(), Some(1), "{content}");
        assert!(stderr(&o).contains(expected), "{content}: {}", stderr(&o));
        assert!(!out.exists(), "nothing written for {content}");
    }
}

#[test]
fn simulate_runs_a_planned_chamber_profile_and_refuses_bad_plans_with_their_place() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("planned.csv");
    let simulate = |plan: &Path| {
        trainer(&[
            "simulate",
            "--chamber-profile",
            plan.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
    };
    let plan = write(
        &dir,
        "plan.csv",
        b"# written by: trainer plan\ntime_s,chamber_c\n0,-20\n600,-20\n1800,40\n3600,40\n",
    );
    let o = simulate(&plan);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(text.contains("# profile: chamber-profile\n"), "{text:.400}");
    assert!(
        text.contains("# power_on: at 0 s, soaked at -20.00 °C\n"),
        "{text:.400}"
    );
    // One sample a second up to the plan's last set point; the coil follows the chamber up.
    let rows = data_rows(&text);
    assert_eq!(rows.len(), 3600);
    let temp = |row: &str| row.split(',').nth(2).unwrap().parse::<f64>().unwrap();
    assert!(
        temp(rows[0]) < -19.9 && temp(rows[3599]) > 0.0,
        "{} … {}",
        rows[0],
        rows[3599]
    );
    std::fs::remove_file(&out).unwrap();
    let bad = write(&dir, "bad.csv", b"time_s,chamber_c\n0,20\n60,2O\n");
    let o = simulate(&bad);
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("bad.csv:3:4: chamber_c: \"2O\" is not a number"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists(), "nothing written for a bad plan");
    // A plan is the profile: both at once is a usage error (exit 1, as every error).
    let o = trainer(&[
        "simulate",
        "--profile",
        "cycle",
        "--chamber-profile",
        plan.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}

#[test]
fn simulate_unit_draws_a_recorded_gyro_that_params_override_and_in_use_runs_start_at_power_on() {
    let dir = TempDir::new().unwrap();
    let run = |name: &str, args: &[&str]| {
        let out = dir.path().join(name);
        let mut all = vec![
            "simulate",
            "--profile",
            "cold-start",
            "--seed",
            "4",
            "-o",
            out.to_str().unwrap(),
        ];
        all.extend(args);
        let o = trainer(&all);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read_to_string(out).unwrap()
    };
    let unit = run("unit.csv", &["--unit", "3"]);
    assert!(
        unit.contains("# unit: 3\n") && unit.contains("# simulator_params: {"),
        "{unit:.600}"
    );
    assert!(unit.contains("in-use history") && unit.contains("# power_on: at 0 s, soaked at -"));
    // The in-use cold start lasts 4 h at 1 Hz unless --hours says otherwise.
    assert_eq!(data_rows(&unit).len(), 4 * 3600);
    assert_ne!(data_rows(&unit), data_rows(&run("documented.csv", &[])));
    // --params over --unit: the unit with that one field changed.
    let arw = write(&dir, "arw.json", br#"{"gyro": {"arw_deg_per_sqrt_h": 0.004}}"#);
    let noisier = run("noisier.csv", &["--unit", "3", "--params", arw.to_str().unwrap()]);
    let params = |text: &str| -> serde_json::Value {
        let line = text
            .lines()
            .find_map(|l| l.strip_prefix("# simulator_params: "))
            .unwrap();
        serde_json::from_str(line).unwrap()
    };
    let (mut expected, got) = (params(&unit), params(&noisier));
    expected["gyro"]["arw_deg_per_sqrt_h"] = serde_json::json!(0.004);
    assert_eq!(got, expected);
    // --design N: a gyro of another design, the same for every run, recorded as such.
    let design = run("design.csv", &["--design", "3"]);
    assert!(
        design.contains("# design: 3\n") && !design.contains("# unit:"),
        "{design:.600}"
    );
    assert_eq!(design, run("design-again.csv", &["--design", "3"]));
    assert_ne!(data_rows(&design), data_rows(&unit), "design 3 is not unit 3");
    assert_eq!(
        params(&design)["gyro"]["shupe_gain_of_layer_temp"],
        serde_json::json!(true)
    );
    assert!(params(&unit)["gyro"].get("shupe_gain_of_layer_temp").is_none());
    let o = trainer(&[
        "simulate",
        "--unit",
        "1",
        "--design",
        "1",
        "-o",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "--unit and --design exclude each other");
    assert!(stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
}

/// Number of data rows of a compensated run whose flags carry `bit`.
fn rows_flagged(compensated: &str, bit: u32) -> usize {
    let mut lines = compensated.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "flags").unwrap();
    lines
        .filter(|l| l.split(',').nth(col).unwrap().parse::<u32>().unwrap() & bit != 0)
        .count()
}

#[test]
fn samples_whose_rates_leave_the_training_range_are_flagged_clamped() {
    let dir = TempDir::new().unwrap();
    // Trained on 1 °C/min ramps.
    let model = fitted_model(&dir);
    let fast = dir.path().join("fast.csv");
    simulated(&fast, &["--ramp", "4", "--hold-min", "30", "--seed", "8"]);
    let compensated = |run: &Path, out: &str| {
        let out = dir.path().join(out);
        let o = compensate(&model, run, &out, &[]);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::read_to_string(out).unwrap()
    };
    const INPUT_CLAMPED: u32 = 1;
    // The training run itself stays inside what it covered ...
    assert_eq!(
        rows_flagged(&compensated(&dir.path().join("train.csv"), "t.csv"), INPUT_CLAMPED),
        0
    );
    // ... 4 °C/min ramps drive the filter rates past it: the ramps are flagged
    // (the holds between them are not).
    let fast_out = compensated(&fast, "f.csv");
    let rows = data_rows(&fast_out).len();
    let clamped = rows_flagged(&fast_out, INPUT_CLAMPED);
    assert!(
        clamped > rows / 20 && clamped < rows / 2,
        "{clamped} of {rows} rows clamped"
    );
}

/// `trainer eval --json` on `run` with `model`: the 100-s cluster STD after compensation, °/h.
fn cluster_std_after_dph(dir: &TempDir, model: &Path, run: &Path) -> f64 {
    let json = dir.path().join("eval.json");
    let o = trainer(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--force",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = crate::common::read_json(json);
    v[0]["cluster_std_after_dph"].as_f64().unwrap()
}

#[test]
fn a_second_training_run_at_another_sample_rate_is_left_out_in_turn_and_improves_the_model() {
    let dir = TempDir::new().unwrap();
    // Run 1: 1 °C/min ramps over 17–32 °C at 10 Hz (the fixture's model).
    let one_run = fitted_model(&dir);
    let sim = |args: &[&str], name: &str| {
        let path = dir.path().join(name);
        let o = trainer(&[&["simulate"], args, &["-o", path.to_str().unwrap()]].concat());
        assert!(o.status.success(), "{}", stderr(&o));
        path
    };
    // Run 2: random set points over −40…60 °C, sampled at 2 Hz.
    let random = sim(
        &["--profile", "random", "--hours", "6", "--rate-hz", "2", "--seed", "9"],
        "random.csv",
    );
    // The unseen history: other random set points.
    let unseen = sim(&["--profile", "random", "--hours", "6", "--seed", "11"], "unseen.csv");
    let two_runs = dir.path().join("two.bin");
    let o = trainer(&[
        "fit",
        dir.path().join("train.csv").to_str().unwrap(),
        random.to_str().unwrap(),
        "-o",
        two_runs.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("leave-one-run-out (2 folds)"), "{}", stdout(&o));
    let (one, two) = (
        cluster_std_after_dph(&dir, &one_run, &unseen),
        cluster_std_after_dph(&dir, &two_runs, &unseen),
    );
    assert!(two < 0.7 * one, "two runs {two} °/h vs one run {one} °/h");
}

#[test]
fn fit_with_report_writes_the_model_the_table_and_the_bias_against_temperature() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let (model, report) = (dir.path().join("m.bin"), dir.path().join("report"));
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            "-q",
            "--method",
            "poly3",
            run.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ];
        args.extend(extra);
        trainer(&args)
    };
    let o = fit(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(model.exists());
    let png = std::fs::read(report.join("ifog_train_1cpm_bias_vs_temp.png")).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let svg = std::fs::read_to_string(report.join("ifog_train_1cpm_bias_vs_temp.svg")).unwrap();
    for needle in [
        "loop temperature T [°C]",
        "residual [°/h]",
        "measured, heating",
        "model",
    ] {
        assert!(svg.contains(needle), "bias_vs_temp.svg lacks {needle:?}");
    }
    // fit.txt is what the command printed, table included.
    let printed = stdout(&o);
    let fit_txt = std::fs::read_to_string(report.join("fit.txt")).unwrap();
    assert!(
        fit_txt.contains("STD100 bef") && printed.starts_with(&fit_txt),
        "{fit_txt}"
    );
    assert!(printed.contains("files into"), "{printed}");
    let md = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(md.contains("(ifog_train_1cpm_bias_vs_temp.svg)"), "{md}");
    // A second fit into the same report replaces nothing without --force.
    let o = fit(&["--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::remove_file(&model).unwrap();
    let o = fit(&[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("exists"), "{}", stderr(&o));
    assert!(!model.exists(), "refused before the fit");
}

#[test]
fn a_compensated_run_names_the_model_that_compensated_it_and_reads_as_a_run() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let (run, out) = (dir.path().join("train.csv"), dir.path().join("out.csv"));
    let o = compensate(&model, &run, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    // The file's name and the blob's CRC-32 trailer (what `trainer device
    // status` names as a unit's running model), before the run's own lines.
    let blob = std::fs::read(&model).unwrap();
    let crc = u32::from_le_bytes(blob[blob.len() - 4..].try_into().unwrap());
    let name = model.file_name().unwrap().to_str().unwrap();
    let text = std::fs::read_to_string(&out).unwrap();
    let head: String = text.lines().take(3).collect::<Vec<_>>().join("\n");
    assert!(
        text.starts_with(&format!("# model: {name}\n# model_blob_crc32: {crc:#010x}\n")),
        "{head}"
    );
    // Still a recorded run: eval reads it.
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn inspect_and_eval_take_model_and_json_file_with_dash_for_stdout() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let (m, run) = (model.to_str().unwrap(), dir.path().join("train.csv"));
    // The summary: no JSON fragments.
    let text = stdout(&trainer(&["inspect", "--model", m]));
    assert!(
        text.contains("CRC-32          ok") && text.contains("serial          none"),
        "{text}"
    );
    assert!(!text.contains("null") && !text.contains('"'), "{text}");
    // --json FILE writes the file, --json - standard output (the summary then goes to stderr).
    let json_file = dir.path().join("inspect.json");
    let o = trainer(&["inspect", "--model", m, "--json", json_file.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let v = crate::common::read_json(&json_file);
    assert_eq!(v["crc"], "ok");
    let o = trainer(&["inspect", "--model", m, "--json", "-"]);
    let w: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert_eq!(v, w);
    assert!(stderr(&o).contains("CRC-32          ok"));
    // --format toml: every parameter, one per line, tables per group.
    let toml = stdout(&trainer(&["inspect", "--model", m, "--format", "toml"]));
    assert!(toml.contains("crc = \"ok\"\n") && toml.contains("\n[rbf]\n"), "{toml}");
    assert!(toml.contains("\n[[training_ranges]]\n"), "{toml}");
    let o = trainer(&["eval", "--model", m, run.to_str().unwrap(), "--json", "-"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let evals: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    assert!(evals[0]["cluster_std_improvement_pct"].as_f64().unwrap() > 50.0);
    assert!(stderr(&o).contains("Overlapping Allan deviation"));
}

#[test]
fn every_subcommand_shows_an_example_and_fit_short_help_fits_a_screen() {
    for command in [
        "fit",
        "compensate",
        "eval",
        "inspect",
        "report",
        "simulate",
        "decode",
        "blocks",
        "correlate",
    ] {
        let help = stdout(&trainer(&[command, "-h"]));
        assert!(
            help.contains(&format!("\n  trainer {command} ")),
            "{command} -h has no example:\n{help}"
        );
    }
    for device in ["status", "update", "record"] {
        let help = stdout(&trainer(&["device", device, "-h"]));
        assert!(
            help.contains(&format!("\n  trainer device {device} --port ")),
            "device {device} -h has no example:\n{help}"
        );
    }
    let short = stdout(&trainer(&["fit", "-h"]));
    assert!(short.lines().count() <= 45, "{short}");
    for heading in ["Data:", "Model:", "Search:", "Output:", "Multi-point:"] {
        assert!(short.contains(heading), "fit -h lacks {heading}");
    }
}

#[test]
fn device_commands_fail_at_once_naming_a_missing_port_or_model_and_change_no_file() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("run.csv");
    for args in [
        &["device", "status", "--port", "/dev/no-such-gyro"][..],
        &[
            "device",
            "record",
            "--port",
            "/dev/no-such-gyro",
            "--seconds",
            "1",
            "-o",
            run.to_str().unwrap(),
        ][..],
    ] {
        let started = std::time::Instant::now();
        let o = trainer(args);
        assert!(!o.status.success());
        assert!(stderr(&o).contains("/dev/no-such-gyro: no such port"), "{}", stderr(&o));
        assert!(started.elapsed() < std::time::Duration::from_secs(5));
    }
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "no file written or left"
    );
    // The blob is checked before the port is opened.
    let blob = dir.path().join("model.bin");
    std::fs::write(&blob, [0xFFu8; 64]).unwrap();
    let o = trainer(&[
        "device",
        "update",
        "--port",
        "/dev/no-such-gyro",
        "--model",
        blob.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains(&format!(
            "{}: no unit would take this blob, nothing sent",
            blob.display()
        )),
        "{}",
        stderr(&o)
    );
}

/// `fit --spec` judges the unit: a spec it meets passes (exit 0), one it cannot meet
/// fails naming the limit (exit 3) with the blob and JSON still written; the spec's
/// SHA-256 is in the blob's provenance; a spec with an unknown key is refused before any
/// work (exit 1, file and line named).
#[test]
fn fit_with_a_spec_passes_or_fails_naming_the_limit_missed() {
    let dir = TempDir::new().unwrap();
    let (train, holdout) = (dir.path().join("train.csv"), dir.path().join("holdout.csv"));
    for (path, seed) in [(&train, "7"), (&holdout, "8")] {
        short_chamber_run(path, seed);
    }
    let lenient = write(
        &dir,
        "lenient.toml",
        b"[holdout]\nstd100_gain_min_pct = 1\nclamped_max_pct = 100\n",
    );
    let strict = write(&dir, "strict.toml", b"[holdout]\nstd100_after_max_dph = 1e-9\n");
    let unknown = write(&dir, "unknown.toml", b"[holdout]\nstd100_after_max_mdph = 1\n");
    let fit = |spec: &Path, name: &str| {
        let model = dir.path().join(format!("{name}.bin"));
        let json = dir.path().join(format!("{name}.json"));
        let o = trainer(&[
            "fit",
            "-q",
            train.to_str().unwrap(),
            "--holdout",
            holdout.to_str().unwrap(),
            "--spec",
            spec.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ]);
        (o, model, json)
    };
    let (o, model, json) = fit(&lenient, "lenient");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["acceptance"]["status"], "pass", "{}", report["acceptance"]);
    let inspected: serde_json::Value = serde_json::from_str(&stdout(&trainer(&[
        "inspect",
        "--model",
        model.to_str().unwrap(),
        "--format",
        "json",
    ])))
    .unwrap();
    assert_eq!(
        inspected["provenance"]["spec_sha256"],
        ::trainer::provenance::sha256_file(&lenient).unwrap().as_str()
    );
    let (o, model, json) = fit(&strict, "strict");
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(stderr(&o).contains("std100_after_max_dph"), "{}", stderr(&o));
    assert!(model.exists() && json.exists(), "a failed unit's outputs are written");
    let report: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(report["acceptance"]["status"], "fail");
    let (o, model, _) = fit(&unknown, "unknown");
    assert_eq!(o.status.code(), Some(1));
    assert!(
        stderr(&o).contains("unknown.toml:2:1:") && stderr(&o).contains("std100_after_max_mdph"),
        "{}",
        stderr(&o)
    );
    assert!(!model.exists());
}
