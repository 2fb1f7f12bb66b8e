//! What a stopping signal leaves: nothing. The staged files and directories
//! not yet committed are registered here; a handler thread removes them when
//! a terminating signal arrives, then ends the process as the signal would
//! have.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
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

/// Signals that, once [`stop_gracefully`] was called, end the command's
/// work instead of the process (the first of them; a second one ends the
/// process as before).
const GRACEFUL_SIGNALS: [i32; 3] = [SIGINT, SIGTERM, SIGHUP];

/// Whether a stopping signal ends the work rather than the process.
static GRACEFUL: AtomicBool = AtomicBool::new(false);
/// Set by the first of [`GRACEFUL_SIGNALS`] while [`GRACEFUL`] holds.
static STOP_REQUESTED: AtomicBool = AtomicBool::new(false);

/// A command that stops by itself when asked ([`stop_gracefully`]).
#[derive(Debug)]
pub struct GracefulStop(());

impl GracefulStop {
    /// Whether SIGINT, SIGTERM or SIGHUP asked the command to stop.
    pub fn requested(&self) -> bool {
        STOP_REQUESTED.load(Ordering::SeqCst)
    }
}

/// Makes the first SIGINT, SIGTERM or SIGHUP (Ctrl-C, `kill`, a closed
/// terminal) ask the command to stop instead of ending the process: the
/// command sees [`GracefulStop::requested`], finishes its outputs and
/// commits them (`trainer device record`, whose run must be a complete file
/// at Ctrl-C). A second such signal, or any other terminating one, removes
/// the staged outputs and ends the process as usual.
pub fn stop_gracefully() -> GracefulStop {
    GRACEFUL.store(true, Ordering::SeqCst);
    install();
    GracefulStop(())
}

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
                for signal in signals.forever() {
                    if GRACEFUL.load(Ordering::SeqCst)
                        && GRACEFUL_SIGNALS.contains(&signal)
                        && !STOP_REQUESTED.swap(true, Ordering::SeqCst)
                    {
                        continue;
                    }
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
