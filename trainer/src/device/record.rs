//! `trainer device record`: the unit's output frames, live, into a
//! recorded-run CSV (docs/recorded-run-format.md) as they arrive.
//!
//! One row per frame: `time_s` from the frame's sequence number at the
//! unit's sample rate (a lost frame leaves a gap in time, as in the unit's
//! own loop), then the columns `trainer decode` writes (`seq`, the raw rate,
//! the firmware's bias, the compensated rate, the temperature and the
//! flags; per axis for a three-axis unit). Metadata lines first say which
//! unit, model and sample rate. The file is a complete recorded run at any
//! row boundary, so the caller commits it at the end, at Ctrl-C or when the
//! line fails, and `trainer fit` reads it as it is.
//!
//! Every frame the unit sent is written. A frame the run's reader would
//! refuse as a row (a rate or temperature that is not a number, a rate
//! beyond ±[`rbf_core::record::MAX_ABS_RATE_DPH`] °/h: flag 16 or 2), or a
//! frame of another kind, is written as a `#` line with the reader's own
//! reason: readers skip it, and its sequence number leaves the gap. The
//! reader's row parser decides, so recorder and reader agree by
//! construction. A sequence number that goes back is a unit that reset:
//! the rows after it follow a gap of [`RESET_GAP_SAMPLES`] periods, so that
//! readers restart the features as the unit did. The time base follows the
//! sequence numbers only where they are trustworthy: a format-2 frame's is
//! CRC-checked, and a format-1 frame (older firmware, no check) that does not
//! follow the one before is held until the next frame confirms it; a frame
//! left unconfirmed is counted as damaged, so one corrupted sequence number
//! never moves `time_s`.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use rbf_core::Flags;

use gyro_wire::frame::FrameFormat;
use rbf_core::record::Columns;

use super::link::{Link, Message};
use super::status::{self, UnitStatus};
use crate::reading::frames::{self, Frame, FrameSync, Kind};
use crate::reading::run::rows::RowParser;
use crate::simulate::profile::Schedule;

/// Sample periods left out of `time_s` after a unit reset (more than the
/// two that make a gap, docs/recorded-run-format.md).
pub const RESET_GAP_SAMPLES: u64 = 3;

/// What to record and how.
#[derive(Clone, Debug)]
pub struct RecordOptions {
    /// Stop after this long (`None`: until stopped).
    pub duration: Option<Duration>,
    /// The unit's sample rate, Hz: `time_s` = samples since the first row / rate.
    pub sample_rate_hz: f64,
    /// A line without frames for this long is an error.
    pub silence_timeout: Duration,
    /// Time between progress reports.
    pub progress_every: Duration,
}

/// Where the recording stands (a progress line).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Progress {
    /// Seconds since the recording started.
    pub elapsed_s: f64,
    /// Rows written.
    pub rows: u64,
    /// Frames the sequence numbers say never arrived.
    pub missed: u64,
    /// Stretches of bytes that were no message (noise, cut frames, a CRC
    /// that did not match), and format-1 frames whose sequence number the
    /// next frame did not confirm.
    pub damaged: u64,
    /// Frames written as `#` lines: rows the reader would refuse (a rate
    /// or temperature not a number, a rate out of range), or frames of another kind.
    pub unusable: u64,
    /// Resets of the unit seen (its sequence number went back).
    pub resets: u64,
    /// Loop temperature of the last frame, °C (axis x's on a three-axis unit).
    pub temp_c: f32,
    /// Raw rate of the last frame, °/h (axis x's).
    pub rate_dph: f32,
    /// Every flag bit seen since the previous progress report.
    pub flags: u8,
}

/// How a recording ended.
#[derive(Debug)]
pub enum End {
    /// The asked duration was reached.
    Duration,
    /// The user stopped it (Ctrl-C, SIGTERM, SIGHUP).
    Stopped,
    /// The line failed (silent, closed); the rows before are valid.
    Failed(anyhow::Error),
}

