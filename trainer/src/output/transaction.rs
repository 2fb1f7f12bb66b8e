//! Every output of a command committed together, or none
//! (docs/reliability.md, "Outputs").

use std::path::{Path, PathBuf};

use tempfile::NamedTempFile;

use super::dir::{InstalledDir, StagedDir};
use super::{Output, cleanup};
use crate::text;

/// The outputs of one command: files ([`Output`]) and directories
/// ([`StagedDir`]), staged while the command works and committed together
/// by [`Transaction::commit`] once every check has passed.
///
/// The commit first flushes and syncs every staged output (where a full
/// disk or a file-size limit shows), then checks every target again, then
/// renames each into place, keeping a second name of what each replaces;
/// should one rename fail, those already made are undone and the replaced
/// files and directories put back. A terminating signal waits for the
/// commit to end. Dropped uncommitted, a transaction removes what it staged.
#[derive(Debug, Default)]
pub struct Transaction {
    files: Vec<Output>,
    dirs: Vec<StagedDir>,
}

/// An output renamed into place, and how to undo that.
pub(crate) enum Installed {
    /// A file: its replaced content under a hidden name, if there was one.
    File {
        /// The target.
        path: PathBuf,
        /// The replaced file's hard link.
        backup: Option<NamedTempFile<()>>,
        /// True when nothing was at the target before.
        created: bool,
    },
    /// A directory, exchanged with what was at the target, if anything.
    Dir(InstalledDir),
}

impl Installed {
    /// Puts back what was at the target (best effort: this runs on a failure already being reported).
    fn undo(self) {
        match self {
            Installed::File { path, backup, created } => {
                if let Some(backup) = backup {
                    let _ = backup.persist(&path);
                } else if created {
                    let _ = std::fs::remove_file(&path);
                }
            }
            Installed::Dir(dir) => dir.undo(),
        }
    }

    /// Removes the replaced content, now that every output is in place.
    fn settle(self) {
        match self {
            Installed::File { backup, .. } => drop(backup),
            Installed::Dir(dir) => dir.settle(),
        }
    }

    /// The target.
    fn path(&self) -> &Path {
        match self {
            Installed::File { path, .. } | Installed::Dir(InstalledDir { path, .. }) => path,
        }
    }
}

impl Transaction {
    /// An empty transaction.
    pub fn new() -> Self {
        Self::default()
    }

    /// The transaction of one output.
    pub fn of(output: Output) -> Self {
        let mut t = Self::new();
        t.add(output);
        t
    }

    /// Adds a staged file.
    pub fn add(&mut self, output: Output) {
        self.files.push(output);
    }

    /// Adds a staged directory.
    pub fn add_dir(&mut self, dir: StagedDir) {
        self.dirs.push(dir);
    }

    /// Commits every output, or none (see the type's documentation).
    pub fn commit(mut self) -> anyhow::Result<()> {
        for file in &mut self.files {
            file.finish()?;
        }
        for dir in &mut self.dirs {
            dir.finish()?;
        }
        let mut staged = cleanup::pending();
        let installed = match self.install_all(&mut staged) {
            Ok(installed) => installed,
            Err(e) => {
                // The outputs are dropped (their leftovers removed) after the lock is released.
                drop(staged);
                return Err(e);
            }
        };
        // The replaced content is removed with the lock still held: a
        // stopping signal waits until no second name of it is left.
        let mut dirs: Vec<PathBuf> = Vec::new();
        for i in installed {
            let parent = match i.path().parent().filter(|p| !p.as_os_str().is_empty()) {
                Some(p) => p.to_owned(),
                None => PathBuf::from("."),
            };
            if !dirs.contains(&parent) {
                dirs.push(parent);
            }
            i.settle();
        }
        drop(staged);
        // The renames are durable once their directories are.
        for dir in dirs {
            std::fs::File::open(&dir)
                .and_then(|d| d.sync_all())
                .map_err(|e| anyhow::anyhow!("{}: directory sync failed: {e}", text::path(&dir)))?;
        }
        Ok(())
    }

