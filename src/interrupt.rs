//! SIGINT and SIGTERM: stop at the next safe point, keep every finished unit, and exit 130 with
//! "interrupted; resume with --resume" (SPEC.md §2). The handler only sets a flag (the one thing
//! a signal handler may safely do); units and the executor look at it between chunks of work, so
//! nothing is left half-written under a final name. A second signal ends the process at once.

use std::sync::atomic::{AtomicBool, Ordering};

use crate::error::{Error, Result};

static REQUESTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(sig: libc::c_int) {
    if REQUESTED.swap(true, Ordering::SeqCst) {
        // Second signal: the default action, now.
        unsafe {
            libc::signal(sig, libc::SIG_DFL);
            libc::raise(sig);
        }
    }
}

/// Install the handler for SIGINT and SIGTERM (once, at the start of a command that runs units).
pub(crate) fn install() {
    unsafe {
        libc::signal(libc::SIGINT, on_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as *const () as libc::sighandler_t);
    }
}

/// Give SIGINT and SIGTERM their default action again (they end the process): for `talus view`
/// after `talus demo`'s run, whose serving loop never looks at the flag.
pub(crate) fn uninstall() {
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
        libc::signal(libc::SIGTERM, libc::SIG_DFL);
    }
}

/// Ask for an interruption, as SIGINT does (for a host that catches the signal itself: the
/// Python bindings, whose interpreter owns SIGINT).
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Forget an interruption once the run it stopped has returned, so that the next run in this
/// process starts (the Python bindings; the command line exits instead).
pub fn reset() {
    REQUESTED.store(false, Ordering::SeqCst);
}

/// Has an interruption been asked for?
pub(crate) fn requested() -> bool {
    REQUESTED.load(Ordering::Relaxed)
}

/// `Err(Error::Interrupted)` once an interruption has been asked for.
pub(crate) fn check() -> Result<()> {
    if requested() {
        Err(Error::Interrupted)
    } else {
        Ok(())
    }
}
