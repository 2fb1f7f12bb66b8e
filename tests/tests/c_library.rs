//! rbf-core's C library (crate rbf-core-c) against `trainer compensate`: the
//! C program rbf-core-c/c/replay.c, built from the header and the static
//! library with the host's `cc`, and with `arm-none-eabi-gcc` and newlib
//! for the STM32F405 under QEMU, replays runs it was not built for
//! (`cargo xtask c-replay`), byte for byte what compensate writes.
//!
//! Ignored in a plain `cargo test` (they need a C compiler, the ARM
//! toolchain and QEMU); `cargo xtask ci` installs those and runs them with
//! `--ignored`.

use std::path::{Path, PathBuf};

use e2e_tests::fixtures;
use tempfile::TempDir;
use trainer::evaluation::axes::{Acceptance, compensate_command};
use trainer::output::Existing;
use xtask::c_library::CTarget;

/// Data rows the QEMU replays keep of a fixture's slice (past its first
/// sensor faults): seconds of emulation, not minutes.
const QEMU_ROWS: usize = 3_100;

/// The first `rows` data rows of the run at `path` (metadata and header
/// kept), written beside it; its path.
fn first_rows(path: &Path, rows: usize) -> PathBuf {
    let text = std::fs::read_to_string(path).unwrap();
    let mut kept = String::new();
    let (mut header, mut data) = (false, 0);
    for line in text.lines() {
        if header && !line.starts_with('#') {
            if data == rows {
                break;
            }
            data += 1;
        }
        header |= !line.starts_with('#');
        kept.push_str(line);
        kept.push('\n');
    }
    assert_eq!(data, rows, "{} is shorter than {rows} rows", path.display());
    let short = path.with_extension(format!("{rows}.csv"));
    std::fs::write(&short, kept).unwrap();
    short
}

/// Replays `run` with the blob at `blob` through the C program on `target`
/// and asserts that its output is byte for byte `trainer compensate`'s.
fn c_replay_matches_compensate(target: CTarget, blob: &Path, run: &Path) {
    let run = match target {
        CTarget::Host => run.to_owned(),
        CTarget::Qemu => first_rows(run, QEMU_ROWS),
    };
    let dir = run.parent().unwrap();
    let expected = dir.join("expected.csv");
    let (_, out) = compensate_command(blob, &run, &expected, Existing::Replace, false).unwrap();
    out.commit().unwrap();
    let got_path = dir.join(format!("c-{target:?}.csv"));
    let summary =
        xtask::c_replay::c_replay(target, blob, &run, &got_path, Existing::Replace, Acceptance::default()).unwrap();
    let (got, want) = (
        std::fs::read_to_string(&got_path).unwrap(),
        std::fs::read_to_string(&expected).unwrap(),
    );
    assert_eq!(got.lines().count(), want.lines().count(), "{summary:?}");
    let differing: Vec<(&str, &str)> = got.lines().zip(want.lines()).filter(|(a, b)| a != b).take(3).collect();
    assert!(
        differing.is_empty(),
        "rows of the C replay differ from trainer compensate: {differing:?}"
    );
    assert!(got == want, "the C replay's output differs from trainer compensate");
}

/// A single gyro's 16-centre lag-bank model and a slice of another run with
/// sensor faults, as the firmware tests use them; (blob path, slice path).
fn single_axis(dir: &Path) -> (PathBuf, PathBuf) {
    let (model, slice) = fixtures::model_and_faulty_slice(dir);
    let blob = dir.join("model.bin");
    trainer::blobfile::write_model(&blob, &model, Existing::Replace).unwrap();
    (blob, slice)
}

#[test]
#[ignore = "needs a C compiler: run by `cargo xtask ci`"]
fn host_c_replay_of_a_single_axis_run_with_sensor_faults_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (blob, slice) = single_axis(dir.path());
    c_replay_matches_compensate(CTarget::Host, &blob, &slice);
}

