//! `specmux.SpecmuxError`: every error of the library reaches Python as this exception, carrying
//! the library's one-line message (the text the CLI prints after `specmux: `).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::{PyErr, PyResult, Python};

create_exception!(
    specmux,
    SpecmuxError,
    PyException,
    "An error of the specmux library: its one-line message names the file, key and value."
);

/// A library error (core, twin, controller, JSON) as a `SpecmuxError` with its one-line message.
pub fn err(e: impl std::fmt::Display) -> PyErr {
    SpecmuxError::new_err(e.to_string())
}

/// Runs `work` on a scoped thread with the GIL released, looking at Python's signals every
/// 50 ms: a Ctrl-C asks the library's loops to stop (`core::interrupt`) and, once the work has
/// stopped at its safe point, is raised as `KeyboardInterrupt` (the request is then cleared, so
/// the session goes on). Without this a Ctrl-C waits for the whole call.
pub fn interruptible<T: Send>(py: Python<'_>, work: impl FnOnce() -> T + Send) -> PyResult<T> {
    use specmux_core::interrupt;
    use std::panic::{catch_unwind, AssertUnwindSafe};
    use std::sync::mpsc::{channel, RecvTimeoutError};
    use std::time::Duration;
    std::thread::scope(|s| {
        let (done, mut finished) = channel();
        s.spawn(move || done.send(catch_unwind(AssertUnwindSafe(work))));
        let mut stop: Option<PyErr> = None;
        loop {
            // The receiver is moved through the GIL-free wait (it is not Sync).
            let (got, back) = py.detach(move || {
                let got = finished.recv_timeout(Duration::from_millis(50));
                (got, finished)
            });
            finished = back;
            match got {
                Ok(out) => {
                    if stop.is_some() {
                        interrupt::clear();
                    }
                    return match (stop, out) {
                        (Some(e), _) => Err(e),
                        (None, Ok(out)) => Ok(out),
                        (None, Err(_)) => Err(SpecmuxError::new_err("internal error: a panic")),
                    };
                }
                Err(RecvTimeoutError::Disconnected) => unreachable!("the worker always sends"),
                Err(RecvTimeoutError::Timeout) => {}
            }
            if stop.is_none() {
                if let Err(e) = py.check_signals() {
                    interrupt::request();
                    stop = Some(e);
                }
            }
        }
    })
}
