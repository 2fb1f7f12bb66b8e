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
//! A frame whose rate or temperature is not a number (a front end or
//! thermometer that has not answered yet, flag 16 or 2) cannot be a row of
//! a recorded run: it is counted, not written, and its sequence number
//! leaves the gap. A sequence number that goes back is a unit that reset:
//! the rows after it follow a gap of [`RESET_GAP_SAMPLES`] periods, so that
//! readers restart the features as the unit did.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use rbf_core::Flags;

use super::link::{Link, Message};
use super::status::{self, UnitStatus};
use crate::reading::frames::{self, Frame, Kind};
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
    /// Stretches of bytes that were no message (noise, cut frames).
    pub damaged: u64,
    /// Frames not written: rate or temperature not a number, or a frame of another kind.
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

/// The metadata lines and the header of a recording of `status`'s unit.
fn write_header(
    out: &mut impl Write,
    port: &str,
    status: &UnitStatus,
    kind: Kind,
    rate_hz: f64,
) -> std::io::Result<()> {
    let m = status.report.model;
    writeln!(out, "# source: trainer device record --port {port}")?;
    writeln!(out, "# unit: {}", status::kind_words(Some(kind)))?;
    writeln!(out, "# model: {}", status::model_words(&status.report))?;
    writeln!(out, "# model_blob_crc32: {:#010x}", m.blob_crc32)?;
    writeln!(out, "# model_sequence: {}", m.sequence)?;
    writeln!(out, "# sample_rate_hz: {rate_hz}")?;
    writeln!(out, "time_s,{}", frames::header(kind))
}

/// The raw rate and temperature of axis x (or the single axis), and whether
/// every axis's rate and temperature are numbers.
fn usable(frame: &Frame) -> (f32, f32, u8, bool) {
    match frame {
        Frame::Single(f) => (
            f.rate_dph,
            f.temp_c,
            f.flags,
            f.rate_dph.is_finite() && f.temp_c.is_finite(),
        ),
        Frame::Axes(f) => {
            let present: Vec<_> = f.axes_present().iter().map(|a| f.axes[a.index()]).collect();
            let finite = present.iter().all(|o| o.rate_dph.is_finite() && o.temp_c.is_finite());
            let flags = present.iter().fold(0, |acc, o| acc | o.flags);
            let first = present.first().copied().unwrap_or_default();
            (first.rate_dph, first.temp_c, flags, finite)
        }
    }
}

/// Sequence numbers to a strictly increasing sample index.
#[derive(Debug, Default)]
struct Timeline {
    last_seq: Option<u32>,
    index: u64,
}

impl Timeline {
    /// The sample index of `seq`, and the frames missed before it; `None`
    /// for a repeated frame. A sequence number that goes back is a reset.
    fn place(&mut self, seq: u32, progress: &mut Progress) -> Option<u64> {
        match self.last_seq {
            None => {}
            Some(last) => {
                let delta = seq.wrapping_sub(last);
                if delta == 0 {
                    return None;
                } else if delta < 1 << 31 {
                    progress.missed += u64::from(delta - 1);
                    self.index += u64::from(delta);
                } else {
                    progress.resets += 1;
                    self.index += RESET_GAP_SAMPLES;
                }
            }
        }
        self.last_seq = Some(seq);
        Some(self.index)
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
    let mut kind = status.kind;
    let mut timeline = Timeline::default();
    let mut last_frame = Instant::now();
    let mut next_report = started + options.progress_every;
    let damaged_before = link.counters().damaged;
    if let Some(k) = kind {
        write_header(out, &name, status, k, options.sample_rate_hz)?;
    }
    let end = loop {
        let now = Instant::now();
        progress.elapsed_s = now.duration_since(started).as_secs_f64();
        progress.damaged = link.counters().damaged - damaged_before;
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
        let Some(Message::Output(frame)) = message else {
            continue;
        };
        last_frame = Instant::now();
        let k = match kind {
            Some(k) => k,
            None => {
                write_header(out, &name, status, frame.kind(), options.sample_rate_hz)?;
                *kind.insert(frame.kind())
            }
        };
        let (rate, temp, flags, finite) = usable(&frame);
        if frame.kind() != k || !finite {
            progress.unusable += 1;
            continue;
        }
        let seq = match frame {
            Frame::Single(f) => f.seq,
            Frame::Axes(f) => f.seq,
        };
        let Some(index) = timeline.place(seq, &mut progress) else {
            continue;
        };
        write!(out, "{},", index as f64 / options.sample_rate_hz)?;
        frames::write_row(out, &frame)?;
        progress.rows += 1;
        (progress.rate_dph, progress.temp_c) = (rate, temp);
        progress.flags |= flags;
    };
    if kind.is_none() {
        // Not one frame: a run with its header and no rows, never a header-less file.
        write_header(out, &name, status, Kind::Single, options.sample_rate_hz)?;
    }
    progress.elapsed_s = started.elapsed().as_secs_f64();
    progress.damaged = link.counters().damaged - damaged_before;
    Ok((progress, end))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequence_numbers_give_increasing_times_with_gaps_for_losses_and_resets() {
        let mut t = Timeline::default();
        let mut p = Progress::default();
        let placed: Vec<Option<u64>> = [10u32, 11, 11, 14, 2, 3, u32::MAX, 0]
            .iter()
            .map(|&s| t.place(s, &mut p))
            .collect();
        // 11 repeated: no row; 12, 13 missed; 2 after 14: a reset; u32::MAX after 3: a reset; 0 wraps.
        assert_eq!(
            placed,
            [Some(0), Some(1), None, Some(4), Some(7), Some(8), Some(11), Some(12)]
        );
        assert_eq!((p.missed, p.resets), (2, 2));
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
