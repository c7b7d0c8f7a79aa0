//! `specmux.Experiment`: the experiment file of the CLI (scene, rig, calibration,
//! reconstruction) from a file, TOML text, a dict or the built-in prototype.

use crate::error::err;
use crate::toml_value::table;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_twin::Experiment;
use std::path::PathBuf;

/// An experiment: scene, rig, calibration and reconstruction settings (the TOML file of
/// `specmux simulate`/`demo`).
#[pyclass(name = "Experiment", module = "specmux")]
pub struct PyExperiment {
    pub inner: Experiment,
}

#[pymethods]
impl PyExperiment {
    /// Read an experiment file (TOML).
    #[staticmethod]
    fn from_file(path: PathBuf) -> PyResult<Self> {
        Ok(PyExperiment {
            inner: Experiment::load(&path).map_err(err)?,
        })
    }

    /// Parse an experiment from TOML text; `file` names it in error messages.
    #[staticmethod]
    #[pyo3(signature = (text, file = "<string>"))]
    fn from_toml(text: &str, file: &str) -> PyResult<Self> {
        Ok(PyExperiment {
            inner: Experiment::from_toml(text, file).map_err(err)?,
        })
    }

    /// An experiment from a dict with the TOML file's structure
    /// (`{"scene": {"size": [64, 64]}, "rig": {...}}`); absent keys take their defaults.
    #[staticmethod]
    #[pyo3(signature = (d, file = "<dict>"))]
    fn from_dict(d: &Bound<'_, PyDict>, file: &str) -> PyResult<Self> {
        // Read as the same TOML file would be (which keys it wrote, an EXR scene's geometry,
        // the auto table).
        let doc = table(d, file, "")?;
        Ok(PyExperiment {
            inner: Experiment::from_table(&doc, file).map_err(err)?,
        })
    }

    /// The built-in prototype (six-segment wheel, dead-leaves scene), optionally on another
    /// scene source (a built-in name such as "shaded-objects") or size (width = height = size).
    #[staticmethod]
    #[pyo3(signature = (scene = None, size = None))]
    fn prototype(scene: Option<String>, size: Option<usize>) -> PyResult<Self> {
        let mut e = Experiment::prototype();
        if let Some(s) = scene {
            e.scene.source = s;
        }
        if let Some(n) = size {
            e.scene.size = [n, n];
        }
        e.validate().map_err(err)?;
        Ok(PyExperiment { inner: e })
    }

    /// The scene size (width, height) in pixels; settable (validated) to a pair or, for a
    /// square, one int.
    #[getter]
    fn size(&self) -> (usize, usize) {
        (self.inner.scene.size[0], self.inner.scene.size[1])
    }

    #[setter]
    fn set_size(&mut self, size: &Bound<'_, PyAny>) -> PyResult<()> {
        let (w, h) = match size.extract::<usize>() {
            Ok(n) => (n, n),
            Err(_) => size.extract::<(usize, usize)>().map_err(|_| {
                err(format!("size = {size}: a (width, height) pair of pixel counts, or one int for a square"))
            })?,
        };
        let mut e = self.inner.clone();
        e.scene.size = [w, h];
        e.validate().map_err(err)?;
        self.inner = e;
        Ok(())
    }

    /// The file it came from (or "<built-in prototype>", "<string>", "<dict>").
    #[getter]
    fn file(&self) -> String {
        self.inner.file.clone()
    }

    /// The scene source: a built-in scene name or `exr:`/`mitsuba:` file.
    #[getter]
    fn scene(&self) -> String {
        self.inner.scene.source.clone()
    }

    /// The whole experiment as a dict (every key, defaults filled in) that `from_dict` reads
    /// back to the same experiment: sections it lacks are absent, and with `method = "auto"`
    /// the iteration counts auto chooses are left out unless they were written.
    fn to_dict(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let text = serde_json::to_string(&self.inner.to_table().map_err(err)?).map_err(err)?;
        Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
    }

    /// The same as `to_dict`, as the text of an experiment file, which `from_toml` and the
    /// command line (`specmux demo FILE.toml`) read back to the same experiment.
    fn to_toml(&self) -> PyResult<String> {
        toml::to_string(&self.inner.to_table().map_err(err)?).map_err(err)
    }

    fn __repr__(&self) -> String {
        format!(
            "Experiment(file={:?}, scene={:?}, size={}x{})",
            self.inner.file,
            self.inner.scene.source,
            self.inner.scene.size[0],
            self.inner.scene.size[1]
        )
    }
}
