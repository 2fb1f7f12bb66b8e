//! Every command all or nothing (docs/reliability.md, "Outputs"): outputs
//! that clash are refused before any work; a failure, a closed standard
//! output, a file-size limit or any terminating signal leaves every earlier
//! output byte-identical and nothing beside it; a report directory is
//! replaced as a whole.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use crate::common::{fitted_model, shared_data, stderr, trainer};
use tempfile::TempDir;

/// Every entry under `dir`, recursively, with the content of files, sorted.
fn tree(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_owned()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(dir).unwrap().to_owned();
            if p.is_dir() {
                stack.push(p);
                out.push((rel, Vec::new()));
            } else {
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// The hidden entries of `dir` (staged files and directories left behind).
fn hidden(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect()
}

/// A directory with an old model, an old JSON and an old report (with a plot
/// of a run the new fit does not have).
fn old_outputs(dir: &TempDir) -> (PathBuf, PathBuf, PathBuf) {
    let (model, json, rep) = (
        dir.path().join("m.bin"),
        dir.path().join("fit.json"),
        dir.path().join("rep"),
    );
    std::fs::write(&model, b"old model").unwrap();
    std::fs::write(&json, b"{\"old\": true}").unwrap();
    std::fs::create_dir(&rep).unwrap();
    std::fs::write(rep.join("report.md"), b"old report").unwrap();
    std::fs::write(rep.join("gone_rate.svg"), b"<svg/>").unwrap();
    (model, json, rep)
}

/// `trainer fit -q --method poly3` on the shipped example with `extra`.
fn fit_args<'a>(run: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["fit", "-q", "--method", "poly3", run];
    args.extend(extra);
    args
}

#[test]
fn outputs_inside_the_report_directory_are_refused_before_any_work() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let run = run.to_str().unwrap();
    let (_, _, rep) = old_outputs(&dir);
    let before = tree(dir.path());
    let inside = |name: &str| rep.join(name).to_str().unwrap().to_owned();
    let (m, j, r) = (inside("m.bin"), inside("report.json"), rep.to_str().unwrap().to_owned());
    for extra in [
        vec!["-o", &m, "--json", &j, "--report", &r, "--force"],
        vec!["-o", &m, "--report", &r],
        vec!["-o", &m, "--report", &r, "--force"],
    ] {
        let o = trainer(&fit_args(run, &extra));
        assert_eq!(o.status.code(), Some(1), "{extra:?}: {}", stderr(&o));
        assert!(
            stderr(&o).contains("is an output of this command inside") && stderr(&o).contains("replaced as a whole"),
            "{}",
            stderr(&o)
        );
        assert_eq!(tree(dir.path()), before, "{extra:?}: nothing changed");
    }
}

#[test]
fn a_fit_stopped_by_a_file_size_limit_leaves_every_old_output_and_says_why() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let (model, json, rep) = old_outputs(&dir);
    let before = tree(dir.path());
    // 64 blocks of 512 bytes: the model and the JSON fit, the report's plots do not.
    let o = Command::new("sh")
        .arg("-c")
        .arg("ulimit -f 64; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_trainer"))
        .args(fit_args(
            run.to_str().unwrap(),
            &[
                "-o",
                model.to_str().unwrap(),
                "--json",
                json.to_str().unwrap(),
                "--report",
                rep.to_str().unwrap(),
                "--force",
            ],
        ))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("File too large"), "{}", stderr(&o));
    assert!(stderr(&o).contains("rep/"), "the file is named: {}", stderr(&o));
    assert!(
        !stderr(&o).contains("at path"),
        "not its hidden temporary file: {}",
        stderr(&o)
    );
    assert_eq!(tree(dir.path()), before, "every old output as it was, nothing beside");
}

#[test]
fn a_closed_standard_output_fails_the_command_before_anything_is_written() {
    let dir = TempDir::new().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let (model, json, _) = old_outputs(&dir);
    let before = tree(dir.path());
    // The reader goes away before the command prints: `trainer fit … | true`.
    let o = with_stdout_closed(&fit_args(
        run.to_str().unwrap(),
        &[
            "-o",
            model.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
            "--force",
        ],
    ));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("standard output"), "{}", stderr(&o));
    assert_eq!(tree(dir.path()), before, "nothing committed");
}

