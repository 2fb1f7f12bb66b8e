//! Unit → host: the health report, why the board last reset, what its
//! peripherals have been through since, and which model it runs; encoded
//! on the unit ([`HealthReport::encode`]), read on the host
//! ([`HealthReport::from_bytes`]).
//!
//! Sent after every reset (after the boot report of a fault or watchdog
//! reset, before the first output frame) and in answer to
//! [`CMD_HEALTH`] over the command channel:
//! `COBS(payload) 0x00`, payload [`HEALTH_REPORT_LEN`] bytes, integers
//! little-endian (docs/firmware.md, "Health report"):
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 1 | tag [`HEALTH_REPORT_TAG`] (0xFC) |
//! | 1 | 1 | format version ([`HEALTH_REPORT_VERSION`]) |
//! | 2 | 1 | reset cause ([`ResetCause`]) |
//! | 3 | 1 | RCC_CSR bits 24–31 at boot |
//! | 4 | 4 | fault PC (panic, HardFault; else 0) |
//! | 8 | 4 | fault LR |
//! | 12 | 4 × 12 | [`HealthCounters`] in field order |
//! | 60 | 4 | running model's blob CRC-32, its trailer (0: none) |
//! | 64 | 4 | running model's commit sequence number (its serial; 0: none or uncommitted) |
//! | 68 | 4 | board flags: bit 0 the crystal did not start (the clocks run from the HSI), bit 1 the brown-out reset is not at 2.7 V |
//! | 72 | 4 | firmware version ([`FirmwareVersion::word`]: major · 2¹⁶ + minor · 2⁸ + patch) |
//! | 76 | 4 | deepest stack use since the reset, bytes (the stack is painted at boot) |
//! | 80 | 4 | running model's short model id, from its blob's provenance (0: none) |
//! | 84 | 32 | the serial its provenance names, UTF-8, zero-padded (all zero: none) |
//!
//! A receiver tells it from the other messages on the UART by its length
//! (116; the others' are in the crate docs' table) and its tag.

use crate::cobs::{cobs_encode, max_encoded_len};
pub use crate::command::CMD_HEALTH;

/// First payload byte of a health report.
pub const HEALTH_REPORT_TAG: u8 = 0xFC;
/// The report layout's version.
pub const HEALTH_REPORT_VERSION: u8 = 3;
/// Payload bytes of a health report.
pub const HEALTH_REPORT_LEN: usize = 116;
/// Bytes of the serial field at the report's end.
pub const REPORT_SERIAL_LEN: usize = rbf_core::model::SERIAL_CAPACITY;
/// Bytes of a COBS-framed health report with its terminator, at most.
pub const HEALTH_FRAME_LEN: usize = max_encoded_len(HEALTH_REPORT_LEN);

byte_enum! {
    /// Why the board last reset (the report's byte 2; the firmware tells it from
    /// its fault record and RCC_CSR).
    pub enum ResetCause {
        /// Power-on (or a brown-out reset at power-on).
        PowerOn = 0,
        /// The NRST pin (a debugger, a button).
        Pin = 1,
        /// Brown-out without power-on.
        BrownOut = 2,
        /// A software reset (SYSRESETREQ) without a fault record.
        Software = 3,
        /// The independent watchdog.
        Watchdog = 4,
        /// A panic (PC and LR in the report).
        Panic = 5,
        /// A HardFault (PC and LR in the report).
        HardFault = 6,
        /// Low-power management or the window watchdog.
        Other = 7,
    }
}

/// Counters since the last reset (each wraps at 2^32).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HealthCounters {
    /// Samples processed (frames emitted or attempted).
    pub samples: u32,
    /// Data-ready edges without a processed sample (flag 32).
    pub samples_missed: u32,
    /// Front-end reads that gave no sample (bus, CRC, not ready, stale).
    pub rate_read_faults: u32,
    /// Thermometer reads that gave no reading.
    pub temp_read_faults: u32,
    /// I2C transactions that ran out of time.
    pub sensor_timeouts: u32,
    /// I2C bus recoveries (nine clocks, STOP, peripheral reset), the one at boot included.
    pub bus_recoveries: u32,
    /// Front-end initialisations (more than one: it was re-initialised).
    pub front_end_inits: u32,
    /// Data-ready edges rejected as glitches.
    pub data_ready_glitches: u32,
    /// Steps synthesised while data-ready was silent.
    pub synthetic_steps: u32,
    /// Data-ready stamps lost to a full queue, plus command bytes lost (UART overrun or full queue).
    pub overruns: u32,
    /// Output frames dropped (the transmit queue was full).
    pub output_dropped: u32,
    /// Flash operations (erase, program) that failed.
    pub flash_errors: u32,
}

