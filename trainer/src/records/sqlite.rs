//! A records store in a SQLite file (rusqlite, SQLite bundled: no system library).
//!
//! WAL journal and a busy timeout, so that several trainers write one file at once
//! (each write transaction takes the lock at its start and waits for it); a killed
//! writer's transaction is rolled back by the next opener. A file that is not a SQLite
//! database, or fails `PRAGMA quick_check`, is refused before anything touches it.

use std::path::Path;
use std::time::Duration;

use rusqlite::types::{Value, ValueRef};
use rusqlite::{Connection, OpenFlags};

use super::backend::{Access, Backend, Dialect, SqlValue};

/// How long a writer waits for another's transaction to end before it gives up.
const BUSY_TIMEOUT: Duration = Duration::from_secs(60);

/// The first 16 bytes of every SQLite 3 database file.
const SQLITE_MAGIC: &[u8; 16] = b"SQLite format 3\0";

/// An open SQLite records store.
pub struct SqliteStore {
    connection: Connection,
}

/// Why the file at `path` is not one a store may use (it is left as it is), if it is not.
fn damage(path: &Path) -> anyhow::Result<Option<String>> {
    use std::io::Read;
    let mut head = Vec::with_capacity(SQLITE_MAGIC.len());
    std::fs::File::open(path)?
        .take(SQLITE_MAGIC.len() as u64)
        .read_to_end(&mut head)?;
    // An empty file is an empty SQLite database (what `touch` makes).
    Ok((!head.is_empty() && head != SQLITE_MAGIC).then(|| {
        "not a SQLite database (it does not begin with \"SQLite format 3\"); refused, left unchanged".to_owned()
    }))
}

impl SqliteStore {
    /// Opens the store at `path`: for [`Access::Write`] a missing file is created; an
    /// existing one must be a whole SQLite database.
    pub fn open(path: &Path, access: Access) -> anyhow::Result<SqliteStore> {
        let exists = path.exists();
        if exists {
            anyhow::ensure!(path.is_file(), "not a file");
            if let Some(why) = damage(path)? {
                anyhow::bail!(why);
            }
        } else {
            anyhow::ensure!(access == Access::Write, "no such file");
        }
        let flags = match access {
            Access::Write => OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_CREATE,
            Access::Read => OpenFlags::SQLITE_OPEN_READ_ONLY,
        } | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let connection = Connection::open_with_flags(path, flags)?;
        connection.busy_timeout(BUSY_TIMEOUT)?;
        if exists {
            let check: String = connection
                .query_row("PRAGMA quick_check", [], |r| r.get(0))
                .map_err(|e| anyhow::anyhow!("damaged ({e}); refused, left unchanged"))?;
            anyhow::ensure!(
                check == "ok",
                "damaged (PRAGMA quick_check: {check}); refused, left unchanged"
            );
        }
        if access == Access::Write {
            // A read-only file is a "do not write" even for a user the system lets write.
            let read_only = std::fs::metadata(path).is_ok_and(|m| m.permissions().readonly());
            anyhow::ensure!(!read_only, "cannot write: the file is read-only");
            let mode: String = connection.query_row("PRAGMA journal_mode = WAL", [], |r| r.get(0))?;
            anyhow::ensure!(
                mode.eq_ignore_ascii_case("wal"),
                "cannot switch to the WAL journal (journal_mode is {mode})"
            );
        }
        Ok(SqliteStore { connection })
    }
}

fn to_value(v: &SqlValue) -> Value {
    match v {
        SqlValue::Null => Value::Null,
        SqlValue::Int(i) => Value::Integer(*i),
        SqlValue::Text(t) => Value::Text(t.clone()),
        SqlValue::Bytes(b) => Value::Blob(b.clone()),
    }
}

impl Backend for SqliteStore {
    fn dialect(&self) -> Dialect {
        Dialect::Sqlite
    }

    fn execute_batch(&mut self, sql: &str) -> anyhow::Result<()> {
        Ok(self.connection.execute_batch(sql)?)
    }

    fn execute(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<u64> {
        let n = self
            .connection
            .execute(sql, rusqlite::params_from_iter(params.iter().map(to_value)))?;
        Ok(n as u64)
    }

    fn query(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<Vec<Vec<SqlValue>>> {
        let mut statement = self.connection.prepare(sql)?;
        let columns = statement.column_count();
        let mut rows = statement.query(rusqlite::params_from_iter(params.iter().map(to_value)))?;
        let mut out = Vec::new();
        while let Some(row) = rows.next()? {
            let mut values = Vec::with_capacity(columns);
            for i in 0..columns {
                values.push(match row.get_ref(i)? {
                    ValueRef::Null => SqlValue::Null,
                    ValueRef::Integer(n) => SqlValue::Int(n),
                    ValueRef::Text(t) => SqlValue::Text(String::from_utf8_lossy(t).into_owned()),
                    ValueRef::Blob(b) => SqlValue::Bytes(b.to_vec()),
                    ValueRef::Real(x) => anyhow::bail!("column {i}: a real number ({x}) where none is stored"),
                });
            }
            out.push(values);
        }
        Ok(out)
    }

    fn cannot_write(&mut self) -> anyhow::Result<Option<String>> {
        if self.connection.is_readonly(rusqlite::MAIN_DB)? {
            return Ok(Some("the file or its directory is read-only".to_owned()));
        }
        // Take the write lock and let it go: a store that cannot be written says so now.
        match self.connection.execute_batch("BEGIN IMMEDIATE; ROLLBACK") {
            Ok(()) => Ok(None),
            Err(e) => Ok(Some(e.to_string())),
        }
    }
}
