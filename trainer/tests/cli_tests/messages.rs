//! Messages that name the cause and the file, limits that hold on every
//! path, and no NaN in a table (issue 35): each test states the case a user
//! met and what they must be told.

use std::path::{Path, PathBuf};

use crate::common::{compensate, fit_ok, shared_data, simulated, stderr, stdout, trainer, write};
use tempfile::TempDir;

/// Fails unless `o` exited 1 with a message containing every one of
/// `expected`, no panic, and nothing was written into `dir` but `keep`.
#[track_caller]
fn refused(o: &std::process::Output, expected: &[&str]) {
    let message = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{message}");
    for e in expected {
        assert!(message.contains(e), "expected {e:?}, got {message}");
    }
    assert!(!message.contains("panicked"), "{message}");
}

/// The first data rows of the shipped 0.2-Hz example, header included, without metadata.
fn example_rows(rows: usize) -> String {
    let text = std::fs::read_to_string(shared_data("cycle_train_1cpm.csv")).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).take(rows + 1).collect();
    lines.join("\n") + "\n"
}

/// A model fitted on the shipped 0.2-Hz example (`m.bin` in `dir`); the fit's printout.
fn example_model(dir: &TempDir) -> (PathBuf, String) {
    let model = dir.path().join("m.bin");
    let run = shared_data("cycle_train_1cpm.csv");
    let o = trainer(&["fit", "-q", run.to_str().unwrap(), "-o", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    (model, stdout(&o))
}

#[test]
fn the_shipped_example_fits_with_every_figure_of_its_table() {
    let dir = TempDir::new().unwrap();
    // 0.2 Hz in the default 1-s blocks: one block every 5 s.
    let (_, printed) = example_model(&dir);
    let row = printed.lines().find(|l| l.starts_with("train ")).unwrap();
    assert!(!row.contains("NaN") && !row.contains('—'), "{row}");
}

#[test]
fn a_run_too_short_for_a_figure_shows_a_dash_and_why_never_nan() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    let three = write(&dir, "three.csv", example_rows(3).as_bytes());
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), three.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = stdout(&o);
    assert!(!printed.contains("NaN"), "{printed}");
    assert!(printed.contains("—: not enough data for the figure"), "{printed}");
    assert!(printed.contains("too short for an Allan deviation"), "{printed}");
}

#[test]
fn cr_only_line_endings_are_named_whatever_the_file_size() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    for rows in [3, 2000] {
        let cr = example_rows(rows).replace('\n', "\r");
        // Also a header ended by \n over rows ended by \r alone.
        let (header, rows_cr) = cr.split_once('\r').unwrap();
        for text in [
            cr.clone(),
            format!("# sample_rate_hz: 0.2\r{cr}"),
            format!("{header}\n{rows_cr}"),
        ] {
            let run = write(&dir, "cr.csv", text.as_bytes());
            let out = dir.path().join("out.csv");
            let o = compensate(&model, &run, &out, &[]);
            refused(&o, &["cr.csv:", "CR-only line endings"]);
            assert!(!out.exists());
        }
    }
}

#[test]
fn arguments_that_cannot_be_files_or_runs_say_so() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("cycle_train_1cpm.csv");
    let run = run.to_str().unwrap();
    let m = dir.path().join("m.bin");
    let m = m.to_str().unwrap();
    refused(
        &trainer(&["fit", dir.path().to_str().unwrap(), "-o", m]),
        &["is a directory, not a recorded run"],
    );
    refused(
        &trainer(&["fit", run, "-o", "-"]),
        &["- (standard output) cannot take this output"],
    );
    refused(
        &trainer(&[
            "fit",
            run,
            "-o",
            m,
            "--method",
            "svr-pso",
            "--inputs",
            "temp_a-temp_b,temp_b-temp_a",
        ]),
        &["--inputs names temp_a-temp_b and temp_b-temp_a: the same input twice"],
    );
    refused(
        &trainer(&["fit", run, "-o", m, "--inputs", "temp_a,temp_a"]),
        &["the same input twice"],
    );
    assert!(!Path::new(m).exists());
}

#[test]
fn block_lengths_are_refused_outside_the_range_they_are_checked_against() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("cycle_train_1cpm.csv");
    let out = dir.path().join("b.csv");
    for bad in ["1e-200", "1e300", "0", "nan"] {
        for command in ["blocks", "fit"] {
            let o = trainer(&[
                command,
                run.to_str().unwrap(),
                "--block-s",
                bad,
                "-o",
                out.to_str().unwrap(),
            ]);
            refused(&o, &["--block-s", "must be 0.001 … 86400 s"]);
        }
    }
    assert!(!out.exists());
}

