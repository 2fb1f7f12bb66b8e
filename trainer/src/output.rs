//! Writing output files so that a crash or a full disk never leaves a
//! half-written model or run behind: write a temporary file beside the
//! target, flush and sync it, then rename it over the target.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use anyhow::Context;

/// What to do when the target file already exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Replace it (atomically).
    Replace,
    /// Refuse with an error naming the file; the check and the final step are
    /// one atomic operation (a hard link, which fails if the name exists), so
    /// a file appearing meanwhile is not overwritten either.
    Refuse,
}

/// Fails if `path` exists and `existing` is [`Existing::Refuse`]: call it
/// before long work so the user learns at once.
pub fn check_target(path: &Path, existing: Existing) -> anyhow::Result<()> {
    if existing == Existing::Refuse && path.symlink_metadata().is_ok() {
        anyhow::bail!("{}: exists; pass --force to overwrite it", path.display());
    }
    Ok(())
}

/// Writes `path` atomically with the content `write` produces (replacing it).
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    write_atomically_with(path, Existing::Replace, write)
}

/// Writes `path` atomically with the content `write` produces; `existing`
/// says whether an existing file may be replaced.
pub fn write_atomically_with(
    path: &Path,
    existing: Existing,
    write: impl FnOnce(&mut BufWriter<File>) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    check_target(path, existing)?;
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let name = path
        .file_name()
        .with_context(|| format!("{}: not a file path", path.display()))?;
    let tmp = dir.join(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    let result = (|| {
        let file = File::create(&tmp).with_context(|| format!("{}: cannot create", tmp.display()))?;
        let mut out = BufWriter::new(file);
        write(&mut out)?;
        let file = out
            .into_inner()
            .map_err(|e| e.into_error())
            .with_context(|| format!("{}: write failed", path.display()))?;
        file.sync_all()
            .with_context(|| format!("{}: sync failed", path.display()))?;
        match existing {
            Existing::Replace => {
                std::fs::rename(&tmp, path).with_context(|| format!("{}: cannot replace", path.display()))
            }
            Existing::Refuse => match std::fs::hard_link(&tmp, path) {
                Ok(()) => {
                    let _ = std::fs::remove_file(&tmp);
                    Ok(())
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    anyhow::bail!("{}: exists; pass --force to overwrite it", path.display())
                }
                Err(e) => Err(e).with_context(|| format!("{}: cannot create", path.display())),
            },
        }
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically (replacing it).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    write_bytes_with(path, Existing::Replace, bytes)
}

/// Writes `bytes` to `path` atomically; `existing` says whether an existing file may be replaced.
pub fn write_bytes_with(path: &Path, existing: Existing, bytes: &[u8]) -> anyhow::Result<()> {
    write_atomically_with(path, existing, |w| {
        w.write_all(bytes)
            .with_context(|| format!("{}: write failed", path.display()))
    })
}
