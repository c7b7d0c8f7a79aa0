//! The scene's configuration (`[scene]`): what is imaged, its size and its band grid.

use serde::{Deserialize, Serialize};
use specmux_core::error::check_count;
use specmux_core::spectral::Grid;
use specmux_core::{Error, Result};
use std::path::{Path, PathBuf};

/// The side lengths a frame may have, in pixels (`scene.size`, and `--size` where a command
/// takes one).
pub const SIDE_PX: std::ops::RangeInclusive<usize> = 16..=8192;

/// What is imaged.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// `dead-leaves`, `shaded-objects`, `bars`, `exr:<path>` (a reflectance or radiance cube,
    /// relative to the experiment file; its size and band grid come from the file), or
    /// `mitsuba:<prefix>` (a Mitsuba render `<prefix>_truth.exr`, radiance; scene/mitsuba.rs).
    pub source: String,
    /// Width and height in pixels (procedural scenes; the prototype's 768 × 768; an EXR cube's
    /// own).
    pub size: [usize; 2],
    /// Illuminant curve (a library name, or a `.csv` file relative to the experiment) for a
    /// reflectance scene; for a radiance scene the light
    /// that lit it (the basis is lit by it, rig.rs), `""` for none.
    pub illuminant: String,
    /// `reflectance` (lit by `illuminant`) or `radiance` (used as it is). Required for an
    /// `exr:` cube: the file cannot say which it holds.
    pub quantity: Quantity,
    /// Seed of the scene's random draws.
    pub seed: u64,
    /// Band grid: first and last band centre and the step, in nm (the CAVE grid 400–700/10).
    pub wavelengths_nm: [f64; 3],
    /// Speed of the objects over the static background, in pixels per second of rig time
    /// (`shaded-objects` only): the spheres move, the velvet stays. Default [0, 0] (still).
    /// The forward model images the scene at t = 0; the controller's rehearsal images it at
    /// each exposure's mid-time.
    pub velocity_px_per_s: [f64; 2],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Quantity {
    Reflectance,
    Radiance,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            source: "dead-leaves".into(),
            size: [768, 768],
            illuminant: "illuminants/D65".into(),
            quantity: Quantity::Reflectance,
            seed: 7,
            wavelengths_nm: [400.0, 700.0, 10.0],
            velocity_px_per_s: [0.0, 0.0],
        }
    }
}

impl SceneConfig {
    /// The band grid of `wavelengths_nm`; `file` names the experiment in errors.
    pub fn grid(&self, file: &str) -> Result<Grid> {
        let [lo, hi, step] = self.wavelengths_nm;
        let count = ((hi - lo) / step).round() as usize + 1;
        if ((count - 1) as f64 * step + lo - hi).abs() > 1e-6 * step {
            return Err(Error::config(
                file,
                "scene.wavelengths_nm",
                format!("[{lo}, {hi}, {step}]"),
                "the step must divide last − first",
            ));
        }
        Grid::new(lo, step, count).map_err(|e| {
            Error::config(
                file,
                "scene.wavelengths_nm",
                format!("[{lo}, {hi}, {step}]"),
                &e.to_string(),
            )
        })
    }

    /// A path the experiment names (an `exr:` source, a CSV curve), relative to the experiment
    /// file's folder.
    pub fn path(&self, rel: &str, file: &str) -> PathBuf {
        let p = Path::new(rel);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        Path::new(file)
            .parent()
            .map(|d| d.join(p))
            .unwrap_or_else(|| p.to_path_buf())
    }

    /// Check the size and band grid (the source: `scene::validate`); the error names the key and
    /// the value.
    pub fn validate(&self, f: &str) -> Result<()> {
        for (k, &n) in self.size.iter().enumerate() {
            check_count(f, &format!("scene.size[{k}]"), n, SIDE_PX, "pixels")?;
        }
        self.validate_motion(f)?;
        let [lo, hi, step] = self.wavelengths_nm;
        if !(step.is_finite() && step > 0.0) {
            return Err(Error::config(
                f,
                "scene.wavelengths_nm[2]",
                step,
                "the step must be positive",
            ));
        }
        if !(lo.is_finite() && lo > 0.0 && hi.is_finite() && hi > lo) {
            return Err(Error::config(
                f,
                "scene.wavelengths_nm",
                format!("[{lo}, {hi}, {step}]"),
                "needs 0 < first < last",
            ));
        }
        Ok(())
    }

