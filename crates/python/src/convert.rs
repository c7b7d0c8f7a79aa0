//! What crosses between Python and the library: numpy arrays as cubes and frames (float32,
//! `(planes, height, width)`, the memory order of `specmux_core::Cube`), reports as Python
//! dicts and lists (through their JSON form), the spectral library, the output folder and the
//! pattern cache the calls share.

use crate::error::err;
use numpy::ndarray::{Array2, Array3};
use numpy::{IntoPyArray, PyArray2, PyArray3, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::pattern_cache::PatternCache;
use std::path::PathBuf;
use std::sync::OnceLock;

/// The spectral library: `spectra` if given, else `$SPECMUX_SPECTRA`, else the copy of
/// `spectra/` embedded in the module.
pub fn library(spectra: Option<PathBuf>) -> Library {
    spectra
        .map(Library::new)
        .unwrap_or_else(Library::default_root)
}

/// A cube as a (planes, height, width) float32 array (moves the data, no copy).
pub fn cube_array(py: Python<'_>, c: Cube) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let a = Array3::from_shape_vec((c.planes, c.height, c.width), c.data).map_err(err)?;
    Ok(a.into_pyarray(py))
}

/// A one-plane cube as a (height, width) float32 array.
pub fn frame_array(py: Python<'_>, c: Cube) -> PyResult<Bound<'_, PyArray2<f32>>> {
    if c.planes != 1 {
        return Err(err(format!(
            "a frame has one plane, this one has {}",
            c.planes
        )));
    }
    let a = Array2::from_shape_vec((c.height, c.width), c.data).map_err(err)?;
    Ok(a.into_pyarray(py))
}

/// A numpy array (or anything `numpy.asarray` takes) of 2 dimensions (height, width) or 3
/// (planes, height, width) as a cube; any real dtype is converted to float32.
pub fn to_cube(a: &Bound<'_, PyAny>, what: &str) -> PyResult<Cube> {
    let np = a.py().import("numpy")?;
    let arr = np
        .call_method1("ascontiguousarray", (a, np.getattr("float32")?))
        .map_err(|e| err(format!("{what}: expected a real numpy array ({e})")))?;
    let arr: PyReadonlyArrayDyn<f32> = arr
        .extract()
        .map_err(|_| err(format!("{what}: expected a real numpy array")))?;
    let shape = arr.shape().to_vec();
    let (planes, height, width) = match shape.as_slice() {
        [h, w] => (1, *h, *w),
        [p, h, w] => (*p, *h, *w),
        _ => {
            return Err(err(format!(
                "{what}: expected shape (height, width) or (planes, height, width), got {shape:?}"
            )))
        }
    };
    let data = arr
        .as_slice()
        .map_err(|e| err(format!("{what}: {e}")))?
        .to_vec();
    Cube::from_vec(width, height, planes, data).map_err(err)
}

/// One camera frame of `width` × `height` (None: any size), finite, as the CLI reads a frame
/// file; `what` names it in errors.
pub fn to_frame(a: &Bound<'_, PyAny>, what: &str, size: Option<(usize, usize)>) -> PyResult<Cube> {
    let f = to_cube(a, what)?;
    if f.planes != 1 {
        return Err(err(format!(
            "{what}: a frame has one plane, this array has {}",
            f.planes
        )));
    }
    check_frame(&f, what, size)?;
    Ok(f)
}

/// Every plane of `f` is `width` × `height` (None: any size), finite and within the range the
/// reconstruction takes ([`Cube::frame_problem`]); `what` names it.
pub fn check_frame(f: &Cube, what: &str, size: Option<(usize, usize)>) -> PyResult<()> {
    if let Some((w, h)) = size.filter(|&s| s != (f.width, f.height)) {
        return Err(err(format!(
            "{what}: shape (height, width) ({}, {}), the frame's is ({h}, {w})",
            f.height, f.width
        )));
    }
    match f.frame_problem(what) {
        Some(why) => Err(err(why)),
        None => Ok(()),
    }
}

/// What `a` is, for an error: "float64 with 3 dimensions" for an array, "a list" otherwise.
pub fn describe(a: &Bound<'_, PyAny>) -> PyResult<String> {
    let array = (a.getattr("dtype")).and_then(|d| Ok((d.str()?, a.getattr("ndim")?)));
    Ok(match array {
        Ok((dtype, ndim)) => format!("{dtype} with {ndim} dimensions"),
        Err(_) => format!("a {}", a.get_type().name()?),
    })
}

/// True when `a` holds integers (`numpy.asarray(a).dtype.kind` is `i` or `u`): raw DN, as a
/// camera delivers them.
pub fn is_integer(a: &Bound<'_, PyAny>) -> PyResult<bool> {
    let kind: String = a
        .py()
        .import("numpy")?
        .call_method1("asarray", (a,))?
        .getattr("dtype")?
        .getattr("kind")?
        .extract()?;
    Ok(kind == "i" || kind == "u")
}

/// A serialisable value (a report, a plan, an event) as Python dicts, lists and numbers.
pub fn to_py<'py>(py: Python<'py>, value: &impl serde::Serialize) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(value).map_err(err)?;
    py.import("json")?.call_method1("loads", (text,))
}

/// The folder a command writes into: the caller's, or a temporary one removed when dropped.
pub struct OutDir {
    pub path: PathBuf,
    temporary: bool,
}

impl OutDir {
    /// `out` when given, else a new folder under the system's temporary directory.
    pub fn new(out: Option<PathBuf>, command: &str) -> OutDir {
        match out {
            Some(path) => OutDir {
                path,
                temporary: false,
            },
            None => {
                static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
                let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let name = format!("specmux-{command}-{}-{n}", std::process::id());
                OutDir {
                    path: std::env::temp_dir().join(name),
                    temporary: true,
                }
            }
        }
    }

    /// The folder for the caller (None when it is temporary).
    pub fn kept(&self) -> Option<String> {
        (!self.temporary).then(|| self.path.display().to_string())
    }

    /// The command's printed text for the caller: a temporary folder is removed on return, so
    /// its path is replaced by a note saying so rather than left pointing nowhere.
    pub fn text(&self, text: String) -> String {
        if !self.temporary {
            return text;
        }
        text.replace(
            &self.path.display().to_string(),
            "(a temporary folder, removed; pass out= to keep the files)",
        )
    }

    /// Read a UTF-8 file the command wrote.
    pub fn read(&self, name: &str) -> PyResult<String> {
        let p = self.path.join(name);
        std::fs::read_to_string(&p).map_err(|e| err(format!("{}: {e}", p.display())))
    }
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if self.temporary {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// The cache the module's calls share: `$SPECMUX_PATTERN_CACHE`'s folder, else the last rig's
/// imaged patterns and calibration captures in this process's memory (about 33 MB for the full
/// rig at 768²), so that a second call on the same rig images and captures nothing.
pub(crate) fn kept() -> specmux_core::Result<PatternCache> {
    static MEMORY: OnceLock<PatternCache> = OnceLock::new();
    match PatternCache::from_env()? {
        Some(folder) => Ok(folder),
        None => Ok(MEMORY.get_or_init(PatternCache::in_memory).clone()),
    }
}
