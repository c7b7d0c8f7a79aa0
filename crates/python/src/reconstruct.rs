//! `reconstruct` (a cube from a frame, calibrated from the user's measured frames or the twin's
//! captures, as `specmux reconstruct`), `Reconstructor` (the same built once and applied to
//! frame after frame, with the real-time path) and `metrics` (an estimate against its truth).

use crate::calibration;
use crate::convert::{cube_array, describe, is_integer, kept, library, to_cube, to_frame, to_py};
use crate::error::{err, interruptible};
use crate::experiment::PyExperiment;
use numpy::{PyArray3, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_core::calibration::{Calibration, CalibrationFrames};
use specmux_core::reconstructor::{Reconstruction, Reconstructor};
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_report::commands::{frame_calibration, frame_experiment, size_note, Measured};
use specmux_twin::device::DeviceReconstructor;
use specmux_twin::experiment::Experiment;
use specmux_twin::scene::Materials;
use specmux_twin::Rig;
use std::ffi::CString;
use std::path::PathBuf;

/// Reconstruct a cube from a frame of this experiment's rig, as `specmux reconstruct` does.
///
/// `frame`: (height, width); its size sets the experiment's. A float array is in the frame's
/// units (raw DN when the experiment has `[rig.sensor]`); an integer array (uint16 from a
/// camera) is raw DN and needs `[rig.sensor]`. `calibration`: the frames the rig measured, a
/// dict `{"dark": (h, w), "flat": (h, w), "patterns": (n, h, w) or [(h, w), …]}` in the frame's
/// units (`dark` and `flat` both or neither; without them the patterns are taken as linear),
/// as `simulate(exp)["calibration"]` returns them; the core calibrates from these alone
/// (`Calibration::from_frames`). Without it the twin simulates the rig's calibration captures.
/// Returns the cube (bands, height, width) float32, or with `full=True` a dict with `cube`,
/// `xhat` (demultiplexed channels), `xgap` (after de-aliasing), the `unmix`, `gap` and `joint`
/// statistics, `calibration` (`source` and the measured `carriers`) and `seconds`
/// (demultiplex, de-alias, unmix), `mean_snr` (the frame's mean signal over its noise, None
/// without a camera noise model and a dark frame) and `device` (where it ran: the experiment's
/// `[compute] device`, a GPU only in a build with the `gpu` feature). A frame under its noise
/// raises a `UserWarning`. The GIL is released while it runs.
#[pyfunction]
#[pyo3(signature = (exp, frame, calibration = None, full = false, spectra = None))]
pub fn reconstruct<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    frame: &Bound<'py, PyAny>,
    calibration: Option<&Bound<'py, PyAny>>,
    full: bool,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let raw_dn = is_integer(frame)?.then_some("frame (an integer array) is raw DN");
    let frame = to_frame(frame, "frame", None)?;
    if let Some(w) = size_note(&exp.inner, &frame) {
        warn(py, &[w])?;
    }
    let e = frame_experiment(&exp.inner, &frame, raw_dn).map_err(err)?;
    let measured = calibration
        .map(|c| calibration::from_dict(c, frame.width, frame.height))
        .transpose()?;
    let lib = library(spectra);
    let (out, cal, snr, recon) = interruptible(py, move || -> specmux_core::Result<_> {
        let (recon, cal) = calibrated(&e, measured.as_ref(), &lib)?;
        let snr = recon.reconstructor().frame_snr(&frame)?;
        Ok((recon.stages(&frame, None)?, cal, snr, recon))
    })?
    .map_err(err)?;
    result(py, out, &recon, &cal, snr, full)
}

/// The rig's reconstructor for experiment `e` (its frame size set) on its `[compute] device`,
/// calibrated from the user's `measured` frames or, without them, the twin's captures of the rig.
fn calibrated(
    e: &Experiment,
    measured: Option<&CalibrationFrames>,
    lib: &Library,
) -> specmux_core::Result<(DeviceReconstructor, Calibration)> {
    let materials = Materials::load(lib)?;
    let rig = Rig::build(e, lib, &materials)?;
    let measured = measured.map(|frames| Measured {
        frames,
        place: "reconstruct",
        key: "calibration",
    });
    let cal = frame_calibration(e, &rig, &materials, measured, Some(&kept()?))?;
    let device = e.open_device()?;
    let table = device.auto_table();
    let recon = Reconstructor::for_device(&e.reconstruct, &rig.design(), &cal, &e.file, table)?;
    Ok((DeviceReconstructor::new(&device, recon)?, cal))
}

