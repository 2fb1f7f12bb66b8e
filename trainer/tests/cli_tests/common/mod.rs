//! Helpers the `trainer` CLI tests share: running the binary, reading what
//! it printed, a fitted model to work with.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

use tempfile::TempDir;

pub mod postgres;

/// Runs `trainer` with `args`.
pub fn trainer(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .output()
        .expect("trainer runs")
}

/// Runs `trainer` with `args`, `input` on its standard input.
pub fn trainer_with_stdin(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_trainer"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("trainer runs");
    let mut stdin = child.stdin.take().expect("piped stdin");
    // A command may stop reading early (an error): a broken pipe is fine.
    let _ = stdin.write_all(input);
    drop(stdin);
    child.wait_with_output().expect("trainer finishes")
}

/// `trainer compensate --model MODEL RUN -o OUT` and `extra` options.
pub fn compensate(model: &Path, run: &Path, out: &Path, extra: &[&str]) -> Output {
    with_model("compensate", model, run, out, extra)
}

/// `trainer COMMAND --model MODEL RUN -o OUT` and `extra` options.
pub fn with_model(command: &str, model: &Path, run: &Path, out: &Path, extra: &[&str]) -> Output {
    let args = [
        command,
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    trainer(&[&args[..], extra].concat())
}

/// What the command printed on standard error.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// What the command printed on standard output.
pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A file of the bundled example data.
pub fn shared_data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples/data")
        .join(name)
}

/// Writes `content` to `name` in `dir`.
pub fn write(dir: &TempDir, name: &str, content: &[u8]) -> PathBuf {
    let p = dir.path().join(name);
    std::fs::write(&p, content).unwrap();
    p
}

/// Simulates into `path` a run of `args` (`trainer simulate ARGS -o PATH`), which must succeed.
pub fn simulated(path: &Path, args: &[&str]) {
    let o = trainer(&[&["simulate"][..], args, &["-o", path.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
}

/// The JSON document in the file at `path` (a report a command wrote).
pub fn read_json(path: impl AsRef<Path>) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// What `trainer eval --model MODEL RUN --json -` prints, parsed; the command must succeed.
pub fn eval_json(model: &str, run: &str) -> serde_json::Value {
    let o = trainer(&["eval", "--model", model, run, "--json", "-"]);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Simulates into `path` a short chamber run (the IFOG protocol at
/// 1 °C/min, 30-min holds, 1 Hz, 12,600 rows) of noise seed `seed`.
pub fn short_chamber_run(path: &Path, seed: &str) {
    short_chamber_run_with(path, seed, &[]);
}

/// [`short_chamber_run`] with `extra` simulate options (`--axes 3`: a three-axis IMU's run).
pub fn short_chamber_run_with(path: &Path, seed: &str, extra: &[&str]) {
    let args = [
        "simulate",
        "--ramp",
        "1",
        "--hold-min",
        "30",
        "--seed",
        seed,
        "-o",
        path.to_str().unwrap(),
    ];
    let o = trainer(&[&args[..], extra].concat());
    assert!(o.status.success(), "{}", stderr(&o));
}

/// What `trainer inspect --model MODEL --format json` prints, parsed.
pub fn inspect_json(model: &Path) -> serde_json::Value {
    let o = trainer(&["inspect", "--model", model.to_str().unwrap(), "--format", "json"]);
    assert!(o.status.success(), "{}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

/// `trainer fit OPTIONS RUN -o MODEL`, which must succeed.
pub fn fit_ok(options: &[&str], run: &Path, model: &Path) -> Output {
    let o = trainer(
        &[
            &["fit"][..],
            options,
            &[run.to_str().unwrap(), "-o", model.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// A model fitted on a short simulated chamber run (`train.csv` in `dir`,
/// 1 Hz, 12,600 rows), for the tests that need any valid model.
pub fn fitted_model(dir: &TempDir) -> PathBuf {
    let run = dir.path().join("train.csv");
    short_chamber_run(&run, "7");
    let model = dir.path().join("model.bin");
    // The option before the run file: it must not swallow it.
    fit_ok(&["-q", "--block-s", "1"], &run, &model);
    model
}
