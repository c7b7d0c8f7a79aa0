//! The rig as an experiment resolves it: curves loaded, the projection cube → channels and the
//! spectral basis computed. The forward model, the reconstruction and the controller share it.

use crate::error::{Error, Result};
use crate::optics::wheel::{ColorWheel, Projection};
use crate::optics::Carrier;
use crate::scene::{self, Experiment, Materials, Quantity};
use crate::spectral::{Basis, Curve, Grid, Library};

/// Everything the experiment's rig resolves to: curves loaded, projection and basis computed.
#[derive(Clone, Debug)]
pub struct Rig {
    pub grid: Grid,
    pub wheel: ColorWheel,
    pub qe: Curve,
    /// The illuminant of a reflectance scene; None for a radiance scene.
    pub illuminant: Option<Curve>,
    /// x = W r: cube bands → wheel channels, normalised (see `ColorWheel::projection`).
    pub projection: Projection,
    pub carriers: Vec<Carrier>,
    pub basis: Basis,
    pub width: usize,
    pub height: usize,
}

impl Rig {
    /// Load the rig's curves from the library and precompute the projection and the basis.
    pub fn build(exp: &Experiment, lib: &Library, materials: &Materials) -> Result<Rig> {
        let grid = scene::grid_of(exp)?;
        let named = |key: &str, name: &str| {
            lib.curve(name)
                .map_err(|e| Error::config(&exp.file, key, format!("\"{name}\""), &e.to_string()))
        };
        let filters = exp
            .rig
            .wheel
            .filters
            .iter()
            .enumerate()
            .map(|(i, n)| named(&format!("rig.wheel.filters[{i}]"), n))
            .collect::<Result<Vec<_>>>()?;
        let qe = named("rig.camera.qe", &exp.rig.camera.qe)?;
        let illuminant = match exp.scene.quantity {
            Quantity::Reflectance => Some(named("scene.illuminant", &exp.scene.illuminant)?),
            Quantity::Radiance => None,
        };
        let wheel = ColorWheel { filters };
        let projection = wheel.projection(&grid, illuminant.as_ref(), &qe)?;
        let basis = Basis::train(&materials.train, &grid, exp.reconstruct.basis)?;
        Ok(Rig {
            grid,
            wheel,
            qe,
            illuminant,
            projection,
            carriers: exp.carriers(),
            basis,
            width: exp.scene.size[0],
            height: exp.scene.size[1],
        })
    }

    /// F_ij = ∫ T_i L QE b_j dλ = Σ_b W_ib B_bj (exact for a basis piecewise linear on the grid).
    pub fn system_matrix(&self) -> nalgebra::DMatrix<f64> {
        &self.projection.w * &self.basis.vectors
    }
}
