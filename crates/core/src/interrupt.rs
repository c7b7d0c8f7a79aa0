//! A process-wide stop request (Ctrl-C): the command line sets it, long loops poll it and end
//! with `Error::Interrupted`, so a run stops at a safe point and writes nothing half-done.

use crate::{Error, Result};
use std::sync::atomic::{AtomicBool, Ordering};

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Ask every running loop to stop at its next safe point.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Whether a stop has been asked for.
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// Forget an earlier request (tests, and a Python session that goes on after Ctrl-C).
pub fn clear() {
    REQUESTED.store(false, Ordering::SeqCst);
}

/// `Err(Error::Interrupted)` naming `during` when a stop has been asked for.
pub fn check(during: &str) -> Result<()> {
    check_flag(&REQUESTED, during)
}

/// `check` against a given flag: tests use their own, since the process-wide one would stop
/// every loop of the tests running beside them.
fn check_flag(flag: &AtomicBool, during: &str) -> Result<()> {
    if flag.load(Ordering::SeqCst) {
        Err(Error::Interrupted(during.to_string()))
    } else {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_turns_check_into_an_error_naming_the_step() {
        let flag = AtomicBool::new(false);
        assert!(check_flag(&flag, "GAP iteration 3").is_ok());
        flag.store(true, Ordering::SeqCst);
        let e = check_flag(&flag, "GAP iteration 3")
            .unwrap_err()
            .to_string();
        assert!(e.contains("GAP iteration 3"), "{e}");
        flag.store(false, Ordering::SeqCst);
        assert!(check_flag(&flag, "x").is_ok());
    }
}
