//! What a stopping signal leaves: nothing. The staged files and directories
//! not yet committed are registered here; a handler thread removes them when
//! a terminating signal arrives, then ends the process as the signal would
//! have.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, Once};

use signal_hook::consts::signal::{
    SIGABRT, SIGALRM, SIGHUP, SIGINT, SIGPROF, SIGQUIT, SIGTERM, SIGTRAP, SIGUSR1, SIGUSR2, SIGVTALRM, SIGXCPU, SIGXFSZ,
};

/// Every signal whose default action ends the process and that a process
/// may catch, except SIGPIPE: the Rust runtime ignores it, so a write to a
/// closed pipe fails with an error the command reports (before it commits
/// anything), and a SIGPIPE sent from outside changes nothing.
pub const TERMINATING: [i32; 12] = [
    SIGINT, SIGTERM, SIGHUP, SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF, SIGXCPU, SIGTRAP, SIGABRT,
];

/// A staged file or directory, removed unless committed.
struct Staged {
    path: PathBuf,
    dir: bool,
}

/// Staged files and directories not yet committed: what a stopping signal removes.
static PENDING: Mutex<Vec<Staged>> = Mutex::new(Vec::new());

/// The registry of staged paths, locked. While a commit holds it, a
/// stopping signal waits: a commit in progress finishes first, none starts
/// after.
pub(crate) struct Pending(MutexGuard<'static, Vec<Staged>>);

/// Locks the registry (see [`Pending`]).
pub(crate) fn pending() -> Pending {
    Pending(PENDING.lock().unwrap_or_else(|poisoned| poisoned.into_inner()))
}

impl Pending {
    /// Registers a staged file (`dir` false) or directory.
    pub(crate) fn add(&mut self, path: &Path, dir: bool) {
        self.0.push(Staged {
            path: path.to_owned(),
            dir,
        });
    }

    /// Forgets `path`: committed or removed.
    pub(crate) fn remove(&mut self, path: &Path) {
        self.0.retain(|s| s.path != path);
    }
}

/// Starts, once per process, the thread that removes the staged paths on a
/// terminating signal ([`TERMINATING`]) and ends the process as the signal
/// would have. SIGXFSZ (past `ulimit -f`) is caught and does nothing, so the
/// write that crossed the limit fails with "File too large" and the command
/// reports it like any failed write.
pub(crate) fn install() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let xfsz = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let _ = signal_hook::flag::register(SIGXFSZ, xfsz);
        let Ok(mut signals) = signal_hook::iterator::Signals::new(TERMINATING) else {
            return;
        };
        let spawned = std::thread::Builder::new()
            .name("output-cleanup".into())
            .spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    // The lock is never released.
                    let staged = pending();
                    for s in staged.0.iter() {
                        let _ = if s.dir {
                            std::fs::remove_dir_all(&s.path)
                        } else {
                            std::fs::remove_file(&s.path)
                        };
                    }
                    let _ = signal_hook::low_level::emulate_default_handler(signal);
                    std::process::exit(128 + signal);
                }
            });
        drop(spawned);
    });
}