    /// True when the scene's objects move.
    pub fn moves(&self) -> bool {
        self.velocity_px_per_s != [0.0, 0.0]
    }

    /// A finite speed, and only for a scene whose objects can move.
    fn validate_motion(&self, f: &str) -> Result<()> {
        let v = self.velocity_px_per_s;
        let value = format!("[{}, {}]", v[0], v[1]);
        if !v.iter().all(|c| c.is_finite() && c.abs() <= 1e6) {
            return Err(Error::config(
                f,
                "scene.velocity_px_per_s",
                value,
                "must be finite, at most 1e6 px/s",
            ));
        }
        if self.moves() && self.source != "shaded-objects" {
            return Err(Error::config(
                f,
                "scene.velocity_px_per_s",
                value,
                "only the objects of \"shaded-objects\" can move",
            ));
        }
        Ok(())
    }
}

/// The file `path` that `cfg`'s source reads (an `exr:` cube, a Mitsuba render) is there; else
/// the error names the experiment file, `scene.source` and where the path led.
pub fn source_file_there(cfg: &SceneConfig, file: &str, path: &Path) -> Result<()> {
    match path.is_file() {
        true => Ok(()),
        false => Err(Error::config(
            file,
            "scene.source",
            format!("\"{}\"", cfg.source),
            &format!(
                "{} is not there (a path is relative to the experiment file)",
                path.display()
            ),
        )),
    }
}

/// An `exr:` scene's size and band grid as the file gives them: `scene.size` and
/// `scene.wavelengths_nm` taken from the file when the experiment leaves them out (`wrote`),
/// checked against it when it writes them. `scene.quantity` must be written.
pub fn exr_geometry(
    cfg: &SceneConfig,
    file: &str,
    wrote: impl Fn(&str) -> bool,
) -> Result<SceneConfig> {
    let path = cfg.path(cfg.source.trim_start_matches("exr:"), file);
    source_file_there(cfg, file, &path)?;
    if !wrote("scene.quantity") {
        let why = format!(
            "required for an external cube: say whether {} holds \"reflectance\" (lit by scene.illuminant) or \"radiance\"",
            path.display()
        );
        return Err(Error::config(file, "scene.quantity", "absent", &why));
    }
    let (w, h, names) = specmux_io::exr::header(&path)?;
    if wrote("scene.size") && cfg.size != [w, h] {
        let [a, b] = cfg.size;
        let why = format!(
            "{} is {w}×{h}: leave scene.size out to take the file's size",
            path.display()
        );
        return Err(Error::config(
            file,
            "scene.size",
            format!("[{a}, {b}]"),
            &why,
        ));
    }
    let mut out = cfg.clone();
    out.size = [w, h];
    if !wrote("scene.wavelengths_nm") {
        out.wavelengths_nm = grid_of_channels(&names, &path)?;
    }
    Ok(out)
}

/// `[first, last, step]` of channels named by wavelength (`0400.0nm`) on a uniform grid.
fn grid_of_channels(names: &[String], path: &Path) -> Result<[f64; 3]> {
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    let wl = names
        .iter()
        .map(|n| {
            specmux_io::exr::parse_band_name(n).ok_or_else(|| {
                err(format!(
                    "channel `{n}` names no wavelength: name the bands like 0400.0nm"
                ))
            })
        })
        .collect::<Result<Vec<f64>>>()?;
    if wl.len() < 2 {
        return Err(err(format!(
            "{} channel(s): a spectral cube needs at least two bands",
            wl.len()
        )));
    }
    let step = (wl[wl.len() - 1] - wl[0]) / (wl.len() - 1) as f64;
    for (k, (n, &v)) in names.iter().zip(&wl).enumerate() {
        let want = wl[0] + k as f64 * step;
        if step.is_nan() || step <= 0.0 || (v - want).abs() > 1e-3 * step.abs().max(1.0) {
            return Err(err(format!(
                "channel `{n}` ({v} nm) is off a uniform grid {} to {} nm (band {k} would be {want} nm); channels sort by name, so zero-pad them (0400.0nm)",
                wl[0],
                wl[wl.len() - 1]
            )));
        }
    }
    Ok([wl[0], wl[wl.len() - 1], step])
}
