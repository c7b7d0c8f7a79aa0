//! Python bindings of specmux: the experiment, the twin's forward simulation, the core's
//! reconstruction from the twin's calibration captures, and the metrics, with numpy arrays in
//! and out. Cubes are float32 arrays of shape (bands, height, width) — the memory order of
//! `specmux_core::Cube` — and frames float32 arrays of shape (height, width).
//!
//! Long work runs with the GIL released (`Python::detach`, PyO3's name for what was
//! `allow_threads`). Every library error is raised as `specmux.SpecmuxError` carrying the
//! library's one-line message (the same text the CLI prints after `specmux: `).

use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::forward::{Pipeline, Simulated};
use specmux_twin::scene::Materials;
use specmux_twin::{Experiment, Rig};
use std::path::PathBuf;

create_exception!(
    specmux,
    SpecmuxError,
    PyException,
    "An error of the specmux library: its one-line message names the file, key and value."
);

fn err(e: specmux_core::Error) -> PyErr {
    SpecmuxError::new_err(e.to_string())
}

fn json_err(e: serde_json::Error) -> PyErr {
    SpecmuxError::new_err(e.to_string())
}

/// The spectral library: `spectra` if given, else `$SPECMUX_SPECTRA`, else the `spectra/`
/// folder of the source tree this module was built from (a compile-time path).
fn library(spectra: Option<PathBuf>) -> Library {
    spectra
        .map(Library::new)
        .unwrap_or_else(Library::default_root)
}

/// A cube as a (planes, height, width) float32 array (moves the data, no copy).
fn cube_array<'py>(py: Python<'py>, c: Cube) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let a = Array3::from_shape_vec((c.planes, c.height, c.width), c.data)
        .map_err(|e| SpecmuxError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// A one-plane cube as a (height, width) float32 array.
fn frame_array<'py>(py: Python<'py>, c: Cube) -> PyResult<Bound<'py, PyArray2<f32>>> {
    if c.planes != 1 {
        return Err(SpecmuxError::new_err(format!(
            "a frame has one plane, this one has {}",
            c.planes
        )));
    }
    let a = Array2::from_shape_vec((c.height, c.width), c.data)
        .map_err(|e| SpecmuxError::new_err(e.to_string()))?;
    Ok(a.into_pyarray(py))
}

/// A numpy array of 2 dimensions (height, width) or 3 (planes, height, width) as a cube; any
/// real dtype is converted to float32 by the caller (`numpy.asarray(a, dtype=float32)`).
fn to_cube(a: &Bound<'_, PyAny>, what: &str) -> PyResult<Cube> {
    let np = a.py().import("numpy")?;
    let f32 = np.getattr("float32")?;
    let arr = np.call_method1("ascontiguousarray", (a, f32))?;
    let arr: PyReadonlyArrayDyn<f32> = arr
        .extract()
        .map_err(|_| SpecmuxError::new_err(format!("{what}: expected a real numpy array")))?;
    let shape = arr.shape().to_vec();
    let (planes, height, width) = match shape.as_slice() {
        [h, w] => (1, *h, *w),
        [p, h, w] => (*p, *h, *w),
        _ => {
            return Err(SpecmuxError::new_err(format!(
                "{what}: expected shape (height, width) or (planes, height, width), got {shape:?}"
            )))
        }
    };
    let data = arr
        .as_slice()
        .map_err(|e| SpecmuxError::new_err(format!("{what}: {e}")))?
        .to_vec();
    Cube::from_vec(width, height, planes, data).map_err(err)
}