#[test]
fn blocks_refuses_more_blocks_than_it_holds_naming_the_limit() {
    let dir = TempDir::new().unwrap();
    // 3.5 h at 100 Hz: 1,260,000 samples, each its own block at --block-s 0.01
    // (the paper's inputs: a short warm-up).
    let run = dir.path().join("fast.csv");
    simulated(&run, &["--hours", "3.5", "--sample-rate-hz", "100"]);
    let out = dir.path().join("b.csv");
    let o = trainer(&[
        "blocks",
        run.to_str().unwrap(),
        "--features",
        "paper",
        "--block-s",
        "0.01",
        "-o",
        out.to_str().unwrap(),
    ]);
    refused(&o, &["more than 1048576 blocks of 0.01 s", "(the limit)", "or longer"]);
    assert!(!out.exists());
}

#[test]
fn a_validation_run_too_short_is_blamed_by_name() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("cycle_train_1cpm.csv");
    let three = write(&dir, "three.csv", example_rows(3).as_bytes());
    let m = dir.path().join("m.bin");
    let o = trainer(&[
        "fit",
        "-q",
        run.to_str().unwrap(),
        "--validate",
        three.to_str().unwrap(),
        "-o",
        m.to_str().unwrap(),
    ]);
    refused(&o, &["three.csv: the --validate run spans only 10 s (3 rows)"]);
    assert!(!m.exists());
}

#[test]
fn multi_axis_diagnostics_name_the_axis_columns() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("imu.csv");
    simulated(&run, &["--axes", "2", "--ramp", "1", "--hold-min", "30"]);
    let model = dir.path().join("imu.bin");
    fit_ok(&["-q", "--method", "poly3"], &run, &model);
    // The y coil's thermometer in kelvin.
    let text = std::fs::read_to_string(&run).unwrap();
    let mut header: Option<Vec<String>> = None;
    let mut kelvin = String::new();
    for line in text.lines() {
        let mut fields: Vec<String> = line.split(',').map(str::to_owned).collect();
        match &header {
            _ if line.starts_with('#') => {}
            None => header = Some(fields.clone()),
            Some(h) => {
                let i = h.iter().position(|c| c == "temp_y_c").unwrap();
                fields[i] = (fields[i].parse::<f64>().unwrap() + 273.15).to_string();
            }
        }
        kelvin.push_str(&fields.join(","));
        kelvin.push('\n');
    }
    let k = write(&dir, "kelvin.csv", kelvin.as_bytes());
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), k.to_str().unwrap()]);
    refused(&o, &["axis y", "kelvin.csv: temp_y_c: 12600 of 12600 readings"]);
}

#[test]
fn compensate_says_what_it_does_with_comment_lines_between_rows() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    let mut text = example_rows(4);
    text.insert_str(text.find("\n5.").unwrap() + 1, "# a note between rows\n");
    let run = write(&dir, "noted.csv", text.as_bytes());
    let out = dir.path().join("out.csv");
    let o = compensate(&model, &run, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(!written.contains("a note"), "{written}");
    let help = stdout(&trainer(&["compensate", "--help"]));
    let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        help.contains("lines between data rows are not part of the format and are dropped"),
        "{help}"
    );
}

#[test]
fn simulate_refuses_what_it_would_not_finish_or_the_reader_would_refuse() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("run.csv");
    let o = |args: &[&str]| trainer(&[&["simulate"][..], args, &["-o", out.to_str().unwrap()]].concat());
    refused(
        &o(&["--hours", "1000", "--sample-rate-hz", "10000"]),
        &["would take about 1728.0 GB", "at most 4 GiB"],
    );
    refused(
        &o(&["--sample-rate-hz", "1e-4", "--hours", "100"]),
        &["--sample-rate-hz 0.0001: must be 0.001 … 10000 Hz"],
    );
    refused(
        &o(&["--sample-rate-hz", "0"]),
        &["--sample-rate-hz 0: must be 0.001 … 10000 Hz"],
    );
    refused(
        &o(&["--hours", "1e-9"]),
        &["the run would hold 0 samples", "at least 2"],
    );
    refused(
        &o(&["--hours", "0"]),
        &["--hours 0: must be more than 0 and at most 1000 h"],
    );
    let far = write(&dir, "far.csv", b"time_s,chamber_c\n0,20\n1e12,30\n");
    refused(
        &o(&["--chamber-profile", far.to_str().unwrap()]),
        &["far.csv: the run would last", "at most 1000 h"],
    );
    refused(
        &o(&["--chamber-profile", "/dev/zero"]),
        &["/dev/zero: more than 134217728 bytes; a chamber profile is at most 128 MiB (the limit)"],
    );
    let one = write(&dir, "one.csv", b"time_s,chamber_c\n0,20\n");
    refused(
        &o(&["--chamber-profile", one.to_str().unwrap()]),
        &["one.csv: the run would hold 0 samples"],
    );
    assert!(!out.exists());
}

