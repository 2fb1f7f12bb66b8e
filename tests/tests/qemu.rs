//! The real thumbv7em firmware image under QEMU (netduinoplus2 = STM32F405).
//!
//! Ignored in a plain `cargo test` (they need qemu-system-arm and a cross
//! build); `cargo xtask ci` installs QEMU and runs them with `--ignored`.

use std::path::Path;

use e2e_tests::fixtures;
use gyro_wire::frame;
use rbf_core::Flags;
use tempfile::TempDir;
use trainer::blobfile::write_model;
use trainer::evaluation::compensate::compensate_file;
use trainer::evaluation::evaluate::FlagCounts;
use trainer::output::Existing;
use xtask::replay::ReplaySummary;

/// Writes `model` into `dir`, compensates `slice` with it on the host and
/// replays it under QEMU (UART frames into `frames` when given); asserts one
/// output row per input row and byte-identical CSVs. Returns the host's flag
/// counts and the replay's summary.
fn replay_matches_host(
    dir: &Path,
    model: &rbf_core::Model,
    slice: &Path,
    frames: Option<&Path>,
) -> (FlagCounts, ReplaySummary) {
    let model_path = dir.join("model.bin");
    write_model(&model_path, model, Existing::Replace).unwrap();
    let expected_path = dir.join("expected.csv");
    let (_, flagged) = compensate_file(Some(model), slice, &expected_path).unwrap();
    let out = dir.join("qemu.csv");
    let summary = xtask::replay::qemu_replay(&model_path, slice, &out, frames).unwrap();
    assert_eq!(summary.samples, fixtures::ROWS);
    // trainer compensate's output: the model's provenance lines, then the
    // compensated run compensate_file writes.
    let mut want = trainer::blobfile::provenance_lines(&model_path, &std::fs::read(&model_path).unwrap()).into_bytes();
    want.extend(std::fs::read(&expected_path).unwrap());
    let got = std::fs::read(&out).unwrap();
    assert!(got == want, "QEMU replay output differs from trainer compensate");
    (flagged, summary)
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_with_sensor_faults_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::model_and_faulty_slice(dir.path());
    // The default model: a lag bank (filters, coil lags, gain, tangent powers) and Gaussians over T̂.
    assert!(matches!(model.features().set, rbf_core::FeatureSet::LagBank(_)));
    let frames_path = dir.path().join("frames.bin");
    replay_matches_host(dir.path(), &model, &slice, Some(&frames_path));

    // The UART frames say the same: one per row, flag 2 exactly on faulted rows.
    let mut frames = std::fs::read(&frames_path).unwrap();
    let decoded: Vec<_> = frames
        .split_mut(|&b| b == 0)
        .filter(|c| !c.is_empty())
        .map(|c| frame::decode(c).unwrap())
        .collect();
    assert_eq!(decoded.len(), fixtures::ROWS);
    for (i, f) in decoded.iter().enumerate() {
        assert_eq!(f.seq as usize, i);
        assert_eq!(
            f.flags().contains(Flags::TEMP_SENSOR_FAULT),
            fixtures::faulty(i),
            "row {i}"
        );
    }
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_of_a_lagged_multiscale_model_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::lagged_model_and_faulty_slice(dir.path());
    assert_eq!(
        model.features().set,
        rbf_core::FeatureSet::MultiScaleLagged { coil_lag_min: 40 }
    );
    let (flagged, _) = replay_matches_host(dir.path(), &model, &slice, None);
    assert_eq!(flagged.temp_sensor_fault, fixtures::FAULTY_ROWS as usize);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_of_a_response_bank_model_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::response_bank_model_and_faulty_slice(dir.path());
    let rbf_core::FeatureSet::ResponseBank(bank) = model.features().set else {
        panic!("not a response bank: {:?}", model.features())
    };
    assert_eq!(bank.filter_count(), 12);
    let (flagged, _) = replay_matches_host(dir.path(), &model, &slice, None);
    assert_eq!(flagged.temp_sensor_fault, fixtures::FAULTY_ROWS as usize);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_of_a_multi_point_run_reads_eight_tmp117s_and_matches_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::multipoint_model_and_faulty_slice(dir.path());
    assert!(
        matches!(model.features().set, rbf_core::FeatureSet::MultiPoint(_)),
        "{:?}",
        model.features()
    );
    let (flagged, summary) = replay_matches_host(dir.path(), &model, &slice, None);
    // The inputs read temp_a, temp_c, temp_d and temp_e: four TMP117s on two
    // buses, each failing on every faulted row.
    let reads_failed = format!("temp_read_faults {} ", 4 * fixtures::FAULTY_ROWS);
    assert!(summary.report.contains(&reads_failed), "{}", summary.report);
    assert_eq!(flagged.temp_sensor_fault, fixtures::FAULTY_ROWS as usize);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_of_a_three_axis_run_is_byte_identical_to_trainer_compensate() {
    let dir = TempDir::new().unwrap();
    let (blob_path, slice) = fixtures::axes_blob_and_slice(dir.path());
    let expected_path = dir.path().join("expected.csv");
    let (_, expected) =
        trainer::evaluation::axes::compensate_command(&blob_path, &slice, &expected_path, Existing::Replace, false)
            .unwrap();
    expected.commit().unwrap();
    let out = dir.path().join("qemu.csv");
    let frames_path = dir.path().join("frames.bin");
    let summary = xtask::replay::qemu_replay(&blob_path, &slice, &out, Some(&frames_path)).unwrap();
    assert_eq!(summary.samples, fixtures::AXES_ROWS);
    let (got, want) = (
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(&expected_path).unwrap(),
    );
    assert_eq!(got.lines().count(), want.lines().count());
    let differing = got.lines().zip(want.lines()).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "rows of the QEMU replay differ from trainer compensate");
    assert!(got == want, "QEMU replay output differs from trainer compensate");

    // One frame per row with x, y and z; flag 2 on every axis exactly on the faulted rows.
    let mut frames = std::fs::read(&frames_path).unwrap();
    let decoded: Vec<_> = frames
        .split_mut(|&b| b == 0)
        .filter(|c| !c.is_empty())
        .map(|c| frame::decode_axes(c).unwrap())
        .collect();
    assert_eq!(decoded.len(), fixtures::AXES_ROWS);
    for (i, f) in decoded.iter().enumerate() {
        assert_eq!((f.seq as usize, f.axis_mask), (i, 0b111));
        for axis in &f.axes {
            assert_eq!(
                axis.flags().contains(Flags::TEMP_SENSOR_FAULT),
                fixtures::axes_faulty(i),
                "row {i}"
            );
        }
    }
}