/// What `reconstruct` returns: the cube, or with `full` the dict of every step; `recon`'s
/// warnings for the frame raised as `UserWarning`s first.
fn result<'py>(
    py: Python<'py>,
    out: Reconstruction,
    recon: &DeviceReconstructor,
    cal: &Calibration,
    snr: Option<f64>,
    full: bool,
) -> PyResult<Bound<'py, PyAny>> {
    warn(py, &recon.reconstructor().warnings(snr))?;
    if !full {
        return Ok(cube_array(py, out.cube)?.into_any());
    }
    let d = PyDict::new(py);
    d.set_item("unmix", to_py(py, &out.unmix)?)?;
    d.set_item("gap", to_py(py, &out.gap)?)?;
    d.set_item("joint", to_py(py, &out.joint)?)?;
    let c = PyDict::new(py);
    c.set_item("source", &cal.source)?;
    c.set_item("carriers", to_py(py, &cal.carriers)?)?;
    d.set_item("calibration", c)?;
    d.set_item("seconds", out.seconds.to_vec())?;
    d.set_item("mean_snr", snr)?;
    d.set_item("device", recon.describe())?;
    d.set_item("cube", cube_array(py, out.cube)?)?;
    d.set_item("xhat", cube_array(py, out.xhat)?)?;
    d.set_item("xgap", cube_array(py, out.xgap)?)?;
    Ok(d.into_any())
}

/// Each warning raised as a `UserWarning`.
fn warn(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    for w in warnings {
        PyErr::warn(
            py,
            &py.get_type::<PyUserWarning>(),
            &CString::new(w.as_str())?,
            1,
        )?;
    }
    Ok(())
}

/// A reconstructor built once for an experiment's rig and its frame size (`scene.size`), then
/// applied to frame after frame, as a camera loop does: `Reconstructor(exp, calibration=None)`
/// calibrates as `reconstruct` does (from the dict of measured frames, or the twin's captures);
/// calling it on a frame gives what `reconstruct(exp, frame)` gives, without building the rig,
/// the calibration and the factorisations again, on the experiment's `[compute] device`;
/// `realtime(frame, out=None)` runs the real-time path on the CPU (demultiplexing and the exact
/// non-negative unmixing, no de-aliasing), the channels in a cube it keeps and the bands
/// straight into `out` when given. The GIL is released while either runs.
#[pyclass(name = "Reconstructor", module = "specmux")]
pub struct PyReconstructor {
    exp: Experiment,
    recon: DeviceReconstructor,
    cal: Calibration,
    /// The channels of the last `realtime` frame, kept for the next.
    channels: Cube,
}

#[pymethods]
impl PyReconstructor {
    #[new]
    #[pyo3(signature = (exp, calibration = None, spectra = None))]
    fn new(
        py: Python<'_>,
        exp: &PyExperiment,
        calibration: Option<&Bound<'_, PyAny>>,
        spectra: Option<PathBuf>,
    ) -> PyResult<Self> {
        let e = exp.inner.clone();
        let [w, h] = e.scene.size;
        let measured = calibration
            .map(|c| calibration::from_dict(c, w, h))
            .transpose()?;
        let lib = library(spectra);
        let (recon, cal) =
            interruptible(py, || calibrated(&e, measured.as_ref(), &lib))?.map_err(err)?;
        warn(py, &recon.reconstructor().warnings(None))?;
        let channels = Cube::zeros(w, h, recon.reconstructor().demux.windows.len());
        Ok(PyReconstructor {
            exp: e,
            recon,
            cal,
            channels,
        })
    }