/// Names of the flag bits, in words for a progress line.
pub fn flag_names(flags: u8) -> String {
    const NAMES: [(Flags, &str); 8] = [
        (Flags::INPUT_CLAMPED, "clamped"),
        (Flags::TEMP_SENSOR_FAULT, "temp-fault"),
        (Flags::NO_VALID_MODEL, "no-model"),
        (Flags::WARMING_UP, "warm-up"),
        (Flags::RATE_INVALID, "rate-invalid"),
        (Flags::SAMPLES_MISSED, "missed"),
        (Flags::OUTPUT_DROPPED, "dropped"),
        (Flags::FAULT_RESET, "fault-reset"),
    ];
    let names: Vec<&str> = NAMES
        .iter()
        .filter(|(f, _)| flags & f.bits() != 0)
        .map(|&(_, n)| n)
        .collect();
    if names.is_empty() {
        "none".to_owned()
    } else {
        names.join(",")
    }
}

/// One progress line: elapsed, temperature, rate, frames, losses, flags
/// and, with a plan, where the run stands in it.
pub fn progress_line(p: &Progress, plan: Option<&Schedule>) -> String {
    let secs = p.elapsed_s as u64;
    let mut line = format!(
        "{:02}:{:02}:{:02}  T {:7.3} °C  rate {:10.4} °/h  rows {}  missed {}  damaged {}  unusable {}  flags {}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60,
        p.temp_c,
        p.rate_dph,
        p.rows,
        p.missed,
        p.damaged,
        p.unusable,
        flag_names(p.flags)
    );
    if p.resets > 0 {
        line.push_str(&format!("  resets {}", p.resets));
    }
    if let Some(plan) = plan {
        let total = plan.duration_s().max(1e-9);
        line.push_str(&format!(
            "  plan {:.1} % (set point {:.1} °C)",
            (100.0 * p.elapsed_s / total).min(100.0),
            plan.air_c(p.elapsed_s)
        ));
    }
    line
}

/// The metadata lines and the header of a recording of `status`'s unit;
/// the header line.
fn write_header(
    out: &mut impl Write,
    port: &str,
    status: &UnitStatus,
    kind: Kind,
    rate_hz: f64,
) -> std::io::Result<String> {
    let m = status.report.model;
    writeln!(out, "# source: trainer device record --port {port}")?;
    writeln!(out, "# unit: {}", status::kind_words(Some(kind)))?;
    writeln!(out, "# model: {}", status::model_words(&status.report))?;
    writeln!(out, "# model_blob_crc32: {:#010x}", m.blob_crc32)?;
    writeln!(out, "# model_sequence: {}", m.sequence)?;
    writeln!(out, "# sample_rate_hz: {rate_hz}")?;
    // time_s counts the unit's samples: the reader takes frames missed as gaps.
    writeln!(out, "{}", crate::reading::sampling::counted_time_base_line())?;
    let header = format!("time_s,{}", frames::recording_header(kind));
    writeln!(out, "{header}")?;
    Ok(header)
}

/// The reader's verdict on the rows of a recording: its own row parser
/// under the recording's header, every axis checked.
struct RowCheck {
    parser: RowParser,
    columns: Vec<Columns>,
}

impl RowCheck {
    fn new(header: &str) -> anyhow::Result<RowCheck> {
        let all = Columns::from_header(header)
            .map_err(|e| anyhow::anyhow!("the recording's header `{header}` is no run's: {e:?}"))?;
        let columns = if all.is_multi_axis() {
            all.axes_present().filter_map(|a| all.for_axis(a)).collect()
        } else {
            vec![all]
        };
        Ok(RowCheck {
            parser: RowParser::new(std::path::Path::new("recording"), header),
            columns,
        })
    }

    /// Why the reader would refuse `row` (`None`: it takes it).
    fn refusal(&self, row: &str) -> Option<String> {
        self.columns.iter().find_map(|c| self.parser.refusal(c, row))
    }
}

/// The raw rate, temperature and flags of axis x (or the single axis), and
/// every axis's flags together.
fn shown(frame: &Frame) -> (f32, f32, u8) {
    match frame {
        Frame::Single(f) => (f.rate_dph, f.temp_c, f.flags),
        Frame::Axes(f) => {
            let present: Vec<_> = f.axes_present().iter().map(|a| f.axes[a.index()]).collect();
            let flags = present.iter().fold(0, |acc, o| acc | o.flags);
            let first = present.first().copied().unwrap_or_default();
            (first.rate_dph, first.temp_c, flags)
        }
    }
}

