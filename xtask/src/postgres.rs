//! The PostgreSQL server the calibration-records tests start themselves (trainer's
//! `cli_tests::records`): Debian's `postgresql` package, installed when missing, as QEMU is.

use std::path::PathBuf;

use anyhow::bail;

/// True when the server binaries the tests run (`initdb`, `pg_ctl`) are installed where
/// the tests look: `pg_config --bindir`, or Debian's /usr/lib/postgresql/*/bin.
pub fn available() -> bool {
    let bindir = crate::output("pg_config", &["--bindir"]);
    let debian = std::fs::read_dir("/usr/lib/postgresql")
        .map(|versions| versions.flatten().map(|v| v.path().join("bin")).collect::<Vec<_>>())
        .unwrap_or_default();
    std::iter::once(PathBuf::from(bindir.trim()))
        .chain(debian)
        .any(|dir| dir.join("initdb").is_file() && dir.join("pg_ctl").is_file())
}

/// Installs Debian's `postgresql` when its server binaries are missing.
pub fn ensure_installed() -> anyhow::Result<()> {
    if available() {
        return Ok(());
    }
    crate::qemu::apt_install(&["postgresql"])?;
    if !available() {
        bail!("PostgreSQL's server binaries (initdb, pg_ctl) still missing after installing postgresql");
    }
    Ok(())
}
