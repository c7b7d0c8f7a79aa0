//! Ctrl-C during an acquisition: the first SIGINT asks the controller to stop between frames
//! (devices stopped camera → DMD → wheel, files finished); a second one ends the process.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_sigint(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
    // SAFETY: signal() is async-signal-safe; the next Ctrl-C takes the default action.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
    }
}

/// Catch the next Ctrl-C.
pub fn install() {
    STOP.store(false, Ordering::SeqCst);
    // SAFETY: the handler only stores an atomic and restores the default disposition.
    unsafe {
        libc::signal(
            libc::SIGINT,
            on_sigint as extern "C" fn(libc::c_int) as libc::sighandler_t,
        );
    }
}

/// True once Ctrl-C was pressed after `install`.
pub fn requested() -> bool {
    STOP.load(Ordering::SeqCst)
}
