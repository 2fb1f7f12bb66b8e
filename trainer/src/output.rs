//! Writing output files so that nothing is destroyed that should not be and
//! nothing is left half-written: every command is one transaction
//! (docs/reliability.md, "Outputs").
//!
//! Every command that writes goes through this module:
//! - **checked before the work starts** ([`check_target`] for a file,
//!   [`check_dir_target`] for a report directory): a file target must be a
//!   regular file or not exist yet (a symbolic link, a device, a FIFO or a
//!   directory is never replaced), must not be one of the command's inputs
//!   or model (same device and inode) nor another of its outputs, and an
//!   existing file is replaced only with `--force` ([`Existing::Replace`])
//!   and only when it is writable; nothing the command reads or writes may
//!   lie inside a directory it replaces;
//! - **staged beside the target**: a file ([`Output`]) in a temporary file
//!   created exclusively (`O_EXCL`) under an unpredictable name (the
//!   `tempfile` crate), with the mode of the file it replaces (a new file:
//!   0666 less the umask); a directory ([`StagedDir`]) in a hidden directory;
//! - **committed together** by [`Transaction::commit`] once the command has
//!   printed what it says: flushed and synced, checked again, renamed into
//!   place (hard-linked when replacing is not allowed; a directory
//!   exchanged), undone as a whole if one step fails, the directories synced;
//! - **removed** when the command fails (dropped), panics, or is stopped by
//!   a terminating signal (`cleanup`: a handler thread removes every staged
//!   path, then lets the signal end the process). Only SIGKILL, a power cut
//!   or the process aborting itself can leave one behind: hidden, named
//!   `.TARGET.` plus six random characters.

use std::fs::{Metadata, Permissions};
use std::io::{BufWriter, Write};
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use anyhow::Context;
use tempfile::NamedTempFile;

use crate::reading::input;
use crate::text;

mod cleanup;
mod dir;
mod transaction;

pub use cleanup::{FROM_OUTSIDE_ONLY, GracefulStop, install as catch_signals, stop_gracefully, terminating};
pub use dir::{DirTarget, StagedDir, check_dir_target};
pub(crate) use transaction::Installed;
pub use transaction::Transaction;

/// What to do when the target file already exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Replace it (`--force`), if it is a writable regular file.
    Replace,
    /// Refuse with an error naming the file (the default of every command).
    Refuse,
}

impl Existing {
    /// [`Existing::Replace`] with `--force`, else [`Existing::Refuse`].
    pub fn from_force(force: bool) -> Self {
        if force { Existing::Replace } else { Existing::Refuse }
    }
}

/// An output target that passed [`check_target`].
#[derive(Clone, Debug)]
pub struct Target {
    path: PathBuf,
    dir: PathBuf,
    existing: Existing,
}

