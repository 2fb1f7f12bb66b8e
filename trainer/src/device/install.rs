//! `trainer device update`: a model blob checked as the unit will check it,
//! sent as the firmware's install command, its reply put in words, and the
//! new model confirmed from the unit's health report.
//!
//! The checks are the firmware's own: [`StoredModel`], through which the
//! board's model store decodes every slot, decodes the blob into the very
//! types the board images run (a single-axis `Model`, the three-axis
//! board's `AxisModels<MAX_AXIS_CENTERS>`, the shared-basis board's
//! `SharedAxisModels<MAX_SHARED_AXIS_CENTERS>`: the capacities the firmware's
//! `AXIS_CENTERS` and `SHARED_AXIS_CENTERS` are). Before the
//! port is opened the blob must suit one of the images; once the unit's
//! frames have said which kind it is, it must suit that kind. The two
//! three-axis images send the same frames, so for a three-axis unit a blob
//! that suits either is sent and the unit's reply decides.

use std::io::{Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use gyro_wire::command::{CMD_INSTALL_MODEL, MAX_COMMAND_FRAME_LEN, UpdateStatus, encode_install_command};
use rbf_core::axis::{Axis, AxisSet};
use rbf_core::blob::axes::AxisModels;
use rbf_core::blob::{DecodeError, MAX_BLOB_LEN};
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::stored_model::StoredModel;
use rbf_core::{MAX_AXIS_CENTERS, MAX_SHARED_AXIS_CENTERS, Model};

use super::link::{Link, Message};
use super::status::{self, UnitStatus};
use crate::reading::frames::Kind;
use crate::text;

/// How long the unit may take to answer an install: the worst-case 128-KiB
/// sector erase (4 s) and the programming, with margin.
pub const INSTALL_TIMEOUT: Duration = Duration::from_secs(15);

/// Which board images take a blob.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Suits {
    /// The single-axis board (image `stm32f405`).
    pub single: bool,
    /// The three-axis board with a model per axis (image `stm32f405-axes`).
    pub per_axis: bool,
    /// The shared-basis three-axis board (image `stm32f405-axes-shared`).
    pub shared: bool,
}

/// A blob read from its file and checked against every board image.
#[derive(Clone, Debug)]
pub struct CheckedBlob {
    /// The blob's bytes (what the unit keeps: trailing bytes of the file dropped).
    pub bytes: Vec<u8>,
    /// Its CRC-32 trailer: what the unit's health report names the running model by.
    pub crc32: u32,
    /// The images that take it.
    pub suits: Suits,
    /// The axes it holds a model for (a single-axis blob: x alone, as the
    /// three-axis board runs it).
    pub axes: AxisSet,
    /// The serial its provenance names (`None`: no provenance, or no serial given).
    pub serial: Option<String>,
}

/// Decodes `bytes` as the board whose running model is an `M` does (into
/// `model`, on the heap: a model of any kind is kilobytes large); the blob's length.
fn check_as<M: StoredModel>(model: &mut M, bytes: &[u8]) -> Result<usize, DecodeError> {
    model.decode_from(bytes)
}

/// Whether `e` only says that the blob is for another image.
fn other_image(e: &DecodeError) -> bool {
    matches!(
        e,
        DecodeError::MultiAxis
            | DecodeError::SharedBasis
            | DecodeError::NotSharedBasis
            | DecodeError::UnsupportedVersion(_)
    )
}

