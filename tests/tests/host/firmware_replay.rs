//! The replay board's code path on the host: a recorded run with injected
//! temperature-sensor faults, replayed through the real drivers on emulated
//! buses, gives output byte-identical to `trainer compensate`.

use e2e_tests::fixtures as common;

use std::cell::Cell;

use firmware::compensation::ModelHolder;
use firmware_harness::replay::{self, ReplaySample, Replayer};
use gyro_wire::frame;
use rbf_core::Flags;
use trainer::evaluation::compensate::compensate_file;

#[test]
fn replay_is_byte_identical_to_trainer_compensate() {
    let dir = tempfile::TempDir::new().unwrap();
    let (model, slice) = common::model_and_faulty_slice(dir.path());
    let expected_path = dir.path().join("expected.csv");
    compensate_file(Some(&model), &slice, &expected_path).unwrap();
    let expected = std::fs::read_to_string(&expected_path).unwrap();

    let input = std::fs::read_to_string(&slice).unwrap();
    let period_s = replay::probe_period(input.lines()).unwrap();
    let current: [Cell<ReplaySample>; 1] = Default::default();
    let mut frames: Vec<u8> = Vec::new();
    let mut replayer = Replayer::new(Some(&model), period_s, &current, &mut frames).unwrap();
    let out = replay_all(&mut replayer, &input);
    let stats = replayer.stats();
    assert_eq!(stats.samples as usize, common::ROWS);
    assert_eq!(stats.temp_read_faults, common::FAULTY_ROWS);
    assert_eq!(stats.output_errors, 0);
    assert_eq!(out, expected, "replay output differs from trainer compensate");

    // Flag 2 on exactly the faulted rows; one frame per row, in order.
    let rows = data_rows(&out);
    let mut seq = 0;
    for chunk in frames.split_mut(|&b| b == 0).filter(|c| !c.is_empty()) {
        let f = frame::decode(chunk).unwrap();
        assert_eq!(f.seq, seq);
        let csv_flags: u8 = rows[seq as usize].rsplit(',').next().unwrap().parse().unwrap();
        assert_eq!(f.flags, csv_flags);
        assert_eq!(
            f.flags().contains(Flags::TEMP_SENSOR_FAULT),
            common::faulty(seq as usize),
            "row {seq}"
        );
        seq += 1;
    }
    assert_eq!(seq as usize, common::ROWS);
}

#[test]
fn replay_without_a_model_passes_every_sample_through_with_flag_4() {
    let dir = tempfile::TempDir::new().unwrap();
    let (_, slice) = common::model_and_faulty_slice(dir.path());
    let input = std::fs::read_to_string(&slice).unwrap();
    let current: [Cell<ReplaySample>; 1] = Default::default();
    let mut replayer = Replayer::new(None::<&rbf_core::Model>, 1.0, &current, Vec::new()).unwrap();
    let out = replay_all(&mut replayer, &input);
    let mut rows = 0;
    for line in data_rows(&out) {
        let mut f = line.rsplit(',');
        let flags: u8 = f.next().unwrap().parse().unwrap();
        let comp: f32 = f.next().unwrap().parse().unwrap();
        let bias: f32 = f.next().unwrap().parse().unwrap();
        assert!(Flags(flags).contains(Flags::NO_VALID_MODEL), "{line}");
        assert_eq!(bias.to_bits(), 0f32.to_bits());
        let rate: f32 = line.split(',').nth(1).unwrap().parse().unwrap();
        assert_eq!(comp.to_bits(), rate.to_bits(), "uncompensated output is the raw rate");
        rows += 1;
    }
    assert_eq!(rows, common::ROWS);
}

#[test]
fn replay_and_trainer_agree_on_the_period_when_metadata_repeats_or_is_bad() {
    // The first `sample_rate_hz` does not parse, the second is a wrong 2 Hz: both
    // sides must take the same one (the first positive), or gaps would differ.
    let dir = tempfile::TempDir::new().unwrap();
    let (model, slice) = common::model_and_faulty_slice(dir.path());
    let text = std::fs::read_to_string(&slice).unwrap();
    let odd = dir.path().join("odd_metadata.csv");
    std::fs::write(&odd, format!("# sample_rate_hz: fast\n# sample_rate_hz: 2\n{text}")).unwrap();
    let expected_path = dir.path().join("expected.csv");
    compensate_file(Some(&model), &odd, &expected_path).unwrap();
    let input = std::fs::read_to_string(&odd).unwrap();
    let period_s = replay::probe_period(input.lines()).unwrap();
    assert_eq!(period_s.to_bits(), 0.5f64.to_bits());
    let current: [Cell<ReplaySample>; 1] = Default::default();
    let mut replayer = Replayer::new(Some(&model), period_s, &current, Vec::new()).unwrap();
    let out = replay_all(&mut replayer, &input);
    assert_eq!(out, std::fs::read_to_string(&expected_path).unwrap());
}