impl HealthCounters {
    fn words(&self) -> [u32; 12] {
        [
            self.samples,
            self.samples_missed,
            self.rate_read_faults,
            self.temp_read_faults,
            self.sensor_timeouts,
            self.bus_recoveries,
            self.front_end_inits,
            self.data_ready_glitches,
            self.synthetic_steps,
            self.overruns,
            self.output_dropped,
            self.flash_errors,
        ]
    }
}

/// Which model runs: its blob's CRC-32, its commit sequence number, and the short model
/// id and serial of its provenance.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ModelIdentity {
    /// The running blob's CRC-32 trailer (ISO-HDLC over its header and payload); 0 when none runs.
    pub blob_crc32: u32,
    /// The slot's commit sequence number; 0 when uncommitted or none.
    pub sequence: u32,
    /// The short model id of the blob's provenance; 0 for a blob without provenance.
    pub model_id: u32,
    /// The serial of the blob's provenance, zero-padded; all zero when none.
    pub serial: [u8; REPORT_SERIAL_LEN],
}

impl ModelIdentity {
    /// The serial as text (`None`: none, or not UTF-8).
    pub fn serial_str(&self) -> Option<&str> {
        let len = self.serial.iter().position(|&b| b == 0).unwrap_or(self.serial.len());
        core::str::from_utf8(self.serial.get(..len)?)
            .ok()
            .filter(|s| !s.is_empty())
    }

    /// Sets the serial from `text` (cut at [`REPORT_SERIAL_LEN`] bytes, which a blob never passes).
    pub fn set_serial(&mut self, text: &str) {
        self.serial = [0; REPORT_SERIAL_LEN];
        for (d, s) in self.serial.iter_mut().zip(text.as_bytes()) {
            *d = *s;
        }
    }
}

/// Everything the report carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HealthReport {
    /// Why the board last reset.
    pub reset_cause: ResetCause,
    /// RCC_CSR bits 24–31 at boot.
    pub reset_flags: u8,
    /// PC and LR of the fault that caused the reset (0 if none).
    pub fault_pc: u32,
    /// See `fault_pc`.
    pub fault_lr: u32,
    /// Counters since the reset.
    pub counters: HealthCounters,
    /// The running model.
    pub model: ModelIdentity,
    /// Board flags ([`BOARD_ON_HSI`], [`BOARD_BROWN_OUT_BELOW_2V7`]).
    pub board_flags: u32,
    /// The firmware that sent the report.
    pub firmware_version: FirmwareVersion,
    /// Deepest stack use since the reset, bytes (the painted stack's high-water mark).
    pub stack_peak_bytes: u32,
}

/// A firmware release, as the workspace's `Cargo.toml` numbers it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FirmwareVersion {
    /// Incompatible changes.
    pub major: u8,
    /// Added behaviour.
    pub minor: u8,
    /// Fixes.
    pub patch: u8,
}

impl FirmwareVersion {
    /// The workspace's version, which the firmware and this crate share
    /// (`version.workspace`; each part parsed at compile time, a part above
    /// 255 fails the build): what a firmware built from this tree reports.
    pub const CURRENT: FirmwareVersion = FirmwareVersion {
        major: parse_u8(env!("CARGO_PKG_VERSION_MAJOR")),
        minor: parse_u8(env!("CARGO_PKG_VERSION_MINOR")),
        patch: parse_u8(env!("CARGO_PKG_VERSION_PATCH")),
    };

    /// The report's word: major · 2¹⁶ + minor · 2⁸ + patch.
    pub const fn word(self) -> u32 {
        (self.major as u32) << 16 | (self.minor as u32) << 8 | self.patch as u32
    }

    /// The version in a report's word; `None` when its top byte is set (no
    /// firmware sends that).
    pub const fn from_word(word: u32) -> Option<FirmwareVersion> {
        if word >> 24 != 0 {
            return None;
        }
        Some(FirmwareVersion {
            major: (word >> 16) as u8,
            minor: (word >> 8) as u8,
            patch: word as u8,
        })
    }
}

