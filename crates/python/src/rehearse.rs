//! `rehearse`: the controller's rehearsal of an acquisition on the simulated rig, as
//! `specmux rehearse` runs it — the plan and its checks, calibration and acquisition on a
//! virtual clock, each frame reconstructed with the calibration acquired in the same run.

use crate::convert::{cube_array, library, to_py, OutDir};
use crate::error::{err, interruptible};
use crate::experiment::PyExperiment;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use specmux_controller::commands::{self as controller, Rehearsed};
use std::path::PathBuf;

/// Rehearse an acquisition of `frames` frames of `exp` on the simulated rig.
///
/// `faults`: faults injected in the simulated devices, `"KIND@N"` as `--fault` takes them
/// (`"dropped-frame@5"`, `"missed-index@10"`, …). `dry_run`: the plan, its checks and
/// timeline only; nothing runs. `cubes`: keep every frame's cube (bands, height, width; 8 MB a
/// frame at 256² × 31 bands). `out`: keep the recording there (`specmux reconstruct OUT`
/// replays it; default: a temporary folder, removed).
///
/// Returns a dict: `plan` (settings, steps, devices, host), `checks` (each `key`, `value`, `ok`,
/// `note`), `timeline` (expected phases, virtual seconds), `passes` (every check passed), and
/// unless `dry_run`: `frames` (per frame `frame_id`, `timestamp_s`, `flags`, `psnr_db`, `ssim`,
/// `sam_deg` against the scene in front of the camera, `reconstruction_s`), `cubes` (a list of
/// arrays, or None), `outcome` (calibration and frame records, `incidents`, `completed`,
/// `stopped_because`), `events` (the devices' log: `t_ns`, `device`, `kind`, `what`),
/// `virtual_s`, `wall_s`; and `text` (what the CLI prints) and `out`. A plan that fails a
/// check raises `SpecmuxError` (except in a dry run, which reports it). The GIL is released
/// while it runs.
#[pyfunction]
#[pyo3(signature = (exp, frames = 100, faults = None, dry_run = false, cubes = false, out = None, spectra = None))]
#[allow(clippy::too_many_arguments)]
pub fn rehearse<'py>(
    py: Python<'py>,
    exp: &PyExperiment,
    frames: usize,
    faults: Option<Vec<String>>,
    dry_run: bool,
    cubes: bool,
    out: Option<PathBuf>,
    spectra: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let e = exp.inner.clone();
    let faults = controller::faults(&faults.unwrap_or_default(), frames, "faults").map_err(err)?;
    let dir = OutDir::new(out, "rehearse");
    let (plan, text) = controller::rehearsal_plan(&e, frames, &dir.path);
    let d = PyDict::new(py);
    d.set_item("plan", to_py(py, &plan)?)?;
    d.set_item("checks", to_py(py, &plan.checks)?)?;
    d.set_item("timeline", to_py(py, &plan.timeline())?)?;
    d.set_item("passes", plan.verify().is_ok())?;
    d.set_item("out", dir.kept())?;
    if dry_run {
        d.set_item("text", dir.text(controller::dry_run(&plan, text)))?;
        return Ok(d);
    }
    let lib = library(spectra);
    let path = dir.path.clone();
    let r: Rehearsed = interruptible(py, move || {
        controller::rehearsal(&e, &plan, faults, &path, cubes, &lib)
    })?
    .map_err(err)?;
    d.set_item("text", dir.text(text + &r.text()))?;
    d.set_item("frames", to_py(py, &r.rows)?)?;
    let arrays = r
        .cubes
        .into_iter()
        .map(|c| cube_array(py, c))
        .collect::<PyResult<Vec<_>>>()?;
    d.set_item("cubes", cubes.then_some(arrays))?;
    d.set_item("outcome", to_py(py, &r.outcome)?)?;
    d.set_item("events", to_py(py, &r.events)?)?;
    d.set_item("virtual_s", r.virtual_s)?;
    d.set_item("wall_s", r.wall_s)?;
    Ok(d)
}
