//! Scenes: procedural (dead leaves, shaded objects, bars), EXR cubes and Mitsuba renders, and the
//! reflectance library split into the basis's training half and the scenes' held-out half.

pub mod bars;
pub mod config;
pub use specmux_core::dead_leaves;
pub mod mitsuba;
pub mod shaded;

pub use config::{exr_geometry, Quantity, SceneConfig};

use rayon::prelude::*;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;
use specmux_core::spectral::Library;
use specmux_core::Cube;

/// A spectral cube on a wavelength grid: reflectance (lit later by the experiment's illuminant)
/// or radiance.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub cube: Cube,
    pub grid: Grid,
    pub quantity: Quantity,
}

/// The measured reflectance library split in two disjoint halves (alternate samples): one trains
/// the spectral basis, the other paints the scenes, so that a scene never contains the very
/// spectra the basis was fitted to.
#[derive(Clone, Debug)]
pub struct Materials {
    pub train: Vec<Curve>,
    pub held_out: Vec<Curve>,
}

impl Materials {
    /// Every curve under `spectra/reflectance/`, split even/odd.
    pub fn load(lib: &Library) -> Result<Materials> {
        let all = lib.folder("reflectance")?;
        let (mut train, mut held_out) = (Vec::new(), Vec::new());
        for (k, c) in all.into_iter().enumerate() {
            if k % 2 == 0 {
                train.push(c)
            } else {
                held_out.push(c)
            }
        }
        Ok(Materials { train, held_out })
    }
}

/// Check a `[scene]` section: the source names a built-in scene, an EXR cube or a Mitsuba
/// render, and the size and grid are valid; the error names the key and the value.
pub fn validate(cfg: &SceneConfig, f: &str) -> Result<()> {
    let known = ["dead-leaves", "shaded-objects", "bars"];
    let prefixed = ["exr:", mitsuba::PREFIX].map(|p| cfg.source.starts_with(p));
    if !known.contains(&cfg.source.as_str()) && !prefixed.contains(&true) {
        return Err(Error::config(
            f,
            "scene.source",
            format!("\"{}\"", cfg.source),
            "expected \"dead-leaves\", \"shaded-objects\", \"bars\", \"exr:<path>\" or \"mitsuba:<prefix>\"",
        ));
    }
    mitsuba::check(cfg, f)?;
    check_source_file(cfg, f)?;
    cfg.validate(f)
}

/// The file an `exr:` or `mitsuba:` source reads is there (a path relative to the experiment
/// file `f`), so a missing one is named by its key before any work.
fn check_source_file(cfg: &SceneConfig, f: &str) -> Result<()> {
    let path = if let Some(rel) = cfg.source.strip_prefix("exr:") {
        cfg.path(rel, f)
    } else if let Some(rel) = cfg.source.strip_prefix(mitsuba::PREFIX) {
        mitsuba::truth_path(&cfg.path(rel, f))
    } else {
        return Ok(());
    };
    config::source_file_there(cfg, f, &path)
}

/// Build the experiment's scene: a procedural one from held-out materials, or an EXR cube.
pub fn build(cfg: &SceneConfig, file: &str, materials: &Materials) -> Result<Scene> {
    build_at(cfg, file, materials, 0.0)
}

