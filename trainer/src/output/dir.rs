//! An output directory replaced as a whole (`report -o DIR`, `fit --report
//! DIR`): written into a hidden directory beside it, then exchanged with it
//! at the commit, so DIR holds the whole old report or the whole new one.

use std::fs::Permissions;
use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use anyhow::Context;

use super::{Existing, OutputExists, OutputReadOnly, cleanup, hidden_prefix, kind};
use crate::{reading::input, text};

/// An output directory that passed [`check_dir_target`].
#[derive(Clone, Debug)]
pub struct DirTarget {
    path: PathBuf,
    parent: PathBuf,
    existing: Existing,
}

impl DirTarget {
    /// The directory to be written.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// `path` made absolute without following its last component (which may not exist yet).
fn absolute(path: &Path) -> Option<PathBuf> {
    if let Ok(p) = std::fs::canonicalize(path) {
        return Some(p);
    }
    let parent = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    Some(std::fs::canonicalize(parent).ok()?.join(path.file_name()?))
}

/// Checks `path` as an output directory before any work. Refused: a
/// name that is not one (`.`, `..`, `/`), a missing parent, anything but a
/// directory at `path`, a mount point, an input or another output of the
/// command (`inputs`, `outputs`) inside it, and an existing directory that
/// is not empty unless `existing` allows replacing it, and then only when
/// every entry in it, file or directory, is one `may_hold` accepts (given
/// its path relative to the directory): the directory is replaced as a whole, so nothing else
/// may be lost with it.
pub fn check_dir_target(
    path: &Path,
    inputs: &[&Path],
    outputs: &[&Path],
    existing: Existing,
    may_hold: &dyn Fn(&Path) -> bool,
) -> anyhow::Result<DirTarget> {
    let shown = text::path(path);
    anyhow::ensure!(
        !input::is_stdin(path),
        "- (standard output) cannot take a directory of files; name the directory to write"
    );
    let name = path
        .file_name()
        .filter(|n| *n != "." && *n != "..")
        .with_context(|| format!("{shown}: not a directory name to write; name the directory itself"))?;
    let parent = match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir.to_owned(),
        None => PathBuf::from("."),
    };
    let parent_meta = match std::fs::metadata(&parent) {
        Ok(m) if m.is_dir() => m,
        Ok(_) => anyhow::bail!("{shown}: {} is not a directory", text::path(&parent)),
        Err(e) => anyhow::bail!("{shown}: directory {}: {e}", text::path(&parent)),
    };
    // The name as given, without a trailing `/` or `/.` (which rename refuses).
    let target = match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(_) => parent.join(name),
        None => PathBuf::from(name),
    };
    let here = absolute(&target).with_context(|| format!("{shown}: cannot resolve"))?;
    for (other, role) in inputs
        .iter()
        .map(|p| (p, "an input"))
        .chain(outputs.iter().map(|p| (p, "an output")))
    {
        if input::is_stdin(other) {
            continue;
        }
        if absolute(other).is_some_and(|o| o == here) {
            anyhow::bail!(
                "{shown}: is {role} of this command, not a directory to write; name a new directory for the output"
            );
        }
        if absolute(other).is_some_and(|o| o.starts_with(&here)) {
            anyhow::bail!(
                "{}: is {role} of this command inside {shown}, which is replaced as a whole; name a file outside it",
                text::path(other)
            );
        }
    }
    match std::fs::symlink_metadata(&target) {
        Ok(meta) if meta.is_dir() => {
            if meta.dev() != parent_meta.dev() {
                anyhow::bail!(
                    "{shown}: is a mount point; a report directory is replaced as a whole, so name one inside it"
                );
            }
            if meta.mode() & 0o222 == 0 {
                return Err(OutputReadOnly {
                    shown,
                    mode: meta.mode() & 0o7777,
                }
                .into());
            }
            super::require_replaceable(&shown, &parent, Some(&meta))?;
            // The old report's files are removed from inside it.
            if rustix::fs::access(&target, rustix::fs::Access::WRITE_OK).is_err() {
                anyhow::bail!(
                    "{shown}: is not writable by this user, so the old output's files in it could not be removed \
                     when it is replaced; name another directory"
                );
            }
            let mut entries = Vec::new();
            list(&target, Path::new(""), &mut entries)?;
            if !entries.is_empty() {
                if existing == Existing::Refuse {
                    return Err(OutputExists { shown }.into());
                }
                if let Some((entry, _)) = entries.iter().find(|(rel, _)| !may_hold(rel)) {
                    anyhow::bail!(
                        "{shown}: holds {}, which this command does not write; the directory is replaced as a whole, so it is not replaced (name another directory or move that file)",
                        text::path(entry)
                    );
                }
            }
        }
        Ok(meta) => anyhow::bail!("{shown}: is {}, not a directory; it is never replaced", kind(&meta)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => super::require_replaceable(&shown, &parent, None)?,
        Err(e) => anyhow::bail!("{shown}: {e}"),
    }
    Ok(DirTarget {
        path: target,
        parent,
        existing,
    })
}