#[test]
fn three_axis_replay_is_byte_identical_to_trainer_compensate_and_frames_carry_every_axis() {
    use rbf_core::blob::axes::{AxisModels, decode_axes_into};
    let dir = tempfile::TempDir::new().unwrap();
    let (blob_path, slice) = common::axes_blob_and_slice(dir.path());
    let expected = multi_axis_compensated_run(&blob_path, &slice, dir.path());
    let expected = expected.as_str();

    // Replayed at the trainer's capacity; the fitted axes (OLS kept at most
    // 16 centres of those asked for) also fit the three-axis board.
    let blob = std::fs::read(&blob_path).unwrap();
    let mut board = Box::new(AxisModels::<{ firmware::AXIS_CENTERS }>::EMPTY);
    assert_eq!(decode_axes_into(&mut board, &blob), Ok(blob.len()));
    let mut models = Box::new(AxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    decode_axes_into(&mut models, &blob).unwrap();
    let input = std::fs::read_to_string(&slice).unwrap();
    let period_s = replay::probe_period(input.lines()).unwrap();
    let current: [Cell<ReplaySample>; 3] = Default::default();
    let mut frames: Vec<u8> = Vec::new();
    let mut replayer = Replayer::new(Some(&*models), period_s, &current, &mut frames).unwrap();
    let out = replay_all(&mut replayer, &input);
    let stats = replayer.stats();
    assert_eq!(stats.samples as usize, common::AXES_ROWS);
    assert_eq!(stats.output_errors, 0);
    assert_same_run(&out, expected);

    // One frame per row carrying x, y and z, flags as in the CSV's flags_<axis>.
    for (seq, f) in axes_frames_matching_rows(&mut frames, &out).iter().enumerate() {
        for (i, axis) in f.axes.iter().enumerate() {
            assert_eq!(
                axis.flags().contains(Flags::TEMP_SENSOR_FAULT),
                common::axes_faulty(seq),
                "row {seq} axis {i}"
            );
        }
    }
}

#[test]
fn shared_basis_replay_is_byte_identical_to_trainer_compensate_and_a_thermometer_fault_flags_every_axis() {
    use rbf_core::blob::shared_layout::decode_shared_into;
    use rbf_core::blob::{BlobKind, blob_kind};
    use rbf_core::shared_basis::SharedAxisModels;
    let dir = tempfile::TempDir::new().unwrap();
    let (blob_path, slice) = common::shared_blob_and_slice(dir.path());
    let expected = multi_axis_compensated_run(&blob_path, &slice, dir.path());
    let expected = expected.as_str();

    let blob = std::fs::read(&blob_path).unwrap();
    assert_eq!(blob_kind(&blob), Ok(BlobKind::SharedBasis));
    let mut models = Box::new(SharedAxisModels::<{ rbf_core::MAX_CENTERS }>::EMPTY);
    assert_eq!(decode_shared_into(&mut models, &blob), Ok(blob.len()));
    let input = std::fs::read_to_string(&slice).unwrap();
    let period_s = replay::probe_period(input.lines()).unwrap();
    let current: [Cell<ReplaySample>; 3] = Default::default();
    let mut frames: Vec<u8> = Vec::new();
    let mut replayer = Replayer::new(Some(&*models), period_s, &current, &mut frames).unwrap();
    let out = replay_all(&mut replayer, &input);
    let stats = replayer.stats();
    assert_eq!(stats.samples as usize, common::AXES_ROWS);
    assert_eq!(stats.output_errors, 0);
    let faulty_rows = (0..common::AXES_ROWS).filter(|&r| common::axes_faulty(r)).count() as u32;
    // One thermometer set read per sample; its failure is every axis's.
    assert_eq!(stats.temp_read_faults, faulty_rows);
    assert_eq!(replayer.temp_read_faults_per_axis(), [faulty_rows; 3]);
    assert_same_run(&out, expected);

    // One frame per row carrying x, y and z; flag 2 on every axis while the
    // one thermometer fails, flag 4 as well once its hold runs out, and
    // compensated (no flag 4) otherwise.
    let mut held_out = 0;
    for (seq, f) in axes_frames_matching_rows(&mut frames, &out).iter().enumerate() {
        let faulty = common::axes_faulty(seq);
        let first = f.axes[0].flags();
        for (i, axis) in f.axes.iter().enumerate() {
            assert_eq!(
                axis.flags().contains(Flags::TEMP_SENSOR_FAULT),
                faulty,
                "row {seq} axis {i}"
            );
            assert_eq!(axis.flags(), first, "row {seq}: the axes' flags differ");
            if !faulty {
                assert!(!axis.flags().contains(Flags::NO_VALID_MODEL), "row {seq} axis {i}");
            }
        }
        held_out += usize::from(first.contains(Flags::NO_VALID_MODEL));
    }
    assert!(held_out > 0, "the outage outlasts the hold: flag 4 on every axis");
}

/// Feeds every line of `input` to `replayer`; returns the run it wrote.
fn replay_all<W: embedded_io::Write, M: ModelHolder<K, N>, const K: usize, const N: usize>(
    replayer: &mut Replayer<'_, W, M, K, N>,
    input: &str,
) -> String {
    let mut out = String::new();
    for line in input.lines() {
        replayer.feed_line(line, &mut out).unwrap();
    }
    out
}

/// The data rows of a written run: after its comment lines and its header.
fn data_rows(run: &str) -> Vec<&str> {
    run.lines().filter(|l| !l.starts_with('#')).skip(1).collect()
}

/// The replay's run is `trainer compensate`'s, row for row and byte for byte.
fn assert_same_run(out: &str, expected: &str) {
    let differing = out.lines().zip(expected.lines()).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "rows differ from trainer compensate");
    assert_eq!(out, expected, "replay output differs from trainer compensate");
}