/// Starts `args`, waits until something hidden (a staged output) appears in
/// `dir`, sends `signal` with kill(1), and returns the exit status.
fn stop_when_staged(dir: &Path, args: &[&str], signal: &str, feed: Option<&[u8]>) -> std::process::ExitStatus {
    let mut child = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .stdin(if feed.is_some() { Stdio::piped() } else { Stdio::null() })
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kept open (the command waits for more input) until the signal.
    let mut stdin = child.stdin.take();
    if let (Some(input), Some(bytes)) = (stdin.as_mut(), feed) {
        input.write_all(bytes).unwrap();
    }
    let started = std::time::Instant::now();
    while hidden(dir).is_empty() {
        assert!(started.elapsed().as_secs() < 60, "{signal}: nothing staged");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(50));
    let pid = child.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-s", signal, &pid])
            .status()
            .unwrap()
            .success()
    );
    if signal == "PIPE" {
        // Ignored: the command goes on; stopped here by SIGTERM.
        std::thread::sleep(std::time::Duration::from_millis(200));
        assert!(child.try_wait().unwrap().is_none(), "SIGPIPE from outside ends nothing");
        assert!(
            Command::new("kill")
                .args(["-s", "TERM", &pid])
                .status()
                .unwrap()
                .success()
        );
    }
    drop(stdin);
    child.wait().unwrap()
}

#[test]
fn every_terminating_signal_leaves_the_old_output_and_no_staged_file() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("long.csv");
    std::fs::write(&out, b"old").unwrap();
    let args = [
        "simulate",
        "--hours",
        "100",
        "--sample-rate-hz",
        "100",
        "-o",
        out.to_str().unwrap(),
        "--force",
    ];
    // The real-time signals by number (kill -s takes numbers too).
    let realtime: Vec<String> = [
        nix::libc::SIGRTMIN(),
        nix::libc::SIGRTMIN() + 5,
        nix::libc::SIGRTMAX() - 1,
        nix::libc::SIGRTMAX(),
    ]
    .iter()
    .map(|n| n.to_string())
    .collect();
    let named = [
        "INT", "TERM", "HUP", "QUIT", "USR1", "USR2", "ALRM", "VTALRM", "PROF", "XCPU", "TRAP", "ABRT", "PIPE",
        // Linux's own, and the faults a process never catches but may be sent.
        "PWR", "IO", "SYS", "STKFLT", "ILL", "FPE",
    ];
    for signal in named.into_iter().chain(realtime.iter().map(String::as_str)) {
        let status = stop_when_staged(dir.path(), &args, signal, None);
        assert!(!status.success(), "{signal}");
        assert_eq!(
            tree(dir.path()),
            [(PathBuf::from("long.csv"), b"old".to_vec())],
            "{signal}"
        );
    }
}