    /// Checks every target again, then installs each, undoing all on the first failure.
    fn install_all(&mut self, staged: &mut cleanup::Pending) -> anyhow::Result<Vec<Installed>> {
        for file in &self.files {
            file.check_again()?;
        }
        for dir in &self.dirs {
            dir.check_again()?;
        }
        let mut installed = Vec::new();
        let step = |result: anyhow::Result<Installed>, installed: &mut Vec<Installed>| match result {
            Ok(i) => {
                installed.push(i);
                Ok(())
            }
            Err(e) => {
                for i in installed.drain(..).rev() {
                    i.undo();
                }
                Err(e)
            }
        };
        for file in &mut self.files {
            step(file.install(staged), &mut installed)?;
        }
        for dir in &mut self.dirs {
            step(dir.install(staged).map(Installed::Dir), &mut installed)?;
        }
        Ok(installed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output::{Existing, Output, check_dir_target};
    use std::io::Write;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_failing_output_leaves_every_other_output_as_it_was() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.bin"), dir.path().join("b.json"));
        std::fs::write(&a, "old a").unwrap();
        let mut tx = Transaction::new();
        let mut out = Output::create(&a, &[], Existing::Replace).unwrap();
        out.write_all(b"new a").unwrap();
        tx.add(out);
        let mut out = Output::create(&b, &[], Existing::Refuse).unwrap();
        out.write_all(b"new b").unwrap();
        tx.add(out);
        // b appears meanwhile: without replacing, the commit fails at b's rename, after a's.
        std::fs::write(&b, "theirs").unwrap();
        let err = tx.commit().unwrap_err().to_string();
        assert!(err.contains("exists"), "{err}");
        assert_eq!(std::fs::read_to_string(&a).unwrap(), "old a", "a put back");
        assert_eq!(std::fs::read_to_string(&b).unwrap(), "theirs");
        assert_eq!(names(dir.path()), ["a.bin", "b.json"], "no debris");
    }

    #[test]
    fn a_directory_is_replaced_as_a_whole_with_the_files() {
        let dir = tempfile::tempdir().unwrap();
        let rep = dir.path().join("rep");
        std::fs::create_dir(&rep).unwrap();
        std::fs::write(rep.join("old_rate.svg"), "old").unwrap();
        let model = dir.path().join("m.bin");
        let any = |_: &Path| true;
        let target = check_dir_target(&rep, &[], &[&model], Existing::Replace, &any).unwrap();
        let staged = StagedDir::create(target).unwrap();
        staged.write(Path::new("report.md"), b"new").unwrap();
        let mut tx = Transaction::new();
        let mut out = Output::create(&model, &[], Existing::Refuse).unwrap();
        out.write_all(b"blob").unwrap();
        tx.add(out);
        tx.add_dir(staged);
        tx.commit().unwrap();
        assert_eq!(names(&rep), ["report.md"], "the old report's files are gone");
        assert_eq!(std::fs::read(&model).unwrap(), b"blob");
        assert_eq!(names(dir.path()), ["m.bin", "rep"], "no debris");
    }

    #[test]
    fn a_dropped_transaction_leaves_nothing_and_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let rep = dir.path().join("rep");
        std::fs::create_dir(&rep).unwrap();
        std::fs::write(rep.join("report.md"), "old").unwrap();
        let any = |_: &Path| true;
        let staged = StagedDir::create(check_dir_target(&rep, &[], &[], Existing::Replace, &any).unwrap()).unwrap();
        staged.write(Path::new("axis-x/report.md"), b"new").unwrap();
        let mut tx = Transaction::new();
        tx.add_dir(staged);
        drop(tx);
        assert_eq!(names(dir.path()), ["rep"]);
        assert_eq!(std::fs::read_to_string(rep.join("report.md")).unwrap(), "old");
    }
}