impl Target {
    /// The file to be written.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// What kind of file `meta` describes, for messages.
fn kind(meta: &Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else {
        "a regular file"
    }
}

/// Refuses an existing target that is not a regular file, is read-only, or
/// may not be replaced.
fn check_existing(path: &Path, meta: &Metadata, existing: Existing) -> anyhow::Result<()> {
    let shown = text::path(path);
    if !meta.file_type().is_file() {
        let advice = if meta.file_type().is_symlink() {
            "outputs never replace a link; name the file itself"
        } else {
            "outputs are written only to regular files"
        };
        anyhow::bail!("{shown}: is {}; {advice}", kind(meta));
    }
    if existing == Existing::Refuse {
        return Err(OutputExists { shown }.into());
    }
    if meta.mode() & 0o222 == 0 {
        return Err(OutputReadOnly {
            shown,
            mode: meta.mode() & 0o7777,
        }
        .into());
    }
    Ok(())
}

/// Refuses, before anything is staged, an output `shown` whose directory
/// `dir` the command cannot write into (it stages beside the target there),
/// or whose existing target (`target`, its metadata) lies in a sticky
/// directory (`/tmp`'s mode) and is another user's: only its owner may
/// replace or remove it there, so the commit would fail and leave the staged
/// copy behind.
pub(crate) fn require_replaceable(shown: &str, dir: &Path, target: Option<&Metadata>) -> anyhow::Result<()> {
    use rustix::fs::{Access, access};
    if access(dir, Access::WRITE_OK).is_err() {
        anyhow::bail!(
            "{shown}: directory {} is not writable by this user, and the output is written beside its target \
             there; name an output in a directory you can write",
            text::path(dir)
        );
    }
    let sticky = std::fs::metadata(dir).is_ok_and(|m| m.mode() & 0o1000 != 0);
    let euid = rustix::process::geteuid();
    // (root may replace anything there.)
    if let Some(meta) = target
        && sticky
        && !euid.is_root()
        && meta.uid() != euid.as_raw()
    {
        anyhow::bail!(
            "{shown}: belongs to another user (uid {}) in the sticky directory {} (mode {:o}), where only its owner \
             may replace it; name another output",
            meta.uid(),
            text::path(dir),
            std::fs::metadata(dir).map_or(0, |m| m.mode() & 0o7777)
        );
    }
    Ok(())
}

/// Checks `path` as an output of a command that reads `inputs` (run files,
/// model, parameter files; `-` is standard input), before any work: see
/// the module documentation for what is refused.
pub fn check_target(path: &Path, inputs: &[&Path], existing: Existing) -> anyhow::Result<Target> {
    let shown = text::path(path);
    anyhow::ensure!(
        !input::is_stdin(path),
        "- (standard output) cannot take this output; name a file (only --json takes -)"
    );
    path.file_name()
        .with_context(|| format!("{shown}: not a file name to write"))?;
    let dir = match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir.to_owned(),
        None => PathBuf::from("."),
    };
    match std::fs::metadata(&dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => anyhow::bail!("{shown}: {} is not a directory", text::path(&dir)),
        Err(e) => anyhow::bail!("{shown}: directory {}: {e}", text::path(&dir)),
    }
    match std::fs::symlink_metadata(path) {
        Ok(meta) => {
            let id = (meta.dev(), meta.ino());
            if let Some(input) = inputs.iter().find(|i| input::identity(i) == Some(id)) {
                anyhow::bail!(
                    "{shown}: is also an input of this command ({}); an output never overwrites an input",
                    text::path(input)
                );
            }
            check_existing(path, &meta, existing)?;
            require_replaceable(&shown, &dir, Some(&meta))?;
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => require_replaceable(&shown, &dir, None)?,
        Err(e) => anyhow::bail!("{shown}: {e}"),
    }
    Ok(Target {
        path: path.to_owned(),
        dir,
        existing,
    })
}

/// [`check_target`] for every output of a command, which must also differ
/// from each other.
pub fn check_targets(outputs: &[&Path], inputs: &[&Path], existing: Existing) -> anyhow::Result<Vec<Target>> {
    let targets = outputs
        .iter()
        .map(|p| check_target(p, inputs, existing))
        .collect::<anyhow::Result<Vec<_>>>()?;
    for (i, a) in targets.iter().enumerate() {
        for b in &targets[..i] {
            if same_place(&a.path, &b.path) {
                anyhow::bail!(
                    "{} is named as two outputs; each output needs its own file",
                    text::path(&a.path)
                );
            }
        }
    }
    Ok(targets)
}

/// True when `a` and `b` name the same file: one directory (by identity) and one name.
fn same_place(a: &Path, b: &Path) -> bool {
    let dir = |p: &Path| {
        let d = p
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        input::identity(d)
    };
    a.file_name() == b.file_name() && dir(a).is_some() && dir(a) == dir(b)
}

/// The prefix of a hidden name beside `target`: `.NAME.`, to which the
/// `tempfile` crate adds six random characters and creates the file
/// exclusively. A long NAME is cut so that the whole stays within 255
/// bytes, the longest file name Linux file systems take.
pub(crate) fn hidden_prefix(target: &Path) -> std::ffi::OsString {
    use std::os::unix::ffi::{OsStrExt, OsStringExt};
    let name = target.file_name().unwrap_or_default().as_bytes();
    // 1 + 200 + 1 + 6 random characters: room to spare under 255.
    let mut prefix = b".".to_vec();
    prefix.extend_from_slice(&name[..name.len().min(MAX_HIDDEN_STEM)]);
    prefix.push(b'.');
    std::ffi::OsString::from_vec(prefix)
}

/// The most bytes of a target's name that its hidden names repeat.
const MAX_HIDDEN_STEM: usize = 200;

/// A temporary file written through its `File`: its errors carry no
/// temporary path (`tempfile` adds one), the message names the target.
struct Staged(NamedTempFile);

impl Write for Staged {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.as_file_mut().write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.0.as_file_mut().flush()
    }
}

