//! A records store in a PostgreSQL database (the `postgres` crate, synchronous; no TLS:
//! a station reaches its factory's server over the plant network or a tunnel).
//!
//! Many chamber stations write one database at once: each record is one transaction,
//! and migrations are serialised by an advisory lock ([`super::backend::Dialect`]).

use std::str::FromStr;
use std::time::Duration;

use postgres::types::{ToSql, Type};
use postgres::{Client, Config, NoTls};

use super::backend::{Backend, Dialect, SqlValue};

/// How long a connection attempt may take when the URL sets no `connect_timeout`.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// An open PostgreSQL records store.
pub struct PostgresStore {
    client: Client,
}

/// `url` as messages show it: the password, if any, replaced by `***`.
pub fn display_url(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_owned();
    };
    let authority_end = rest.find('/').unwrap_or(rest.len());
    match rest[..authority_end].rsplit_once('@') {
        Some((userinfo, host)) => match userinfo.split_once(':') {
            Some((user, _password)) => format!("{scheme}://{user}:***@{host}{}", &rest[authority_end..]),
            None => url.to_owned(),
        },
        None => url.to_owned(),
    }
}

impl PostgresStore {
    /// Connects to the database `url` names (`postgres://user[:password]@host[:port]/database`).
    pub fn connect(url: &str) -> anyhow::Result<PostgresStore> {
        let mut config = Config::from_str(url).map_err(|e| anyhow::anyhow!("not a PostgreSQL URL: {e}"))?;
        if config.get_connect_timeout().is_none() {
            config.connect_timeout(CONNECT_TIMEOUT);
        }
        let client = config
            .connect(NoTls)
            .map_err(|e| anyhow::anyhow!("cannot connect: {e}"))?;
        Ok(PostgresStore { client })
    }
}

/// `value` as a parameter of SQL type `ty` (a NULL takes the type too: PostgreSQL checks it).
fn parameter(value: &SqlValue, ty: &Type) -> anyhow::Result<Box<dyn ToSql + Sync>> {
    Ok(match (value, ty) {
        (SqlValue::Null, t) if *t == Type::INT8 => Box::new(None::<i64>),
        (SqlValue::Null, t) if *t == Type::INT4 => Box::new(None::<i32>),
        (SqlValue::Null, t) if *t == Type::BYTEA => Box::new(None::<Vec<u8>>),
        (SqlValue::Null, _) => Box::new(None::<String>),
        (SqlValue::Int(i), t) if *t == Type::INT4 => Box::new(i32::try_from(*i)?),
        (SqlValue::Int(i), _) => Box::new(*i),
        (SqlValue::Text(s), _) => Box::new(s.clone()),
        (SqlValue::Bytes(b), _) => Box::new(b.clone()),
    })
}

impl PostgresStore {
    fn run<T>(
        &mut self,
        sql: &str,
        params: &[SqlValue],
        f: impl FnOnce(&mut Client, &postgres::Statement, &[&(dyn ToSql + Sync)]) -> Result<T, postgres::Error>,
    ) -> anyhow::Result<T> {
        let statement = self.client.prepare(sql)?;
        let boxed = params
            .iter()
            .zip(statement.params())
            .map(|(v, t)| parameter(v, t))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let refs: Vec<&(dyn ToSql + Sync)> = boxed.iter().map(|b| b.as_ref()).collect();
        Ok(f(&mut self.client, &statement, &refs)?)
    }
}

impl Backend for PostgresStore {
    fn dialect(&self) -> Dialect {
        Dialect::Postgres
    }

    fn execute_batch(&mut self, sql: &str) -> anyhow::Result<()> {
        Ok(self.client.batch_execute(sql)?)
    }

    fn execute(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<u64> {
        self.run(sql, params, |c, s, p| c.execute(s, p))
    }

    fn query(&mut self, sql: &str, params: &[SqlValue]) -> anyhow::Result<Vec<Vec<SqlValue>>> {
        let rows = self.run(sql, params, |c, s, p| c.query(s, p))?;
        let mut out = Vec::with_capacity(rows.len());
        for row in rows {
            let mut values = Vec::with_capacity(row.len());
            for (i, column) in row.columns().iter().enumerate() {
                let ty = column.type_();
                let value = if *ty == Type::INT8 {
                    row.try_get::<_, Option<i64>>(i)?.map(SqlValue::Int)
                } else if *ty == Type::INT4 {
                    row.try_get::<_, Option<i32>>(i)?.map(|n| SqlValue::Int(n.into()))
                } else if *ty == Type::BOOL {
                    row.try_get::<_, Option<bool>>(i)?.map(|b| SqlValue::Int(b.into()))
                } else if *ty == Type::BYTEA {
                    row.try_get::<_, Option<Vec<u8>>>(i)?.map(SqlValue::Bytes)
                } else if [Type::TEXT, Type::VARCHAR, Type::NAME].contains(ty) {
                    row.try_get::<_, Option<String>>(i)?.map(SqlValue::Text)
                } else {
                    anyhow::bail!("column {}: type {ty} where the records store none", column.name());
                };
                values.push(value.unwrap_or(SqlValue::Null));
            }
            out.push(values);
        }
        Ok(out)
    }

    fn cannot_write(&mut self) -> anyhow::Result<Option<String>> {
        let rows = self.query(
            "SELECT CASE WHEN current_setting('transaction_read_only') = 'on' THEN 'the database is read-only' \
             WHEN NOT has_table_privilege('calibrations', 'INSERT') THEN 'no INSERT privilege on table calibrations' \
             ELSE '' END",
            &[],
        )?;
        Ok(match rows.first().and_then(|r| r.first()) {
            Some(SqlValue::Text(why)) if !why.is_empty() => Some(why.clone()),
            _ => None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_url_s_password_never_reaches_a_message() {
        assert_eq!(
            display_url("postgres://cal:s3cret@db.plant:5432/records"),
            "postgres://cal:***@db.plant:5432/records"
        );
        assert_eq!(
            display_url("postgresql://cal@db/records"),
            "postgresql://cal@db/records"
        );
    }
}