#[test]
fn a_report_is_replaced_as_a_whole_or_not_at_all() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let rep = dir.path().join("rep");
    std::fs::create_dir(&rep).unwrap();
    std::fs::write(rep.join("report.md"), b"old report").unwrap();
    std::fs::write(rep.join("gone_rate.svg"), b"<svg/>").unwrap();
    let before = tree(&rep);
    let m = model.to_str().unwrap();
    let r = rep.to_str().unwrap();
    // Stopped while it reads its run (from a pipe that has not ended): the old report whole.
    let head: Vec<u8> = std::fs::read(&run).unwrap().into_iter().take(200_000).collect();
    let status = stop_when_staged(
        dir.path(),
        &["report", "--model", m, "-", "-o", r, "--force"],
        "TERM",
        Some(&head),
    );
    assert!(!status.success());
    assert_eq!(tree(&rep), before, "the old report, whole");
    assert!(hidden(dir.path()).is_empty(), "{:?}", hidden(dir.path()));
    // Done: the new report whole, no plot of a run it did not read.
    let o = trainer(&["report", "--model", m, run.to_str().unwrap(), "-o", r, "--force"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let names: Vec<PathBuf> = tree(&rep).into_iter().map(|(p, _)| p).collect();
    assert!(names.contains(&PathBuf::from("train_rate.svg")), "{names:?}");
    assert!(!names.contains(&PathBuf::from("gone_rate.svg")), "{names:?}");
    // A directory holding anything a report does not write is never replaced.
    std::fs::write(rep.join("notes.txt"), b"mine").unwrap();
    let before = tree(&rep);
    let o = trainer(&["report", "--model", m, run.to_str().unwrap(), "-o", r, "--force"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stderr(&o).contains("holds notes.txt"), "{}", stderr(&o));
    assert_eq!(tree(&rep), before);
}

#[test]
fn outputs_named_with_the_longest_legal_names_are_written() {
    let dir = TempDir::new().unwrap();
    let name = format!("{}.csv", "r".repeat(251));
    assert_eq!(name.len(), 255);
    let out = dir.path().join(&name);
    let o = trainer(&["simulate", "--hours", "1", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.is_file());
    assert!(hidden(dir.path()).is_empty());
}

/// Runs `trainer args` under `ulimit -f 0` with standard output into a
/// file (standard error stays a pipe, which the limit does not reach).
fn under_file_size_limit(dir: &Path, args: &[&str]) -> std::process::Output {
    let out = std::fs::File::create(dir.join("printed.txt")).unwrap();
    Command::new("sh")
        .arg("-c")
        .arg("ulimit -f 0; exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .stdout(out)
        .output()
        .unwrap()
}

#[test]
fn commands_that_only_print_fail_with_a_message_past_a_file_size_limit() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let m = model.to_str().unwrap();
    let run = shared_data("ifog_train_1cpm.csv");
    let r = run.to_str().unwrap();
    for args in [
        vec!["eval", "--model", m, r, "--json", "-"],
        vec!["inspect", m],
        vec!["inspect", "--model", m, "--format", "json"],
    ] {
        let o = under_file_size_limit(dir.path(), &args);
        // Not killed by SIGXFSZ (no exit code), not a panic (101).
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert_eq!(
            err.lines().filter(|l| l.starts_with("error: ")).count(),
            1,
            "{args:?}: {err}"
        );
        assert!(
            err.contains("error: standard output: write failed (File too large"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn a_json_reader_that_stops_early_costs_neither_the_table_nor_a_clear_exit() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = shared_data("ifog_train_1cpm.csv");
    // `| head -c 0`: the pipe closed before the JSON comes (a reader that
    // took 100 bytes of a JSON the pipe's buffer holds whole would see no
    // error at all).
    let o = with_stdout_closed(&[
        "eval",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--json",
        "-",
    ]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("Overlapping Allan deviation"), "the table is whole: {err}");
    assert!(
        err.contains("Settled bias of soak plateaus"),
        "the table is whole: {err}"
    );
    let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error: ")).collect();
    assert_eq!(
        errors,
        ["error: standard output: closed by its reader before the output was whole (broken pipe); nothing written"],
        "{err}"
    );
    assert!(!err.contains("os error 32"), "{err}");
}

#[test]
fn a_stop_at_any_moment_of_a_report_leaves_one_whole_report_and_no_hidden_copy() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = dir.path().join("train.csv");
    let rep = dir.path().join("rep");
    let (m, r, rp) = (model.to_str().unwrap(), run.to_str().unwrap(), rep.to_str().unwrap());
    let o = trainer(&["report", "--model", m, r, "-o", rp]);
    assert!(o.status.success(), "{}", stderr(&o));
    let names = |t: Vec<(PathBuf, Vec<u8>)>| t.into_iter().map(|(p, _)| p).collect::<Vec<_>>();
    let whole = names(tree(&rep));
    // SIGTERM at moments spread over the whole command, the commit and the
    // removal of the replaced report included.
    for delay_ms in (0..25).map(|k| 30 * k) {
        let mut child = Command::new(env!("CARGO_BIN_EXE_trainer"))
            .args(["report", "--model", m, r, "-o", rp, "--force"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(std::time::Duration::from_millis(delay_ms));
        let _ = Command::new("kill")
            .args(["-s", "TERM", &child.id().to_string()])
            .status();
        let _ = child.wait();
        assert!(hidden(dir.path()).is_empty(), "{delay_ms} ms: {:?}", hidden(dir.path()));
        assert_eq!(names(tree(&rep)), whole, "{delay_ms} ms: one whole report");
    }
}

/// `trainer ARGS` with its standard output's reader gone before it prints
/// (`trainer … | true`): its output and exit status.
fn with_stdout_closed<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> std::process::Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    child.wait_with_output().unwrap()
}
