//! The colour wheel: its filter curves T_i(λ) and the linear map from a spectral cube to the
//! filtered images, x_i = ∫ T_i(λ) L(λ) QE(λ) r(λ) dλ, computed exactly for a cube read as
//! piecewise linear between band centres.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use specmux_core::error::Result;
use specmux_core::spectral::integrate_product;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;

/// The wheel's filters in segment order.
#[derive(Clone, Debug)]
pub struct ColorWheel {
    pub filters: Vec<Curve>,
}

/// The projection from cube bands to wheel channels, `w[(i, b)]`, normalised so that the
/// brightest channel of a perfect white reflector is 1 (`scale` is the factor applied).
#[derive(Clone, Debug)]
pub struct Projection {
    pub w: DMatrix<f64>,
    pub scale: f64,
}

impl ColorWheel {
    /// w_ib = ∫ T_i · L · QE · hat_b dλ exactly (hat_b: band b's hat function on `grid`), then
    /// normalised. `light` is the illuminant for a reflectance cube, None for a radiance cube.
    pub fn projection(&self, grid: &Grid, light: Option<&Curve>, qe: &Curve) -> Result<Projection> {
        let mut w = DMatrix::zeros(self.filters.len(), grid.count);
        for (i, t) in self.filters.iter().enumerate() {
            for b in 0..grid.count {
                let hat = Curve::hat(grid, b);
                let mut parts = vec![t, qe, &hat];
                if let Some(l) = light {
                    parts.push(l);
                }
                w[(i, b)] = integrate_product(&parts)?;
            }
        }
        let brightest = w.row_iter().map(|r| r.sum()).fold(0.0, f64::max);
        let scale = if brightest > 0.0 {
            1.0 / brightest
        } else {
            1.0
        };
        Ok(Projection {
            w: w * scale,
            scale,
        })
    }
}

/// The colour wheel's segments, as curve names under spectra/.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WheelConfig {
    pub filters: Vec<String>,
}

impl Default for WheelConfig {
    fn default() -> Self {
        // Section 4 of the paper: three dichroic R/G/B segments and three broadband colour papers.
        WheelConfig {
            filters: [
                "wheel/red",
                "wheel/green",
                "wheel/blue",
                "paper/a",
                "paper/b",
                "paper/c",
            ]
            .map(String::from)
            .to_vec(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_spectrum_projects_to_the_filter_integral() {
        // A white reflector (r = 1 on every band) under a flat light with flat QE gives
        // x_i ∝ ∫_400^700 T_i dλ; a box filter 500–600 nm has integral 100 nm.
        let g = Grid::VISIBLE;
        let boxf = Curve::new(
            "box",
            vec![500.0, 500.0001, 600.0, 600.0001],
            vec![0.0, 1.0, 1.0, 0.0],
        )
        .unwrap();
        let half = boxf.scaled(0.5);
        let wheel = ColorWheel {
            filters: vec![boxf, half],
        };
        let flat = Curve::constant("flat", 300.0, 900.0, 1.0).unwrap();
        let p = wheel.projection(&g, Some(&flat), &flat).unwrap();
        let white: Vec<f64> = (0..2).map(|i| p.w.row(i).sum()).collect();
        assert!((white[0] - 1.0).abs() < 1e-12);
        assert!((white[1] - 0.5).abs() < 1e-12);
        assert!((1.0 / p.scale - 100.0).abs() < 1e-3, "{}", 1.0 / p.scale);
    }
}