/// Sequence numbers to a strictly increasing sample index.
#[derive(Debug, Default)]
struct Timeline {
    last_seq: Option<u32>,
    index: u64,
    /// A format-1 frame whose sequence number does not follow the last
    /// one, waiting for the next frame to confirm it.
    held: Option<Frame>,
    /// Held frames the next frame did not confirm.
    unconfirmed: u64,
}

impl Timeline {
    /// Places `frame` (`checked`: its sequence number is CRC-checked): the
    /// frames to write now with their sample indices (a confirmed held
    /// frame first), counting missed frames, resets and frames left
    /// unconfirmed. A repeated frame gets none.
    fn place(&mut self, frame: Frame, checked: bool, progress: &mut Progress) -> Vec<(u64, Frame)> {
        let seq = frame.seq();
        let mut placed = Vec::with_capacity(2);
        if let Some(held) = self.held.take() {
            if seq == held.seq().wrapping_add(1) {
                placed.push((self.advance(held.seq(), progress), held));
                placed.push((self.advance(seq, progress), frame));
                return placed;
            }
            // The held frame's sequence number was damage, not the unit's.
            self.unconfirmed += 1;
        }
        match self.last_seq.map(|last| seq.wrapping_sub(last)) {
            Some(0) => {}
            Some(1) | None => placed.push((self.advance(seq, progress), frame)),
            Some(_) if checked => placed.push((self.advance(seq, progress), frame)),
            Some(_) => self.held = Some(frame),
        }
        placed
    }

    /// The sample index of `seq`, the frames missed before it counted; a
    /// sequence number that goes back is a reset.
    fn advance(&mut self, seq: u32, progress: &mut Progress) -> u64 {
        if let Some(last) = self.last_seq {
            let delta = seq.wrapping_sub(last);
            if delta < 1 << 31 {
                progress.missed += u64::from(delta.saturating_sub(1));
                self.index += u64::from(delta);
            } else {
                progress.resets += 1;
                self.index += RESET_GAP_SAMPLES;
            }
        }
        self.last_seq = Some(seq);
        self.index
    }

    /// At the end: a held frame never confirmed is damage.
    fn finish(&mut self) {
        self.unconfirmed += u64::from(self.held.take().is_some());
    }
}