/// Every entry under `dir` (relative to the top, `rel`), with whether it is
/// a directory; a link or special file counts as a file.
fn list(dir: &Path, rel: &Path, out: &mut Vec<(PathBuf, bool)>) -> anyhow::Result<()> {
    let here = dir.join(rel);
    let entries = std::fs::read_dir(&here).with_context(|| format!("{}: cannot list", text::path(&here)))?;
    for entry in entries {
        let entry = entry.with_context(|| format!("{}: cannot list", text::path(&here)))?;
        let sub = rel.join(entry.file_name());
        let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
        out.push((sub.clone(), is_dir));
        if is_dir {
            list(dir, &sub, out)?;
        }
    }
    Ok(())
}

/// An output directory being written: a hidden directory beside its target
/// until its [`super::Transaction`] commits; dropped uncommitted, it is
/// removed with all it holds.
#[derive(Debug)]
pub struct StagedDir {
    target: DirTarget,
    staged: Option<PathBuf>,
}

impl StagedDir {
    /// Creates the hidden directory of a checked target (mode 0777 less the umask).
    pub fn create(target: DirTarget) -> anyhow::Result<StagedDir> {
        cleanup::install();
        let mut pending = cleanup::pending();
        let dir = tempfile::Builder::new()
            .prefix(&hidden_prefix(&target.path))
            .permissions(Permissions::from_mode(0o777))
            .tempdir_in(&target.parent)
            .with_context(|| format!("{}: cannot create a directory beside it", text::path(&target.path)))?;
        let staged = dir.keep();
        pending.add(&staged, true);
        Ok(StagedDir {
            target,
            staged: Some(staged),
        })
    }

    /// The directory this becomes.
    pub fn target(&self) -> &Path {
        &self.target.path
    }