impl core::fmt::Display for FirmwareVersion {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// A decimal version part at compile time; the build fails on anything
/// but 1–3 digits up to 255.
const fn parse_u8(text: &str) -> u8 {
    let bytes = text.as_bytes();
    assert!(!bytes.is_empty() && bytes.len() <= 3, "version part of 1-3 digits");
    let mut value: u32 = 0;
    let mut i = 0;
    while i < bytes.len() {
        assert!(bytes[i].is_ascii_digit(), "version part must be decimal");
        value = value * 10 + (bytes[i] - b'0') as u32;
        i += 1;
    }
    assert!(value <= 255, "version part above 255");
    value as u8
}

/// Board flag: the crystal did not start; the clocks run from the internal RC oscillator.
pub const BOARD_ON_HSI: u32 = 1 << 0;
/// Board flag: the brown-out reset is not at level 3 (2.70 V): the option
/// bytes leave the chip running below the 2.7 V its ×32 flash erase and
/// 5 wait states at 168 MHz need (a production step sets it:
/// docs/firmware.md, "Brown-out level").
pub const BOARD_BROWN_OUT_BELOW_2V7: u32 = 1 << 1;

impl HealthReport {
    /// The payload bytes (module docs).
    pub fn to_bytes(&self) -> [u8; HEALTH_REPORT_LEN] {
        let mut p = [0u8; HEALTH_REPORT_LEN];
        let mut words = [0u32; 16];
        words[0] = u32::from_le_bytes([
            HEALTH_REPORT_TAG,
            HEALTH_REPORT_VERSION,
            self.reset_cause as u8,
            self.reset_flags,
        ]);
        words[1] = self.fault_pc;
        words[2] = self.fault_lr;
        for (d, s) in words[3..15].iter_mut().zip(self.counters.words()) {
            *d = s;
        }
        words[15] = self.model.blob_crc32;
        let tail = [
            self.model.sequence,
            self.board_flags,
            self.firmware_version.word(),
            self.stack_peak_bytes,
            self.model.model_id,
        ];
        for (chunk, w) in p.chunks_exact_mut(4).zip(words.iter().chain(&tail)) {
            chunk.copy_from_slice(&w.to_le_bytes());
        }
        if let Some(serial) = p.get_mut(HEALTH_REPORT_LEN - REPORT_SERIAL_LEN..) {
            serial.copy_from_slice(&self.model.serial);
        }
        p
    }

    /// The report in `payload` (a decoded frame, [`HEALTH_REPORT_LEN`]
    /// bytes, tag and layout version checked); `None` for anything else.
    /// The host side (`trainer device status`) reads reports with it.
    pub fn from_bytes(payload: &[u8]) -> Option<HealthReport> {
        let p: &[u8; HEALTH_REPORT_LEN] = payload.try_into().ok()?;
        let [tag, version, cause, reset_flags] = *p.first_chunk::<4>()?;
        if tag != HEALTH_REPORT_TAG || version != HEALTH_REPORT_VERSION {
            return None;
        }
        let mut words = [0u32; HEALTH_REPORT_LEN / 4];
        for (w, chunk) in words.iter_mut().zip(p.chunks_exact(4)) {
            *w = u32::from_le_bytes(chunk.try_into().ok()?);
        }
        let c = &words[3..15];
        Some(HealthReport {
            reset_cause: ResetCause::from_u8(cause)?,
            reset_flags,
            fault_pc: words[1],
            fault_lr: words[2],
            counters: HealthCounters {
                samples: c[0],
                samples_missed: c[1],
                rate_read_faults: c[2],
                temp_read_faults: c[3],
                sensor_timeouts: c[4],
                bus_recoveries: c[5],
                front_end_inits: c[6],
                data_ready_glitches: c[7],
                synthetic_steps: c[8],
                overruns: c[9],
                output_dropped: c[10],
                flash_errors: c[11],
            },
            model: ModelIdentity {
                blob_crc32: words[15],
                sequence: words[16],
                model_id: words[20],
                serial: *p.last_chunk::<REPORT_SERIAL_LEN>()?,
            },
            board_flags: words[17],
            firmware_version: FirmwareVersion::from_word(words[18])?,
            stack_peak_bytes: words[19],
        })
    }

