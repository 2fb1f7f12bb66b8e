//! Three-axis IMU runs end to end through the CLI: `simulate --axes 3`, one
//! `fit` for every axis, `eval`, `compensate` and `inspect` per axis, and
//! each axis no worse than fitting it alone.

use std::path::{Path, PathBuf};

use crate::common::{compensate, eval_json, stderr, stdout, trainer, with_model};
use tempfile::TempDir;

/// `trainer simulate --axes 3` of `profile` with `seed` into `dir/name`.
fn simulate_imu(dir: &TempDir, name: &str, profile: &str, seed: &str) -> PathBuf {
    simulate_axes(dir, name, &["--profile", profile, "--seed", seed])
}

/// `trainer simulate --axes 3 --shared-thermometer` of `profile` with `seed` into `dir/name`.
fn simulate_shared_imu(dir: &TempDir, name: &str, profile: &str, seed: &str) -> PathBuf {
    simulate_axes(
        dir,
        name,
        &["--profile", profile, "--seed", seed, "--shared-thermometer"],
    )
}

/// `trainer simulate --axes 3` with `args` into `dir/name`, which must succeed.
fn simulate_axes(dir: &TempDir, name: &str, args: &[&str]) -> PathBuf {
    let path = dir.path().join(name);
    let fixed = ["simulate", "--axes", "3", "-o", path.to_str().unwrap()];
    let o = trainer(&[&fixed[..], args].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    path
}

/// The single-axis run of `axis` in the multi-axis run `run`: its metadata,
/// then time_s, rate_dph, temp_c, ref_dph with the axis's fields as written.
fn extract_axis(run: &Path, axis: &str, out: &Path) {
    let text = std::fs::read_to_string(run).unwrap();
    let mut lines = text.lines();
    let mut single = String::new();
    let header = loop {
        let line = lines.next().unwrap();
        if line.starts_with('#') {
            single.push_str(line);
            single.push('\n');
        } else {
            break line;
        }
    };
    let names: Vec<&str> = header.split(',').collect();
    let at = |name: String| names.iter().position(|n| *n == name).unwrap();
    let wanted = [
        at("time_s".into()),
        at(format!("rate_{axis}_dph")),
        names
            .iter()
            .position(|n| *n == format!("temp_{axis}_c"))
            .unwrap_or_else(|| at("temp_c".into())),
        at(format!("ref_{axis}_dph")),
    ];
    single.push_str("time_s,rate_dph,temp_c,ref_dph\n");
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        let row: Vec<&str> = wanted.iter().map(|&i| fields[i]).collect();
        single.push_str(&row.join(","));
        single.push('\n');
    }
    std::fs::write(out, single).unwrap();
}

/// `trainer fit TRAIN -o MODEL`.
fn fit(train: &Path, model: &Path) -> String {
    fit_with(train, model, &[])
}

/// `trainer fit` with `extra` options; what it printed.
fn fit_with(train: &Path, model: &Path, extra: &[&str]) -> String {
    fit_printing(train, model, extra).0
}

/// `trainer fit` with `extra` options; its standard output and error.
fn fit_printing(train: &Path, model: &Path, extra: &[&str]) -> (String, String) {
    let args = ["fit", train.to_str().unwrap(), "-o", model.to_str().unwrap(), "--quiet"];
    let o = trainer(&[&args[..], extra].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    (stdout(&o), stderr(&o))
}

/// MSD improvements (%) `trainer eval --json` gives for `run`, per row.
fn msd_gains(model: &Path, run: &Path) -> Vec<(Option<String>, f64)> {
    gains(model, run, "msd_improvement_pct")
}

/// The improvement `key` (%) `trainer eval --json` gives for `run`, per row.
fn gains(model: &Path, run: &Path, key: &str) -> Vec<(Option<String>, f64)> {
    let json = eval_json(model.to_str().unwrap(), run.to_str().unwrap());
    json.as_array()
        .unwrap()
        .iter()
        .map(|e| (e["axis"].as_str().map(str::to_owned), e[key].as_f64().unwrap()))
        .collect()
}

/// The values of the columns `names` in the data rows of a compensated run.
fn columns(path: &Path, names: &[String]) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at: Vec<usize> = names
        .iter()
        .map(|n| header.iter().position(|h| h == n).unwrap())
        .collect();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            at.iter().map(|&i| f[i].to_owned()).collect()
        })
        .collect()
}

