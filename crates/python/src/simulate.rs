//! `simulate` (the frame the camera records, the truth and the calibration frames the rig would
//! capture) and `run` (simulate, reconstruct and compare every stage: `specmux demo`).

use crate::calibration;
use crate::convert::{cube_array, frame_array, kept, library, to_py};
use crate::error::{err, interruptible};
use crate::experiment::PyExperiment;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_twin::forward::Pipeline;
use specmux_twin::run as twin_run;
use specmux_twin::scene::Materials;
use specmux_twin::Rig;
use std::path::PathBuf;

/// Simulate the frame the camera records.
///
/// Returns a dict: `frame` (height, width), `truth` (bands, height, width), `channels`
/// (filters, height, width: the scene through each wheel filter), `exposed` (what each pattern
/// saw), `patterns` (the patterns as they reach the sample), `calibration` (the frames the
/// rig's calibration captures, as `reconstruct(calibration=…)` takes them: `dark`, `flat`
/// (None without `[rig.sensor]`) and `patterns` (one white-target capture per carrier); None
/// for `[calibration] source = "oracle"`, which is no capture), `raw` (True when the frame and
/// the calibration frames are in raw DN), `full_scale`, `stages` (name and seconds of each
/// forward stage).
#[pyfunction]
#[pyo3(signature = (exp, spectra = None))]
pub fn simulate<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = exp.inner.clone();
    let lib = library(spectra);
    let (sim, stages, frames) = interruptible(py, move || -> specmux_core::Result<_> {
        let materials = Materials::load(&lib)?;
        let rig = Rig::build(&e, &lib, &materials)?;
        let cache = kept()?;
        let pipeline =
            Pipeline::build(&e, &rig, &materials)?.with_pattern_cache(Some(cache.clone()));
        let (sim, mut stages) = pipeline.run()?;
        let frames = twin_run::captured_calibration(&e, &rig, &sim, Some(&cache), &mut stages)?;
        Ok((sim, stages, frames))
    })?
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
    let cal = frames.map(|f| calibration::to_dict(py, f)).transpose()?;
    d.set_item("calibration", cal)?;
    Ok(d)
}

/// Simulate, reconstruct and compare every stage with the truth: what `specmux demo` prints.
///
/// Returns a dict: `report` (the run report, as `report.json` of `specmux demo`), `table` (the
/// text table the CLI prints) and the arrays `frame`, `truth`, `channels`, `xhat` (channel
/// estimates) and `cube` (the reconstructed cube).
#[pyfunction]
#[pyo3(signature = (exp, spectra = None))]
pub fn run<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = exp.inner.clone();
    let lib = library(spectra);
    let (rep, data) =
        interruptible(py, move || twin_run::run_in(&e, &lib, Some(&kept()?)))?.map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("report", to_py(py, &rep)?)?;
    d.set_item("table", rep.table())?;
    d.set_item("frame", frame_array(py, data.frame)?)?;
    d.set_item("truth", cube_array(py, data.truth)?)?;
    d.set_item("channels", cube_array(py, data.channels)?)?;
    d.set_item("xhat", cube_array(py, data.xhat)?)?;
    d.set_item("cube", cube_array(py, data.cube)?)?;
    Ok(d)
}