/// Checks `bytes` against every board image: the blob if some image takes
/// it, else the reason the most fitting image gives.
pub fn check_blob(bytes: &[u8]) -> Result<CheckedBlob, DecodeError> {
    let single = check_as(&mut *Box::new(Model::<{ rbf_core::MAX_CENTERS }>::EMPTY), bytes);
    let mut per_axis_models = Box::new(AxisModels::<MAX_AXIS_CENTERS>::EMPTY);
    let per_axis = check_as(&mut *per_axis_models, bytes);
    let mut shared_models = Box::new(SharedAxisModels::<MAX_SHARED_AXIS_CENTERS>::EMPTY);
    let shared = check_as(&mut *shared_models, bytes);
    let axes = match (&single, &per_axis, &shared) {
        (Ok(_), _, _) => AxisSet::from_bits(1 << Axis::X.index()),
        (_, Ok(_), _) => AxisSet::from_bits(per_axis_models.mask()),
        (_, _, Ok(_)) => AxisSet::from_bits(shared_models.mask()),
        _ => AxisSet::from_bits(0),
    };
    let suits = Suits {
        single: single.is_ok(),
        per_axis: per_axis.is_ok(),
        shared: shared.is_ok(),
    };
    let len = match (single, per_axis, shared) {
        (Ok(n), _, _) | (_, Ok(n), _) | (_, _, Ok(n)) => n,
        (Err(a), Err(b), Err(c)) => {
            return Err([a, b, c].into_iter().find(|e| !other_image(e)).unwrap_or(a));
        }
    };
    let bytes = bytes.get(..len).ok_or(DecodeError::Malformed)?.to_vec();
    let crc32 = crate::blobfile::blob_crc32(&bytes);
    let serial = rbf_core::blob::provenance(&bytes)?
        .map(|p| p.serial.to_owned())
        .filter(|s| !s.is_empty());
    Ok(CheckedBlob {
        bytes,
        crc32,
        suits,
        axes,
        serial,
    })
}

/// Reads and checks the blob at `path` (`-`: standard input); errors name
/// the file and say why no unit would take it.
pub fn read_blob(path: &Path) -> anyhow::Result<CheckedBlob> {
    let shown = text::path(path);
    // A blob is at most MAX_BLOB_LEN bytes; a little more tells "too long" apart.
    let limit = (MAX_BLOB_LEN * 2) as u64;
    let mut bytes = Vec::new();
    crate::reading::input::open(path)
        .and_then(|f| f.take(limit + 1).read_to_end(&mut bytes))
        .map_err(|e| anyhow::anyhow!("{shown}: cannot read: {e}"))?;
    anyhow::ensure!(
        bytes.len() as u64 <= limit,
        "{shown}: longer than {limit} bytes, not a model blob (at most {MAX_BLOB_LEN} bytes); nothing sent"
    );
    check_blob(&bytes).map_err(|e| anyhow::anyhow!("{shown}: no unit would take this blob, nothing sent: {e}"))
}

/// Whether a unit of `kind` takes `blob`; the reason when it does not. A
/// three-axis unit would take a blob with fewer axes than it has (the
/// others then run uncompensated, flag 4) or other axes: that is refused
/// too unless `force`.
pub fn check_for_unit(blob: &CheckedBlob, kind: Kind, force: bool) -> Result<(), String> {
    let names = |axes: AxisSet| axes.iter().map(Axis::name).collect::<Vec<_>>().join(", ");
    match kind {
        Kind::Single if blob.suits.single => Ok(()),
        Kind::Single => {
            Err("a single-axis unit takes a single-axis blob (format 2); this one is for a three-axis unit".into())
        }
        Kind::Axes(_) if !(blob.suits.per_axis || blob.suits.shared) => Err(format!(
            "a three-axis unit takes a blob with a model per axis of at most {MAX_AXIS_CENTERS} centres, or a shared basis \
             of at most {MAX_SHARED_AXIS_CENTERS}; this one is neither"
        )),
        Kind::Axes(unit) if blob.axes != unit && !force => Err(format!(
            "the unit's frames carry the axes {} but the blob has a model for {} alone{}; the unit would run \
             the other axes uncompensated (flag 4): fit a model for every axis, or --force to install it anyway",
            names(unit),
            names(blob.axes),
            if blob.suits.single { " (a single-axis blob)" } else { "" }
        )),
        Kind::Axes(_) => Ok(()),
    }
}

/// Whether a unit whose running model names `unit_serial` takes a blob for `blob_serial`:
/// a calibration of another unit is refused unless `force`. A unit without a serial (no
/// model, or one without provenance) and a blob without one take anything.
pub fn check_serial(blob_serial: Option<&str>, unit_serial: Option<&str>, force: bool) -> Result<(), String> {
    match (blob_serial, unit_serial) {
        (Some(blob), Some(unit)) if blob != unit && !force => Err(format!(
            "the blob is the calibration of serial {blob:?} but the unit runs one of serial {unit:?}; a model fitted              on another gyro does not compensate this one: install that unit's blob, or --force"
        )),
        _ => Ok(()),
    }
}