#[test]
fn a_three_axis_imu_is_fitted_compensated_and_evaluated_per_axis_as_well_as_each_axis_alone() {
    let dir = TempDir::new().unwrap();
    let train = simulate_imu(&dir, "cycle3.csv", "cycle", "11");
    let verify = simulate_imu(&dir, "random3.csv", "random", "12");
    let model = dir.path().join("imu.bin");
    let printed = fit(&train, &model);
    for axis in ["x", "y", "z"] {
        assert!(printed.contains(&format!("axis {axis}:\nmodel: ")), "{printed}");
        assert!(
            printed
                .lines()
                .any(|l| l.starts_with("train") && l.contains("cycle3.csv") && l.contains(&format!(" {axis} "))),
            "a table row per run and axis: {printed}"
        );
    }
    assert!(printed.contains("axes x, y, z)"), "{printed}");

    let gains = msd_gains(&model, &verify);
    assert_eq!(gains.len(), 3);
    // Read once: standard input gives the same figures.
    let o = crate::common::trainer_with_stdin(
        &["eval", "--model", model.to_str().unwrap(), "-", "--json", "-"],
        &std::fs::read(&verify).unwrap(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let piped: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let piped: Vec<f64> = piped
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["msd_improvement_pct"].as_f64().unwrap())
        .collect();
    assert_eq!(piped, gains.iter().map(|g| g.1).collect::<Vec<_>>());
    let compensated = dir.path().join("random3-comp.csv");
    let o = compensate(&model, &verify, &compensated, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    for (axis, gain) in &gains {
        let axis = axis.as_deref().expect("each row names its axis");
        assert!(
            *gain >= 85.0,
            "axis {axis}: MSD improvement {gain:.1} % on the random profile"
        );
        // The axis alone: extracted to single-axis runs, fitted, evaluated.
        let train_alone = dir.path().join(format!("cycle-{axis}.csv"));
        let verify_alone = dir.path().join(format!("random-{axis}.csv"));
        extract_axis(&train, axis, &train_alone);
        extract_axis(&verify, axis, &verify_alone);
        let model_alone = dir.path().join(format!("{axis}.bin"));
        fit(&train_alone, &model_alone);
        let alone = msd_gains(&model_alone, &verify_alone);
        assert_eq!(alone.len(), 1);
        assert_eq!(alone[0].0, None);
        assert!(
            *gain >= alone[0].1 - 0.5,
            "axis {axis}: {gain:.2} % in the IMU fit, {:.2} % alone",
            alone[0].1
        );
        // The same model and the same compensation step: the IMU output's
        // columns of this axis are the single-axis output's, digit for digit.
        let out_alone = dir.path().join(format!("random-{axis}-comp.csv"));
        let o = compensate(&model_alone, &verify_alone, &out_alone, &[]);
        assert!(o.status.success(), "{}", stderr(&o));
        let multi = columns(
            &compensated,
            &[
                format!("bias_{axis}_dph"),
                format!("rate_comp_{axis}_dph"),
                format!("flags_{axis}"),
            ],
        );
        let single = columns(&out_alone, &["bias_dph".into(), "rate_comp_dph".into(), "flags".into()]);
        assert_eq!(multi.len(), single.len());
        assert!(
            multi == single,
            "axis {axis}: compensated columns differ from the axis alone"
        );
        eprintln!(
            "axis {axis}: MSD improvement {gain:.2} % (IMU fit), {:.2} % (alone)",
            alone[0].1
        );
    }

    let o = trainer(&["inspect", "--model", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let shown = stdout(&o);
    assert!(
        shown.contains("format version  5\n") && shown.contains("axis z\n"),
        "{shown}"
    );
}

#[test]
fn models_and_runs_of_different_axes_are_refused_naming_both() {
    let dir = TempDir::new().unwrap();
    let imu = dir.path().join("imu.csv");
    let o = trainer(&["simulate", "--axes", "2", "--hours", "3", "-o", imu.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let single_run = dir.path().join("single.csv");
    extract_axis(&imu, "x", &single_run);
    let single_model = dir.path().join("single.bin");
    fit(&single_run, &single_model);
    let imu_model = dir.path().join("imu.bin");
    fit(&imu, &imu_model);
    // A report per axis.
    let report = dir.path().join("report");
    let o = with_model("report", &imu_model, &imu, &report, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A summary page puts the axes side by side; each axis's page and plots name the axis.
    let summary = std::fs::read_to_string(report.join("report.md")).unwrap();
    assert!(
        summary.contains("# Compensation report, axes x, y")
            && summary.contains("| imu | x |")
            && summary.contains("| imu | y |")
            && summary.contains("(axis-y/report.md)"),
        "{summary}"
    );
    for axis in ["x", "y"] {
        let md = std::fs::read_to_string(report.join(format!("axis-{axis}/report.md"))).unwrap();
        assert!(
            md.contains("| imu |") && md.contains(&format!("# Compensation report, axis {axis}")),
            "{md}"
        );
        let allan = std::fs::read_to_string(report.join(format!("axis-{axis}/imu_allan.svg"))).unwrap();
        assert!(
            allan.contains(&format!("imu, axis {axis}: overlapping Allan deviation")),
            "axis {axis}"
        );
    }
    assert!(!report.join("axis-z").exists());
    let out = dir.path().join("out.csv");
    let o = compensate(&single_model, &imu, &out, &[]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("holds a model for one axis (rate_dph)") && stderr(&o).contains("has axes x, y"),
        "{}",
        stderr(&o)
    );
    let o = trainer(&[
        "eval",
        "--model",
        imu_model.to_str().unwrap(),
        single_run.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("holds a model for axes x, y"), "{}", stderr(&o));
    assert!(!out.exists(), "nothing written");
    // A fit's runs carry the same axes.
    let o = trainer(&[
        "fit",
        imu.to_str().unwrap(),
        single_run.to_str().unwrap(),
        "-o",
        dir.path().join("m.bin").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("the runs of one fit carry the same axes"),
        "{}",
        stderr(&o)
    );
    // A bad field of the second axis, deep in the run: named by file, line
    // and column, and nothing written.
    let text = std::fs::read_to_string(&imu).unwrap();
    let header_line = text.lines().position(|l| !l.starts_with('#')).unwrap();
    let bad_line = header_line + 5000;
    let damaged: Vec<String> = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == bad_line {
                let mut f: Vec<&str> = l.split(',').collect();
                f[4] = "1.2.3";
                f.join(",")
            } else {
                l.to_owned()
            }
        })
        .collect();
    let damaged = crate::common::write(&dir, "damaged.csv", (damaged.join("\n") + "\n").as_bytes());
    let want = format!(
        "damaged.csv:{}: column rate_y_dph (field 5): \"1.2.3\" is not a number",
        bad_line + 1
    );
    let o = compensate(&imu_model, &damaged, &out, &[]);
    assert!(!o.status.success() && stderr(&o).contains(&want), "{}", stderr(&o));
    assert!(!out.exists(), "nothing written");
    let o = trainer(&[
        "eval",
        "--model",
        imu_model.to_str().unwrap(),
        damaged.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains(&want), "{}", stderr(&o));
    // A run with rate_dph and a per-axis rate.
    let mixed = crate::common::write(
        &dir,
        "mixed.csv",
        b"time_s,rate_dph,temp_c,rate_y_dph\n0,1,20,2\n1,1,20,2\n",
    );
    let o = compensate(&imu_model, &mixed, &out, &[]);
    assert!(
        stderr(&o).contains("mixed.csv:1: column rate_y_dph (field 4): a run has rate_dph"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_multi_axis_fit_keeps_every_axis_within_the_three_axis_firmware_s_centers() {
    let dir = TempDir::new().unwrap();
    let imu = dir.path().join("imu.csv");
    let o = trainer(&["simulate", "--axes", "2", "--hours", "2", "-o", imu.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let model = dir.path().join("imu.bin");
    let fit = |extra: &[&str]| {
        let args = [
            "fit",
            "-q",
            "--force",
            imu.to_str().unwrap(),
            "-o",
            model.to_str().unwrap(),
        ];
        trainer(&[&args[..], extra].concat())
    };
    let o = fit(&["--centers", "17"]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("at most 16 centres per axis"), "{}", stderr(&o));
    assert!(!model.exists(), "nothing written");
    // The limit itself is taken.
    let o = fit(&["--centers", "16"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = trainer(&["inspect", "--model", model.to_str().unwrap(), "--format", "json"]);
    let json: serde_json::Value = serde_json::from_str(&stdout(&o)).unwrap();
    let text = json.to_string();
    assert!(text.contains("\"centers\""), "{text}");
    for axis in json["axes"].as_array().unwrap() {
        assert!(
            axis["centers"].as_u64().unwrap() <= rbf_core::MAX_AXIS_CENTERS as u64,
            "{axis}"
        );
    }
}

#[test]
fn on_a_shared_thermometer_imu_every_axis_keeps_the_accuracy_of_its_own_fit_and_joint_forces_one_basis() {
    let dir = TempDir::new().unwrap();
    let train = simulate_shared_imu(&dir, "cycle3.csv", "cycle", "11");
    let verify = simulate_shared_imu(&dir, "random3.csv", "random", "12");
    // The default tries the joint model and says per axis what it costs.
    let default = dir.path().join("default.bin");
    let printed = fit(&train, &default);
    for axis in ["x", "y", "z"] {
        assert!(
            printed.contains(&format!("  axis {axis}: ")) && printed.contains("% own fit: "),
            "the choice per axis: {printed}"
        );
    }
    assert!(printed.contains("chose: "), "{printed}");
    // Whatever it chose, no axis compensates the unseen run worse than that
    // axis fitted alone (STD100 within 0.5 points), and every axis ≥ 85 %.
    let deployed = gains(&default, &verify, "cluster_std_improvement_pct");
    assert_eq!(deployed.len(), 3);
    for (axis, gain) in &deployed {
        let axis = axis.as_deref().expect("each row names its axis");
        // The axis alone: extracted to a single-axis run, fitted, evaluated.
        let train_alone = dir.path().join(format!("cycle-{axis}.csv"));
        let verify_alone = dir.path().join(format!("random-{axis}.csv"));
        extract_axis(&train, axis, &train_alone);
        extract_axis(&verify, axis, &verify_alone);
        let model_alone = dir.path().join(format!("{axis}.bin"));
        fit(&train_alone, &model_alone);
        let alone = gains(&model_alone, &verify_alone, "cluster_std_improvement_pct")[0].1;
        eprintln!("axis {axis}: STD100 improvement {gain:.2} % (default), {alone:.2} % (alone)");
        assert!(*gain >= 85.0, "axis {axis}: {gain:.2} %");
        assert!(
            *gain >= alone - 0.5,
            "axis {axis}: {gain:.2} % deployed, {alone:.2} % alone"
        );
    }

    // --joint writes the one-basis model whatever it costs an axis.
    let model = dir.path().join("imu.bin");
    let printed = fit_with(&train, &model, &["--joint"]);
    assert!(printed.contains("chose: the joint model"), "{printed}");
    let o = trainer(&["inspect", "--model", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("shared basis    yes"), "{}", stdout(&o));
    for (axis, gain) in msd_gains(&model, &verify) {
        assert!(gain >= 85.0, "axis {axis:?}: {gain:.2} % (joint)");
    }
    // Compensated with the shared step: every axis's columns, one row per input row.
    let compensated = dir.path().join("random3-comp.csv");
    let o = compensate(&model, &verify, &compensated, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let names: Vec<String> = ["x", "y", "z"].iter().map(|a| format!("bias_{a}_dph")).collect();
    let biases = columns(&compensated, &names);
    assert!(biases.len() > 1000);
    assert!(
        biases
            .iter()
            .all(|r| r.iter().all(|v| v.parse::<f32>().is_ok_and(f32::is_finite)))
    );

    // --no-joint keeps a model per axis.
    let per_axis = dir.path().join("per-axis.bin");
    let o = trainer(&[
        "fit",
        train.to_str().unwrap(),
        "-o",
        per_axis.to_str().unwrap(),
        "--no-joint",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("not tried: --no-joint"), "{}", stdout(&o));
    let o = trainer(&["inspect", "--model", per_axis.to_str().unwrap()]);
    assert!(!stdout(&o).contains("shared basis    yes"), "{}", stdout(&o));

    // A report per axis.
    let report = dir.path().join("report");
    let o = trainer(&[
        "report",
        "--model",
        model.to_str().unwrap(),
        verify.to_str().unwrap(),
        "-o",
        report.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(report.join("axis-z").is_dir());

    // A run whose axes have their own thermometers is refused by this model, naming why.
    let own = simulate_imu(&dir, "own.csv", "random", "13");
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), own.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("own thermometers"), "{}", stderr(&o));
    // And fitting such runs keeps a model per axis, saying why.
    let separate = dir.path().join("own.bin");
    let printed = fit(&own, &separate);
    assert!(
        printed.contains("not tried") && printed.contains("chose: a model per axis"),
        "{printed}"
    );
}

/// A multi-axis fit names the gaps of its runs' time column as a
/// single-axis fit does, once for all axes (they share the column), and
/// says nothing of a run without any.
#[test]
fn a_multi_axis_fit_names_the_gaps_of_its_runs_once() {
    let dir = TempDir::new().unwrap();
    let imu = simulate_axes(&dir, "imu.csv", &["--profile", "cycle", "--hours", "2"]);
    // 600 s lost before the 3000th data row.
    let text = std::fs::read_to_string(&imu).unwrap();
    let (mut gapped, mut data_rows, mut gap_line) = (String::new(), 0usize, 0usize);
    for (k, line) in text.lines().enumerate() {
        let is_data = !line.starts_with('#') && !line.starts_with("time_s");
        if is_data && data_rows >= 3000 {
            let (time, rest) = line.split_once(',').unwrap();
            gapped.push_str(&format!("{:.4},{rest}\n", time.parse::<f64>().unwrap() + 600.0));
            if gap_line == 0 {
                gap_line = k + 1;
            }
        } else {
            gapped.push_str(line);
            gapped.push('\n');
        }
        data_rows += usize::from(is_data);
    }
    let gapped_path = dir.path().join("gapped.csv");
    std::fs::write(&gapped_path, gapped).unwrap();
    let (_, errors) = fit_printing(&gapped_path, &dir.path().join("gapped.bin"), &[]);
    assert_eq!(errors.matches("note:").count(), 1, "{errors}");
    assert!(errors.contains("1 gap in time_s"), "{errors}");
    assert!(errors.contains(&format!("before line {gap_line}")), "{errors}");
    let (_, errors) = fit_printing(&imu, &dir.path().join("imu.bin"), &[]);
    assert!(!errors.contains("note:"), "{errors}");
}
