//! What a records store needs of a database: run SQL with parameters, read rows back.
//! SQLite ([`super::sqlite`]) and PostgreSQL ([`super::postgres`]) each implement it;
//! every statement and the record mapping above it are shared.

/// One SQL value, as the records use them (integers, text, bytes; no floats: figures are JSON text).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SqlValue {
    /// SQL NULL.
    Null,
    /// A 64-bit integer (BIGINT).
    Int(i64),
    /// Text.
    Text(String),
    /// Bytes (BLOB in SQLite, BYTEA in PostgreSQL).
    Bytes(Vec<u8>),
}

impl SqlValue {
    /// Text, or NULL for `None`.
    pub fn text_or_null(text: Option<&str>) -> SqlValue {
        text.map_or(SqlValue::Null, |t| SqlValue::Text(t.to_owned()))
    }
}

/// What a command does with a store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Writes records: created (a new SQLite file) and migrated when needed; must be writable.
    Write,
    /// Only reads records: must exist; never created, migrated or otherwise changed.
    Read,
}

/// The SQL dialect of a store: the few words in which SQLite and PostgreSQL differ.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// SQLite 3 (rusqlite, bundled).
    Sqlite,
    /// PostgreSQL.
    Postgres,
}

impl Dialect {
    /// Starts a transaction that will write. SQLite takes the write lock at once, so that
    /// a second writer waits (busy timeout) instead of failing when it upgrades; PostgreSQL
    /// serialises migrations with an advisory lock held until the transaction ends.
    pub fn begin_write(self) -> &'static str {
        match self {
            Dialect::Sqlite => "BEGIN IMMEDIATE",
            Dialect::Postgres => "BEGIN; SELECT pg_advisory_xact_lock(5050)",
        }
    }

    /// A schema text with its type words for this dialect: `{id}` (an integer key the
    /// store assigns in insertion order) and `{bytes}`.
    pub fn ddl(self, sql: &str) -> String {
        let (id, bytes) = match self {
            Dialect::Sqlite => ("INTEGER PRIMARY KEY", "BLOB"),
            Dialect::Postgres => ("BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY", "BYTEA"),
        };
        sql.replace("{id}", id).replace("{bytes}", bytes)
    }

    /// A query counting the tables named `$1` in the store (0 or 1).
    pub fn table_count_sql(self) -> &'static str {
        match self {
            Dialect::Sqlite => "SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = $1",
            Dialect::Postgres => {
                "SELECT COUNT(*) FROM information_schema.tables WHERE table_schema = current_schema() AND table_name = $1"
            }
        }
    }
}

/// A connection to a records store.
pub trait Backend: Send {
    /// The store's dialect.
    fn dialect(&self) -> Dialect;
    /// Runs `sql`, one or more statements without parameters.
    fn execute_batch(&mut self, sql: &str) -> anyhow::Result<()>;
    /// Runs one statement with `params` (`$1`, `$2`, … in order); the rows it changed.
    fn execute(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<u64>;
    /// Runs one query with `params`; its rows, each a value per column.
    fn query(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<Vec<Vec<SqlValue>>>;
    /// Why this connection cannot write, or `None` when it can; asked before any fit.
    fn cannot_write(&mut self) -> anyhow::Result<Option<String>>;
}

/// Runs `work` in one write transaction: committed whole, or rolled back on any error.
pub fn in_write_transaction<T>(
    backend: &mut dyn Backend,
    work: impl FnOnce(&mut dyn Backend) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    let begin = backend.dialect().begin_write();
    backend.execute_batch(begin)?;
    match work(&mut *backend) {
        Ok(value) => {
            backend.execute_batch("COMMIT")?;
            Ok(value)
        }
        Err(e) => {
            // The error that matters is the work's; a failed rollback ends the connection anyway.
            let _ = backend.execute_batch("ROLLBACK");
            Err(e)
        }
    }
}