    /// The COBS-framed report into `out`; the bytes used.
    #[inline(never)]
    pub fn encode(&self, out: &mut [u8]) -> Option<usize> {
        cobs_encode(&self.to_bytes(), out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_lays_out_its_fields_as_documented_and_frames_to_116_bytes() {
        let report = HealthReport {
            reset_cause: ResetCause::Watchdog,
            reset_flags: 0x24,
            fault_pc: 0x0800_1234,
            fault_lr: 0,
            counters: HealthCounters {
                samples_missed: 7,
                flash_errors: 1,
                ..HealthCounters::default()
            },
            model: {
                let mut model = ModelIdentity {
                    blob_crc32: 0xDEAD_BEEF,
                    sequence: 3,
                    model_id: 0x6e48_3868,
                    ..ModelIdentity::default()
                };
                model.set_serial("FOG-0001");
                model
            },
            board_flags: BOARD_ON_HSI,
            firmware_version: FirmwareVersion {
                major: 1,
                minor: 2,
                patch: 3,
            },
            stack_peak_bytes: 4_040,
        };
        let p = report.to_bytes();
        assert_eq!(&p[..4], &[0xFC, 3, 4, 0x24]);
        assert_eq!(u32::from_le_bytes(p[4..8].try_into().unwrap()), 0x0800_1234);
        assert_eq!(u32::from_le_bytes(p[16..20].try_into().unwrap()), 7, "samples_missed");
        assert_eq!(u32::from_le_bytes(p[56..60].try_into().unwrap()), 1, "flash_errors");
        assert_eq!(u32::from_le_bytes(p[60..64].try_into().unwrap()), 0xDEAD_BEEF);
        assert_eq!(u32::from_le_bytes(p[64..68].try_into().unwrap()), 3);
        assert_eq!(u32::from_le_bytes(p[68..72].try_into().unwrap()), 1);
        assert_eq!(&p[72..76], &[3, 2, 1, 0], "firmware version 1.2.3");
        assert_eq!(u32::from_le_bytes(p[76..80].try_into().unwrap()), 4_040, "stack peak");
        assert_eq!(
            u32::from_le_bytes(p[80..84].try_into().unwrap()),
            0x6e48_3868,
            "model id"
        );
        assert_eq!(&p[84..92], b"FOG-0001");
        assert!(p[92..].iter().all(|&b| b == 0), "the serial zero-padded");
        assert_eq!(report.model.serial_str(), Some("FOG-0001"));
        let mut out = [0u8; HEALTH_FRAME_LEN];
        let n = report.encode(&mut out).unwrap();
        let mut frame = out[..n].to_vec();
        assert_eq!(
            crate::cobs::cobs_decode_in_place(&mut frame[..n - 1]),
            Some(HEALTH_REPORT_LEN)
        );
        assert_eq!(&frame[..HEALTH_REPORT_LEN], &p[..]);
        assert_eq!(
            HealthReport::from_bytes(&p),
            Some(report),
            "the host reads what the board sent"
        );
        let mut wrong_tag = p;
        wrong_tag[0] = 0xFB;
        assert_eq!(HealthReport::from_bytes(&wrong_tag), None);
        let mut wrong_cause = p;
        wrong_cause[2] = 8;
        assert_eq!(HealthReport::from_bytes(&wrong_cause), None);
        assert_eq!(HealthReport::from_bytes(&p[..76]), None, "layout 2 was 76 bytes");
        assert_eq!(HealthReport::from_bytes(&p[..HEALTH_REPORT_LEN - 1]), None);
        let mut older_layout = p;
        older_layout[1] = 2;
        assert_eq!(
            HealthReport::from_bytes(&older_layout),
            None,
            "layout 2 had no stack peak"
        );
    }

    #[test]
    fn this_builds_version_is_the_workspaces_and_its_word_round_trips() {
        let current = FirmwareVersion::CURRENT;
        assert_eq!(current.to_string(), env!("CARGO_PKG_VERSION"));
        assert_eq!(FirmwareVersion::from_word(current.word()), Some(current));
        assert_eq!(FirmwareVersion::from_word(0x0102_0304), None, "top byte set");
        assert_eq!(parse_u8("255"), 255);
    }
}
