//! Where a model blob came from: the unit's serial, the fit time (UTC), the trainer's
//! version and commit, the SHA-256 and file name of each training run, the acceptance
//! spec's SHA-256 and the batch id. Written into every blob `trainer fit` and `trainer
//! batch` write (format 4/5, `rbf_core::blob::Provenance`); `trainer inspect` shows it.
//!
//! The record is JSON inside the blob's provenance section (the firmware skips it; a
//! reader of a later trainer ignores fields it does not know). The short model id the
//! unit's health report carries is the first four bytes of the SHA-256 of that record,
//! so two calibrations differ in their id whenever they differ in any field.

use std::io::Read;
use std::path::Path;

use anyhow::Context;
use rbf_core::model::SERIAL_CAPACITY;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::text;

/// One training run: its file name (without the directory) and the SHA-256 of its bytes.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrainingRun {
    /// The file's name.
    pub file: String,
    /// SHA-256 of the file's bytes, lowercase hex (what `sha256sum` prints).
    pub sha256: String,
}

/// The provenance of one calibration.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ProvenanceRecord {
    /// The unit's serial number, when given.
    #[serde(skip)]
    pub serial: Option<String>,
    /// When the fit ran, RFC 3339 UTC to the second.
    pub fitted_utc: String,
    /// The trainer's version (the workspace's).
    pub trainer_version: String,
    /// The commit the trainer was built from (`unknown` outside a git checkout).
    pub trainer_commit: String,
    /// The runs the model was fitted on, in the order given.
    pub training_runs: Vec<TrainingRun>,
    /// SHA-256 of the acceptance spec the unit was judged against, when one was.
    pub spec_sha256: Option<String>,
    /// The batch id, for a unit of `trainer batch`.
    pub batch: Option<String>,
}

