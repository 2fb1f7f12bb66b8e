//! `trainer device status`: the unit's health report (the firmware's health
//! command, 0x03) and what kind of unit sends the frames, in words and JSON.

use std::fmt::Write as _;
use std::io::{Read, Write};
use std::time::{Duration, Instant};

use gyro_wire::health::{BOARD_BROWN_OUT_BELOW_2V7, BOARD_ON_HSI, CMD_HEALTH, HealthReport, ResetCause};

use super::link::{Link, Message};
use crate::reading::frames::{FrameSync, Kind};

/// How often an unanswered health command is sent again (a duplicate only
/// brings another report; QEMU's pty may take a second to connect).
const RESEND_EVERY: Duration = Duration::from_secs(1);
/// How long, after the report, to wait for an output frame that tells the unit's kind.
const KIND_WAIT: Duration = Duration::from_millis(300);

/// What the unit said about itself.
#[derive(Clone, Debug, PartialEq)]
pub struct UnitStatus {
    /// Its health report.
    pub report: HealthReport,
    /// The kind of its output frames (`None`: none seen, or not one
    /// confirmed ([`FrameSync`]); the unit sends one per sample, so its
    /// sampling has stopped).
    pub kind: Option<Kind>,
}

/// Asks the unit for its health report and waits at most `timeout` for it.
pub fn query<P: Read + Write>(link: &mut Link<P>, timeout: Duration) -> anyhow::Result<UnitStatus> {
    let started = Instant::now();
    let deadline = started + timeout;
    let mut sync = FrameSync::default();
    let mut sent = None::<Instant>;
    let report = loop {
        if sent.is_none_or(|at| at.elapsed() >= RESEND_EVERY) {
            link.send(&[CMD_HEALTH])?;
            sent = Some(Instant::now());
        }
        let slice_end = (Instant::now() + RESEND_EVERY / 4).min(deadline);
        match link.next(slice_end)? {
            Some(Message::Health(report)) => break report,
            Some(Message::Output(frame, format)) => {
                sync.push(frame, format);
            }
            Some(_) => {}
            None if Instant::now() >= deadline => {
                let c = link.counters();
                anyhow::bail!(
                    "{}: no health report within {:.1} s ({} bytes, {} messages, {} damaged received): is the unit \
                     powered, connected to this port and at this baud rate?",
                    link.name(),
                    timeout.as_secs_f64(),
                    c.bytes,
                    c.messages,
                    c.damaged
                );
            }
            None => {}
        }
    };
    let kind_deadline = Instant::now() + KIND_WAIT;
    while sync.kind().is_none() {
        match link.next(kind_deadline)? {
            Some(Message::Output(frame, format)) => {
                sync.push(frame, format);
            }
            Some(_) => {}
            None => break,
        }
    }
    Ok(UnitStatus {
        report,
        kind: sync.kind(),
    })
}

/// The reset cause in words.
pub fn reset_cause_words(cause: ResetCause) -> &'static str {
    match cause {
        ResetCause::PowerOn => "power-on",
        ResetCause::Pin => "reset pin (a debugger or a button)",
        ResetCause::BrownOut => "brown-out (the supply dipped)",
        ResetCause::Software => "software reset",
        ResetCause::Watchdog => "independent watchdog (the loop hung)",
        ResetCause::Panic => "panic",
        ResetCause::HardFault => "HardFault",
        ResetCause::Other => "other (window watchdog or low-power reset)",
    }
}

/// The unit's kind in words.
pub fn kind_words(kind: Option<Kind>) -> String {
    match kind {
        None => "no output frames seen (its sampling has stopped?)".to_owned(),
        Some(Kind::Single) => "single-axis (one output frame per sample)".to_owned(),
        Some(Kind::Axes(axes)) => {
            let axes: Vec<&str> = axes.iter().map(|a| a.name()).collect();
            format!(
                "three-axis IMU, axes {} (one frame with every axis per sample)",
                axes.join(", ")
            )
        }
    }
}

/// The running model in words.
pub fn model_words(report: &HealthReport) -> String {
    let m = report.model;
    if m.blob_crc32 == 0 {
        "none running (output uncompensated, flag 4)".to_owned()
    } else if m.sequence == 0 {
        format!(
            "blob CRC-32 {:#010x}, flashed by a programmer (no commit record)",
            m.blob_crc32
        )
    } else {
        format!(
            "blob CRC-32 {:#010x}, installed over the UART as commit {}",
            m.blob_crc32, m.sequence
        )
    }
}