    /// Writes `bytes` to the file `rel` (relative to the directory), creating
    /// its subdirectories; errors name the file as it will be.
    pub fn write(&self, rel: &Path, bytes: &[u8]) -> anyhow::Result<()> {
        let shown = text::path(&self.target.path.join(rel));
        let staged = self
            .staged
            .as_deref()
            .with_context(|| format!("{shown}: already committed"))?;
        let path = staged.join(rel);
        // With the registry locked: a stopping signal's cleanup, which
        // holds it to the end, never meets a write that would recreate the
        // directory it removes.
        let _no_cleanup_meanwhile = cleanup::pending();
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("{shown}: cannot create its directory"))?;
        }
        std::fs::write(&path, bytes).with_context(|| format!("{shown}: write failed"))
    }

    /// Syncs every file and directory written: write errors show here, before any commit.
    pub(crate) fn finish(&mut self) -> anyhow::Result<()> {
        let shown = text::path(&self.target.path);
        let staged = self
            .staged
            .as_deref()
            .with_context(|| format!("{shown}: already committed"))?;
        let mut entries = Vec::new();
        list(staged, Path::new(""), &mut entries)?;
        for (rel, _) in entries.iter().chain([&(PathBuf::new(), true)]) {
            std::fs::File::open(staged.join(rel))
                .and_then(|f| f.sync_all())
                .with_context(|| format!("{}: sync failed", text::path(&self.target.path.join(rel))))?;
        }
        Ok(())
    }

    /// Checks the target again just before the commit.
    pub(crate) fn check_again(&self) -> anyhow::Result<()> {
        let shown = text::path(&self.target.path);
        match std::fs::symlink_metadata(&self.target.path) {
            Ok(meta) if meta.is_dir() => {
                // Without replacing, only an empty directory that appeared meanwhile is taken.
                let empty = std::fs::read_dir(&self.target.path).is_ok_and(|mut d| d.next().is_none());
                if self.target.existing == Existing::Refuse && !empty {
                    return Err(OutputExists { shown }.into());
                }
                Ok(())
            }
            Ok(meta) => anyhow::bail!("{shown}: is {}, not a directory; it is never replaced", kind(&meta)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => anyhow::bail!("{shown}: {e}"),
        }
    }

    /// Puts the staged directory at the target: exchanged with the directory
    /// there (which then sits at the staging name until the transaction
    /// settles), or renamed when there is none. With the registry locked.
    pub(crate) fn install(&mut self, pending: &mut cleanup::Pending) -> anyhow::Result<InstalledDir> {
        let path = self.target.path.clone();
        let shown = text::path(&path);
        let staged = self
            .staged
            .clone()
            .with_context(|| format!("{shown}: already committed"))?;
        let replaced = match std::fs::symlink_metadata(&path) {
            Ok(meta) => {
                // The new directory keeps the mode of the one it replaces.
                std::fs::set_permissions(&staged, Permissions::from_mode(meta.mode() & 0o7777))
                    .with_context(|| format!("{shown}: cannot keep the replaced directory's mode"))?;
                exchange(&staged, &path).with_context(|| format!("{shown}: cannot replace"))?;
                true
            }
            Err(_) => {
                std::fs::rename(&staged, &path).with_context(|| format!("{shown}: cannot create"))?;
                false
            }
        };
        self.staged = None;
        pending.remove(&staged);
        Ok(InstalledDir { path, staged, replaced })
    }
}

/// A directory [`StagedDir::install`] put in place, exchanged with what was
/// at the target, if anything; and how to undo that.
#[derive(Debug)]
pub(crate) struct InstalledDir {
    /// The target.
    pub(crate) path: PathBuf,
    /// The staging name: the replaced directory after the exchange.
    staged: PathBuf,
    /// True when a directory was replaced (it is now at `staged`).
    replaced: bool,
}

impl InstalledDir {
    /// Puts back what was at the target (best effort).
    pub(crate) fn undo(self) {
        if self.replaced {
            let _ = exchange(&self.staged, &self.path);
            let _ = std::fs::remove_dir_all(&self.staged);
        } else {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }

    /// Removes the replaced directory, now that every output is in place.
    pub(crate) fn settle(self) {
        if self.replaced {
            let _ = std::fs::remove_dir_all(self.staged);
        }
    }
}

impl Drop for StagedDir {
    fn drop(&mut self) {
        if let Some(staged) = self.staged.take() {
            let mut pending = cleanup::pending();
            let _ = std::fs::remove_dir_all(&staged);
            pending.remove(&staged);
        }
    }
}

/// Exchanges two directories of one parent: atomically where the kernel
/// can (`renameat2` with `RENAME_EXCHANGE`), else by three renames through
/// an empty hidden directory.
fn exchange(a: &Path, b: &Path) -> std::io::Result<()> {
    use rustix::fs::{CWD, RenameFlags, renameat_with};
    match renameat_with(CWD, a, CWD, b, RenameFlags::EXCHANGE) {
        Ok(()) => return Ok(()),
        Err(e) if e == rustix::io::Errno::INVAL || e == rustix::io::Errno::NOSYS => {}
        Err(e) => return Err(e.into()),
    }
    let parent = b
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let slot = tempfile::Builder::new()
        .prefix(&hidden_prefix(b))
        .tempdir_in(parent)?
        .keep();
    // A directory renames over an empty one.
    std::fs::rename(b, &slot)?;
    if let Err(e) = std::fs::rename(a, b) {
        let _ = std::fs::rename(&slot, b);
        return Err(e);
    }
    std::fs::rename(&slot, a)
}