/// The shipped 1-Hz example with `time_s` multiplied by `factor` and no
/// `# sample_rate_hz` line, as `name` in `dir`.
fn retimed(dir: &TempDir, name: &str, factor: f64) -> PathBuf {
    let text = std::fs::read_to_string(shared_data("ifog_train_1cpm.csv")).unwrap();
    let mut out = String::new();
    let mut header = false;
    for line in text.lines() {
        if line.starts_with('#') {
            if !line.contains("sample_rate_hz") {
                out.push_str(line);
                out.push('\n');
            }
            continue;
        }
        if !header {
            header = true;
            out.push_str(line);
        } else {
            let (t, rest) = line.split_once(',').unwrap();
            out.push_str(&format!("{},{rest}", t.parse::<f64>().unwrap() * factor));
        }
        out.push('\n');
    }
    write(dir, name, out.as_bytes())
}

#[test]
fn a_time_column_in_milliseconds_or_hours_is_suspected_by_name() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    let out = dir.path().join("out.csv");
    let ms = retimed(&dir, "ms.csv", 1000.0);
    for o in [
        compensate(&model, &ms, &out, &[]),
        trainer(&["eval", "--model", model.to_str().unwrap(), ms.to_str().unwrap()]),
        trainer(&["fit", "-q", ms.to_str().unwrap(), "-o", out.to_str().unwrap()]),
    ] {
        refused(
            &o,
            &["ms.csv:", "column time_s steps by 1000 s", "is time_s in milliseconds?"],
        );
    }
    let hours = retimed(&dir, "hours.csv", 1.0 / 3600.0);
    let o = trainer(&["fit", "-q", hours.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    refused(
        &o,
        &[
            "hours.csv: its 28800 rows span only 8 s",
            "is time_s in seconds (not hours or minutes)?",
        ],
    );
    assert!(!out.exists());
}

#[test]
fn a_cr_only_tail_after_lf_rows_is_named_as_such_by_every_command() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    let m = model.to_str().unwrap();
    // 1500 rows ending in \n, then 600 ending in \r alone (past the reader's look-ahead).
    let rows = example_rows(2100);
    let lines: Vec<&str> = rows.lines().collect();
    let text = format!("{}\n{}\r", lines[..1501].join("\n"), lines[1501..].join("\r"));
    let run = write(&dir, "tail.csv", text.as_bytes());
    let r = run.to_str().unwrap();
    let out = dir.path().join("out.csv");
    let o_ = out.to_str().unwrap();
    for args in [
        vec!["compensate", "--model", m, r, "-o", o_],
        vec!["eval", "--model", m, r],
        vec!["fit", "-q", r, "-o", o_],
    ] {
        let o = trainer(&args);
        refused(
            &o,
            &["tail.csv:1502:", "from this line on the file uses CR-only line endings"],
        );
        assert!(!stderr(&o).contains("fields"), "{args:?}: {}", stderr(&o));
    }
}

#[test]
fn a_block_longer_than_the_run_is_named_as_the_cause() {
    let dir = TempDir::new().unwrap();
    // 3.5 h: a day-long block holds none of it whole.
    let run = dir.path().join("short.csv");
    crate::common::short_chamber_run(&run, "3");
    let model = dir.path().join("m.bin");
    let o = trainer(&[
        "fit",
        "-q",
        "--block-s",
        "86400",
        run.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
    ]);
    refused(
        &o,
        &[
            "no block of 86400 s is whole",
            "--block-s 86400 is longer than the runs",
        ],
    );
    assert!(!stderr(&o).contains("warming up"), "{}", stderr(&o));
}

