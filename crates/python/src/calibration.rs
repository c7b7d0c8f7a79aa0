//! Calibration frames as numpy arrays: the dict `simulate` returns (the captures the twin's rig
//! records) and the dict `reconstruct(calibration=…)` takes (frames a user measured), both
//! `{"dark": (h, w) or None, "flat": (h, w) or None, "patterns": (n, h, w)}` in the frame's
//! units. Only the frames cross: the core calibrates from them as from a `--calibration` folder.

use crate::convert::{check_frame, cube_array, frame_array, to_cube, to_frame};
use crate::error::err;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use specmux_core::calibration::CalibrationFrames;
use specmux_core::Cube;

/// The keys of a calibration dict.
const KEYS: [&str; 3] = ["dark", "flat", "patterns"];

/// What `source` says of frames given as arrays (reports and `full=True` name it).
pub const SOURCE: &str = "arrays given to reconstruct(calibration=…)";

/// The frames as a dict of arrays; `dark` and `flat` are None for a rig without a camera model.
pub fn to_dict(py: Python<'_>, f: CalibrationFrames) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    let plane = |c: Option<Cube>| -> PyResult<Option<Bound<'_, PyAny>>> {
        c.map(|c| frame_array(py, c).map(Bound::into_any))
            .transpose()
    };
    d.set_item("dark", plane(f.dark)?)?;
    d.set_item("flat", plane(f.flat)?)?;
    d.set_item("patterns", cube_array(py, f.patterns)?)?;
    Ok(d)
}

/// A calibration dict for frames of `width` × `height`: every array finite and of the frame's
/// size; `patterns` an (n, h, w) array or a list of (h, w) arrays. Without `dark` and `flat`
/// the patterns are taken as linear, as for a `--calibration` folder without them.
pub fn from_dict(d: &Bound<'_, PyAny>, width: usize, height: usize) -> PyResult<CalibrationFrames> {
    let d = d.cast::<PyDict>().map_err(|_| {
        err("calibration: expected a dict {\"dark\": array, \"flat\": array, \"patterns\": [array, …]}")
    })?;
    for k in d.keys() {
        let k = k.str()?.to_string();
        if !KEYS.contains(&k.as_str()) {
            return Err(err(format!(
                "calibration: unknown key {k:?}; the keys are dark, flat and patterns"
            )));
        }
    }
    let size = Some((width, height));
    let plane = |key: &str| -> PyResult<Option<Cube>> {
        match d.get_item(key)? {
            Some(a) if !a.is_none() => {
                to_frame(&a, &format!("calibration[{key:?}]"), size).map(Some)
            }
            _ => Ok(None),
        }
    };
    let (dark, flat) = (plane("dark")?, plane("flat")?);
    let patterns = match d.get_item("patterns")? {
        Some(p) if !p.is_none() => patterns(&p, width, height)?,
        _ => {
            return Err(err(
                "calibration: no \"patterns\": one frame per carrier of the white target",
            ))
        }
    };
    Ok(CalibrationFrames::single(
        dark,
        flat,
        patterns,
        SOURCE.into(),
    ))
}

/// The pattern frames: a list or tuple of (h, w) arrays, or one (n, h, w) array.
fn patterns(p: &Bound<'_, PyAny>, width: usize, height: usize) -> PyResult<Cube> {
    const WHAT: &str = "calibration[\"patterns\"]";
    if !(p.is_instance_of::<PyList>() || p.is_instance_of::<PyTuple>()) {
        let c = to_cube(p, WHAT)?;
        check_frame(&c, WHAT, Some((width, height)))?;
        return Ok(c);
    }
    let planes: Vec<Cube> = p
        .try_iter()?
        .enumerate()
        .map(|(k, a)| to_frame(&a?, &format!("{WHAT}[{k}]"), Some((width, height))))
        .collect::<PyResult<_>>()?;
    let mut out = Cube::zeros(width, height, planes.len());
    for (k, c) in planes.iter().enumerate() {
        out.plane_mut(k).copy_from_slice(&c.data);
    }
    Ok(out)
}