/// Runs the `trainer` CLI at `trainer` with `args`; panics with its
/// output when it fails.
fn run_trainer(trainer: &Path, args: &[&str]) -> String {
    let out = std::process::Command::new(trainer).args(args).output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "trainer {args:?} failed:\n{stdout}\n{stderr}");
    format!("{stdout}{stderr}")
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn qemu_replay_of_a_shared_thermometer_run_with_the_joint_blob_trainer_fit_wrote_is_byte_identical() {
    let dir = TempDir::new().unwrap();
    let trainer = xtask::firmware::trainer_cli().unwrap();
    let path = |name: &str| dir.path().join(name).to_str().unwrap().to_owned();
    let (train, verify, blob, slice, host, qemu) = (
        path("cycle.csv"),
        path("random.csv"),
        path("imu.bin"),
        path("slice.csv"),
        path("host.csv"),
        path("qemu.csv"),
    );
    let simulate = |profile: &str, seed: &str, out: &str| {
        run_trainer(
            &trainer,
            &[
                "simulate",
                "--profile",
                profile,
                "--axes",
                "3",
                "--shared-thermometer",
                "--seed",
                seed,
                "-o",
                out,
            ],
        )
    };
    simulate("cycle", "11", &train);
    simulate("random", "12", &verify);
    let summary = run_trainer(&trainer, &["fit", &train, "-o", &blob, "--joint"]);
    let bytes = std::fs::read(&blob).unwrap();
    assert!(
        rbf_core::blob::blob_kind(&bytes) == Ok(rbf_core::blob::BlobKind::SharedBasis),
        "trainer fit did not choose the joint model:\n{summary}"
    );

    // The first AXES_ROWS data rows of the random run.
    let text = std::fs::read_to_string(&verify).unwrap();
    let mut kept = String::new();
    let mut data = 0;
    let mut header = false;
    for line in text.lines() {
        if !header || line.starts_with('#') {
            header |= !line.starts_with('#');
        } else if data < fixtures::AXES_ROWS {
            data += 1;
        } else {
            break;
        }
        kept.push_str(line);
        kept.push('\n');
    }
    assert_eq!(data, fixtures::AXES_ROWS, "the random run is shorter than the slice");
    std::fs::write(&slice, kept).unwrap();

    run_trainer(&trainer, &["compensate", "--model", &blob, &slice, "-o", &host]);
    let summary = xtask::replay::qemu_replay(Path::new(&blob), Path::new(&slice), Path::new(&qemu), None).unwrap();
    assert_eq!(summary.samples, fixtures::AXES_ROWS);
    let (got, want) = (
        std::fs::read_to_string(&qemu).unwrap(),
        std::fs::read_to_string(&host).unwrap(),
    );
    assert_eq!(got.lines().count(), want.lines().count());
    let differing = got.lines().zip(want.lines()).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "rows of the QEMU replay differ from trainer compensate");
    assert!(got == want, "QEMU replay output differs from trainer compensate");
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn corrupt_model_slot_runs_uncompensated_with_flag_4_never_halts() {
    // The replay command refuses a corrupt blob up front (as trainer compensate
    // does), so place the corrupt bytes in flash directly and run the image.
    let dir = TempDir::new().unwrap();
    let (model, slice) = fixtures::model_and_faulty_slice(dir.path());
    let mut blob = trainer::blobfile::write_model(&dir.path().join("m.bin"), &model, Existing::Replace).unwrap();
    blob[20] ^= 0x40;
    std::fs::write(dir.path().join("model.bin"), &blob).unwrap();
    std::fs::copy(&slice, dir.path().join("input.csv")).unwrap();
    let elf = xtask::firmware::build(xtask::firmware::HARNESS, "qemu-replay", &[]).unwrap();
    let loader = format!("loader,file=model.bin,addr={:#x}", xtask::replay::MODEL_SLOT_A);
    let run = xtask::qemu::run(
        &elf,
        dir.path(),
        &["-device".into(), loader],
        std::time::Duration::from_secs(120),
    )
    .unwrap();
    assert!(run.success, "{}", run.log);
    assert!(run.log.contains("model slot refused (CRC mismatch"), "{}", run.log);
    let out = std::fs::read_to_string(dir.path().join("output.csv")).unwrap();
    let rows: Vec<&str> = out.lines().filter(|l| !l.starts_with('#')).skip(1).collect();
    assert_eq!(rows.len(), fixtures::ROWS);
    for row in rows {
        let flags: u8 = row.rsplit(',').next().unwrap().parse().unwrap();
        assert!(Flags(flags).contains(Flags::NO_VALID_MODEL), "{row}");
    }
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn benchmark_image_runs_and_reports_every_model_size() {
    // A smoke test: the figures themselves are `cargo xtask bench-fw`'s job.
    let elf = xtask::firmware::build(xtask::firmware::FIRMWARE, "qemu-bench", &[]).unwrap();
    let dir = TempDir::new().unwrap();
    let icount = ["-icount".to_owned(), "shift=0".to_owned()];
    let run = xtask::qemu::run(&elf, dir.path(), &icount, std::time::Duration::from_secs(120)).unwrap();
    assert!(run.success, "{}", run.log);
    for shape in [
        "lag-bank K=32 F=5:",
        "K=32 D=8 (multi-scale set",
        "over T̄",
        "K=8 D=3:",
        "K=16 D=3:",
        "K=64 D=3:",
        "K=32 D=3:",
        "axes=3 K=32 D=3:",
        "axes=3 K=32 D=3 three separate models",
    ] {
        let line = run
            .log
            .lines()
            .find(|l| l.starts_with("instructions_per_sample") && l.contains(shape));
        let count: u64 = line
            .and_then(|l| l.rsplit(' ').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or(0);
        assert!(count > 100, "no figure for {shape}:\n{}", run.log);
    }
    assert!(
        run.log.lines().last().unwrap_or("").starts_with("stack_peak_bytes"),
        "{}",
        run.log
    );
}

/// A board run under QEMU (`run`) took its update and answered the bench
/// command, one frame per sample; board image `image`
/// fits its flash budget, and its static RAM and the run's stack peak its
/// RAM budget (`xtask::bench::budget_for`: 96 KiB flash, 24 KiB RAM, every image).
fn board_within_budgets(run: &xtask::board_stack::BoardRun, image: xtask::firmware::BoardImage) {
    assert!(run.summary.contains("update Some(Installed)"), "{run:?}");
    assert!(run.frames > 10_000, "one frame per sample and the replies: {run:?}");
    let budget = xtask::bench::budget_for(image);
    let board = image.build().unwrap();
    let size = xtask::firmware::image_size(&board).unwrap();
    assert!(
        size.static_ram + run.stack_peak_bytes <= budget.ram_bytes,
        "static RAM {} B + stack {} B over {} B",
        size.static_ram,
        run.stack_peak_bytes,
        budget.ram_bytes
    );
    assert!(
        size.flash <= budget.flash_bytes && size.largest_rodata.1 <= 4096,
        "{size:?} over {budget:?}"
    );
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn the_board_image_takes_an_update_and_a_bench_command_within_its_ram_budget() {
    // The stm32f405 board's code under QEMU (stm32f405-qemu: QEMU's missing
    // pieces swapped): boot with a model, an install and a bench command over its
    // UART (measure() refuses a run without the install or the bench
    // report), 10,000 samples; its static RAM and painted stack fit 24 KiB.
    let run = xtask::board_stack::measure().unwrap();
    board_within_budgets(&run, xtask::firmware::BOARD);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn the_three_axis_board_takes_a_three_axis_update_within_the_boards_budgets() {
    // The three-axis board under QEMU (stm32f405-axes-qemu): three models of
    // firmware::AXIS_CENTERS centres at boot, a three-axis install and a bench
    // command over its UART, 10,000 samples; flash, static RAM and stack fit.
    let run = xtask::board_stack::measure_axes().unwrap();
    board_within_budgets(&run, xtask::firmware::BOARD_AXES);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn the_shared_basis_board_takes_a_shared_basis_update_within_the_boards_budgets() {
    // The shared-basis board under QEMU (stm32f405-axes-shared-qemu): a
    // shared basis of firmware::SHARED_AXIS_CENTERS centres at boot, a
    // shared-basis install and a bench command over its UART, 10,000
    // samples; flash, static RAM and stack fit.
    let run = xtask::board_stack::measure_axes_shared().unwrap();
    board_within_budgets(&run, xtask::firmware::BOARD_AXES_SHARED);
}

#[test]
#[ignore = "needs qemu-system-arm and the thumbv7em target: run by `cargo xtask ci`"]
fn fault_campaign_on_the_target_loses_no_sample_and_never_panics() {
    let dir = TempDir::new().unwrap();
    let (model, _) = fixtures::model_and_faulty_slice(dir.path());
    let running = dir.path().join("running.bin");
    write_model(&running, &model, Existing::Replace).unwrap();
    let cubic = fixtures::cubic_model();
    let update = dir.path().join("update.bin");
    write_model(&update, &cubic, Existing::Replace).unwrap();

    let lines = xtask::faults::qemu_faults(&running, &update).unwrap();
    let report = lines.join("\n");
    let summary = lines.last().unwrap();
    assert!(summary.contains("samples lost 0, panics 0"), "{report}");
    let injected: u32 = summary
        .strip_prefix("faults injected ")
        .and_then(|s| s.split(',').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert!(injected > 2000, "{report}");
    for must in [
        "frames 20000",
        "missing-flags 0 non-finite 0",
        "accepted 0",
        "booted invalid 0 retry failures 0",
        "expected replies 5 switched true",
        "faults: axes: y thermometer failing: samples 20000 frames 20000",
        "missing-flags 0 y-uncompensated",
        "others-disturbed 0 temp-read-faults x 0 y",
    ] {
        assert!(report.contains(must), "`{must}` missing from:\n{report}");
    }
}
