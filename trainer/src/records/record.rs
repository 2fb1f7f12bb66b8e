//! One calibration record: what a unit's axis was fitted on, with what, when, what it
//! measured (the summary row) and the model it gave, and how it maps to a table row.

use serde_json::{Value, json};

use super::backend::SqlValue;
use crate::calibration::Status;
use crate::provenance::{ProvenanceRecord, TrainingRun, crc32_text, model_id_text};

/// One calibration: a unit's axis fitted once (or the attempt, for an error).
#[derive(Clone, Debug, PartialEq)]
pub struct Record {
    /// The unit's serial number.
    pub serial: String,
    /// The axis: `single`, `x`, `y`, `z`, or `-` for a unit whose fit failed.
    pub axis: String,
    /// The batch id, for a unit of `trainer batch`.
    pub batch: Option<String>,
    /// When the fit ran (the blob's provenance), or was attempted; RFC 3339 UTC.
    pub fitted_utc: String,
    /// When the record was written, RFC 3339 UTC.
    pub recorded_utc: String,
    /// The trainer's version.
    pub trainer_version: String,
    /// The commit the trainer was built from.
    pub trainer_commit: String,
    /// The training runs' file names and SHA-256.
    pub training_runs: Vec<TrainingRun>,
    /// The `trainer fit` arguments the calibration ran with.
    pub options: Vec<String>,
    /// SHA-256 of the acceptance spec, when the unit was judged against one.
    pub spec_sha256: Option<String>,
    /// The blob's CRC-32 (what the unit's health report names), when a model was written.
    pub model_crc32: Option<u32>,
    /// The short model id of the blob's provenance.
    pub model_id: Option<u32>,
    /// The model blob, byte for byte as written.
    pub blob: Option<Vec<u8>>,
    /// Pass, fail or error.
    pub status: Status,
    /// For a fail, each limit missed; for an error, the input at fault.
    pub reasons: Vec<String>,
    /// The axis's summary row ([`crate::calibration::rows`]): every figure it was judged on.
    pub figures: Value,
}

/// The current time, RFC 3339 UTC to the second (the record's own time, never fixed by
/// `SOURCE_DATE_EPOCH`).
pub fn now_utc() -> String {
    time::OffsetDateTime::now_utc()
        .replace_nanosecond(0)
        .ok()
        .and_then(|t| t.format(&time::format_description::well_known::Rfc3339).ok())
        .unwrap_or_else(|| "1970-01-01T00:00:00Z".to_owned())
}

impl Record {
    /// The record of one summary `row` ([`crate::calibration::rows`]: a unit's axis, its
    /// status, reasons and figures) of a calibration whose provenance is `provenance`
    /// (for an error, what its fit would have recorded), run with `options`; no model yet.
    pub fn new(row: &Value, provenance: &ProvenanceRecord, options: &[String]) -> anyhow::Result<Record> {
        let text = |key: &str| {
            row[key]
                .as_str()
                .map(str::to_owned)
                .ok_or_else(|| anyhow::anyhow!("the summary row has no {key}"))
        };
        let status_text = text("status")?;
        Ok(Record {
            serial: text("serial")?,
            axis: text("axis")?,
            batch: provenance.batch.clone(),
            fitted_utc: provenance.fitted_utc.clone(),
            recorded_utc: now_utc(),
            trainer_version: provenance.trainer_version.clone(),
            trainer_commit: provenance.trainer_commit.clone(),
            training_runs: provenance.training_runs.clone(),
            options: options.to_vec(),
            spec_sha256: provenance.spec_sha256.clone(),
            model_crc32: None,
            model_id: None,
            blob: None,
            status: Status::parse(&status_text).ok_or_else(|| anyhow::anyhow!("unknown status {status_text:?}"))?,
            reasons: serde_json::from_value(row["reasons"].clone())?,
            figures: row.clone(),
        })
    }

    /// The record of one summary `row` of a fitted unit whose blob, as written, is `blob`
    /// (its provenance gives time, version, runs, spec and batch; its CRC and id the model).
    pub fn fitted(row: &Value, blob: &[u8], options: &[String]) -> anyhow::Result<Record> {
        let (provenance, model_id) =
            crate::blobfile::blob_provenance(blob)?.ok_or_else(|| anyhow::anyhow!("the blob holds no provenance"))?;
        let mut record = Record::new(row, &provenance, options)?;
        record.model_crc32 = Some(crate::blobfile::blob_crc32(blob));
        record.model_id = Some(model_id);
        record.blob = Some(blob.to_vec());
        Ok(record)
    }

    /// Why the stored blob is not the model this record names (`None`: it is): damaged,
    /// or its CRC-32 is not `model_crc32`.
    pub fn blob_problem(&self) -> Option<String> {
        let blob = self.blob.as_deref()?;
        if let Some(why) = crate::blobfile::file_problem(blob) {
            return Some(why);
        }
        let crc = crate::blobfile::blob_crc32(blob);
        (Some(crc) != self.model_crc32).then(|| format!("the blob's CRC-32 is {}", crc32_text(crc)))
    }