/// The install reply's status in words.
pub fn status_words(status: u8) -> String {
    let words = match UpdateStatus::from_u8(status) {
        Some(UpdateStatus::Installed) => "installed: the new model runs",
        Some(UpdateStatus::UnknownCommand) => "unknown command (firmware too old for model updates?)",
        Some(UpdateStatus::Malformed) => "the command frame arrived damaged (line noise?); the old model runs on",
        Some(UpdateStatus::TooLong) => "the command was longer than the unit's buffer; the old model runs on",
        Some(UpdateStatus::Refused) => {
            "the unit refused the blob (CRC, shape or parameters, or a blob for another image); the old model runs on"
        }
        Some(UpdateStatus::FlashFailed) => {
            "writing or verifying the flash failed; the old model runs on (the health report counts flash errors)"
        }
        None => "a status this trainer does not know",
    };
    format!("status {status}: {words}")
}

/// What an update did.
#[derive(Clone, Debug, PartialEq)]
pub struct Installed {
    /// The unit before the update.
    pub before: UnitStatus,
    /// The unit after it (its health report names the new model).
    pub after: UnitStatus,
    /// How long the unit took to answer the install, s.
    pub reply_s: f64,
}

/// Installs `blob` on the unit behind `link`: asks its status (which also
/// says its kind), checks the blob for that kind ([`check_for_unit`]; `force`
/// lets a blob for other axes through), sends it, waits for the reply and
/// confirms from a new health report that the blob runs.
pub fn install<P: Read + Write>(
    link: &mut Link<P>,
    blob: &CheckedBlob,
    timeout: Duration,
    force: bool,
) -> anyhow::Result<Installed> {
    let name = link.name().to_owned();
    let before = status::query(link, timeout)?;
    let kind = before.kind.ok_or_else(|| {
        anyhow::anyhow!("{name}: the unit sends no output frames, so its kind is unknown; nothing sent")
    })?;
    check_for_unit(blob, kind, force)
        .and_then(|()| check_serial(blob.serial.as_deref(), before.report.model.serial_str(), force))
        .map_err(|why| anyhow::anyhow!("{name}: blob refused, nothing sent: {why}"))?;
    let mut command = vec![0u8; MAX_COMMAND_FRAME_LEN];
    let n = encode_install_command(&blob.bytes, &mut command)
        .ok_or_else(|| anyhow::anyhow!("{name}: blob too long for the install command"))?;
    link.send_encoded(&command[..n])?;
    let sent = Instant::now();
    let deadline = sent + INSTALL_TIMEOUT;
    let status = loop {
        match link.next(deadline)? {
            Some(Message::Reply {
                command: CMD_INSTALL_MODEL,
                status,
            }) => break status,
            // A late answer to a health command the status query repeated.
            Some(Message::Health(report)) if report.counters.samples >= before.report.counters.samples => {}
            // The board sends its health report after every reset (counters
            // from 0 again), and the boot report after a fault or watchdog reset.
            Some(Message::Health(_) | Message::BootReport) => anyhow::bail!(
                "{name}: the unit reset during the update; it runs the old model or the new one \
                 (a reset at any point leaves one of them): see `trainer device status --port {name}`"
            ),
            Some(_) => {}
            None => anyhow::bail!(
                "{name}: no answer to the install within {} s; the unit runs the old model or the new one: \
                 see `trainer device status --port {name}`",
                INSTALL_TIMEOUT.as_secs()
            ),
        }
    };
    let reply_s = sent.elapsed().as_secs_f64();
    anyhow::ensure!(
        status == UpdateStatus::Installed as u8,
        "{name}: {}",
        status_words(status)
    );
    let after = status::query(link, timeout)?;
    anyhow::ensure!(
        after.report.model.blob_crc32 == blob.crc32,
        "{name}: the unit answered `installed` but its health report names another model (CRC-32 {:#010x}, \
         expected {:#010x})",
        after.report.model.blob_crc32,
        blob.crc32
    );
    Ok(Installed { before, after, reply_s })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_blob_of_another_serial_is_refused_unless_forced_naming_both() {
        let why = check_serial(Some("FOG-0002"), Some("FOG-0001"), false).unwrap_err();
        assert!(
            why.contains("\"FOG-0002\"") && why.contains("\"FOG-0001\"") && why.contains("--force"),
            "{why}"
        );
        assert_eq!(check_serial(Some("FOG-0002"), Some("FOG-0001"), true), Ok(()));
        assert_eq!(check_serial(Some("FOG-0001"), Some("FOG-0001"), false), Ok(()));
        assert_eq!(
            check_serial(Some("FOG-0001"), None, false),
            Ok(()),
            "a unit with no serial yet"
        );
        assert_eq!(
            check_serial(None, Some("FOG-0001"), false),
            Ok(()),
            "a blob without provenance"
        );
    }

    /// The framed health report of a unit with `samples` since its reset.
    fn health(samples: u32) -> Vec<u8> {
        let report = gyro_wire::health::HealthReport {
            reset_cause: gyro_wire::health::ResetCause::PowerOn,
            reset_flags: 0,
            fault_pc: 0,
            fault_lr: 0,
            counters: gyro_wire::health::HealthCounters {
                samples,
                ..Default::default()
            },
            model: Default::default(),
            board_flags: 0,
            firmware_version: gyro_wire::health::FirmwareVersion::CURRENT,
            stack_peak_bytes: 0,
        };
        let mut buf = [0u8; gyro_wire::health::HEALTH_FRAME_LEN];
        let n = report.encode(&mut buf).unwrap();
        buf[..n].to_vec()
    }

    #[test]
    fn a_unit_that_resets_during_the_install_is_told_from_a_late_answer() {
        use super::super::link::tests::{FakePort, output_frame};
        let blob = CheckedBlob {
            bytes: vec![1, 2, 3, 4],
            crc32: 0x0403_0201,
            suits: Suits {
                single: true,
                per_axis: false,
                shared: false,
            },
            axes: AxisSet::from_bits(1),
            serial: None,
        };
        let answer = |after_install: Vec<u8>| {
            let mut input = [output_frame(1), health(100), output_frame(2)].concat();
            input.extend(after_install);
            Link::new(FakePort::answering(input), "/dev/fake")
        };
        // Counters from 0 again: a reset.
        let mut link = answer([health(5), output_frame(3)].concat());
        let err = install(&mut link, &blob, Duration::from_millis(300), false)
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("/dev/fake: the unit reset during the update"), "{err}");
        // A second answer to the health command, counters on: no reset; then a refusal.
        let mut reply = [0u8; 8];
        let n = gyro_wire::command::encode_reply(CMD_INSTALL_MODEL, UpdateStatus::Refused, &mut reply).unwrap();
        let mut link = answer([health(150), reply[..n].to_vec()].concat());
        let err = install(&mut link, &blob, Duration::from_millis(300), false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("/dev/fake: status 4: the unit refused the blob"), "{err}");
    }

    #[test]
    fn a_blob_for_fewer_or_other_axes_than_the_unit_s_is_refused_unless_forced() {
        let xyz = Kind::Axes(AxisSet::from_bits(0b111));
        let blob = |single: bool, mask: u8| CheckedBlob {
            bytes: vec![],
            crc32: 0,
            suits: Suits {
                single,
                per_axis: true,
                shared: false,
            },
            axes: AxisSet::from_bits(mask),
            serial: None,
        };
        let err = check_for_unit(&blob(true, 0b001), xyz, false).unwrap_err();
        assert!(
            err.starts_with(
                "the unit's frames carry the axes x, y, z but the blob has a model for x alone (a single-axis blob)"
            ),
            "{err}"
        );
        assert!(check_for_unit(&blob(false, 0b011), xyz, false).is_err());
        assert!(check_for_unit(&blob(true, 0b001), xyz, true).is_ok(), "--force");
        assert!(check_for_unit(&blob(false, 0b111), xyz, false).is_ok());
        assert!(check_for_unit(&blob(true, 0b001), Kind::Single, false).is_ok());
        let xz = Kind::Axes(AxisSet::from_bits(0b101));
        assert!(check_for_unit(&blob(false, 0b101), xz, false).is_ok());
    }

    #[test]
    fn every_status_is_put_in_words() {
        assert!(status_words(0).contains("installed"));
        assert!(status_words(4).contains("refused the blob"));
        assert!(status_words(5).contains("flash failed"));
        assert!(status_words(9).contains("does not know"));
    }

    #[test]
    fn a_blob_no_image_takes_is_refused_with_the_firmware_s_reason() {
        assert_eq!(check_blob(&[0xFF; 64]).unwrap_err(), DecodeError::BadMagic);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.bin");
        std::fs::write(&path, b"IFOGnot a blob").unwrap();
        let err = read_blob(&path).unwrap_err().to_string();
        assert!(
            err.starts_with(&format!("{}: no unit would take this blob", path.display())),
            "{err}"
        );
    }
}