/// Where an [`Output`] stands.
enum State {
    /// Content is being written to the temporary file.
    Writing(BufWriter<Staged>),
    /// Flushed and synced, waiting for the commit.
    Ready(NamedTempFile),
    /// Committed (or its temporary file removed).
    Done,
}

/// An output being written: a temporary file beside its target until it is
/// committed ([`Output::commit`], or with others by a [`Transaction`]);
/// dropped uncommitted, it is removed.
pub struct Output {
    target: Target,
    state: State,
}

impl std::fmt::Debug for Output {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Output").field("target", &self.target.path).finish()
    }
}

impl Output {
    /// Checks `path` ([`check_target`]) and creates its temporary file.
    pub fn create(path: &Path, inputs: &[&Path], existing: Existing) -> anyhow::Result<Output> {
        Self::open(check_target(path, inputs, existing)?)
    }

    /// Creates the temporary file of a checked target.
    pub fn open(target: Target) -> anyhow::Result<Output> {
        cleanup::install();
        let mut staged = cleanup::pending();
        let file = tempfile::Builder::new()
            .prefix(&hidden_prefix(&target.path))
            .permissions(Permissions::from_mode(0o666))
            .tempfile_in(&target.dir)
            .with_context(|| format!("{}: cannot create a file in its directory", text::path(&target.path)))?;
        staged.add(file.path(), false);
        drop(staged);
        Ok(Output {
            target,
            state: State::Writing(BufWriter::with_capacity(1 << 16, Staged(file))),
        })
    }

    /// The file this output becomes.
    pub fn path(&self) -> &Path {
        &self.target.path
    }

    /// Makes the written content the target: flush, sync, rename over the
    /// target (keeping the replaced file's mode), sync the directory. The
    /// [`Transaction`] of this one output.
    pub fn commit(self) -> anyhow::Result<()> {
        Transaction::of(self).commit()
    }

    /// Flushes and syncs the content: every write error (a full disk, a
    /// file-size limit) shows here, before any output is committed.
    pub(crate) fn finish(&mut self) -> anyhow::Result<()> {
        let shown = text::path(&self.target.path);
        match std::mem::replace(&mut self.state, State::Done) {
            State::Writing(writer) => {
                let temp = match writer.into_inner() {
                    Ok(Staged(temp)) => temp,
                    Err(e) => {
                        let (error, writer) = e.into_parts();
                        self.state = State::Writing(writer);
                        return Err(error).with_context(|| format!("{shown}: write failed"));
                    }
                };
                let synced = temp.as_file().sync_all();
                self.state = State::Ready(temp);
                synced.with_context(|| format!("{shown}: sync failed"))
            }
            State::Ready(temp) => {
                self.state = State::Ready(temp);
                Ok(())
            }
            State::Done => anyhow::bail!("{shown}: already committed"),
        }
    }

    /// Checks the target again just before the commit: it may have become a
    /// link, a directory or (without replacing) a file during the work.
    pub(crate) fn check_again(&self) -> anyhow::Result<()> {
        match std::fs::symlink_metadata(&self.target.path) {
            Ok(meta) => check_existing(&self.target.path, &meta, self.target.existing),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
            Err(e) => anyhow::bail!("{}: {e}", text::path(&self.target.path)),
        }
    }

