//! The `trainer` binary against hostile inputs and targets: outputs that
//! never destroy what they should not, memory bounded on every input, inputs
//! read once, and messages that name the real cause (docs/reliability.md).

use std::os::unix::fs::{PermissionsExt, symlink};
use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::{compensate, fit_ok, fitted_model, stderr, stdout, trainer, trainer_with_stdin, write};
use tempfile::TempDir;

/// Fails unless `o` exited 1 with a message containing `expected` and no panic.
#[track_caller]
fn refused(o: &Output, expected: &str) {
    let message = stderr(o);
    assert_eq!(o.status.code(), Some(1), "{message}");
    assert!(message.contains(expected), "expected {expected:?}, got {message}");
    assert!(!message.contains("panicked"), "{message}");
}

/// Every file in `dir` with its content (links by their target), hidden ones included.
fn snapshot(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let content = if meta.file_type().is_symlink() {
                std::fs::read_link(&path).unwrap().to_string_lossy().as_bytes().to_vec()
            } else if meta.is_file() {
                std::fs::read(&path).unwrap()
            } else {
                Vec::new()
            };
            (name, content)
        })
        .collect();
    files.sort();
    files
}

/// The data rows of the training run, mapped by `edit` (row index, fields), as a run file.
fn edited_run(dir: &TempDir, name: &str, metadata: &str, edit: impl Fn(usize, &mut Vec<String>)) -> PathBuf {
    let text = std::fs::read_to_string(dir.path().join("train.csv")).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let mut out = format!("{metadata}{}\n", lines.next().unwrap());
    for (i, line) in lines.enumerate() {
        let mut fields: Vec<String> = line.split(',').map(str::to_owned).collect();
        edit(i, &mut fields);
        out.push_str(&fields.join(","));
        out.push('\n');
    }
    write(dir, name, out.as_bytes())
}

/// Column indices of the simulated run: time_s, rate_dph, temp_c, ref_dph.
const TIME: usize = 0;
const RATE: usize = 1;
const TEMP: usize = 2;
const REF: usize = 3;

/// The command lines of every writing command, writing to `out`, with the
/// inputs each reads.
fn writers<'a>(model: &'a str, run: &'a str, out: &'a str, capture: &'a str) -> Vec<(Vec<&'a str>, Vec<&'a str>)> {
    vec![
        (vec!["compensate", "--model", model, run, "-o", out], vec![model, run]),
        (vec!["simulate", "--hours", "1", "-o", out], vec![]),
        (vec!["decode", capture, "-o", out], vec![capture]),
        (vec!["blocks", run, "--block-s", "60", "-o", out], vec![run]),
        (vec!["eval", "--model", model, run, "--json", out], vec![model, run]),
        (vec!["fit", "-q", "--block-s", "1", run, "-o", out], vec![run]),
    ]
}

#[test]
fn no_command_replaces_a_link_a_device_an_input_the_model_or_an_existing_file_without_force() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let capture = write(&dir, "frames.bin", &[0u8; 4]);
    let victim = write(&dir, "victim.txt", b"keep me");
    let link = dir.path().join("link.csv");
    symlink(&victim, &link).unwrap();
    let existing = write(&dir, "existing.csv", b"old");
    let (m, r, c) = (
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        capture.to_str().unwrap(),
    );
    let targets: [(&Path, &str); 5] = [
        (&link, "is a symbolic link"),
        (Path::new("/dev/null"), "is a character device"),
        (&run, "is also an input of this command"),
        (&model, "is also an input of this command"),
        (&existing, "exists; pass --force to overwrite it"),
    ];
    for (target, expected) in targets {
        let before = snapshot(dir.path());
        let t = target.to_str().unwrap();
        for (args, inputs) in writers(m, r, t, c) {
            if (target == run || target == model) && !inputs.contains(&t) {
                continue; // not an input of this command: --force would rightly replace it
            }
            let mut forced = args.clone();
            if target != existing {
                forced.push("--force");
            }
            let o = trainer(&forced);
            refused(&o, expected);
            assert_eq!(snapshot(dir.path()), before, "{forced:?} changed the directory");
        }
    }
    // The capture is decode's input.
    let o = trainer(&["decode", c, "-o", c, "--force"]);
    refused(&o, "is also an input of this command");
    // With --force an ordinary file is replaced, keeping its mode.
    std::fs::set_permissions(&existing, std::fs::Permissions::from_mode(0o640)).unwrap();
    let o = compensate(&model, &run, &existing, &["--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(std::fs::read(&existing).unwrap(), b"old");
    let mode = std::fs::metadata(&existing).unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o640, "the replaced file's mode is kept");
    // A read-only file is not replaced even with --force.
    std::fs::set_permissions(&existing, std::fs::Permissions::from_mode(0o444)).unwrap();
    let o = trainer(&["simulate", "--hours", "1", "-o", existing.to_str().unwrap(), "--force"]);
    refused(&o, "is read-only (mode 0444); not replaced, even with --force");
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep me");
}

