//! Calibration records: one row per calibration (each unit and axis of a batch, each
//! `trainer fit --records`), kept in a real database so that a unit's calibrations can be
//! found again years later (`trainer history`), by serial, batch or the model id its
//! health report names.
//!
//! A store is a SQLite file (the default, `--records PATH`) or a PostgreSQL database
//! (`--records postgres://…`): one schema ([`schema`]), one set of statements and one
//! record mapping ([`record`]); only the connection differs ([`backend::Backend`]).
//! A store is opened, checked and migrated before any fit, so a store that cannot take
//! the records fails the command before work is done; each record is written in one
//! transaction, after the unit's blob is committed.

pub mod backend;
pub mod postgres;
pub mod record;
pub mod schema;
pub mod sqlite;

pub use backend::Access;
use backend::{Backend, SqlValue, in_write_transaction};
pub use record::Record;

/// True when `locator` names a PostgreSQL database (`postgres://…`, `postgresql://…`).
pub fn is_postgres_url(locator: &str) -> bool {
    locator.starts_with("postgres://") || locator.starts_with("postgresql://")
}

/// An open records store.
pub struct Store {
    backend: Box<dyn Backend>,
    name: String,
    version: i64,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

/// The SELECT of whole records that the WHERE clause picks: newest first; one calibration's
/// axes (same time) by serial and axis.
fn select(where_clause: &str) -> String {
    format!(
        "SELECT {} FROM calibrations WHERE {where_clause} ORDER BY fitted_utc DESC, serial, axis, id DESC",
        record::COLUMNS
    )
}

impl Store {
    /// Opens the store `locator` names (a SQLite file path or a PostgreSQL URL) for
    /// `access`: connects, refuses a damaged store or one of a newer schema, migrates an
    /// older one and (for [`Access::Write`]) proves it writable. Every error names the store.
    pub fn open(locator: &str, access: Access) -> anyhow::Result<Store> {
        let name = if is_postgres_url(locator) {
            postgres::display_url(locator)
        } else {
            crate::text::path(std::path::Path::new(locator))
        };
        Self::open_named(locator, access, &name).map_err(|e| anyhow::anyhow!("{name}: records store: {e:#}"))
    }

    fn open_named(locator: &str, access: Access, name: &str) -> anyhow::Result<Store> {
        let mut backend: Box<dyn Backend> = if is_postgres_url(locator) {
            Box::new(postgres::PostgresStore::connect(locator)?)
        } else {
            Box::new(sqlite::SqliteStore::open(std::path::Path::new(locator), access)?)
        };
        let mut version = schema::version(backend.as_mut())?;
        if let Some(why) = schema::refusal(version) {
            anyhow::bail!(why);
        }
        if access == Access::Write {
            schema::migrate(backend.as_mut())?;
            version = schema::SCHEMA_VERSION;
            if let Some(why) = backend.cannot_write()? {
                anyhow::bail!("cannot write: {why}");
            }
        } else if version != 0 && version != schema::SCHEMA_VERSION {
            anyhow::bail!(
                "its schema is version {version}; the next `trainer batch --records` or `trainer fit --records` \
                 migrates it to {}",
                schema::SCHEMA_VERSION
            );
        }
        Ok(Store {
            backend,
            name: name.to_owned(),
            version,
        })
    }

    /// The store as messages name it (a PostgreSQL URL without its password).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Writes `record` in one transaction.
    pub fn insert(&mut self, record: &Record) -> anyhow::Result<()> {
        let placeholders: Vec<String> = (1..=record::COLUMN_COUNT).map(|i| format!("${i}")).collect();
        let sql = format!(
            "INSERT INTO calibrations ({}) VALUES ({})",
            record::COLUMNS,
            placeholders.join(", ")
        );
        let values = record.to_sql();
        in_write_transaction(self.backend.as_mut(), |b| b.execute(&sql, &values).map(drop)).map_err(|e| {
            anyhow::anyhow!(
                "{}: records store: the record of {} not written: {e:#}",
                self.name,
                record.serial
            )
        })
    }

    /// Whether the store holds a record of `serial`'s `axis` with the model `model_id`.
    pub fn has_model(&mut self, serial: &str, axis: &str, model_id: u32) -> anyhow::Result<bool> {
        let rows = self.backend.query(
            "SELECT COUNT(*) FROM calibrations WHERE serial = $1 AND axis = $2 AND model_id = $3",
            &[
                SqlValue::Text(serial.to_owned()),
                SqlValue::Text(axis.to_owned()),
                SqlValue::Int(i64::from(model_id)),
            ],
        )?;
        Ok(matches!(rows.first().and_then(|r| r.first()), Some(SqlValue::Int(n)) if *n > 0))
    }

    /// Every calibration of the unit `serial`, newest first.
    pub fn for_serial(&mut self, serial: &str) -> anyhow::Result<Vec<Record>> {
        self.records(&select("serial = $1"), serial)
    }

    /// Every calibration of the batch `batch`, newest first.
    pub fn for_batch(&mut self, batch: &str) -> anyhow::Result<Vec<Record>> {
        self.records(&select("batch = $1"), batch)
    }

    fn records(&mut self, sql: &str, key: &str) -> anyhow::Result<Vec<Record>> {
        if self.version == 0 {
            return Ok(Vec::new());
        }
        let name = self.name.clone();
        self.backend
            .query(sql, &[SqlValue::Text(key.to_owned())])
            .and_then(|rows| rows.into_iter().map(Record::from_sql).collect())
            .map_err(|e| anyhow::anyhow!("{name}: records store: {e:#}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::{Outcome, rows};
    use crate::provenance::ProvenanceRecord;

    fn record(serial: &str, fitted_utc: &str) -> Record {
        let provenance = ProvenanceRecord {
            serial: Some(serial.to_owned()),
            fitted_utc: fitted_utc.to_owned(),
            trainer_version: "0.1.0".to_owned(),
            trainer_commit: "abc".to_owned(),
            training_runs: vec![crate::provenance::TrainingRun {
                file: "run.csv".to_owned(),
                sha256: "00".repeat(32),
            }],
            spec_sha256: None,
            batch: Some("B-1".to_owned()),
        };
        let outcome = Outcome::error(serial, "run.csv:12:3: not a number".to_owned());
        Record::new(&rows(&outcome)[0], &provenance, &["fit".to_owned()]).unwrap()
    }

    /// What is written is read back field for field, newest first; a second open
    /// migrates nothing; a store opened to read is never created.
    #[test]
    fn a_record_reads_back_whole_and_a_reader_never_creates_a_store() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("cal.sqlite");
        let locator = path.to_str().unwrap();
        let e = Store::open(locator, Access::Read).unwrap_err();
        assert!(e.to_string().contains("no such file"), "{e}");
        assert!(!path.exists());
        let (older, newer) = (
            record("FOG-1", "2026-01-01T00:00:00Z"),
            record("FOG-1", "2026-02-01T00:00:00Z"),
        );
        {
            let mut store = Store::open(locator, Access::Write).unwrap();
            store.insert(&older).unwrap();
            store.insert(&newer).unwrap();
        }
        let mut store = Store::open(locator, Access::Write).unwrap();
        assert_eq!(store.version, schema::SCHEMA_VERSION);
        assert_eq!(store.for_serial("FOG-1").unwrap(), vec![newer.clone(), older]);
        assert_eq!(store.for_batch("B-1").unwrap().len(), 2);
        assert!(store.for_serial("FOG-2").unwrap().is_empty());
        assert!(!store.has_model("FOG-1", crate::calibration::UNKNOWN_AXIS, 1).unwrap());
    }
}