/// An experiment: scene, rig, calibration and reconstruction settings (the TOML file of
/// `specmux simulate`/`demo`).
#[pyclass(name = "Experiment", module = "specmux")]
struct PyExperiment {
    inner: Experiment,
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
    fn from_dict(py: Python<'_>, d: &Bound<'_, PyDict>, file: &str) -> PyResult<Self> {
        let text: String = py.import("json")?.call_method1("dumps", (d,))?.extract()?;
        let mut e: Experiment = serde_json::from_str(&text)
            .map_err(|x| SpecmuxError::new_err(format!("{file}: {x}")))?;
        e.file = file.to_string();
        e.validate().map_err(err)?;
        Ok(PyExperiment { inner: e })
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

    /// The scene size (width, height) in pixels; settable (validated).
    #[getter]
    fn size(&self) -> (usize, usize) {
        (self.inner.scene.size[0], self.inner.scene.size[1])
    }

    #[setter]
    fn set_size(&mut self, size: (usize, usize)) -> PyResult<()> {
        let mut e = self.inner.clone();
        e.scene.size = [size.0, size.1];
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

    /// The whole experiment as a dict (every key, defaults filled in).
    fn to_dict(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let text = serde_json::to_string(&self.inner).map_err(json_err)?;
        Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
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

/// The forward model of an experiment: rig and simulated products.
fn forward(exp: &Experiment, lib: &Library) -> specmux_core::Result<(Rig, Simulated)> {
    let materials = Materials::load(lib)?;
    let rig = Rig::build(exp, lib, &materials)?;
    let pipeline = Pipeline::build(exp, &rig, &materials)?;
    let (sim, _) = pipeline.run()?;
    Ok((rig, sim))
}

/// Simulate the frame the camera records.
///
/// Returns a dict: `frame` (height, width), `truth` (bands, height, width), `channels`
/// (filters, height, width: the scene through each wheel filter), `exposed` (what each pattern
/// saw), `patterns` (the patterns as they reach the sample), `raw` (True when the frame is in
/// raw DN), `full_scale`, `stages` (name and seconds of each forward stage).
#[pyfunction]
#[pyo3(signature = (exp, spectra = None))]
fn simulate<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = exp.inner.clone();
    let lib = library(spectra);
    let (sim, stages) = py
        .detach(move || -> specmux_core::Result<_> {
            let materials = Materials::load(&lib)?;
            let rig = Rig::build(&e, &lib, &materials)?;
            Pipeline::build(&e, &rig, &materials)?.run()
        })
        .map_err(err)?;
    let d = PyDict::new(py);
    let stages: Vec<(String, f64)> = stages
        .into_iter()
        .map(|s| (s.stage.to_string(), s.seconds))
        .collect();
    d.set_item("raw", sim.raw)?;
    d.set_item("full_scale", sim.full_scale)?;
    d.set_item("stages", stages)?;
    d.set_item("frame", frame_array(py, sim.frame)?)?;
    d.set_item("truth", cube_array(py, sim.scene.cube)?)?;
    d.set_item("channels", cube_array(py, sim.channels)?)?;
    d.set_item("exposed", cube_array(py, sim.exposed)?)?;
    d.set_item("patterns", cube_array(py, sim.patterns)?)?;
    Ok(d)
}

/// Simulate, reconstruct and compare every stage with the truth: what `specmux demo` prints.
///
/// Returns a dict: `report` (the run report, as `report.json` of `specmux demo`), `table` (the
/// text table the CLI prints) and the arrays `frame`, `truth`, `channels`, `xhat` (channel
/// estimates) and `cube` (the reconstructed cube).
#[pyfunction]
#[pyo3(signature = (exp, spectra = None))]
fn run<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = exp.inner.clone();
    let lib = library(spectra);
    let (rep, data) = py
        .detach(move || specmux_twin::run::run(&e, &lib))
        .map_err(err)?;
    let text = serde_json::to_string(&rep).map_err(json_err)?;
    let d = PyDict::new(py);
    d.set_item("report", py.import("json")?.call_method1("loads", (text,))?)?;
    d.set_item("table", rep.table())?;
    d.set_item("frame", frame_array(py, data.frame)?)?;
    d.set_item("truth", cube_array(py, data.truth)?)?;
    d.set_item("channels", cube_array(py, data.channels)?)?;
    d.set_item("xhat", cube_array(py, data.xhat)?)?;
    d.set_item("cube", cube_array(py, data.cube)?)?;
    Ok(d)
}

/// Reconstruct a cube from a frame of this experiment's rig.
///
/// The core is calibrated from the twin's simulated calibration captures (dark, flat, one per
/// pattern; or the oracle when `[calibration] source = "oracle"`), so the experiment's forward
/// model runs once to make them. `frame`: (height, width) or (1, height, width), any real dtype.
/// Returns the cube (bands, height, width) float32, or with `full=True` a dict with `cube`,
/// `xhat` (demultiplexed channels), `xgap` (after de-aliasing), `unmix` and `gap` statistics and
/// `seconds` (demultiplex, de-alias, unmix).
#[pyfunction]
#[pyo3(signature = (exp, frame, full = false, spectra = None))]
fn reconstruct<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    frame: &Bound<'py, PyAny>,
    full: bool,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let frame = to_cube(frame, "frame")?;
    if frame.planes != 1 {
        return Err(SpecmuxError::new_err(format!(
            "frame: expected one plane, got {}",
            frame.planes
        )));
    }
    let e = exp.inner.clone();
    let lib = library(spectra);
    let out = py
        .detach(move || -> specmux_core::Result<_> {
            let (rig, sim) = forward(&e, &lib)?;
            let recon = specmux_twin::run::reconstructor(&e, &rig, &sim)?;
            recon.run(&frame, None)
        })
        .map_err(err)?;
    if !full {
        return Ok(cube_array(py, out.cube)?.into_any());
    }
    let d = PyDict::new(py);
    let json = py.import("json")?;
    let unmix = serde_json::to_string(&out.unmix).map_err(json_err)?;
    let gap = serde_json::to_string(&out.gap).map_err(json_err)?;
    d.set_item("unmix", json.call_method1("loads", (unmix,))?)?;
    d.set_item("gap", json.call_method1("loads", (gap,))?)?;
    d.set_item("seconds", out.seconds.to_vec())?;
    d.set_item("cube", cube_array(py, out.cube)?)?;
    d.set_item("xhat", cube_array(py, out.xhat)?)?;
    d.set_item("xgap", cube_array(py, out.xgap)?)?;
    Ok(d.into_any())
}

/// PSNR (dB), SSIM, RMSE, NRMSE and SAM (degrees) of an estimate against its truth, both
/// (planes, height, width) or (height, width). Returns a dict (`psnr_db`, `psnr_per_plane`,
/// `ssim`, `ssim_per_plane`, `rmse`, `nrmse`, `sam_deg` (None where undefined), `peak`, `flags`,
/// …); per-plane PSNR of an exact plane is None (+inf).
#[pyfunction]
fn metrics<'py>(
    py: Python<'py>,
    truth: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = to_cube(truth, "truth")?;
    let e = to_cube(estimate, "estimate")?;
    let m = py
        .detach(move || specmux_core::metrics::compare(&t, &e))
        .map_err(err)?;
    let text = serde_json::to_string(&m).map_err(json_err)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The folder of the spectral library this module uses by default (`$SPECMUX_SPECTRA`), or
/// None for the copy of `spectra/` embedded in the module at build time.
#[pyfunction]
fn spectra_root() -> Option<PathBuf> {
    Library::default_root().root().map(PathBuf::from)
}

#[pymodule]
fn specmux(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SpecmuxError", m.py().get_type::<SpecmuxError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<PyExperiment>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(metrics, m)?)?;
    m.add_function(wrap_pyfunction!(spectra_root, m)?)?;
    Ok(())
}
