//! Scenes: the hyperspectral cube, EXR input/output, procedural scenes, the experiment file.

pub mod cube;
pub mod dead_leaves;
pub mod experiment;
pub mod exr_io;
pub mod shaded;

pub use cube::Cube;
pub use experiment::{Experiment, Quantity};

use crate::error::{Error, Result};
use crate::spectral::{Curve, Grid, Library};
use rayon::prelude::*;

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

/// The experiment's band grid.
pub fn grid_of(exp: &Experiment) -> Result<Grid> {
    let [lo, hi, step] = exp.scene.wavelengths_nm;
    let count = ((hi - lo) / step).round() as usize + 1;
    if ((count - 1) as f64 * step + lo - hi).abs() > 1e-6 * step {
        return Err(Error::config(
            &exp.file,
            "scene.wavelengths_nm",
            format!("[{lo}, {hi}, {step}]"),
            "the step must divide last − first",
        ));
    }
    Grid::new(lo, step, count).map_err(|e| {
        Error::config(
            &exp.file,
            "scene.wavelengths_nm",
            format!("[{lo}, {hi}, {step}]"),
            &e.to_string(),
        )
    })
}

/// Build the experiment's scene: a procedural one from held-out materials, or an EXR cube.
pub fn build(exp: &Experiment, materials: &Materials) -> Result<Scene> {
    let grid = grid_of(exp)?;
    let [w, h] = exp.scene.size;
    let spectra: Vec<Vec<f32>> = materials
        .held_out
        .iter()
        .map(|c| c.sample(&grid).into_iter().map(|v| v as f32).collect())
        .collect();
    let src = exp.scene.source.as_str();
    let cube = match src {
        "dead-leaves" => {
            let labels = dead_leaves::labels(w, h, spectra.len(), exp.scene.seed);
            paint(w, h, grid.count, |b, p| spectra[labels[p] as usize][b])
        }
        "shaded-objects" => {
            // The background is black velvet: a flat 2 % reflectance.
            let s = shaded::spheres(w, h, spectra.len(), exp.scene.seed);
            let refl = |m: Option<u32>, b: usize| m.map_or(0.02, |m| spectra[m as usize][b]);
            paint(w, h, grid.count, |b, p| {
                let (m1, w1, m2, w2) = s.layers[p];
                w1 * refl(m1, b) + w2 * refl(m2, b)
            })
        }
        _ => return exr_scene(exp, &grid),
    };
    Ok(Scene {
        name: src.to_string(),
        cube,
        grid,
        quantity: exp.scene.quantity,
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
fn exr_scene(exp: &Experiment, grid: &Grid) -> Result<Scene> {
    let rel = exp.scene.source.trim_start_matches("exr:");
    let path = exp.scene_path(rel);
    let (cube, names) = exr_io::read(&path)?;
    let err = |msg: String| Error::Exr {
        path: path.clone(),
        msg,
    };
    if cube.planes != grid.count {
        return Err(err(format!(
            "{} channels, the experiment's grid scene.wavelengths_nm has {} bands",
            cube.planes, grid.count
        )));
    }
    for (k, n) in names.iter().enumerate() {
        match exr_io::parse_band_name(n) {
            Some(wl) if (wl - grid.wavelength(k)).abs() < 1e-3 => {}
            _ => {
                return Err(err(format!(
                    "channel `{n}` should be band {} nm",
                    grid.wavelength(k)
                )))
            }
        }
    }
    if !cube.all_finite() {
        return Err(err("contains NaN or infinite values".into()));
    }
    Ok(Scene {
        name: rel.to_string(),
        cube,
        grid: *grid,
        quantity: exp.scene.quantity,
    })
}