/// The three-axis frames in `frames`, checked against the replay's run
/// `out`: one per row, in order, each carrying x, y and z with the flags
/// and bias of its row's columns.
fn axes_frames_matching_rows(frames: &mut [u8], out: &str) -> Vec<frame::AxesFrame> {
    let rows = data_rows(out);
    let mut decoded = Vec::new();
    for chunk in frames.split_mut(|&b| b == 0).filter(|c| !c.is_empty()) {
        let f = frame::decode_axes(chunk).unwrap();
        let seq = decoded.len() as u32;
        assert_eq!((f.seq, f.axis_mask), (seq, 0b111));
        let fields: Vec<&str> = rows[seq as usize].split(',').collect();
        for (i, axis) in f.axes.iter().enumerate() {
            let csv_flags: u8 = fields[fields.len() - 7 + 3 * i].parse().unwrap();
            let csv_bias: f32 = fields[fields.len() - 9 + 3 * i].parse().unwrap();
            assert_eq!((axis.flags, axis.bias_dph), (csv_flags, csv_bias), "row {seq} axis {i}");
        }
        decoded.push(f);
    }
    assert_eq!(decoded.len(), common::AXES_ROWS);
    decoded
}

/// `trainer compensate` of a multi-axis blob on `slice`, written in `dir`,
/// without the provenance lines before the run: the replay library writes
/// the run, the host tools (trainer compensate, cargo xtask qemu-replay)
/// the lines before it.
fn multi_axis_compensated_run(blob_path: &std::path::Path, slice: &std::path::Path, dir: &std::path::Path) -> String {
    let expected_path = dir.join("expected.csv");
    let (_, expected) = trainer::evaluation::axes::compensate_command(
        blob_path,
        slice,
        &expected_path,
        trainer::output::Existing::Replace,
        false,
    )
    .unwrap();
    expected.commit().unwrap();
    let provenance = trainer::blobfile::provenance_lines(blob_path, &std::fs::read(blob_path).unwrap());
    let expected = std::fs::read_to_string(&expected_path).unwrap();
    expected
        .strip_prefix(&provenance)
        .expect("compensate starts with the provenance lines")
        .to_owned()
}