#[test]
#[ignore = "needs a C compiler: run by `cargo xtask ci`"]
fn host_c_replay_of_a_multi_point_run_reading_eight_thermometers_is_byte_identical() {
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::multipoint_model_and_faulty_slice(dir.path());
    let blob = dir.path().join("multi.bin");
    trainer::blobfile::write_model(&blob, &model, Existing::Replace).unwrap();
    c_replay_matches_compensate(CTarget::Host, &blob, &slice);
}

#[test]
#[ignore = "needs a C compiler: run by `cargo xtask ci`"]
fn host_c_replay_of_three_axes_with_a_model_per_axis_and_with_a_shared_basis_is_byte_identical() {
    let dir = TempDir::new().unwrap();
    let (blob, slice) = fixtures::axes_blob_and_slice(dir.path());
    c_replay_matches_compensate(CTarget::Host, &blob, &slice);
    let dir = TempDir::new().unwrap();
    let (blob, slice) = fixtures::shared_blob_and_slice(dir.path());
    c_replay_matches_compensate(CTarget::Host, &blob, &slice);
}

#[test]
#[ignore = "needs arm-none-eabi-gcc, newlib and qemu-system-arm: run by `cargo xtask ci`"]
fn qemu_c_replay_of_single_and_three_axis_runs_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (blob, slice) = single_axis(dir.path());
    c_replay_matches_compensate(CTarget::Qemu, &blob, &slice);
    let dir = TempDir::new().unwrap();
    let (blob, slice) = fixtures::axes_blob_and_slice(dir.path());
    c_replay_matches_compensate(CTarget::Qemu, &blob, &slice);
    let dir = TempDir::new().unwrap();
    let (blob, slice) = fixtures::shared_blob_and_slice(dir.path());
    c_replay_matches_compensate(CTarget::Qemu, &blob, &slice);
}

#[test]
#[ignore = "needs a C compiler, arm-none-eabi-gcc and qemu-system-arm: run by `cargo xtask ci`"]
fn a_corrupt_blob_is_refused_in_the_libraries_words_and_writes_nothing() {
    let dir = TempDir::new().unwrap();
    let (blob, slice) = single_axis(dir.path());
    let mut bytes = std::fs::read(&blob).unwrap();
    let middle = bytes.len() / 2;
    bytes[middle] ^= 0x10;
    let corrupt = dir.path().join("corrupt.bin");
    std::fs::write(&corrupt, bytes).unwrap();
    let short = first_rows(&slice, 100);
    for target in [CTarget::Host, CTarget::Qemu] {
        let out = dir.path().join("out.csv");
        let e = xtask::c_replay::c_replay(target, &corrupt, &short, &out, Existing::Replace, Acceptance::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(
                "corrupt.bin: the C library refuses the blob: CRC-32 mismatch: the blob is corrupt (status -14)"
            ),
            "{target:?}: {e}"
        );
        assert!(!out.exists(), "{target:?}: a refused replay writes no output");
    }
}

#[test]
#[ignore = "needs a C compiler: run by `cargo xtask ci`"]
fn from_c_a_blob_with_provenance_gives_its_model_id_and_serial_and_one_without_gives_none() {
    let dir = TempDir::new().unwrap();
    let (blob, slice) = single_axis(dir.path());
    let short = first_rows(&slice, 100);
    let (model, _) = trainer::blobfile::read_model(&blob).unwrap();
    let record = trainer::provenance::ProvenanceRecord::for_fit(Some("FOG-0042"), &[&slice], None, None).unwrap();
    let with = dir.path().join("with-provenance.bin");
    std::fs::write(&with, trainer::blobfile::encode_model(&model, Some(&record)).unwrap()).unwrap();
    let out = dir.path().join("out.csv");
    let report = |blob: &Path| {
        xtask::c_replay::c_replay(
            CTarget::Host,
            blob,
            &short,
            &out,
            Existing::Replace,
            Acceptance::default(),
        )
        .unwrap()
        .report
    };
    let id = trainer::provenance::model_id_text(record.model_id());
    assert!(
        report(&with).ends_with(&format!(" provenance {id} serial \"FOG-0042\"")),
        "{}",
        report(&with)
    );
    // The fixture's blob is written without provenance (format 2).
    assert!(report(&blob).ends_with(" provenance none"), "{}", report(&blob));
}
