//! A real PostgreSQL server for the records tests, started by the test itself: Debian's
//! `postgresql` binaries (`pg_config --bindir`, else /usr/lib/postgresql/*/bin), a data
//! directory and socket directory in a temporary directory, a free TCP port on
//! 127.0.0.1, trust authentication; stopped when the guard drops. The server refuses to
//! run as root, so as root it runs as the `postgres` system user (`runuser`).
//!
//! Without the binaries a test skips, saying so, except under `CI=true` (where
//! `cargo xtask ci` installs them): there it fails.

use std::net::TcpListener;
use std::path::PathBuf;
use std::process::{Command, Output};

use tempfile::TempDir;

/// A running PostgreSQL server; stopped on drop.
pub struct PostgresServer {
    bin: PathBuf,
    dir: TempDir,
    port: u16,
    as_postgres_user: bool,
}

/// The directory holding `initdb`, `pg_ctl` and `postgres`, if installed.
fn server_binaries() -> Option<PathBuf> {
    let from_pg_config = Command::new("pg_config")
        .arg("--bindir")
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| PathBuf::from(String::from_utf8_lossy(&o.stdout).trim()));
    let debian = std::fs::read_dir("/usr/lib/postgresql").ok().and_then(|versions| {
        let mut dirs: Vec<PathBuf> = versions.flatten().map(|v| v.path().join("bin")).collect();
        dirs.sort();
        dirs.pop()
    });
    from_pg_config
        .into_iter()
        .chain(debian)
        .find(|dir| dir.join("initdb").is_file() && dir.join("pg_ctl").is_file())
}

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

impl PostgresServer {
    /// Starts a server; `None` (with a line saying the test skipped) when the binaries
    /// are missing outside CI. Under `CI=true` a missing server fails the test.
    pub fn start_or_skip(test: &str) -> Option<PostgresServer> {
        let Some(bin) = server_binaries() else {
            assert!(
                std::env::var("CI").as_deref() != Ok("true"),
                "{test}: PostgreSQL's server binaries (initdb, pg_ctl) are missing; `cargo xtask ci` installs Debian's postgresql"
            );
            eprintln!("{test}: SKIPPED: no PostgreSQL server binaries (apt-get install postgresql)");
            return None;
        };
        Some(PostgresServer::start(bin))
    }

    fn start(bin: PathBuf) -> PostgresServer {
        let dir = TempDir::new().unwrap();
        let as_postgres_user = is_root();
        if as_postgres_user {
            let chown = Command::new("chown")
                .args(["-R", "postgres:postgres"])
                .arg(dir.path())
                .status()
                .unwrap();
            assert!(chown.success(), "chown of the server's directory to postgres");
        }
        let mut server = PostgresServer {
            bin,
            dir,
            port: 0,
            as_postgres_user,
        };
        let data = server.dir.path().join("data");
        let o = server.pg(
            "initdb",
            &[
                "-D",
                data.to_str().unwrap(),
                "-A",
                "trust",
                "-U",
                "postgres",
                "-E",
                "UTF8",
                "--no-sync",
            ],
        );
        assert!(o.status.success(), "initdb: {}", String::from_utf8_lossy(&o.stderr));
        // A free port: another process may take it between here and the start; try again then.
        for _ in 0..5 {
            server.port = TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
            let options = format!(
                "-p {} -k {} -c listen_addresses=127.0.0.1 -c fsync=off",
                server.port,
                server.dir.path().display()
            );
            let log = server.dir.path().join("server.log");
            let o = server.pg(
                "pg_ctl",
                &[
                    "-D",
                    data.to_str().unwrap(),
                    "-l",
                    log.to_str().unwrap(),
                    "-o",
                    &options,
                    "-w",
                    "-t",
                    "60",
                    "start",
                ],
            );
            if o.status.success() {
                return server;
            }
            eprintln!(
                "postgres did not start on port {}: {}",
                server.port,
                std::fs::read_to_string(&log).unwrap_or_default()
            );
        }
        panic!("the PostgreSQL server did not start");
    }

    /// Runs the server binary `name` with `args` (as `postgres` when we are root).
    fn pg(&self, name: &str, args: &[&str]) -> Output {
        let program = self.bin.join(name);
        let mut cmd = if self.as_postgres_user {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&program);
            c
        } else {
            Command::new(&program)
        };
        cmd.args(args).current_dir(self.dir.path()).output().unwrap()
    }

    /// The URL of the server's `postgres` database.
    pub fn url(&self) -> String {
        format!("postgres://postgres@127.0.0.1:{}/postgres", self.port)
    }
}

impl Drop for PostgresServer {
    fn drop(&mut self) {
        let data = self.dir.path().join("data");
        let _ = self.pg(
            "pg_ctl",
            &["-D", data.to_str().unwrap(), "-m", "immediate", "-w", "stop"],
        );
    }
}