/// The running model's calibration in words: the short model id and serial of its
/// provenance (`trainer inspect` and `trainer history` show the same id).
pub fn calibration_words(report: &HealthReport) -> String {
    let m = report.model;
    if m.blob_crc32 == 0 {
        "none".to_owned()
    } else if m.model_id == 0 {
        "no provenance (a blob written before format 4)".to_owned()
    } else {
        format!(
            "model id {}, serial {}",
            crate::provenance::model_id_text(m.model_id),
            m.serial_str().unwrap_or("none")
        )
    }
}

/// The counters' names as the report lists them, with their values.
pub fn counters(report: &HealthReport) -> [(&'static str, u32); 12] {
    let c = &report.counters;
    [
        ("samples", c.samples),
        ("samples_missed", c.samples_missed),
        ("rate_read_faults", c.rate_read_faults),
        ("temp_read_faults", c.temp_read_faults),
        ("sensor_timeouts", c.sensor_timeouts),
        ("bus_recoveries", c.bus_recoveries),
        ("front_end_inits", c.front_end_inits),
        ("data_ready_glitches", c.data_ready_glitches),
        ("synthetic_steps", c.synthetic_steps),
        ("overruns", c.overruns),
        ("output_dropped", c.output_dropped),
        ("flash_errors", c.flash_errors),
    ]
}

/// What `trainer device status` prints for `status` of the unit on `port`.
pub fn describe(port: &str, status: &UnitStatus) -> String {
    let r = &status.report;
    let mut s = String::new();
    let _ = writeln!(s, "unit on {port}: {}", kind_words(status.kind));
    let _ = writeln!(s, "firmware:    {}", r.firmware_version);
    let _ = writeln!(
        s,
        "last reset:  {} (RCC_CSR flags {:#04x})",
        reset_cause_words(r.reset_cause),
        r.reset_flags
    );
    if matches!(r.reset_cause, ResetCause::Panic | ResetCause::HardFault) {
        let _ = writeln!(s, "fault at:    PC {:#010x}, LR {:#010x}", r.fault_pc, r.fault_lr);
    }
    let _ = writeln!(s, "model:       {}", model_words(r));
    let _ = writeln!(s, "calibration: {}", calibration_words(r));
    let _ = writeln!(
        s,
        "clocks:      {}",
        if r.board_flags & BOARD_ON_HSI != 0 {
            "the crystal did not start: running on the internal 16 MHz RC oscillator (±1 %)"
        } else {
            "crystal"
        }
    );
    if r.board_flags & BOARD_BROWN_OUT_BELOW_2V7 != 0 {
        let _ = writeln!(
            s,
            "supply:      brown-out reset not at 2.7 V (option bytes; docs/firmware.md, \"Brown-out level\")"
        );
    }
    let _ = writeln!(s, "stack peak:  {} bytes", r.stack_peak_bytes);
    let _ = writeln!(s, "since the reset:");
    for (name, value) in counters(r) {
        let _ = writeln!(s, "  {name:<20} {value}");
    }
    if let Some(note) = emulator_note(port, r) {
        let _ = writeln!(s, "{note}");
    }
    s
}

/// On a pseudo-terminal (the port `cargo xtask qemu-board` serves), the note
/// that what would be faults on a unit are QEMU's doing: it emulates no
/// reset flags (cause `other`) and no crystal, and misses samples when the
/// host is loaded. `None` on a serial device or when nothing odd is read.
fn emulator_note(port: &str, r: &HealthReport) -> Option<String> {
    if !port.starts_with("/dev/pts/") {
        return None;
    }
    let odd: Vec<&str> = [
        (r.reset_cause == ResetCause::Other).then_some("the reset cause `other` (QEMU emulates no reset flags)"),
        (r.board_flags & BOARD_ON_HSI != 0).then_some("the crystal that did not start (QEMU emulates none)"),
        (r.counters.samples_missed > 0)
            .then_some("the missed samples (QEMU's virtual clock runs on while the host is busy)"),
    ]
    .into_iter()
    .flatten()
    .collect();
    (!odd.is_empty()).then(|| {
        format!(
            "note:        {port} is a pseudo-terminal, as the QEMU board serves: {} come from the emulator, not from \
             a failing unit; on a unit's serial port they would be faults",
            odd.join(", ")
        )
    })
}

/// `status` as JSON (the fields of [`describe`], counters by name).
pub fn to_json(port: &str, status: &UnitStatus) -> serde_json::Value {
    let r = &status.report;
    let counters: serde_json::Map<String, serde_json::Value> =
        counters(r).iter().map(|&(n, v)| (n.to_owned(), v.into())).collect();
    serde_json::json!({
        "port": port,
        "firmware_version": r.firmware_version.to_string(),
        "kind": match status.kind {
            None => serde_json::Value::Null,
            Some(Kind::Single) => "single-axis".into(),
            Some(Kind::Axes(_)) => "three-axis".into(),
        },
        "axis_mask": match status.kind { Some(Kind::Axes(axes)) => axes.bits().into(), _ => serde_json::Value::Null },
        "reset_cause": reset_cause_words(r.reset_cause),
        "reset_cause_code": r.reset_cause as u8,
        "reset_flags": r.reset_flags,
        "fault_pc": r.fault_pc,
        "fault_lr": r.fault_lr,
        "model_blob_crc32": r.model.blob_crc32,
        "model_sequence": r.model.sequence,
        "model_id": (r.model.model_id != 0).then(|| crate::provenance::model_id_text(r.model.model_id)),
        "model_serial": r.model.serial_str(),
        "board_flags": r.board_flags,
        "stack_peak_bytes": r.stack_peak_bytes,
        "counters": counters,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_wire::health::{FirmwareVersion, HealthCounters, ModelIdentity};

    fn report(crc: u32, sequence: u32) -> HealthReport {
        HealthReport {
            reset_cause: ResetCause::HardFault,
            reset_flags: 0x04,
            fault_pc: 0x0800_1234,
            fault_lr: 0x0800_0101,
            counters: HealthCounters {
                samples_missed: 7,
                ..Default::default()
            },
            model: {
                let mut model = ModelIdentity {
                    blob_crc32: crc,
                    sequence,
                    model_id: 0x6e48_3868,
                    ..ModelIdentity::default()
                };
                model.set_serial("FOG-0001");
                model
            },
            board_flags: BOARD_ON_HSI,
            firmware_version: FirmwareVersion {
                major: 0,
                minor: 4,
                patch: 1,
            },
            stack_peak_bytes: 4_040,
        }
    }

    #[test]
    fn the_description_says_what_the_report_means() {
        let status = UnitStatus {
            report: report(0x1234_abcd, 3),
            kind: Some(Kind::Axes(rbf_core::axis::AxisSet::from_bits(0b111))),
        };
        let text = describe("/dev/ttyUSB0", &status);
        assert!(
            text.contains("unit on /dev/ttyUSB0: three-axis IMU, axes x, y, z"),
            "{text}"
        );
        assert!(text.contains("firmware:    0.4.1"), "{text}");
        assert!(text.contains("last reset:  HardFault"), "{text}");
        assert!(text.contains("PC 0x08001234"), "{text}");
        assert!(
            text.contains("blob CRC-32 0x1234abcd, installed over the UART as commit 3"),
            "{text}"
        );
        assert!(text.contains("internal 16 MHz RC"), "{text}");
        assert!(
            text.contains("calibration: model id 6e483868, serial FOG-0001"),
            "{text}"
        );
        assert!(text.contains("samples_missed       7"), "{text}");
        let none = UnitStatus {
            report: report(0, 0),
            kind: None,
        };
        assert!(describe("p", &none).contains("none running (output uncompensated, flag 4)"));
        // On a unit's serial port no word of QEMU; on the QEMU board's pty, its causes named.
        assert!(!text.contains("QEMU"), "{text}");
        let qemu = describe("/dev/pts/3", &status);
        assert!(
            qemu.contains("note:        /dev/pts/3 is a pseudo-terminal, as the QEMU board serves: the crystal that did not start (QEMU emulates none), the missed samples"),
            "{qemu}"
        );
        let json = to_json("p", &status);
        assert_eq!(json["model_blob_crc32"], 0x1234_abcd);
        assert_eq!(json["counters"]["samples_missed"], 7);
        assert_eq!(json["kind"], "three-axis");
        assert_eq!(json["firmware_version"], "0.4.1");
        assert_eq!(
            (json["model_id"].as_str(), json["model_serial"].as_str()),
            (Some("6e483868"), Some("FOG-0001"))
        );
    }
}