    /// The record as `trainer history --json` prints it.
    pub fn to_json(&self) -> Value {
        json!({
            "serial": self.serial,
            "axis": self.axis,
            "batch": self.batch,
            "fitted_utc": self.fitted_utc,
            "recorded_utc": self.recorded_utc,
            "trainer_version": self.trainer_version,
            "trainer_commit": self.trainer_commit,
            "training_runs": self.training_runs,
            "options": self.options,
            "spec_sha256": self.spec_sha256,
            "model_crc32": self.model_crc32.map(crc32_text),
            "model_id": self.model_id.map(model_id_text),
            "blob_bytes": self.blob.as_ref().map(Vec::len),
            "blob_check": match (&self.blob, self.blob_problem()) {
                (None, _) => Value::Null,
                (Some(_), None) => json!("ok"),
                (Some(_), Some(why)) => json!(why),
            },
            "status": self.status.as_str(),
            "reasons": self.reasons,
            "figures": self.figures,
        })
    }
}

/// The table's columns that a record fills, in the order of [`Record::to_sql`].
pub const COLUMNS: &str = "serial, axis, batch, fitted_utc, recorded_utc, trainer_version, trainer_commit, \
     training_runs, options, spec_sha256, model_crc32, model_id, blob, status, reasons, figures";

/// The number of [`COLUMNS`].
pub const COLUMN_COUNT: usize = 16;

impl Record {
    /// The record's values in [`COLUMNS`] order (lists and figures as JSON text).
    pub fn to_sql(&self) -> [SqlValue; COLUMN_COUNT] {
        let text = |s: &str| SqlValue::Text(s.to_owned());
        let json_text = |v: Value| SqlValue::Text(v.to_string());
        [
            text(&self.serial),
            text(&self.axis),
            SqlValue::text_or_null(self.batch.as_deref()),
            text(&self.fitted_utc),
            text(&self.recorded_utc),
            text(&self.trainer_version),
            text(&self.trainer_commit),
            json_text(json!(self.training_runs)),
            json_text(json!(self.options)),
            SqlValue::text_or_null(self.spec_sha256.as_deref()),
            self.model_crc32.map_or(SqlValue::Null, |c| SqlValue::Int(i64::from(c))),
            self.model_id.map_or(SqlValue::Null, |c| SqlValue::Int(i64::from(c))),
            self.blob.clone().map_or(SqlValue::Null, SqlValue::Bytes),
            text(self.status.as_str()),
            json_text(json!(self.reasons)),
            json_text(self.figures.clone()),
        ]
    }

    /// The record a row of [`COLUMNS`] holds; a value of the wrong kind is refused by column.
    pub fn from_sql(values: Vec<SqlValue>) -> anyhow::Result<Record> {
        let names: Vec<&str> = COLUMNS.split(',').map(str::trim).collect();
        anyhow::ensure!(
            values.len() == COLUMN_COUNT,
            "a calibration row has {} columns, not {COLUMN_COUNT}",
            values.len()
        );
        let mut it = values.into_iter().zip(names);
        let mut next = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("a calibration row ended early"))
        };
        let text = |(v, name): (SqlValue, &str)| match v {
            SqlValue::Text(t) => Ok(t),
            other => Err(anyhow::anyhow!("column {name}: text expected, found {other:?}")),
        };
        let opt_text = |(v, name): (SqlValue, &str)| match v {
            SqlValue::Null => Ok(None),
            other => text((other, name)).map(Some),
        };
        let opt_u32 = |(v, name): (SqlValue, &str)| match v {
            SqlValue::Null => Ok(None),
            SqlValue::Int(i) => u32::try_from(i)
                .map(Some)
                .map_err(|_| anyhow::anyhow!("column {name}: {i} is not a 32-bit value")),
            other => Err(anyhow::anyhow!("column {name}: an integer expected, found {other:?}")),
        };
        let parsed = |(v, name): (SqlValue, &str)| -> anyhow::Result<Value> {
            serde_json::from_str(&text((v, name))?).map_err(|e| anyhow::anyhow!("column {name}: not JSON: {e}"))
        };
        let serial = text(next()?)?;
        let axis = text(next()?)?;
        let batch = opt_text(next()?)?;
        let fitted_utc = text(next()?)?;
        let recorded_utc = text(next()?)?;
        let trainer_version = text(next()?)?;
        let trainer_commit = text(next()?)?;
        let training_runs = serde_json::from_value(parsed(next()?)?)?;
        let options = serde_json::from_value(parsed(next()?)?)?;
        let spec_sha256 = opt_text(next()?)?;
        let model_crc32 = opt_u32(next()?)?;
        let model_id = opt_u32(next()?)?;
        let blob = match next()? {
            (SqlValue::Null, _) => None,
            (SqlValue::Bytes(b), _) => Some(b),
            (other, name) => anyhow::bail!("column {name}: bytes expected, found {other:?}"),
        };
        let status_text = text(next()?)?;
        let status = Status::parse(&status_text)
            .ok_or_else(|| anyhow::anyhow!("column status: unknown status {status_text:?}"))?;
        let reasons = serde_json::from_value(parsed(next()?)?)?;
        let figures = parsed(next()?)?;
        Ok(Record {
            serial,
            axis,
            batch,
            fitted_utc,
            recorded_utc,
            trainer_version,
            trainer_commit,
            training_runs,
            options,
            spec_sha256,
            model_crc32,
            model_id,
            blob,
            status,
            reasons,
            figures,
        })
    }
}
