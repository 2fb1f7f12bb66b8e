//! `trainer device` against the board image under QEMU, through the
//! pseudo-terminal of `cargo xtask qemu-board --pty` (the same library code):
//! status → update → status → record, a blob refused before sending, a
//! port that does not exist or does not answer, Ctrl-C and a unit that
//! goes away during a recording.
//!
//! Ignored in a plain `cargo test` (they need qemu-system-arm and a cross
//! build); `cargo xtask ci` runs them with `--ignored`. Every QEMU runs
//! under `timeout` and is killed when its test ends.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use tempfile::TempDir;
use xtask::qemu_board::{BoardOptions, QemuBoard};

/// No QEMU outlives this, whatever happens to the test.
const QEMU_LIMIT: Duration = Duration::from_secs(180);

/// One board at a time: each QEMU runs in real time, and the machine's
/// cores are shared (a starved board misses samples).
static ONE_BOARD: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A single-axis board without a model, and the lock that keeps it the only one.
fn board() -> (QemuBoard, std::sync::MutexGuard<'static, ()>) {
    let lock = ONE_BOARD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    xtask::qemu::ensure_installed().unwrap();
    let board = QemuBoard::start(&BoardOptions {
        three_axes: false,
        model: None,
        run: None,
        limit: Some(QEMU_LIMIT),
    })
    .unwrap();
    (board, lock)
}

/// The trainer CLI, built once (cargo's build lock would otherwise count
/// in the timings of the tests that run beside each other).
fn trainer() -> PathBuf {
    static TRAINER: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    TRAINER.get_or_init(|| xtask::firmware::trainer_cli().unwrap()).clone()
}

/// A trainer started in the background: killed if its test ends first (a
/// failed assertion), so that it never holds a pty into the next test.
struct Background(Option<std::process::Child>);

impl Background {
    fn spawn(command: &mut Command) -> Background {
        Background(Some(
            command
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap(),
        ))
    }

    fn id(&self) -> u32 {
        self.0.as_ref().unwrap().id()
    }

    fn wait(mut self) -> Output {
        self.0.take().unwrap().wait_with_output().unwrap()
    }

    /// Panics with the process's error output if it has already exited:
    /// a wait for its work then names why it never came.
    fn assert_running(&mut self) {
        let child = self.0.as_mut().unwrap();
        if child.try_wait().unwrap().is_some() {
            let out = self.0.take().unwrap().wait_with_output().unwrap();
            panic!(
                "the process exited early ({}): {}",
                out.status,
                String::from_utf8_lossy(&out.stderr)
            );
        }
    }
}

