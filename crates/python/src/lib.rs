//! Python bindings of specmux: the experiment, the twin's forward simulation with its
//! calibration frames, the core's reconstruction (from the twin's captures or the user's
//! measured frames), the metrics, the design tools and the controller's rehearsal, with numpy
//! arrays in and out. Cubes are float32 arrays of shape (bands, height, width) — the memory
//! order of `specmux_core::Cube` — and frames float32 arrays of shape (height, width).
//!
//! Every function calls the library function its CLI command calls. Long work runs with the
//! GIL released on a worker thread, and a Ctrl-C stops it at its next safe point
//! (`error::interruptible`, raised as `KeyboardInterrupt`). Every library
//! error is raised as `specmux.SpecmuxError` carrying the library's one-line message.

mod calibration;
mod convert;
mod design;
mod error;
mod experiment;
mod reconstruct;
mod rehearse;
mod simulate;
mod toml_value;

use pyo3::prelude::*;
use specmux_core::spectral::Library;
use std::path::PathBuf;

/// The folder of the spectral library this module uses by default (`$SPECMUX_SPECTRA`), or
/// None for the copy of `spectra/` embedded in the module at build time.
#[pyfunction]
fn spectra_root() -> Option<PathBuf> {
    Library::default_root().root().map(PathBuf::from)
}

#[pymodule]
fn specmux(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SpecmuxError", m.py().get_type::<error::SpecmuxError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<experiment::PyExperiment>()?;
    m.add_class::<reconstruct::PyReconstructor>()?;
    m.add_function(wrap_pyfunction!(simulate::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate::run, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct::metrics, m)?)?;
    m.add_function(wrap_pyfunction!(design::design_filters, m)?)?;
    m.add_function(wrap_pyfunction!(design::design_carriers, m)?)?;
    m.add_function(wrap_pyfunction!(rehearse::rehearse, m)?)?;
    m.add_function(wrap_pyfunction!(spectra_root, m)?)?;
    Ok(())
}