#[test]
fn report_checks_every_file_it_would_write_before_reading_a_run() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let out = dir.path().join("report");
    std::fs::create_dir(&out).unwrap();
    write(&dir, "report/report.md", b"mine");
    let args = |extra: &[&'static str]| {
        let mut a = vec![
            "report".to_owned(),
            "--model".into(),
            model.to_str().unwrap().into(),
            run.to_str().unwrap().into(),
            "-o".into(),
            out.to_str().unwrap().into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let run_args = |a: Vec<String>| trainer(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let o = run_args(args(&[]));
    // The directory is replaced as a whole: a report's own files need --force.
    refused(&o, "report: exists; pass --force to overwrite it");
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 1, "nothing written");
    let o = run_args(args(&["--force"]));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_ne!(std::fs::read(out.join("report.md")).unwrap(), b"mine");
    // Two runs of one name would overwrite each other's plots.
    let other = dir.path().join("other");
    std::fs::create_dir(&other).unwrap();
    // Another run (its last row left out) under the same name.
    let text = std::fs::read_to_string(&run).unwrap();
    let shorter = text.trim_end().rsplit_once('\n').unwrap().0.to_owned() + "\n";
    std::fs::write(other.join("train.csv"), shorter).unwrap();
    let mut twice = args(&["--force"]);
    twice.push(other.join("train.csv").to_str().unwrap().into());
    refused(&run_args(twice), "two runs are named train");
}

#[test]
fn fit_leaves_the_old_model_when_a_later_step_fails_and_no_temporary_file() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let original = std::fs::read(&model).unwrap();
    // Past the rows read at opening: found only when the table streams the holdout.
    let bad = edited_run(&dir, "bad_tail.csv", "", |i, f| {
        if i == 5000 {
            f[TEMP] = "z".into();
        }
    });
    let json = dir.path().join("fit.json");
    let o = trainer(&[
        "fit",
        "-q",
        "--block-s",
        "1",
        dir.path().join("train.csv").to_str().unwrap(),
        "--holdout",
        bad.to_str().unwrap(),
        "-o",
        model.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--force",
    ]);
    refused(&o, "bad_tail.csv:5002: column temp_c (field 3): \"z\" is not a number");
    assert_eq!(std::fs::read(&model).unwrap(), original, "the model is untouched");
    assert!(!json.exists());
    let hidden: Vec<_> = snapshot(dir.path())
        .into_iter()
        .filter(|(n, _)| n.starts_with('.'))
        .collect();
    assert!(hidden.is_empty(), "temporary files left: {hidden:?}");
}

