//! `reconstruct` (a cube from a frame, calibrated from the user's measured frames or the twin's
//! captures, as `specmux reconstruct`) and `metrics` (an estimate against its truth).

use crate::calibration;
use crate::convert::{cube_array, is_integer, kept, library, to_cube, to_frame, to_py};
use crate::error::{err, interruptible};
use crate::experiment::PyExperiment;
use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_core::reconstructor::Reconstructor;
use specmux_report::commands::{frame_calibration, frame_experiment, size_note, Measured};
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
/// (demultiplex, de-alias, unmix) and `mean_snr` (the frame's mean signal over its noise, None
/// without a camera noise model and a dark frame). A frame under its noise raises a
/// `UserWarning`. The GIL is released while it runs.
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
        PyErr::warn(py, &py.get_type::<PyUserWarning>(), &CString::new(w)?, 1)?;
    }
    let e = frame_experiment(&exp.inner, &frame, raw_dn).map_err(err)?;
    let measured = calibration
        .map(|c| calibration::from_dict(c, frame.width, frame.height))
        .transpose()?;
    let lib = library(spectra);
    let (out, cal, snr, warnings) = interruptible(py, move || -> specmux_core::Result<_> {
        let materials = Materials::load(&lib)?;
        let rig = Rig::build(&e, &lib, &materials)?;
        let measured = measured.as_ref().map(|frames| Measured {
            frames,
            place: "reconstruct",
            key: "calibration",
        });
        let cache = kept()?;
        let cal = frame_calibration(&e, &rig, &materials, measured, Some(&cache))?;
        let recon = Reconstructor::new(&e.reconstruct, &rig.design(), &cal, &e.file)?;
        let snr = recon.frame_snr(&frame)?;
        Ok((recon.run(&frame, None)?, cal, snr, recon.warnings(snr)))
    })?
    .map_err(err)?;
    for w in warnings {
        PyErr::warn(py, &py.get_type::<PyUserWarning>(), &CString::new(w)?, 1)?;
    }
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
