//! A unit's output as the trainer takes it: frame captures (`decode`),
//! recordings (`device record`'s checks, `compensate` of a recording) and
//! what every command does when its messages cannot be written.

use std::fs::File;
use std::process::{Command, Stdio};

use gyro_wire::frame::{self, MAX_FRAME_LEN, OutputFrame};
use tempfile::TempDir;

use crate::common::*;

fn frame_at(seq: u32) -> OutputFrame {
    OutputFrame {
        seq,
        rate_dph: 10.0 + seq as f32,
        bias_dph: 0.5,
        rate_comp_dph: 9.5 + seq as f32,
        temp_c: 25.0,
        flags: 0,
    }
}

#[test]
fn decode_refuses_an_empty_capture_and_writes_nothing() {
    let dir = TempDir::new().unwrap();
    for (name, bytes) in [("empty.bin", &b""[..]), ("zeros.bin", &b"\0\0\0\0"[..])] {
        let capture = write(&dir, name, bytes);
        let out = dir.path().join(format!("{name}.csv"));
        let o = trainer(&["decode", capture.to_str().unwrap(), "-o", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
        assert!(
            stderr(&o).contains(&format!("{}: empty: not one byte of a frame", capture.display())),
            "{}",
            stderr(&o)
        );
        assert!(!out.exists(), "no CSV with a header that names no unit's columns");
    }
}

#[test]
fn decode_skips_a_frame_whose_crc_fails_and_still_reads_captures_of_older_firmware() {
    let dir = TempDir::new().unwrap();
    let mut capture = Vec::new();
    for seq in 0..4u32 {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = frame::encode(&frame_at(seq), &mut buf).unwrap();
        if seq == 2 {
            buf[3] ^= 0x04; // one bit flipped on the line
        }
        capture.extend_from_slice(&buf[..n]);
    }
    let frames = write(&dir, "frames.bin", &capture);
    let out = dir.path().join("frames.csv");
    let o = trainer(&["decode", frames.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("1 damaged frame(s) skipped"), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    let seqs: Vec<&str> = text.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(seqs, ["0", "1", "3"]);
    // Format 1 (no tag, no CRC: COBS of the bare postcard fields, a
    // one-byte varint sequence number, four f32 little-endian, the flags).
    let mut old = Vec::new();
    for seq in 0..3u32 {
        let f = frame_at(seq);
        let mut raw = vec![seq as u8];
        for v in [f.rate_dph, f.bias_dph, f.rate_comp_dph, f.temp_c] {
            raw.extend(v.to_le_bytes());
        }
        raw.push(f.flags);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = gyro_wire::cobs::cobs_encode(&raw, &mut buf).unwrap();
        old.extend_from_slice(&buf[..n]);
    }
    let frames = write(&dir, "old.bin", &old);
    let out = dir.path().join("old.csv");
    let o = trainer(&["decode", frames.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        "seq,rate_dph,bias_dph,rate_comp_dph,temp_c,flags\n0,10,0.5,9.5,25,0\n1,11,0.5,10.5,25,0\n2,12,0.5,11.5,25,0\n"
    );
}

#[test]
fn device_record_refuses_absurd_durations_and_rates_before_opening_the_port() {
    let dir = TempDir::new().unwrap();
    let run = dir.path().join("run.csv");
    for (flag, value, says) in [
        (
            "--seconds",
            "1e300",
            "--seconds 1e300: the duration must be positive and at most 1000 h",
        ),
        (
            "--hours",
            "1e300",
            "--hours 1e300: the duration must be positive and at most 1000 h",
        ),
        ("--hours", "1001", "--hours 1001: the duration must be positive"),
        ("--progress-s", "1e300", "--progress-s 1e300: must be 0.01 … 3600 s"),
        (
            "--sample-rate-hz",
            "1e7",
            "--sample-rate-hz 10000000: must be 0.001 … 1000000 Hz",
        ),
    ] {
        let o = trainer(&[
            "device",
            "record",
            "--port",
            "/dev/no-such-gyro",
            flag,
            value,
            "-o",
            run.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(1), "{flag} {value}: {}", stderr(&o));
        assert!(stderr(&o).contains(says), "{flag} {value}: {}", stderr(&o));
    }
    assert!(!run.exists());
}

#[test]
fn compensating_a_recording_keeps_the_unit_s_columns_and_adds_its_own_once() {
    let dir = TempDir::new().unwrap();
    let model = fitted_model(&dir);
    let run = std::fs::read_to_string(dir.path().join("train.csv")).unwrap();
    // The run as `device record` writes it (the unit's outputs as unit_*),
    // and as an older trainer wrote it (or a compensated output).
    let with_columns = |names: &str| {
        run.lines()
            .map(|l| match l {
                l if l.starts_with('#') => l.to_owned(),
                l if l.starts_with("time_s") => format!("{l},{names}"),
                l => format!("{l},0.5,1,0"),
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let recording = write(
        &dir,
        "rec.csv",
        with_columns("unit_bias_dph,unit_rate_comp_dph,unit_flags").as_bytes(),
    );
    let out = dir.path().join("rec_comp.csv");
    let o = compensate(&model, &recording, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&out).unwrap();
    let header = text.lines().find(|l| l.starts_with("time_s")).unwrap();
    let names: Vec<&str> = header.split(',').collect();
    for name in [
        "bias_dph",
        "rate_comp_dph",
        "flags",
        "unit_bias_dph",
        "unit_rate_comp_dph",
        "unit_flags",
    ] {
        assert_eq!(names.iter().filter(|n| **n == name).count(), 1, "{name} in {header}");
    }
    let old = write(&dir, "old.csv", with_columns("bias_dph,rate_comp_dph,flags").as_bytes());
    let out = dir.path().join("old_comp.csv");
    let o = compensate(&model, &old, &out, &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("column bias_dph (field 5) is one compensate adds"),
        "{}",
        stderr(&o)
    );
    assert!(!out.exists());
}

/// Runs `trainer` with its standard error (or output) on /dev/full.
fn trainer_full(args: &[&str], stdout_full: bool) -> std::process::Output {
    let full = || Stdio::from(File::options().write(true).open("/dev/full").unwrap());
    let mut command = Command::new(env!("CARGO_BIN_EXE_trainer"));
    command.args(args).stderr(full());
    if stdout_full {
        command.stdout(full());
    }
    command.output().expect("trainer runs")
}

#[test]
fn an_error_or_warning_that_cannot_be_written_exits_1_never_101() {
    if !std::path::Path::new("/dev/full").exists() {
        return;
    }
    let dir = TempDir::new().unwrap();
    let missing = dir.path().join("missing.csv");
    let out = dir.path().join("out.csv");
    // An error: its message has nowhere to go.
    for args in [
        &["eval", "--model", "no-model.bin", missing.to_str().unwrap()][..],
        &["decode", missing.to_str().unwrap(), "-o", out.to_str().unwrap()][..],
        &["fit", "--no-such-flag"][..],
    ] {
        let o = trainer_full(args, false);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let o = trainer_full(args, true);
        assert_eq!(o.status.code(), Some(1), "{args:?} with stdout full too");
    }
    // --help that cannot be printed.
    assert_eq!(trainer_full(&["--help"], true).status.code(), Some(1));
    assert_eq!(trainer_full(&["--help"], false).status.code(), Some(0));
    // A warning (a damaged frame) that cannot be written: the output is
    // written, the warning lost, no panic.
    let mut capture = vec![3, 1, 1, 0];
    for seq in 0..3u32 {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = frame::encode(&frame_at(seq), &mut buf).unwrap();
        capture.extend_from_slice(&buf[..n]);
    }
    let frames = write(&dir, "frames.bin", &capture);
    let o = trainer_full(
        &["decode", frames.to_str().unwrap(), "-o", out.to_str().unwrap()],
        false,
    );
    assert_eq!(o.status.code(), Some(0));
    assert!(out.exists());
    // Standard output full: the summary cannot be printed, so nothing is committed.
    let again = dir.path().join("again.csv");
    let o = trainer_full(
        &["decode", frames.to_str().unwrap(), "-o", again.to_str().unwrap()],
        true,
    );
    assert_eq!(o.status.code(), Some(1));
    assert!(!again.exists());
}
