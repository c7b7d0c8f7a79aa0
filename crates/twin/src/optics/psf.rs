//! Imaging the pattern onto the sample and the sensor: the DMD-to-sample magnification (its
//! sign is the image flip), the projection lens's diffraction-limited incoherent OTF (Airy PSF),
//! and the sensor's pixel integration (a box) on a grid that may differ from the mirror grid.

use crate::optics::dmd::sinc;
use crate::optics::fourier_filter::circ_otf;
use serde::{Deserialize, Serialize};
use specmux_core::error::Error;
use specmux_core::error::Result;

/// `[rig.lens]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LensConfig {
    /// Image-side numerical aperture of the projection lens at the sample (0.1: assumed; the
    /// paper does not give it).
    pub na: f64,
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

    /// The Airy OTF's cutoff in cycles per mirror for light of `wavelength_nm`: 2 NA/λ on the
    /// sample, times the mirror's image pitch there.
    fn cutoff(&self, pitch_um: f64, wavelength_nm: f64) -> f64 {
        2.0 * self.na / (wavelength_nm * 1e-3) * pitch_um * self.magnification.abs()
    }

    /// The sensor pixel box's transfer at (fx, fy) cycles per mirror: sinc(fx/s)·sinc(fy/s).
    pub fn pixel_transfer(&self, pitch_um: f64, fx: f64, fy: f64) -> f64 {
        let s = self.sensor_pixels_per_mirror(pitch_um);
        sinc(fx / s) * sinc(fy / s)
    }

    /// The projection lens's Airy OTF at (fx, fy) cycles per mirror for light of `wavelength_nm`.
    pub fn airy(&self, pitch_um: f64, fx: f64, fy: f64, wavelength_nm: f64) -> f64 {
        circ_otf(fx.hypot(fy) / self.cutoff(pitch_um, wavelength_nm))
    }

    /// ∂/∂λ of [`LensConfig::airy`] per nm: ν = f/cutoff grows as λ, and d OTF/dν = −(4/π)√(1 − ν²).
    pub fn airy_slope(&self, pitch_um: f64, fx: f64, fy: f64, wavelength_nm: f64) -> f64 {
        let nu = fx.hypot(fy) / self.cutoff(pitch_um, wavelength_nm);
        if nu >= 1.0 {
            return 0.0;
        }
        -4.0 / std::f64::consts::PI * (1.0 - nu * nu).sqrt() * nu / wavelength_nm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn airy_cutoff_by_hand_and_its_slope() {
        // NA 0.1, 550 nm, 13.68 µm mirrors imaged at |m| = 1: cutoff 2·0.1/0.55 µm⁻¹ · 13.68 µm
        // = 4.975 cycles/mirror.
        let l = LensConfig::default();
        assert!((l.cutoff(13.68, 550.0) - 2.0 * 0.1 / 0.55 * 13.68).abs() < 1e-12);
        assert_eq!(l.airy(13.68, 5.0, 0.0, 550.0), 0.0);
        assert!((l.airy(13.68, 0.0, 0.0, 550.0) - 1.0).abs() < 1e-15);
        for (fx, fy, wl) in [(0.5, 0.25, 550.0), (1.5, -0.7, 420.0), (3.0, 2.0, 690.0)] {
            let h = 1e-3;
            let fd = (l.airy(13.68, fx, fy, wl + h) - l.airy(13.68, fx, fy, wl - h)) / (2.0 * h);
            let an = l.airy_slope(13.68, fx, fy, wl);
            assert!(
                an < 0.0 && (fd - an).abs() < 1e-6 * an.abs().max(1e-9),
                "{fd} vs {an}"
            );
        }
    }
}