#[test]
fn a_stopped_command_leaves_neither_its_output_nor_a_temporary_file() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("long.csv");
    for signal in ["-TERM", "-INT"] {
        let child = std::process::Command::new(env!("CARGO_BIN_EXE_trainer"))
            .args([
                "simulate",
                "--hours",
                "100",
                "--rate-hz",
                "100",
                "-o",
                out.to_str().unwrap(),
            ])
            .spawn()
            .unwrap();
        // Wait until the temporary file exists and is being written.
        let started = std::time::Instant::now();
        while snapshot(dir.path()).iter().all(|(_, c)| c.is_empty()) {
            assert!(started.elapsed().as_secs() < 30, "simulate did not start writing");
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let status = std::process::Command::new("kill")
            .args([signal, &child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        let output = child.wait_with_output().unwrap();
        assert!(!output.status.success(), "{signal}");
        assert!(
            snapshot(dir.path()).is_empty(),
            "{signal}: left {:?}",
            snapshot(dir.path())
        );
    }
}

#[test]
fn every_input_is_read_within_its_limit_whatever_its_shape() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let out = dir.path().join("out.csv");
    let compensate_run = |run: &Path| compensate(&model, run, &out, &[]);
    let commas = write(
        &dir,
        "commas.csv",
        format!("{}\n0,1,2\n", ",".repeat(10_000_000)).as_bytes(),
    );
    refused(
        &compensate_run(&commas),
        "commas.csv:1: line is longer than 64 KiB (the limit",
    );
    let wide = write(
        &dir,
        "wide.csv",
        format!("time_s,rate_dph,temp_c{}\n", ",x".repeat(2000)).as_bytes(),
    );
    refused(
        &compensate_run(&wide),
        "wide.csv:1: header has 2003 columns; at most 1024 are read (the limit)",
    );
    let comments = write(&dir, "comments.csv", "# a comment line\n".repeat(100_000).as_bytes());
    refused(
        &compensate_run(&comments),
        "of metadata, comment and blank lines before the header (the limit)",
    );
    refused(
        &compensate_run(Path::new("/dev/zero")),
        "/dev/zero:1: line is longer than 64 KiB",
    );
    assert!(!out.exists());
    // Model blobs: at most 4 KiB, one blob per file.
    let run = dir.path().join("train.csv");
    let o = compensate(Path::new("/dev/zero"), &run, &out, &[]);
    refused(&o, "/dev/zero: model refused: more than 4096 bytes");
    let mut padded = std::fs::read(&model).unwrap();
    padded.extend_from_slice(b"trailing bytes");
    let padded = write(&dir, "padded.bin", &padded);
    let o = trainer(&["inspect", padded.to_str().unwrap()]);
    refused(&o, "padded.bin: model refused: 14 bytes follow the blob's end");
    assert!(stdout(&o).contains("valid           no"), "{}", stdout(&o));
    let o = trainer(&["eval", "--model", padded.to_str().unwrap(), run.to_str().unwrap()]);
    refused(&o, "14 bytes follow the blob's end");
    // A frame capture without a frame: refused after the search limit, not read forever.
    let o = trainer(&["decode", "/dev/zero", "-o", out.to_str().unwrap()]);
    refused(&o, "no valid frame in its first 1 MiB");
    // Parameter files.
    let o = trainer(&["simulate", "--params", "/dev/zero", "-o", out.to_str().unwrap()]);
    refused(&o, "/dev/zero: more than 1048576 bytes");
    assert!(!out.exists());
}

#[test]
fn standard_input_and_fifos_are_read_once_and_fit_asks_for_a_file() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let m = model.to_str().unwrap();
    let from_file = dir.path().join("file.csv");
    let o = compensate(&model, &run, &from_file, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let from_stdin = dir.path().join("stdin.csv");
    let text = std::fs::read(&run).unwrap();
    let o = trainer_with_stdin(
        &["compensate", "--model", m, "-", "-o", from_stdin.to_str().unwrap()],
        &text,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(std::fs::read(&from_stdin).unwrap(), std::fs::read(&from_file).unwrap());
    let o = trainer_with_stdin(&["eval", "--model", m, "-"], &text);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("<stdin>"), "{}", stdout(&o));
    refused(
        &trainer_with_stdin(&["eval", "--model", m, "-", "-"], &text),
        "given more than once",
    );
    refused(
        &trainer_with_stdin(&["fit", "-", "-o", dir.path().join("m.bin").to_str().unwrap()], &text),
        "<stdin>: `trainer fit` reads its runs several times and needs a seekable file",
    );
    // A FIFO: read once by compensate.
    let fifo = dir.path().join("fifo");
    assert!(
        std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success()
    );
    let writer = {
        let (fifo, text) = (fifo.clone(), text.clone());
        std::thread::spawn(move || std::fs::write(fifo, text))
    };
    let from_fifo = dir.path().join("fifo.csv");
    let o = compensate(&model, &fifo, &from_fifo, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    writer.join().unwrap().unwrap();
    assert_eq!(std::fs::read(&from_fifo).unwrap(), std::fs::read(&from_file).unwrap());
    refused(
        &trainer(&[
            "fit",
            fifo.to_str().unwrap(),
            "-o",
            dir.path().join("m.bin").to_str().unwrap(),
        ]),
        "needs a seekable file",
    );
}

/// A conversion of the loop temperature, °C to what a broken recorder wrote.
type Convert = fn(f64) -> f64;

#[test]
fn implausible_temperatures_are_named_with_their_range_and_a_units_hint() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let out = dir.path().join("out.csv");
    let cases: [(&str, Convert, &str); 3] = [
        ("kelvin", |t| t + 273.15, "kelvin? temperatures are °C"),
        ("absolute_zero", |_| -273.15, "read -273.1 … -273.1 °C"),
        ("hot", |_| 10_000.0, "not a temperature in °C"),
    ];
    for (name, convert, hint) in cases {
        let run = edited_run(&dir, &format!("{name}.csv"), "", |_, f| {
            f[TEMP] = convert(f[TEMP].parse().unwrap()).to_string();
        });
        let (m, r) = (model.to_str().unwrap(), run.to_str().unwrap());
        let range = "readings lie outside -60 … 160 °C";
        let o = trainer(&["fit", "-q", r, "-o", dir.path().join("m.bin").to_str().unwrap()]);
        refused(&o, range);
        refused(&o, hint);
        let o = compensate(&model, &run, &out, &[]);
        refused(&o, "no row could be compensated");
        refused(&o, hint);
        assert!(!out.exists(), "{name}: nothing compensated, nothing written");
        let o = trainer(&["eval", "--model", m, r]);
        refused(&o, range);
        // Asked for, the uncompensated output is written (the run is
        // implausible as a gyro recording too: it must be accepted as such).
        let o = compensate(&model, &run, &out, &["--allow-uncompensated"]);
        refused(&o, "pass --allow-implausible");
        let o = compensate(&model, &run, &out, &["--allow-uncompensated", "--allow-implausible"]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(stdout(&o).contains("no valid model (4) 12600"), "{}", stdout(&o));
        std::fs::remove_file(&out).unwrap();
    }
}

#[test]
fn sample_rate_metadata_and_changes_of_rate_are_refused_where_they_are() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let m = model.to_str().unwrap();
    let out = dir.path().join("out.csv");
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            edited_run(&dir, "mhz.csv", "# sample_rate_hz: 1000000\n", |_, _| {}),
            "mhz.csv:1: # sample_rate_hz: 1000000 states a sample period of 0.000001 s, but the time column steps by 1 s (1 Hz; the median of the 1000 steps of lines 3–1003)",
        ),
        (
            edited_run(&dir, "zero.csv", "# sample_rate_hz: 0\n", |_, _| {}),
            "zero.csv:1: # sample_rate_hz: \"0\" is not positive",
        ),
        (
            edited_run(&dir, "negative.csv", "# sample_rate_hz: -5\n", |_, _| {}),
            "negative.csv:1: # sample_rate_hz: \"-5\" is not positive",
        ),
        (
            edited_run(&dir, "tiny.csv", "# a comment\n# sample_rate_hz: 1e-9\n", |_, _| {}),
            "tiny.csv:2: # sample_rate_hz: \"1e-9\" is out of range; it must be the gyro sample rate in Hz, 0.001 … 1000000",
        ),
        (
            // The first 1000 steps at 100 Hz, the rest at 1 Hz.
            edited_run(&dir, "slower.csv", "", |i, f| {
                let t = if i <= 1000 {
                    0.01 * i as f64
                } else {
                    10.0 + (i - 1000) as f64
                };
                f[TIME] = format!("{t:.2}");
            }),
            "slower.csv:1003: the sample rate changes here: the 10 time steps from this line on are 1 s each (1 Hz), the run's nominal period is 0.01 s (100 Hz, the median of its first 1000 steps)",
        ),
    ];
    for (run, expected) in &cases {
        let r = run.to_str().unwrap();
        refused(
            &trainer(&["fit", "-q", r, "-o", dir.path().join("m.bin").to_str().unwrap()]),
            expected,
        );
        refused(&compensate(&model, run, &out, &[]), expected);
        refused(&trainer(&["eval", "--model", m, r]), expected);
    }
    // An annotation that is not a number states nothing and is ignored, as by the firmware replay.
    let noted = edited_run(&dir, "noted.csv", "# sample_rate_hz: 1 (assumed)\n", |_, _| {});
    let o = compensate(&model, &noted, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn rates_beyond_any_gyro_and_a_rate_that_never_varies_are_refused() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let m = model.to_str().unwrap();
    let fit_out = dir.path().join("m.bin");
    for (name, column, line) in [("big_rate", RATE, 5000), ("big_ref", REF, 6000)] {
        let run = edited_run(&dir, &format!("{name}.csv"), "", |i, f| {
            if i == line - 2 {
                f[column] = "1e30".into();
            }
        });
        let r = run.to_str().unwrap();
        let expected = format!(
            "{name}.csv:{line}: column {} (field {}): \"1e30\" is beyond ±3600000 °/h",
            ["time_s", "rate_dph", "temp_c", "ref_dph"][column],
            column + 1
        );
        refused(&trainer(&["fit", "-q", r, "-o", fit_out.to_str().unwrap()]), &expected);
        refused(&trainer(&["eval", "--model", m, r]), &expected);
    }
    let flat = edited_run(&dir, "flat.csv", "", |_, f| {
        f[RATE] = "0".into();
        f[REF] = "0".into();
    });
    let r = flat.to_str().unwrap();
    let o = trainer(&["fit", "-q", "--block-s", "1", r, "-o", fit_out.to_str().unwrap()]);
    refused(
        &o,
        "the bias target rate_dph − ref_dph is 0 °/h in every block: no excitation to fit",
    );
    assert!(!fit_out.exists());
    refused(
        &trainer(&["eval", "--model", m, r]),
        "rate_dph − ref_dph is 0 °/h on every one of its 12600 rows",
    );
    // A header alone: nothing to evaluate; compensating it gives the model's
    // provenance lines and the header alone.
    let empty = write(&dir, "empty.csv", b"time_s,rate_dph,temp_c\n");
    refused(
        &trainer(&["eval", "--model", m, empty.to_str().unwrap()]),
        "empty.csv: run has 0 data rows; at least 2 are needed",
    );
    let out = dir.path().join("empty_out.csv");
    let o = compensate(&model, &empty, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    let rest: Vec<&str> = text.lines().filter(|l| !l.starts_with("# model")).collect();
    assert_eq!(rest, ["time_s,rate_dph,temp_c,bias_dph,rate_comp_dph,flags"], "{text}");
    assert_eq!(
        text.lines().take_while(|l| l.starts_with("# model")).count(),
        2,
        "{text}"
    );
}

#[test]
fn control_characters_from_files_are_printed_escaped() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("train.csv");
    fitted_model(&dir);
    let model = dir.path().join("serial.bin");
    let serial = "SN\x1b[2J\nforged";
    fit_ok(&["-q", "--block-s", "1", "--serial", serial], &run, &model);
    let o = trainer(&["inspect", model.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let printed = stdout(&o);
    assert!(printed.contains("serial          SN\\u{1b}[2J\\nforged"), "{printed}");
    assert!(!printed.contains('\x1b'), "{printed}");
    // A field and a file name with escape codes, quoted in an error.
    let bad = write(&dir, "bell\x07.csv", b"time_s,rate_dph,temp_c\n0,\x1b[31m,20\n");
    let o = trainer(&["eval", "--model", model.to_str().unwrap(), bad.to_str().unwrap()]);
    refused(
        &o,
        "bell\\u{7}.csv:2: column rate_dph (field 2): \"\\u{1b}[31m\" is not a number",
    );
    assert!(
        !stderr(&o).contains('\x1b') && !stderr(&o).contains('\x07'),
        "{}",
        stderr(&o)
    );
}