    /// Renames the finished content over the target (a hard link without
    /// replacing, so a file that appeared meanwhile is not overwritten);
    /// returns how to undo it. Called by [`Transaction::commit`] with the
    /// registry of staged paths locked.
    pub(crate) fn install(&mut self, staged: &mut cleanup::Pending) -> anyhow::Result<Installed> {
        let path = self.target.path.clone();
        let shown = text::path(&path);
        let State::Ready(temp) = std::mem::replace(&mut self.state, State::Done) else {
            anyhow::bail!("{shown}: not finished");
        };
        let temp_path = temp.path().to_owned();
        let mut backup = None;
        if let Ok(meta) = std::fs::symlink_metadata(&path) {
            if let Err(e) = temp
                .as_file()
                .set_permissions(Permissions::from_mode(meta.mode() & 0o7777))
            {
                self.state = State::Ready(temp);
                return Err(e).with_context(|| format!("{shown}: cannot keep the replaced file's mode"));
            }
            // A second name of the old content, to put it back if a later
            // output of the transaction fails. A file system without hard
            // links gets no way back.
            backup = tempfile::Builder::new()
                .prefix(&hidden_prefix(&path))
                .make_in(&self.target.dir, |p| std::fs::hard_link(&path, p))
                .ok();
        }
        let created = backup.is_none() && std::fs::symlink_metadata(&path).is_err();
        let persisted = match self.target.existing {
            Existing::Replace => temp.persist(&path),
            Existing::Refuse => temp.persist_noclobber(&path),
        };
        match persisted {
            Ok(_) => {
                staged.remove(&temp_path);
                Ok(Installed::File { path, backup, created })
            }
            Err(e) => {
                self.state = State::Ready(e.file);
                if e.error.kind() == std::io::ErrorKind::AlreadyExists {
                    Err(OutputExists { shown }.into())
                } else {
                    Err(e.error).with_context(|| format!("{shown}: cannot create"))
                }
            }
        }
    }
}

impl Write for Output {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.state {
            State::Writing(w) => w.write(buf),
            _ => Err(std::io::Error::other("output already finished")),
        }
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        match &mut self.state {
            State::Writing(w) => w.write_all(buf),
            _ => Err(std::io::Error::other("output already finished")),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.state {
            State::Writing(w) => w.flush(),
            _ => Ok(()),
        }
    }
}

impl Drop for Output {
    fn drop(&mut self) {
        let temp = match std::mem::replace(&mut self.state, State::Done) {
            State::Writing(writer) => writer.into_parts().0.0,
            State::Ready(temp) => temp,
            State::Done => return,
        };
        let mut staged = cleanup::pending();
        let temp_path = temp.path().to_owned();
        let _ = temp.close();
        staged.remove(&temp_path);
    }
}

/// An output that exists where the command may not replace one
/// ([`Existing::Refuse`]).
#[derive(Debug, thiserror::Error)]
#[error("{shown}: exists")]
pub struct OutputExists {
    /// The output as messages name it ([`text::path`]).
    pub shown: String,
}

/// An existing output that is read-only: never replaced.
#[derive(Debug, thiserror::Error)]
#[error("{shown}: is read-only (mode {mode:04o}); not replaced")]
pub struct OutputReadOnly {
    /// The output as messages name it ([`text::path`]).
    pub shown: String,
    /// Its permission bits.
    pub mode: u32,
}

