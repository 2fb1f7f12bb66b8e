//! The records' schema and its versioned migrations.
//!
//! `schema_version` holds a row per migration applied. A store is migrated forward in one
//! write transaction (concurrent openers wait for it, then find nothing left to do); a
//! store of a newer version than [`SCHEMA_VERSION`] is refused, never altered.

use super::backend::{Backend, SqlValue, in_write_transaction};

/// The schema version this trainer writes and reads.
pub const SCHEMA_VERSION: i64 = MIGRATIONS.len() as i64;

/// Migration `i` brings a store from version `i` to `i + 1`. Type words in braces are the
/// dialect's (`Dialect::ddl`). Append only: a migration that has shipped never changes.
const MIGRATIONS: [&str; 1] = [
    // 1: one row per calibration (a unit's axis fitted once).
    "CREATE TABLE calibrations (
        id {id},
        serial TEXT NOT NULL,
        axis TEXT NOT NULL,
        batch TEXT,
        fitted_utc TEXT NOT NULL,
        recorded_utc TEXT NOT NULL,
        trainer_version TEXT NOT NULL,
        trainer_commit TEXT NOT NULL,
        training_runs TEXT NOT NULL,
        options TEXT NOT NULL,
        spec_sha256 TEXT,
        model_crc32 BIGINT,
        model_id BIGINT,
        blob {bytes},
        status TEXT NOT NULL CHECK (status IN ('pass', 'fail', 'error')),
        reasons TEXT NOT NULL,
        figures TEXT NOT NULL
    );
    CREATE INDEX calibrations_by_serial ON calibrations (serial, fitted_utc);
    CREATE INDEX calibrations_by_batch ON calibrations (batch);",
];

/// The table that holds the applied migrations.
const VERSION_TABLE: &str = "CREATE TABLE IF NOT EXISTS schema_version (
    version BIGINT NOT NULL PRIMARY KEY,
    applied_utc TEXT NOT NULL
)";

/// The store's schema version: 0 for a store nothing was written to yet.
pub fn version(backend: &mut dyn Backend) -> anyhow::Result<i64> {
    let sql = backend.dialect().table_count_sql();
    let tables = backend.query(sql, &[SqlValue::Text("schema_version".to_owned())])?;
    if !matches!(tables.first().and_then(|r| r.first()), Some(SqlValue::Int(n)) if *n > 0) {
        return Ok(0);
    }
    let rows = backend.query("SELECT MAX(version) FROM schema_version", &[])?;
    Ok(match rows.first().and_then(|r| r.first()) {
        Some(SqlValue::Int(v)) => *v,
        _ => 0,
    })
}

/// Why a store of `version` cannot be used by this trainer, if it cannot.
pub fn refusal(version: i64) -> Option<String> {
    (version > SCHEMA_VERSION).then(|| {
        format!(
            "its schema is version {version}, newer than this trainer knows ({SCHEMA_VERSION}); \
             use the trainer that wrote it or a newer one (the store was left unchanged)"
        )
    })
}

/// Brings the store to [`SCHEMA_VERSION`], in one write transaction; refuses a newer one.
pub fn migrate(backend: &mut dyn Backend) -> anyhow::Result<()> {
    if let Some(why) = refusal(version(backend)?) {
        anyhow::bail!(why);
    }
    if version(backend)? == SCHEMA_VERSION {
        return Ok(());
    }
    let dialect = backend.dialect();
    in_write_transaction(backend, |b| {
        b.execute_batch(VERSION_TABLE)?;
        // Read again under the write lock: another trainer may have migrated meanwhile.
        let from = version(b)?;
        if let Some(why) = refusal(from) {
            anyhow::bail!(why);
        }
        for (i, migration) in MIGRATIONS.iter().enumerate().skip(usize::try_from(from).unwrap_or(0)) {
            b.execute_batch(&dialect.ddl(migration))?;
            b.execute(
                "INSERT INTO schema_version (version, applied_utc) VALUES ($1, $2)",
                &[
                    SqlValue::Int(i as i64 + 1),
                    SqlValue::Text(crate::provenance::fitted_utc_now()),
                ],
            )?;
        }
        Ok(())
    })
}