impl Drop for Background {
    fn drop(&mut self) {
        if let Some(mut child) = self.0.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Runs the trainer; its output and how long it took.
fn run(args: &[&str]) -> (Output, Duration) {
    let trainer = trainer();
    let started = Instant::now();
    let out = Command::new(trainer).args(args).stdin(Stdio::null()).output().unwrap();
    (out, started.elapsed())
}

/// Runs the trainer, which must succeed; its standard output and error.
fn ok(args: &[&str]) -> String {
    let (out, _) = run(args);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "trainer {args:?} failed:\n{text}");
    text
}

/// Runs the trainer, which must fail; its standard error.
fn fails(args: &[&str]) -> String {
    let (out, _) = run(args);
    assert!(!out.status.success(), "trainer {args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A model fitted now on the bundled 1 °C/min run.
fn fitted_model(dir: &Path) -> PathBuf {
    let model = dir.join("model.bin");
    let train = e2e_tests::example("ifog_train_1cpm.csv");
    ok(&["fit", train.to_str().unwrap(), "-o", model.to_str().unwrap()]);
    model
}

/// The CRC-32 trailer of the blob at `path`, as the health report names it.
fn crc_of(path: &Path) -> String {
    let bytes = std::fs::read(path).unwrap();
    format!("{:#010x}", u32::from_le_bytes(*bytes.last_chunk::<4>().unwrap()))
}

/// The samples counter of a `status` print.
fn samples(status: &str) -> u64 {
    status
        .lines()
        .find_map(|l| l.trim().strip_prefix("samples "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no samples line in:\n{status}"))
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn status_update_status_record_through_the_board_s_pty() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(dir.path());
    let (board, _one) = board();
    let port = board.pty().to_str().unwrap().to_owned();

    let before = ok(&["device", "status", "--port", &port]);
    assert!(before.contains("single-axis"), "{before}");
    assert!(
        before.contains("none running (output uncompensated, flag 4)"),
        "{before}"
    );

    let started = Instant::now();
    let updated = ok(&["device", "update", "--port", &port, "--model", model.to_str().unwrap()]);
    assert!(updated.contains("status 0: installed"), "{updated}");
    eprintln!("device update took {:.2} s", started.elapsed().as_secs_f64());

    let json = dir.path().join("health.json");
    let after = ok(&["device", "status", "--port", &port, "--json", json.to_str().unwrap()]);
    let crc = crc_of(&model);
    assert!(
        after.contains(&format!("blob CRC-32 {crc}, installed over the UART as commit 1")),
        "{after}"
    );
    let health: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    assert_eq!(health["model_sequence"], 1);
    assert_eq!(format!("{:#010x}", health["model_blob_crc32"].as_u64().unwrap()), crc);

    let recorded = dir.path().join("run.csv");
    let started = Instant::now();
    let said = ok(&[
        "device",
        "record",
        "--port",
        &port,
        "--seconds",
        "3",
        "-o",
        recorded.to_str().unwrap(),
    ]);
    let took = started.elapsed();
    assert!(took < Duration::from_secs(8), "record --seconds 3 took {took:?}");
    let text = std::fs::read_to_string(&recorded).unwrap();
    assert!(text.contains(&format!("# model_blob_crc32: {crc}")), "{said}");
    let header = text.lines().find(|l| !l.starts_with('#')).unwrap();
    assert_eq!(
        header,
        "time_s,seq,rate_dph,unit_bias_dph,unit_rate_comp_dph,temp_c,unit_flags"
    );
    // A recorded run the trainer reads; at 1 kHz for 3 s of real time
    // (QEMU in real time on a shared machine: at least a third of it).
    let run = trainer::reading::run::samples::Run::load(&recorded).unwrap();
    assert!(run.time_s.len() > 1000, "{} rows; {said}", run.time_s.len());
    eprintln!("recorded {} rows in {:.2} s", run.time_s.len(), took.as_secs_f64());
    // The new model runs: no row flagged 4 (no valid model).
    let flags_col = header.split(',').position(|c| c == "unit_flags").unwrap();
    let no_model = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .skip(1)
        .filter(|l| l.split(',').nth(flags_col).unwrap().parse::<u8>().unwrap() & 4 != 0)
        .count();
    assert_eq!(no_model, 0, "rows flagged 4 with the new model installed");
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn a_blob_the_unit_would_refuse_is_refused_before_sending_and_the_unit_runs_on() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(dir.path());
    let (axes_blob, _) = e2e_tests::fixtures::axes_blob_and_slice(dir.path());
    let (board, _one) = board();
    let port = board.pty().to_str().unwrap().to_owned();
    ok(&["device", "update", "--port", &port, "--model", model.to_str().unwrap()]);
    let before = ok(&["device", "status", "--port", &port]);

    // One flipped bit: the CRC fails, as the firmware's check would find.
    let mut bytes = std::fs::read(&model).unwrap();
    bytes[40] ^= 0x01;
    let corrupt = dir.path().join("corrupt.bin");
    std::fs::write(&corrupt, &bytes).unwrap();
    let update = |blob: &Path| fails(&["device", "update", "--port", &port, "--model", blob.to_str().unwrap()]);
    // Refused while a recording holds the port: checked before any port is opened.
    let recorded = dir.path().join("during.csv");
    let recording = Background::spawn(
        Command::new(trainer())
            .args(["device", "record", "--port", &port, "--seconds", "3", "-o"])
            .arg(&recorded),
    );
    std::thread::sleep(Duration::from_secs(1));
    let err = update(&corrupt);
    assert!(
        err.contains(&format!(
            "{}: no unit would take this blob, nothing sent: CRC",
            corrupt.display()
        )),
        "{err}"
    );

    let out = recording.wait();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let rows = trainer::reading::run::samples::Run::load(&recorded)
        .unwrap()
        .time_s
        .len();
    assert!(rows > 1000, "the unit recorded on: {rows} rows in 3 s");
    // A multi-axis blob: valid, but not for a single-axis unit (its frames say which).
    let err = update(&axes_blob);
    assert!(
        err.contains(&format!("{port}: blob refused, nothing sent: a single-axis unit")),
        "{err}"
    );

    let after = ok(&["device", "status", "--port", &port]);
    let crc = crc_of(&model);
    for status in [&before, &after] {
        assert!(
            status.contains(&format!("blob CRC-32 {crc}, installed over the UART as commit 1")),
            "{status}"
        );
    }
    assert!(
        samples(&after) > samples(&before),
        "the unit kept sampling:\n{before}\n{after}"
    );
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn a_dead_port_fails_within_seconds_naming_the_port() {
    // No such port.
    let (out, took) = run(&["device", "status", "--port", "/dev/no-such-gyro"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("/dev/no-such-gyro: no such port"), "{err}");
    assert!(took < Duration::from_secs(5), "{took:?}");

    // A port that exists and never answers: a board whose QEMU is gone
    // leaves nothing; a pty nobody serves stays silent.
    let (master, pts) = silent_pty();
    let (out, took) = run(&["device", "status", "--port", &pts, "--timeout-s", "1"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains(&format!("{pts}: no health report within 1.0 s")), "{err}");
    assert!(took < Duration::from_secs(5), "{took:?}");
    drop(master);
}

/// A pseudo-terminal whose master end nobody reads: (master, slave path).
fn silent_pty() -> (std::os::fd::OwnedFd, String) {
    use rustix::pty::{OpenptFlags, grantpt, openpt, ptsname, unlockpt};
    let master = openpt(OpenptFlags::RDWR | OpenptFlags::NOCTTY).unwrap();
    grantpt(&master).unwrap();
    unlockpt(&master).unwrap();
    let name = ptsname(&master, Vec::new()).unwrap();
    (master, name.to_str().unwrap().to_owned())
}

/// Waits until `record` is recording into `dir`: it opens its staged file
/// (beside the target, named with a leading dot) once the unit answered
/// its status query, so the wait covers however long a loaded machine
/// takes to start it and reach the unit; then lets it record for 2 s, time
/// for the hundreds of rows the complete run must hold. Panics with its
/// error output if `record` exits first, and after a minute without a
/// staged file.
fn let_record_run(dir: &Path, record: &mut Background) {
    let started = Instant::now();
    let staged = || {
        std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .any(|e| e.file_name().to_string_lossy().starts_with('.'))
    };
    while !staged() {
        record.assert_running();
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "record staged no file in a minute"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(2));
    record.assert_running();
}

/// `record`'s `--timeout-s` in the Ctrl-C test: the unit's first answer
/// and its silence after it goes away are both judged by it, and a
/// machine busy compiling beside QEMU (as in CI) can delay that answer
/// past one second.
const RECORD_TIMEOUT_S: u64 = 5;

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn ctrl_c_or_a_unit_that_goes_away_leaves_a_complete_recorded_run() {
    let dir = TempDir::new().unwrap();
    let (mut board, _one) = board();
    let port = board.pty().to_str().unwrap().to_owned();
    let record = |out: &Path| {
        Background::spawn(
            Command::new(trainer())
                .args(["device", "record", "--port", &port, "--timeout-s"])
                .arg(RECORD_TIMEOUT_S.to_string())
                .arg("-o")
                .arg(out),
        )
    };
    let complete = |path: &Path| {
        let text = std::fs::read_to_string(path).unwrap();
        assert!(text.ends_with('\n'), "the last row is whole");
        let run = trainer::reading::run::samples::Run::load(path).unwrap();
        assert!(run.time_s.len() > 100, "{} rows", run.time_s.len());
        run.time_s.len()
    };

    // Ctrl-C: the run so far, committed, exit 0.
    let stopped = dir.path().join("stopped.csv");
    let mut child = record(&stopped);
    let_record_run(dir.path(), &mut child);
    rustix::process::kill_process(
        rustix::process::Pid::from_raw(child.id() as i32).unwrap(),
        rustix::process::Signal::INT,
    )
    .unwrap();
    let out = child.wait();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    complete(&stopped);
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "staged files left: {leftovers:?}");

    // The unit goes away: the rows before, committed, exit 1 naming the port.
    let cut = dir.path().join("cut.csv");
    let mut child = record(&cut);
    let_record_run(dir.path(), &mut child);
    board.check_running().unwrap();
    drop(board);
    let started = Instant::now();
    let out = child.wait();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    // Silence for the timeout ends it, with a margin for a loaded machine.
    let limit = Duration::from_secs(RECORD_TIMEOUT_S + 4);
    assert!(started.elapsed() < limit, "{:?}", started.elapsed());
    assert!(err.contains(&port), "{err}");
    assert!(err.contains("the rows before the failure are written"), "{err}");
    complete(&cut);
}

/// The `column` of every data row of the CSV `text`, parsed.
fn column<T: std::str::FromStr>(text: &str, column: &str) -> Vec<T> {
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let i = header.iter().position(|c| *c == column).unwrap();
    lines
        .map(|l| l.split(',').nth(i).unwrap().parse().ok().unwrap())
        .collect()
}

/// 3,000 rows of the bundled chamber run (the board takes one per sample).
fn bundled_rows() -> String {
    std::fs::read_to_string(e2e_tests::example("ifog_train_1cpm.csv"))
        .unwrap()
        .lines()
        .take(3_010)
        .map(|l| format!("{l}\n"))
        .collect()
}

/// Records 2 s of the board serving `source_text` (three-axis image if
/// `three_axes`) and checks that each axis's recorded raw columns are the
/// source's (`rate`, `temp` column pairs of source and recording).
fn replayed_run_comes_back(source_text: &str, three_axes: bool, columns: &[(&str, &str, &str, &str)]) {
    let dir = TempDir::new().unwrap();
    let source = dir.path().join("source.csv");
    std::fs::write(&source, source_text).unwrap();
    let _one = ONE_BOARD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let board = QemuBoard::start(&BoardOptions {
        three_axes,
        model: None,
        run: Some(source.clone()),
        limit: Some(QEMU_LIMIT),
    })
    .unwrap();
    let recorded = dir.path().join("recorded.csv");
    let port = board.pty().to_str().unwrap();
    ok(&[
        "device",
        "record",
        "--port",
        port,
        "--seconds",
        "2",
        "-o",
        recorded.to_str().unwrap(),
    ]);
    drop(board);
    let text = std::fs::read_to_string(&recorded).unwrap();
    for &(rate_column, temp_column, got_rate_column, got_temp_column) in columns {
        let rates: Vec<f32> = column::<f64>(source_text, rate_column)
            .iter()
            .map(|&r| r as f32)
            .collect();
        let temps: Vec<f64> = column(source_text, temp_column);
        let (got_rates, got_temps): (Vec<f32>, Vec<f32>) =
            (column(&text, got_rate_column), column(&text, got_temp_column));
        assert!(got_rates.len() > 500, "{} rows", got_rates.len());
        // Each row's raw rate is the source's next row's, bit for bit (the
        // board steps through the run one row per sample, from its start
        // again at its end); a frame lost on the way skips a row.
        let n = rates.len();
        let step_from = |at: usize, rate: f32| {
            (1..=8)
                .map(|step| (at + step) % n)
                .find(|&j| rates[j].to_bits() == rate.to_bits())
        };
        // The first row's rate may recur in the source (rates of five
        // decimals over thousands of rows): start at the occurrence from
        // which the next recorded rows follow, not at the first one.
        let follows = |start: usize| {
            got_rates
                .iter()
                .skip(1)
                .take(32)
                .try_fold(start, |at, &rate| step_from(at, rate))
                .is_some()
        };
        let mut at = (0..n)
            .filter(|&i| rates[i].to_bits() == got_rates[0].to_bits())
            .find(|&i| follows(i))
            .or_else(|| rates.iter().position(|&r| r.to_bits() == got_rates[0].to_bits()))
            .unwrap();
        let mut skipped = 0;
        for (k, &rate) in got_rates.iter().enumerate().skip(1) {
            let next = step_from(at, rate).unwrap_or_else(|| {
                panic!(
                    "{got_rate_column} row {k}: rate {rate} is not among the source rows after row {at} \
                         ({:?});\nrecorded:\n{}",
                    &rates[at..(at + 9).min(n)],
                    text.lines().take(12).collect::<Vec<_>>().join("\n")
                )
            });
            skipped += (next + n - at - 1) % n;
            at = next;
            // The temperature is a source row's of this axis, read through
            // the TMP117 (the source's values are whole 1/128 °C, which it
            // carries exactly) on every 125th sample number (a missed one
            // defers the read): on the single-axis board one of the rows
            // before; on the three-axis board (three thermometers, three
            // evaluations per step) the loaded host's missed samples move
            // the reads, so there only its column is checked.
            let t = got_temps[k];
            if three_axes {
                assert!(
                    temps.iter().any(|&s| (s as f32).to_bits() == t.to_bits()),
                    "{got_temp_column} row {k}: {t} is in no row of the source's {temp_column}"
                );
            } else {
                assert!(
                    (0..1000).any(|back| (temps[(at + n - back) % n] as f32).to_bits() == t.to_bits()),
                    "{got_temp_column} row {k}: {t} is none of the source's rows before row {at}"
                );
            }
        }
        assert!(skipped * 100 <= got_rates.len(), "{skipped} source rows skipped");
    }
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn a_recorded_run_replayed_through_the_board_comes_back_in_its_raw_columns() {
    replayed_run_comes_back(&bundled_rows(), false, &[("rate_dph", "temp_c", "rate_dph", "temp_c")]);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn a_three_axis_run_replayed_through_the_three_axis_board_comes_back_axis_by_axis() {
    // The bundled run as axis x; y and z its rates negated and offset, their
    // coils 0.5 and 1 °C warmer (still whole 1/128 °C), so that an axis
    // answering from another's columns shows.
    let mut source_text = String::new();
    for line in bundled_rows().lines() {
        if line.starts_with('#') {
            continue;
        }
        let cells: Vec<&str> = line.split(',').collect();
        let (time, rate, temp) = (cells[0], cells[1], cells[2]);
        if time == "time_s" {
            source_text.push_str("time_s,rate_x_dph,temp_x_c,rate_y_dph,temp_y_c,rate_z_dph,temp_z_c\n");
            continue;
        }
        let (r, t): (f64, f64) = (rate.parse().unwrap(), temp.parse().unwrap());
        source_text.push_str(&format!(
            "{time},{rate},{temp},{},{},{},{}\n",
            -r,
            t + 0.5,
            r + 100.0,
            t + 1.0
        ));
    }
    replayed_run_comes_back(
        &source_text,
        true,
        &[
            ("rate_x_dph", "temp_x_c", "rate_x_dph", "temp_x_c"),
            ("rate_y_dph", "temp_y_c", "rate_y_dph", "temp_y_c"),
            ("rate_z_dph", "temp_z_c", "rate_z_dph", "temp_z_c"),
        ],
    );
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn a_three_axis_unit_refuses_a_single_axis_blob_unless_forced() {
    let dir = TempDir::new().unwrap();
    // A single-axis model within the three-axis board's capacity (it would run it as axis x).
    let model = dir.path().join("single.bin");
    let train = e2e_tests::example("ifog_train_1cpm.csv");
    ok(&[
        "fit",
        train.to_str().unwrap(),
        "--max-centers",
        "16",
        "-o",
        model.to_str().unwrap(),
    ]);
    let _one = ONE_BOARD.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    xtask::qemu::ensure_installed().unwrap();
    let board = QemuBoard::start(&BoardOptions {
        three_axes: true,
        model: None,
        run: None,
        limit: Some(QEMU_LIMIT),
    })
    .unwrap();
    let port = board.pty().to_str().unwrap().to_owned();
    let update = ["device", "update", "--port", &port, "--model", model.to_str().unwrap()];
    let err = fails(&update);
    assert!(
        err.contains(&format!(
            "{port}: blob refused, nothing sent: the unit's frames carry the axes x, y, z but the blob has a model for x alone"
        )),
        "{err}"
    );
    assert!(
        ok(&["device", "status", "--port", &port]).contains("none running"),
        "no model was installed"
    );
    let said = ok(&[&update[..], &["--force"]].concat());
    assert!(said.contains("installed: the new model runs"), "{said}");
}