/// Writes `bytes` to `path` through an [`Output`] (checked against `inputs`).
pub fn write_bytes_with(path: &Path, inputs: &[&Path], existing: Existing, bytes: &[u8]) -> anyhow::Result<()> {
    let mut out = Output::create(path, inputs, existing)?;
    out.write_all(bytes)
        .with_context(|| format!("{}: write failed", text::path(path)))?;
    out.commit()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with('.'))
            .collect()
    }

    #[test]
    fn a_new_file_appears_only_at_commit_and_a_dropped_output_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        let mut out = Output::create(&path, &[], Existing::Refuse).unwrap();
        out.write_all(b"a,b\n").unwrap();
        assert!(!path.exists(), "nothing at the target before the commit");
        assert_eq!(leftovers(dir.path()).len(), 1, "one hidden temporary file");
        drop(out);
        assert!(leftovers(dir.path()).is_empty(), "removed when dropped");
        assert!(!path.exists());
        let mut out = Output::create(&path, &[], Existing::Refuse).unwrap();
        out.write_all(b"a,b\n").unwrap();
        out.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"a,b\n");
        assert!(leftovers(dir.path()).is_empty());
    }

    #[test]
    fn temporary_names_are_unpredictable_and_never_follow_a_planted_link() {
        let dir = tempfile::tempdir().unwrap();
        let victim = dir.path().join("victim.txt");
        std::fs::write(&victim, "keep").unwrap();
        // The name an older scheme would have used, planted as a link.
        symlink(&victim, dir.path().join(format!(".out.csv.tmp-{}", std::process::id()))).unwrap();
        let path = dir.path().join("out.csv");
        let a = Output::create(&path, &[], Existing::Refuse).unwrap();
        let b = Output::create(&dir.path().join("other.csv"), &[], Existing::Refuse).unwrap();
        let names = leftovers(dir.path());
        assert_eq!(names.len(), 3, "{names:?}");
        let mut out = a;
        out.write_all(b"new").unwrap();
        out.commit().unwrap();
        drop(b);
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep");
    }

    #[test]
    fn replacing_needs_replace_a_writable_regular_file_and_keeps_its_mode() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.bin");
        std::fs::write(&path, "old").unwrap();
        std::fs::set_permissions(&path, Permissions::from_mode(0o640)).unwrap();
        let err = Output::create(&path, &[], Existing::Refuse).unwrap_err().to_string();
        assert!(err.ends_with(": exists"), "{err}");
        write_bytes_with(&path, &[], Existing::Replace, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        let mode = std::fs::metadata(&path).unwrap().mode() & 0o7777;
        assert_eq!(mode, 0o640, "the replaced file's mode is kept");
        std::fs::set_permissions(&path, Permissions::from_mode(0o444)).unwrap();
        let err = Output::create(&path, &[], Existing::Replace).unwrap_err().to_string();
        assert!(err.contains("is read-only (mode 0444)"), "{err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
    }

    #[test]
    fn links_devices_directories_and_inputs_are_never_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("run.csv");
        std::fs::write(&input, "data").unwrap();
        let link = dir.path().join("link.csv");
        symlink(&input, &link).unwrap();
        let hard = dir.path().join("hard.csv");
        std::fs::hard_link(&input, &hard).unwrap();
        let cases: [(&Path, &str); 5] = [
            (&link, "is a symbolic link"),
            (Path::new("/dev/null"), "is a character device"),
            (dir.path(), "is a directory"),
            (&input, "is also an input of this command"),
            (&hard, "is also an input of this command"),
        ];
        for (target, expected) in cases {
            let err = check_target(target, &[&input], Existing::Replace)
                .unwrap_err()
                .to_string();
            assert!(err.contains(expected), "{}: {err}", target.display());
        }
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "data");
        let same = check_targets(
            &[&dir.path().join("a.csv"), &dir.path().join("./a.csv")],
            &[],
            Existing::Refuse,
        )
        .unwrap_err()
        .to_string();
        assert!(same.contains("named as two outputs"), "{same}");
        let missing = check_target(&dir.path().join("no/such/out.csv"), &[], Existing::Refuse)
            .unwrap_err()
            .to_string();
        assert!(missing.contains("directory"), "{missing}");
    }

    #[test]
    fn a_file_that_appears_during_the_work_is_not_overwritten_without_replace() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.csv");
        let mut out = Output::create(&path, &[], Existing::Refuse).unwrap();
        out.write_all(b"ours").unwrap();
        std::fs::write(&path, "theirs").unwrap();
        let err = out.commit().unwrap_err().to_string();
        assert!(err.contains("exists"), "{err}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "theirs");
        assert!(leftovers(dir.path()).is_empty());
    }
}
