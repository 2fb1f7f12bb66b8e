//! What a stopping signal leaves: nothing. The staged files and directories
//! not yet committed are registered here; a handler thread removes them when
//! a terminating signal arrives, then ends the process as the signal would
//! have.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard, Once};

use nix::sys::signal::{SigSet, Signal};
use signal_hook::consts::signal::{
    SIGABRT, SIGALRM, SIGHUP, SIGINT, SIGIO, SIGPROF, SIGQUIT, SIGSYS, SIGTERM, SIGTRAP, SIGUSR1, SIGUSR2, SIGVTALRM,
    SIGXCPU, SIGXFSZ,
};

/// Every signal whose default action ends the process and that a handler
/// may catch, but SIGPIPE and the faults: the classic ones, Linux's SIGPWR,
/// SIGIO, SIGSYS and SIGSTKFLT, and the real-time signals SIGRTMIN …
/// SIGRTMAX. SIGPIPE is left out: the Rust runtime ignores it, so a write
/// to a closed pipe fails with an error the command reports (before it
/// commits anything), and a SIGPIPE sent from outside changes nothing.
/// The faults SIGILL and SIGFPE are [`FROM_OUTSIDE_ONLY`]; SIGSEGV and
/// SIGBUS stay the runtime's (its stack-overflow report).
pub fn terminating() -> Vec<i32> {
    let mut signals = vec![
        SIGINT,
        SIGTERM,
        SIGHUP,
        SIGQUIT,
        SIGUSR1,
        SIGUSR2,
        SIGALRM,
        SIGVTALRM,
        SIGPROF,
        SIGXCPU,
        SIGTRAP,
        SIGABRT,
        SIGIO,
        SIGSYS,
        nix::libc::SIGPWR,
        nix::libc::SIGSTKFLT,
    ];
    signals.extend(nix::libc::SIGRTMIN()..=nix::libc::SIGRTMAX());
    signals
}

/// Fault signals that no handler may catch (a handler returning would
/// re-run the faulting instruction), so they are blocked in every thread
/// and waited for by one: sent from outside (`kill -ILL`), they clean up
/// like any other terminating signal. A real fault of the process still
/// ends it at once: the kernel delivers a synchronous SIGILL or SIGFPE
/// even when it is blocked.
pub const FROM_OUTSIDE_ONLY: [Signal; 2] = [Signal::SIGILL, Signal::SIGFPE];

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

/// Starts, once per process, the threads that remove the staged paths on
/// a terminating signal ([`terminating`], [`FROM_OUTSIDE_ONLY`]) and end
/// the process as the signal would have. SIGXFSZ (past `ulimit -f`) is
/// caught and does nothing, so the write that crossed the limit fails with
/// "File too large" and the command reports it like any failed write.
///
/// `main` calls it first, before any other thread exists: the blocked
/// [`FROM_OUTSIDE_ONLY`] signals are blocked in every thread started
/// after it, and every command, even one that only prints, is covered.
pub fn install() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let xfsz = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        let _ = signal_hook::flag::register(SIGXFSZ, xfsz);
        let mut faults = SigSet::empty();
        for signal in FROM_OUTSIDE_ONLY {
            faults.add(signal);
        }
        if faults.thread_block().is_ok() {
            let spawned = std::thread::Builder::new()
                .name("output-cleanup-faults".into())
                .spawn(move || {
                    if let Ok(signal) = faults.wait() {
                        remove_staged_and_end(signal as i32);
                    }
                });
            drop(spawned);
        }
        let Ok(mut signals) = signal_hook::iterator::Signals::new(terminating()) else {
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
                    remove_staged_and_end(signal);
                }
            });
        drop(spawned);
    });
}

/// Removes every staged path and ends the process as `signal` would have.
/// The registry's lock is taken and never released: a commit in progress
/// (which holds it through its renames and the removal of what they
/// replaced) ends first, and none starts after.
fn remove_staged_and_end(signal: i32) -> ! {
    let staged = pending();
    for s in staged.0.iter() {
        let _ = if s.dir {
            std::fs::remove_dir_all(&s.path)
        } else {
            std::fs::remove_file(&s.path)
        };
    }
    if let Ok(blocked) = Signal::try_from(signal) {
        let mut this = SigSet::empty();
        this.add(blocked);
        let _ = this.thread_unblock();
    }
    let _ = signal_hook::low_level::emulate_default_handler(signal);
    std::process::exit(128 + signal);
}
