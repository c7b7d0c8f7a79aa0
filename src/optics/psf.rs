//! Imaging the pattern onto the sample and the sensor: the DMD-to-sample magnification (its
//! sign is the image flip), the projection lens's diffraction-limited incoherent OTF (Airy PSF),
//! and the sensor's pixel integration (a box) on a grid that may differ from the mirror grid.

use super::dmd::sinc;
use super::fourier_filter::circ_otf;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// `[rig.lens]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LensConfig {
    /// Image-side numerical aperture of the projection lens at the sample (0.1: assumed; the
    /// paper does not give it).
    pub na: f64,
    /// Wavelength of the PSF, nm. One PSF for all patterns (a documented choice): 550 nm, the
    /// centroid of the 400–700 nm band; its blur is a fraction of a mirror at NA 0.1.
    pub wavelength_nm: f64,
    /// Lateral magnification DMD → sample; negative = inverted image (−1: a single relay).
    pub magnification: f64,
    /// Lateral magnification sample → sensor (5/13.68 = 0.3655 makes one mirror one pixel,
    /// the prototype's 768 ↔ 768 mapping).
    pub camera_magnification: f64,
    /// Sensor pixel pitch in µm (5 µm: JAI GO-5000M, paper §4).
    pub sensor_pitch_um: f64,
}

impl Default for LensConfig {
    fn default() -> Self {
        LensConfig {
            na: 0.1,
            wavelength_nm: 550.0,
            magnification: -1.0,
            camera_magnification: 5.0 / 13.68,
            sensor_pitch_um: 5.0,
        }
    }
}

impl LensConfig {
    pub fn validate(&self, file: &str) -> Result<()> {
        if !(self.na > 0.0 && self.na <= 1.5) {
            return Err(Error::config(
                file,
                "rig.lens.na",
                self.na,
                "must lie in (0, 1.5]",
            ));
        }
        if !(self.wavelength_nm.is_finite() && (200.0..=2000.0).contains(&self.wavelength_nm)) {
            return Err(Error::config(
                file,
                "rig.lens.wavelength_nm",
                self.wavelength_nm,
                "must be 200–2000 nm",
            ));
        }
        if !(self.magnification.is_finite() && (1e-3..=1e3).contains(&self.magnification.abs())) {
            return Err(Error::config(
                file,
                "rig.lens.magnification",
                self.magnification,
                "|m| must be 0.001–1000",
            ));
        }
        if !(self.camera_magnification.is_finite()
            && (1e-3..=1e3).contains(&self.camera_magnification))
        {
            return Err(Error::config(
                file,
                "rig.lens.camera_magnification",
                self.camera_magnification,
                "must be 0.001–1000",
            ));
        }
        if !(self.sensor_pitch_um.is_finite()
            && self.sensor_pitch_um > 0.1
            && self.sensor_pitch_um < 1000.0)
        {
            return Err(Error::config(
                file,
                "rig.lens.sensor_pitch_um",
                self.sensor_pitch_um,
                "must be 0.1–1000 µm",
            ));
        }
        Ok(())
    }

    /// Sensor pixels per mirror: |m|·pitch·m_camera / sensor pitch.
    pub fn sensor_pixels_per_mirror(&self, pitch_um: f64) -> f64 {
        self.magnification.abs() * pitch_um * self.camera_magnification / self.sensor_pitch_um
    }

    /// Whether the image of the DMD on the sample is inverted (rotated by 180°).
    pub fn inverted(&self) -> bool {
        self.magnification < 0.0
    }

    /// Transfer of the projection lens and the pixel box at (fx, fy) in cycles per mirror:
    /// the Airy OTF at ν = f/(pitch·|m|) / (2 NA/λ) times sinc(fx/s)·sinc(fy/s), s pixels/mirror.
    pub fn transfer(&self, pitch_um: f64, fx: f64, fy: f64) -> f64 {
        let cutoff_per_mirror =
            2.0 * self.na / (self.wavelength_nm * 1e-3) * pitch_um * self.magnification.abs();
        let s = self.sensor_pixels_per_mirror(pitch_um);
        circ_otf(fx.hypot(fy) / cutoff_per_mirror) * sinc(fx / s) * sinc(fy / s)
    }
}
