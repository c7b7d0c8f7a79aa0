//! `specmux.SpecmuxError`: every error of the library reaches Python as this exception, carrying
//! the library's one-line message (the text the CLI prints after `specmux: `).

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::PyErr;

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