    /// (height, width) of the frames it takes.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        (self.channels.height, self.channels.width)
    }

    /// Bands of the cubes it returns.
    #[getter]
    fn bands(&self) -> usize {
        self.recon.reconstructor().unmixer.bands()
    }

    /// Where `__call__` reconstructs (`[compute] device`): "CPU, N threads" or "GPU NAME (…)".
    #[getter]
    fn device(&self) -> &str {
        self.recon.describe()
    }

    /// The cube of `frame` by the experiment's method, as `reconstruct(exp, frame, full=…)`.
    #[pyo3(signature = (frame, full = false))]
    fn __call__<'py>(
        &self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
        full: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        let frame = self.frame(frame)?;
        let recon = &self.recon;
        let (out, snr) = interruptible(py, || -> specmux_core::Result<_> {
            let snr = recon.reconstructor().frame_snr(&frame)?;
            Ok((recon.stages(&frame, None)?, snr))
        })?
        .map_err(err)?;
        result(py, out, &self.recon, &self.cal, snr, full)
    }

    /// The real-time path on `frame`: demultiplexing and the exact non-negative unmixing (the
    /// cube of `method = "fourier"`), the channels in a cube this reconstructor keeps. Returns the
    /// bands (bands, height, width) float32, unmixed straight into `out` when it is given (a
    /// C-contiguous float32 array of that shape, so the loop allocates nothing), else into a new
    /// array.
    #[pyo3(signature = (frame, out = None))]
    fn realtime<'py>(
        &mut self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
        out: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let frame = self.frame(frame)?;
        let (h, w) = self.shape();
        let shape = [self.recon.reconstructor().unmixer.bands(), h, w];
        let out = match out.map(|a| a.cast_into::<PyArray3<f32>>()).transpose() {
            Err(e) => {
                let kind = describe(&e.into_inner())?;
                return Err(err(format!(
                    "realtime: out must be a C-contiguous float32 array of shape {shape:?} (bands, height, width); this one is {kind}"
                )));
            }
            Ok(Some(a)) if a.shape() != shape => {
                return Err(err(format!(
                    "realtime: out is {:?}, the cube is {shape:?} (bands, height, width)",
                    a.shape()
                )))
            }
            Ok(Some(a)) => a,
            Ok(None) => PyArray3::zeros(py, shape, false),
        };
        let mut view = out.try_readwrite().map_err(err)?;
        let dst = view
            .as_slice_mut()
            .map_err(|_| err("realtime: out must be a C-contiguous float32 array"))?;
        let (recon, channels) = (self.recon.reconstructor(), &mut self.channels);
        py.detach(|| -> specmux_core::Result<()> {
            recon.demultiplex_into(&frame, channels)?;
            recon.unmixer.unmix_into_slice(channels, dst).map(|_| ())
        })
        .map_err(err)?;
        drop(view);
        Ok(out)
    }
}

impl PyReconstructor {
    /// `frame` as a frame of this reconstructor's size, finite; an integer (raw DN) frame needs
    /// the experiment's camera, as in `reconstruct`.
    fn frame(&self, frame: &Bound<'_, PyAny>) -> PyResult<Cube> {
        let raw_dn = is_integer(frame)?.then_some("frame (an integer array) is raw DN");
        let f = to_frame(frame, "frame", None)?;
        let (w, h) = (self.channels.width, self.channels.height);
        if (f.width, f.height) != (w, h) {
            return Err(err(format!(
                "frame: {}×{}, this reconstructor was built for {w}×{h} ({}: scene.size)",
                f.width, f.height, self.exp.file
            )));
        }
        if raw_dn.is_some() {
            frame_experiment(&self.exp, &f, raw_dn).map_err(err)?;
        }
        Ok(f)
    }
}

/// PSNR (dB), SSIM, RMSE, NRMSE and SAM (degrees) of an estimate against its truth, both
/// (planes, height, width) or (height, width). Returns a dict (`psnr_db`, `psnr_per_plane`,
/// `ssim`, `ssim_per_plane`, `rmse`, `nrmse`, `sam_deg` (None where undefined), `peak`, `flags`,
/// …); per-plane PSNR of an exact plane is None (+inf).
#[pyfunction]
pub fn metrics<'py>(
    py: Python<'py>,
    truth: &Bound<'py, PyAny>,
    estimate: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let t = to_cube(truth, "truth")?;
    let e = to_cube(estimate, "estimate")?;
    let m = py
        .detach(move || specmux_core::metrics::compare(&t, &e))
        .map_err(err)?;
    to_py(py, &m)
}