/// The scene at time `t_s` (s): moving objects shifted by `velocity_px_per_s`·t; a still
/// scene is the same at every time.
pub fn build_at(cfg: &SceneConfig, file: &str, materials: &Materials, t_s: f64) -> Result<Scene> {
    let grid = cfg.grid(file)?;
    let [w, h] = cfg.size;
    let spectra: Vec<Vec<f32>> = materials
        .held_out
        .iter()
        .map(|c| c.sample(&grid).into_iter().map(|v| v as f32).collect())
        .collect();
    let src = cfg.source.as_str();
    let cube = match src {
        "dead-leaves" | "bars" => {
            let labels = if src == "bars" {
                bars::labels(w, h, spectra.len(), cfg.seed)
            } else {
                dead_leaves::labels(w, h, spectra.len(), cfg.seed)
            };
            paint(w, h, grid.count, |b, p| spectra[labels[p] as usize][b])
        }
        "shaded-objects" => {
            // The background is black velvet: a flat 2 % reflectance.
            let [vx, vy] = cfg.velocity_px_per_s;
            let s = shaded::spheres_at(w, h, spectra.len(), cfg.seed, [vx * t_s, vy * t_s]);
            let refl = |m: Option<u32>, b: usize| m.map_or(0.02, |m| spectra[m as usize][b]);
            paint(w, h, grid.count, |b, p| {
                let (m1, w1, m2, w2) = s.layers[p];
                w1 * refl(m1, b) + w2 * refl(m2, b)
            })
        }
        s if s.starts_with(mitsuba::PREFIX) => {
            // A render is radiance, whatever the key says (`mitsuba::check` refuses another).
            let cube = mitsuba::cube(cfg, file, &grid)?;
            let quantity = Quantity::Radiance;
            return Ok(Scene {
                name: src.to_string(),
                cube,
                grid,
                quantity,
            });
        }
        _ => return exr_scene(cfg, file, &grid),
    };
    Ok(Scene {
        name: src.to_string(),
        cube,
        grid,
        quantity: cfg.quantity,
    })
}

/// A cube whose plane b, pixel p is `value(b, p)`, filled in parallel over planes.
fn paint(w: usize, h: usize, bands: usize, value: impl Fn(usize, usize) -> f32 + Sync) -> Cube {
    let mut cube = Cube::zeros(w, h, bands);
    cube.data
        .par_chunks_mut(w * h)
        .enumerate()
        .for_each(|(b, plane)| {
            plane
                .iter_mut()
                .enumerate()
                .for_each(|(p, v)| *v = value(b, p))
        });
    cube
}

/// A cube read from EXR; its channel names must carry the grid's wavelengths.
fn exr_scene(cfg: &SceneConfig, file: &str, grid: &Grid) -> Result<Scene> {
    let rel = cfg.source.trim_start_matches("exr:");
    let path = cfg.path(rel, file);
    let (cube, names) = specmux_io::exr::read(&path)?;
    let err = |msg: String| Error::Exr {
        path: path.clone(),
        msg,
    };
    if [cube.width, cube.height] != cfg.size {
        let [w, h] = cfg.size;
        return Err(Error::config(
            file,
            "scene.size",
            format!("[{w}, {h}]"),
            &format!(
                "{} is {}×{}: an EXR scene takes its size from the file",
                path.display(),
                cube.width,
                cube.height
            ),
        ));
    }
    if cube.planes != grid.count {
        return Err(err(format!(
            "{} channels, the experiment's grid scene.wavelengths_nm has {} bands",
            cube.planes, grid.count
        )));
    }
    for (k, n) in names.iter().enumerate() {
        match specmux_io::exr::parse_band_name(n) {
            Some(wl) if (wl - grid.wavelength(k)).abs() < 1e-3 => {}
            _ => {
                return Err(err(format!(
                    "channel `{n}` should be band {} nm",
                    grid.wavelength(k)
                )))
            }
        }
    }
    if let Some(at) = specmux_io::exr::first_value(&cube, &names, |v| !v.is_finite()) {
        return Err(err(format!("{at}: a scene's values must be finite")));
    }
    if let Some(at) = specmux_io::exr::first_value(&cube, &names, |v| v < 0.0) {
        let what = match cfg.quantity {
            Quantity::Reflectance => "a reflectance",
            Quantity::Radiance => "a radiance",
        };
        return Err(err(format!("{at}: {what} cannot be negative")));
    }
    Ok(Scene {
        name: rel.to_string(),
        cube,
        grid: *grid,
        quantity: cfg.quantity,
    })
}