/// SHA-256 of the file at `path`, lowercase hex; read in 64-KiB pieces.
pub fn sha256_file(path: &Path) -> anyhow::Result<String> {
    let mut file = std::fs::File::open(path).with_context(|| format!("{}: cannot read", text::path(path)))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file
            .read(&mut buf)
            .with_context(|| format!("{}: cannot read", text::path(path)))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

/// SHA-256 of `bytes`, lowercase hex.
pub fn sha256_bytes(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The fit time: now, or `SOURCE_DATE_EPOCH` (seconds since 1970, UTC) when set, so that a
/// rebuild of the same inputs can give the same blob byte for byte.
pub fn fitted_utc_now() -> String {
    let now = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<i64>().ok())
        .and_then(|s| time::OffsetDateTime::from_unix_timestamp(s).ok())
        .unwrap_or_else(time::OffsetDateTime::now_utc)
        .replace_nanosecond(0)
        .unwrap_or(time::OffsetDateTime::UNIX_EPOCH);
    now.format(&time::format_description::well_known::Rfc3339)
        .unwrap_or_else(|_| "1970-01-01T00:00:00Z".to_owned())
}

impl ProvenanceRecord {
    /// The provenance of a fit now on `runs`, for `serial`, judged against the spec at
    /// `spec` (if any), in `batch` (if any). Reads every run and the spec once to digest them.
    pub fn for_fit(
        serial: Option<&str>,
        runs: &[impl AsRef<Path>],
        spec: Option<&Path>,
        batch: Option<&str>,
    ) -> anyhow::Result<ProvenanceRecord> {
        if let Some(s) = serial {
            anyhow::ensure!(
                s.len() <= SERIAL_CAPACITY,
                "--serial {s:?} is {} bytes; a blob holds at most {SERIAL_CAPACITY}",
                s.len()
            );
        }
        let training_runs = runs
            .iter()
            .map(|p| {
                let p = p.as_ref();
                Ok(TrainingRun {
                    file: p
                        .file_name()
                        .map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned()),
                    sha256: sha256_file(p)?,
                })
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        Ok(ProvenanceRecord {
            serial: serial.map(str::to_owned),
            fitted_utc: fitted_utc_now(),
            trainer_version: env!("CARGO_PKG_VERSION").to_owned(),
            trainer_commit: env!("TRAINER_COMMIT").to_owned(),
            training_runs,
            spec_sha256: spec.map(sha256_file).transpose()?,
            batch: batch.map(str::to_owned),
        })
    }

    /// The record's bytes as the blob holds them (JSON; the serial lies before it in the section).
    pub fn record_bytes(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// The short model id: the first four bytes of the SHA-256 of the serial and the record.
    pub fn model_id(&self) -> u32 {
        let mut hasher = Sha256::new();
        hasher.update(self.serial.as_deref().unwrap_or("").as_bytes());
        hasher.update([0]);
        hasher.update(self.record_bytes());
        let digest = hasher.finalize();
        u32::from_be_bytes([digest[0], digest[1], digest[2], digest[3]])
    }

    /// The blob's provenance section of this record, for `rbf_core::blob::encode_with` and
    /// its multi-axis twins.
    pub fn with_section<T>(&self, f: impl FnOnce(&rbf_core::blob::Provenance<'_>) -> T) -> T {
        let record = self.record_bytes();
        f(&rbf_core::blob::Provenance {
            model_id: self.model_id(),
            serial: self.serial.as_deref().unwrap_or(""),
            record: &record,
        })
    }

    /// The record a blob's provenance section holds; a record that does not parse is
    /// refused with the reason (the blob's CRC held, so a trainer wrote it that way).
    pub fn from_section(section: &rbf_core::blob::Provenance<'_>) -> anyhow::Result<ProvenanceRecord> {
        let mut record: ProvenanceRecord =
            serde_json::from_slice(section.record).context("the blob's provenance record is not valid")?;
        record.serial = (!section.serial.is_empty()).then(|| section.serial.to_owned());
        Ok(record)
    }

    /// The JSON `trainer inspect` shows: `serial`, `fitted_utc`, `trainer_version`,
    /// `trainer_commit`, `training_runs` [{`file`, `sha256`}], `spec_sha256`, `batch`, `model_id`.
    pub fn to_json(&self, model_id: u32) -> serde_json::Value {
        serde_json::json!({
            "serial": self.serial,
            "fitted_utc": self.fitted_utc,
            "trainer_version": self.trainer_version,
            "trainer_commit": self.trainer_commit,
            "training_runs": self.training_runs,
            "spec_sha256": self.spec_sha256,
            "batch": self.batch,
            "model_id": model_id_text(model_id),
        })
    }
}

/// A model id as people see it: eight lowercase hex digits.
pub fn model_id_text(model_id: u32) -> String {
    format!("{model_id:08x}")
}

/// A CRC-32 as `inspect`, `history` and the records show it: `0x` and eight hex digits.
pub fn crc32_text(crc: u32) -> String {
    format!("{crc:#010x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_digest_is_sha256sum_s_and_the_record_round_trips_through_a_blob_section() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("run.csv");
        std::fs::write(&run, b"abc").unwrap();
        let record = ProvenanceRecord::for_fit(Some("FOG-0001"), &[&run], None, Some("B-1")).unwrap();
        // sha256("abc"), as `sha256sum` prints it.
        assert_eq!(
            record.training_runs[0].sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(record.training_runs[0].file, "run.csv");
        let back = record.with_section(|s| ProvenanceRecord::from_section(s).unwrap());
        assert_eq!(back, record);
        let mut other = record.clone();
        other.batch = Some("B-2".to_owned());
        assert_ne!(other.model_id(), record.model_id(), "any field changes the id");
    }

    #[test]
    fn a_serial_longer_than_the_blob_holds_is_refused_by_name() {
        let long = "X".repeat(SERIAL_CAPACITY + 1);
        let e = ProvenanceRecord::for_fit(Some(&long), &[] as &[&Path], None, None).unwrap_err();
        assert!(e.to_string().contains("at most 32"), "{e}");
    }
}
