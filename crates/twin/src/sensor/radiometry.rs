//! Radiometry: mean photo-electrons per pixel from the spectral irradiance on the pixel,
//! μ_e = A·t ∫ η(λ) E(λ) λ/(h c) dλ (EMVA 1288: μ_p = A E t λ/(hc) for one wavelength).
//! Integrals are exact: every factor is piecewise linear in λ.

use crate::sensor::Sensor;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::spectral::integrate_product;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;
use specmux_core::Cube;

/// Planck constant (J·s), exact in the SI since 2019.
const PLANCK_J_S: f64 = 6.626_070_15e-34;
/// Speed of light (m/s), exact.
const LIGHT_M_PER_S: f64 = 299_792_458.0;

/// Spectral irradiance on the pixel plane, in W·m⁻²·nm⁻¹.
#[derive(Clone, Copy, Debug)]
pub enum SpectralIrradiance<'a> {
    /// The same spectrum on every pixel.
    Uniform(&'a Curve),
    /// One plane per band of `grid`, read as piecewise linear between band centres.
    Bands { cube: &'a Cube, grid: &'a Grid },
}

/// The curve λ ↦ λ (nm) over `[lo, hi]`: the photon count per joule is λ/(hc).
fn wavelength_curve(lo: f64, hi: f64) -> Result<Curve> {
    Curve::new("wavelength", vec![lo, hi], vec![lo, hi])
}

/// Check a quantum-efficiency curve: values in [0, 1].
fn check_qe(qe: &Curve) -> Result<()> {
    if let Some((w, v)) = qe
        .wavelengths()
        .iter()
        .zip(qe.values())
        .find(|(_, v)| !(**v >= 0.0 && **v <= 1.0))
    {
        return Err(Error::Curve {
            name: qe.name.clone(),
            msg: format!("quantum efficiency {v} at {w} nm lies outside [0, 1]"),
        });
    }
    Ok(())
}

/// A·t/(hc) · ∫ η(λ) · f(λ) · λ dλ for a piecewise-linear f (W·m⁻²·nm⁻¹): electrons.
fn electrons_per_unit(f: &Curve, qe: &Curve, pixel_area_m2: f64, exposure_s: f64) -> Result<f64> {
    let (lo, hi) = f.support();
    let lambda = wavelength_curve(lo, hi)?;
    // ∫ E·η·λ dλ has units W·m⁻²·nm; λ in m brings the factor 1e-9.
    let integral = integrate_product(&[f, qe, &lambda])?;
    Ok(integral * 1e-9 / (PLANCK_J_S * LIGHT_M_PER_S) * pixel_area_m2 * exposure_s)
}

/// Mean photo-electrons of one pixel of area `pixel_area_m2` exposed for `exposure_s` to the
/// spectral irradiance `irradiance` (W·m⁻²·nm⁻¹) with quantum efficiency `qe`.
pub fn photo_electrons(
    irradiance: &Curve,
    qe: &Curve,
    pixel_area_m2: f64,
    exposure_s: f64,
) -> Result<f64> {
    check_qe(qe)?;
    if let Some(v) = irradiance.values().iter().find(|v| **v < 0.0) {
        return Err(Error::Curve {
            name: irradiance.name.clone(),
            msg: format!("irradiance {v} W·m⁻²·nm⁻¹ is negative"),
        });
    }
    for (what, v) in [
        ("pixel area (m²)", pixel_area_m2),
        ("exposure (s)", exposure_s),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::Numerical(format!(
                "{what} is {v}; it must be finite and > 0"
            )));
        }
    }
    electrons_per_unit(irradiance, qe, pixel_area_m2, exposure_s)
}

impl Sensor {
    /// Mean photo-electrons per pixel (one plane, before PRNU) from the spectral irradiance on
    /// the sensor, with the configured pixel pitch (square pixel, fill factor in `qe`) and
    /// exposure time.
    pub fn electrons_from_irradiance(
        &self,
        irradiance: SpectralIrradiance,
        qe: &Curve,
    ) -> Result<Cube> {
        let area = (self.cfg.pixel_pitch_um * 1e-6).powi(2);
        let t = self.cfg.exposure_s;
        match irradiance {
            SpectralIrradiance::Uniform(e) => {
                let electrons = photo_electrons(e, qe, area, t)? as f32;
                Cube::from_vec(
                    self.width,
                    self.height,
                    1,
                    vec![electrons; self.width * self.height],
                )
            }
            SpectralIrradiance::Bands { cube, grid } => {
                check_qe(qe)?;
                if (cube.width, cube.height, cube.planes) != (self.width, self.height, grid.count) {
                    return Err(Error::Shape(format!(
                        "irradiance cube {}×{}×{} for a {}×{} sensor and {} bands",
                        cube.width, cube.height, cube.planes, self.width, self.height, grid.count
                    )));
                }
                if let Some(i) = cube.data.iter().position(|v| !(*v >= 0.0 && v.is_finite())) {
                    let (band, p) = (i / cube.pixels(), i % cube.pixels());
                    return Err(Error::Numerical(format!(
                        "irradiance {} at pixel ({}, {}) of band {band}; it must be finite and ≥ 0",
                        cube.data[i],
                        p % cube.width,
                        p / cube.width
                    )));
                }
                let weights = (0..grid.count)
                    .map(|k| electrons_per_unit(&Curve::hat(grid, k), qe, area, t))
                    .collect::<Result<Vec<f64>>>()?;
                cube.mix(&[weights])
            }
        }
    }
}