/// Records the frames of the unit behind `link` into `out` (header first)
/// until the duration, `stop()`, or a failure of the line; reports
/// progress through `report` every `options.progress_every`. Returns the
/// final progress and how it ended; `out` then holds a complete run
/// (flushed by the caller).
pub fn record<P: Read + Write>(
    link: &mut Link<P>,
    out: &mut impl Write,
    status: &UnitStatus,
    options: &RecordOptions,
    stop: &dyn Fn() -> bool,
    report: &mut dyn FnMut(&Progress),
) -> anyhow::Result<(Progress, End)> {
    let name = link.name().to_owned();
    let started = Instant::now();
    let mut progress = Progress::default();
    let mut sync = FrameSync::default();
    let mut refused = 0u64;
    let mut timeline = Timeline::default();
    let mut last_frame = Instant::now();
    let mut next_report = started + options.progress_every;
    let damaged_before = link.counters().damaged;
    // The header: the unit's kind as its status said, else its first frame's.
    let mut recording = match status.kind {
        Some(k) => Some((
            k,
            RowCheck::new(&write_header(out, &name, status, k, options.sample_rate_hz)?)?,
        )),
        None => None,
    };
    let mut row = String::new();
    let end = loop {
        let now = Instant::now();
        progress.elapsed_s = now.duration_since(started).as_secs_f64();
        progress.damaged = link.counters().damaged - damaged_before + refused + timeline.unconfirmed;
        if now >= next_report {
            report(&progress);
            progress.flags = 0;
            next_report = now + options.progress_every;
        }
        if options.duration.is_some_and(|d| now.duration_since(started) >= d) {
            break End::Duration;
        }
        if stop() {
            break End::Stopped;
        }
        if now.duration_since(last_frame) >= options.silence_timeout {
            break End::Failed(anyhow::anyhow!(
                "{name}: no output frame for {:.1} s (the unit stopped sampling, reset or went away)",
                options.silence_timeout.as_secs_f64()
            ));
        }
        let message = match link.next(now + Duration::from_millis(100)) {
            Ok(m) => m,
            Err(e) => break End::Failed(e),
        };
        let Some(Message::Output(frame, format)) = message else {
            continue;
        };
        last_frame = Instant::now();
        let synced = sync.push(frame, format);
        refused += synced.refused;
        for frame in synced.frames {
            let (kind, check) = match &recording {
                Some(r) => r,
                None => {
                    let header = write_header(out, &name, status, frame.kind(), options.sample_rate_hz)?;
                    recording.insert((frame.kind(), RowCheck::new(&header)?))
                }
            };
            let checked = sync.format().is_some_and(FrameFormat::is_checked);
            for (index, frame) in timeline.place(frame, checked, &mut progress) {
                row.clear();
                let mut bytes = Vec::with_capacity(128);
                write!(bytes, "{},", index as f64 / options.sample_rate_hz)?;
                frames::write_row(&mut bytes, &frame)?;
                row.push_str(String::from_utf8_lossy(&bytes).trim_end());
                let refusal = if frame.kind() == *kind {
                    check.refusal(&row)
                } else {
                    Some(format!("a frame of another kind: {}", frames::header(frame.kind())))
                };
                let (rate, temp, flags) = shown(&frame);
                match refusal {
                    None => {
                        writeln!(out, "{row}")?;
                        progress.rows += 1;
                    }
                    // Kept, where readers skip it: the frame is the unit's, the row is no run's.
                    Some(why) => {
                        writeln!(out, "# not a row ({why}): {row}")?;
                        progress.unusable += 1;
                    }
                }
                (progress.rate_dph, progress.temp_c) = (rate, temp);
                progress.flags |= flags;
            }
        }
    };
    if recording.is_none() {
        // Not one frame: a run with its header and no rows, never a header-less file.
        write_header(out, &name, status, Kind::Single, options.sample_rate_hz)?;
    }
    refused += sync.finish();
    timeline.finish();
    progress.elapsed_s = started.elapsed().as_secs_f64();
    progress.damaged = link.counters().damaged - damaged_before + refused + timeline.unconfirmed;
    Ok((progress, end))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seq: u32) -> Frame {
        Frame::Single(gyro_wire::frame::OutputFrame {
            seq,
            rate_dph: 1.0,
            bias_dph: 0.0,
            rate_comp_dph: 1.0,
            temp_c: 25.0,
            flags: 0,
        })
    }

    /// The sample index of each of `seqs`, in the order they are written.
    fn indices(seqs: &[u32], checked: bool) -> (Vec<(u64, u32)>, Progress, u64) {
        let mut t = Timeline::default();
        let mut p = Progress::default();
        let mut placed = Vec::new();
        for &s in seqs {
            placed.extend(
                t.place(frame(s), checked, &mut p)
                    .into_iter()
                    .map(|(i, f)| (i, f.seq())),
            );
        }
        t.finish();
        (placed, p, t.unconfirmed)
    }

    #[test]
    fn sequence_numbers_give_increasing_times_with_gaps_for_losses_and_resets() {
        let (placed, p, unconfirmed) = indices(&[10, 11, 11, 14, 2, 3, u32::MAX, 0], true);
        // 11 repeated: no row; 12, 13 missed; 2 after 14: a reset; u32::MAX after 3: a reset; 0 wraps.
        assert_eq!(
            placed,
            [(0, 10), (1, 11), (4, 14), (7, 2), (8, 3), (11, u32::MAX), (12, 0)]
        );
        assert_eq!((p.missed, p.resets, unconfirmed), (2, 2, 0));
        // Unchecked (format 1), the same stream gives the same times: each jump is confirmed.
        let (unchecked, p, unconfirmed) = indices(&[10, 11, 11, 14, 15, 2, 3, u32::MAX, 0], false);
        assert_eq!(
            unchecked,
            [
                (0, 10),
                (1, 11),
                (4, 14),
                (5, 15),
                (8, 2),
                (9, 3),
                (12, u32::MAX),
                (13, 0)
            ]
        );
        assert_eq!((p.missed, p.resets, unconfirmed), (2, 2, 0));
    }

    #[test]
    fn an_unchecked_sequence_number_with_a_bit_flipped_never_moves_the_time_base() {
        // Frame 12 arrives as 12 + 2^20 (a bit flipped on the line), then 13, 14;
        // then frame 16 arrives with its top bit cleared (as if the unit reset).
        let seqs = [10, 11, 12 + (1 << 20), 13, 14, 15, 16 & !(1 << 4), 17, 18];
        let (placed, p, unconfirmed) = indices(&seqs, false);
        assert_eq!(
            placed,
            [(0, 10), (1, 11), (3, 13), (4, 14), (5, 15), (7, 17), (8, 18)],
            "time_s follows the unit's samples"
        );
        assert_eq!((p.missed, p.resets, unconfirmed), (2, 0, 2));
    }

    /// What `record` writes of a unit that sends `frames` (then falls silent).
    fn recording_of(frames: &[gyro_wire::frame::OutputFrame], wire: impl Fn(&[u8]) -> Vec<u8>) -> (String, Progress) {
        use super::super::link::tests::FakePort;
        let mut input = Vec::new();
        for f in frames {
            let mut buf = [0u8; gyro_wire::frame::MAX_FRAME_LEN];
            let n = gyro_wire::frame::encode(f, &mut buf).unwrap();
            input.extend(wire(&buf[..n]));
        }
        let mut link = Link::new(FakePort::answering(input), "/dev/fake");
        let status = UnitStatus {
            report: gyro_wire::health::HealthReport {
                reset_cause: gyro_wire::health::ResetCause::PowerOn,
                reset_flags: 0,
                fault_pc: 0,
                fault_lr: 0,
                counters: Default::default(),
                model: Default::default(),
                board_flags: 0,
                firmware_version: gyro_wire::health::FirmwareVersion::CURRENT,
                stack_peak_bytes: 0,
            },
            kind: Some(Kind::Single),
        };
        let options = RecordOptions {
            duration: None,
            sample_rate_hz: 1000.0,
            silence_timeout: Duration::from_millis(300),
            progress_every: Duration::from_secs(60),
        };
        let mut out = Vec::new();
        let (progress, end) = record(&mut link, &mut out, &status, &options, &|| false, &mut |_| {}).unwrap();
        assert!(matches!(end, End::Failed(_)), "{end:?}");
        (String::from_utf8(out).unwrap(), progress)
    }

    fn sample(seq: u32) -> gyro_wire::frame::OutputFrame {
        gyro_wire::frame::OutputFrame {
            seq,
            rate_dph: 10.0 + seq as f32,
            bias_dph: 0.5,
            rate_comp_dph: 9.5 + seq as f32,
            temp_c: 25.0,
            flags: 0,
        }
    }

    #[test]
    fn every_frame_is_written_and_the_run_reader_takes_the_file_whole() {
        let over_range = rbf_core::record::MAX_ABS_RATE_DPH as f32 * 1.5;
        let frames = [
            sample(1),
            gyro_wire::frame::OutputFrame {
                rate_dph: over_range,
                rate_comp_dph: over_range,
                flags: 16,
                ..sample(2)
            },
            gyro_wire::frame::OutputFrame {
                temp_c: f32::NAN,
                flags: 2,
                ..sample(3)
            },
            gyro_wire::frame::OutputFrame {
                rate_dph: f32::INFINITY,
                flags: 16,
                ..sample(4)
            },
        ];
        let frames: Vec<_> = frames.into_iter().chain((5..=12).map(sample)).collect();
        let (text, progress) = recording_of(&frames, |b| b.to_vec());
        assert_eq!((progress.rows, progress.unusable, progress.missed), (9, 3, 0), "{text}");
        let lines: Vec<&str> = text
            .lines()
            .filter(|l| !l.starts_with("# ") || l.starts_with("# not a row"))
            .collect();
        assert_eq!(
            lines[0],
            "time_s,seq,rate_dph,unit_bias_dph,unit_rate_comp_dph,temp_c,unit_flags"
        );
        assert_eq!(lines[1], "0,1,11,0.5,10.5,25,0");
        assert!(
            lines[2].starts_with("# not a row (column rate_dph (field 3): \"5400000\" is beyond ±3600000 °/h")
                && lines[2].ends_with("): 0.001,2,5400000,0.5,5400000,25,16"),
            "{}",
            lines[2]
        );
        assert!(
            lines[3].starts_with("# not a row (column temp_c (field 6): \"NaN\""),
            "{}",
            lines[3]
        );
        assert!(lines[4].ends_with(": 0.003,4,inf,0.5,13.5,25,16"), "{}", lines[4]);
        assert_eq!(lines[5..7], ["0.004,5,15,0.5,14.5,25,0", "0.005,6,16,0.5,15.5,25,0"]);
        // The reader (fit's, eval's, compensate's) takes every row of it.
        let path = std::path::Path::new("rec.csv");
        let mut reader =
            crate::reading::run::RunReader::from_reader(path, std::io::Cursor::new(text.clone().into_bytes())).unwrap();
        let mut times = Vec::new();
        while let Some(row) = reader.next_row().unwrap() {
            times.push(row.row.time_s);
        }
        assert_eq!(times.len(), 9);
        assert_eq!(times[..3], [0.0, 0.004, 0.005]);
    }

    #[test]
    fn a_recording_with_frames_dropped_in_stretches_is_read_whole() {
        // 1200 samples at 1 kHz; frames 300 … 899 arrive only one in three
        // (a congested line), then 100 are lost at once.
        let kept = |seq: &u32| !(300..900).contains(seq) || seq.is_multiple_of(3);
        let frames: Vec<_> = (1..=1200)
            .filter(kept)
            .filter(|seq| !(1000..1100).contains(seq))
            .map(sample)
            .collect();
        let (text, progress) = recording_of(&frames, |b| b.to_vec());
        assert_eq!(progress.rows, frames.len() as u64);
        assert_eq!(progress.missed, 400 + 100);
        let path = std::path::Path::new("rec.csv");
        let mut reader =
            crate::reading::run::RunReader::from_reader(path, std::io::Cursor::new(text.clone().into_bytes())).unwrap();
        let mut rows = 0;
        while let Some(row) = reader.next_row().unwrap() {
            rows += 1;
            let from_seq_s = (row.row.rate_dph - 11.0) / 1000.0;
            assert!((row.row.time_s - from_seq_s).abs() < 1e-9, "time_s from seq");
        }
        assert_eq!(rows, frames.len(), "every row read");
        // The same rows without the time-base line: the reader would call it a change of rate.
        let plain = text.replace(
            &crate::reading::sampling::counted_time_base_line(),
            "# time_base: other",
        );
        let refused = crate::reading::run::RunReader::from_reader(path, std::io::Cursor::new(plain.into_bytes()))
            .and_then(|mut r| {
                while r.next_row()?.is_some() {}
                Ok(())
            });
        assert!(refused.is_err());
    }

    #[test]
    fn a_frame_whose_crc_fails_is_counted_and_skipped_and_time_s_does_not_move() {
        // Frame 3's sequence number has a bit flipped on the line (its CRC no longer matches).
        let frames: Vec<_> = (1..=5).map(sample).collect();
        let (text, progress) = recording_of(&frames, |b| {
            let mut b = b.to_vec();
            let n = b.len() - 1; // without the 0x00
            if gyro_wire::frame::decode(&mut b.clone()[..n]).unwrap().seq == 3 {
                b[3] ^= 0x10;
            }
            b
        });
        let rows: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).skip(1).collect();
        assert_eq!(
            rows.iter().map(|r| r.split(',').next().unwrap()).collect::<Vec<_>>(),
            ["0", "0.001", "0.003", "0.004"]
        );
        assert_eq!((progress.rows, progress.damaged, progress.missed), (4, 1, 1));
    }

    #[test]
    fn the_progress_line_names_flags_and_the_plan() {
        let p = Progress {
            elapsed_s: 3725.0,
            rows: 10,
            missed: 1,
            temp_c: 25.5,
            rate_dph: 10.25,
            flags: 4 | 8,
            ..Progress::default()
        };
        let plan = Schedule::from_knots(vec![(0.0, 20.0), (7450.0, 40.0)]);
        let line = progress_line(&p, Some(&plan));
        assert!(line.starts_with("01:02:05  T  25.500 °C"), "{line}");
        assert!(line.contains("flags no-model,warm-up"), "{line}");
        assert!(line.contains("plan 50.0 % (set point 30.0 °C)"), "{line}");
        assert_eq!(flag_names(0), "none");
    }
}