#[test]
fn a_header_with_near_names_names_every_missing_column_and_what_was_meant() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    let rows = example_rows(50);
    let text = rows.replacen("time_s,rate_dph,temp_c,ref_dph", "time,rate,temperature,ref", 1);
    assert_ne!(text, rows, "the example's header is the one replaced");
    let run = write(&dir, "names.csv", text.as_bytes());
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), run.to_str().unwrap()]);
    refused(
        &o,
        &[
            "names.csv:1:",
            "columns time_s and rate_dph",
            "nor temp_c",
            "did you mean time_s for time, rate_dph for rate, temp_c for temperature, ref_dph for ref?",
        ],
    );
}

/// `trainer report` of `run` with `model` into `out`: its standard error and `report.md`.
fn report_of(model: &str, run: &Path, out: &Path) -> (String, String) {
    let o = trainer(&[
        "report",
        "--model",
        model,
        run.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    (stderr(&o), std::fs::read_to_string(out.join("report.md")).unwrap())
}

#[test]
fn eval_compensate_fit_and_report_name_the_gaps_of_a_run_by_line() {
    let dir = TempDir::new().unwrap();
    let (model, _) = example_model(&dir);
    // The 0.2-Hz example (data row k at line k + 2) with 100 s lost before
    // row 1000 and 600 s before row 1500: steps of 105 s and 605 s.
    let whole = example_rows(2000);
    let mut lines = whole.lines();
    let mut gapped = format!("{}\n", lines.next().unwrap());
    for (k, line) in lines.enumerate() {
        let (time, rest) = line.split_once(',').unwrap();
        let lost = match k {
            0..1000 => 0.0,
            1000..1500 => 100.0,
            _ => 700.0,
        };
        gapped.push_str(&format!("{:.4},{rest}\n", time.parse::<f64>().unwrap() + lost));
    }
    let run = write(&dir, "gapped.csv", gapped.as_bytes());
    let notice = format!(
        "note: {}: 2 gaps in time_s (time steps over twice the nominal period of 5 s), the longest 605 s before line \
         1502, the first before line 1002; the features restart after each, and the rows that follow warm up (flag 8)\n",
        run.display()
    );
    let m = model.to_str().unwrap();
    let o = trainer(&["eval", "--model", m, run.to_str().unwrap(), "--json", "-"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).starts_with(&notice), "{}", stderr(&o));
    assert_eq!(stderr(&o).matches("note:").count(), 1, "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        json[0]["gaps"],
        serde_json::json!({"count": 2, "longest_s": 605.0, "longest_line": 1502, "first_line": 1002})
    );
    assert!(json[0]["msd_improvement_pct"].is_number(), "{json}");

    let out = dir.path().join("out.csv");
    let o = compensate(&model, &run, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stderr(&o), notice);
    assert!(stdout(&o).starts_with("wrote "), "{}", stdout(&o));
    // A single-axis fit names the gaps of its runs as well.
    let o = fit_ok(&["-q"], &run, &dir.path().join("gapped.bin"));
    assert_eq!(stderr(&o), notice);
    // So does a report, on its terminal and in report.md.
    let (errors, md) = report_of(m, &run, &dir.path().join("report"));
    assert_eq!(errors, notice);
    let listed = format!("## Gaps in the runs\n\n- {}", notice.trim_start_matches("note: "));
    assert!(md.contains(&listed), "{md}");
    // report.json counts them as eval's JSON does.
    assert_eq!(
        crate::common::read_json(dir.path().join("report").join("report.json"))["runs"][0]["gaps"],
        json[0]["gaps"]
    );

    // Without gaps: no note, and the JSON says none.
    let whole = write(&dir, "whole.csv", whole.as_bytes());
    let o = trainer(&["eval", "--model", m, whole.to_str().unwrap(), "--json", "-"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains("note:"), "{}", stderr(&o));
    let json: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        json[0]["gaps"],
        serde_json::json!({"count": 0, "longest_s": 0.0, "longest_line": null, "first_line": null})
    );
    let out = dir.path().join("whole-out.csv");
    let o = compensate(&model, &whole, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stderr(&o), "");
    let (errors, md) = report_of(m, &whole, &dir.path().join("whole-report"));
    assert_eq!(errors, "");
    assert!(!md.contains("## Gaps"), "{md}");
    assert_eq!(
        crate::common::read_json(dir.path().join("whole-report").join("report.json"))["runs"][0]["gaps"],
        json[0]["gaps"]
    );
}
