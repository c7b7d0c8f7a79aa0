//! The DMD: a grid of square micromirrors, each on (light to the relay) or off, showing the
//! binary version of the grey target s_i/2. Its geometry fixes the Fourier-plane scale (pitch)
//! and the envelope of its spectrum (the mirror's own aperture, set by the fill factor).

use crate::optics::dither::dither;
use crate::optics::dither::DitherMethod;
use crate::optics::dither::Passband;
use serde::{Deserialize, Serialize};
use specmux_core::error::Error;
use specmux_core::error::Result;

/// `[rig.dmd]`: the mirror array and how it dithers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DmdConfig {
    /// Mirrors across used for patterns: the prototype shows 768 × 768 patterns (paper, §4).
    pub width: usize,
    /// Mirrors down used for patterns (768, paper §4; the DLP7000 array itself is 1024 × 768).
    pub height: usize,
    /// Mirror pitch in µm: 13.68 µm, TI DLP7000 (0.7" XGA) data sheet.
    pub pitch_um: f64,
    /// Reflective area fraction of one pitch cell: ≈ 0.92 for the DLP7000-class arrays.
    pub fill_factor: f64,
    /// Binarisation: the paper dithers; serpentine Floyd–Steinberg is the best classic choice.
    pub dither: DitherMethod,
    /// Side of the Bayer matrix for `dither = "bayer"` (a power of two, 2–64; 8 is the usual).
    pub bayer_tile: usize,
    /// Toggle passes of `dither = "in-band-feedback"` (8: the in-band error settles by then).
    pub feedback_iterations: usize,
}

impl Default for DmdConfig {
    fn default() -> Self {
        DmdConfig {
            width: 768,
            height: 768,
            pitch_um: 13.68,
            fill_factor: 0.92,
            dither: DitherMethod::FloydSteinberg,
            bayer_tile: 8,
            feedback_iterations: 8,
        }
    }
}

/// sin(πx)/(πx).
pub fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-12 {
        1.0
    } else {
        let px = std::f64::consts::PI * x;
        px.sin() / px
    }
}

impl DmdConfig {
    pub fn validate(&self, file: &str) -> Result<()> {
        for (key, v) in [
            ("rig.dmd.width", self.width),
            ("rig.dmd.height", self.height),
        ] {
            if !(2..=16384).contains(&v) {
                return Err(Error::config(file, key, v, "must be 2–16384 mirrors"));
            }
        }
        if !(self.pitch_um.is_finite() && self.pitch_um > 0.1 && self.pitch_um < 1000.0) {
            return Err(Error::config(
                file,
                "rig.dmd.pitch_um",
                self.pitch_um,
                "must be a pitch in µm, 0.1–1000",
            ));
        }
        if !(self.fill_factor > 0.0 && self.fill_factor <= 1.0) {
            return Err(Error::config(
                file,
                "rig.dmd.fill_factor",
                self.fill_factor,
                "must lie in (0, 1]",
            ));
        }
        if !(self.bayer_tile.is_power_of_two() && (2..=64).contains(&self.bayer_tile)) {
            return Err(Error::config(
                file,
                "rig.dmd.bayer_tile",
                self.bayer_tile,
                "must be a power of two, 2–64",
            ));
        }
        if !(1..=100).contains(&self.feedback_iterations) {
            return Err(Error::config(
                file,
                "rig.dmd.feedback_iterations",
                self.feedback_iterations,
                "must be 1–100",
            ));
        }
        Ok(())
    }

    /// Spectrum envelope of one mirror (a square of side √fill · pitch) at (fx, fy) in cycles
    /// per mirror, normalised to 1 at DC: the field (or intensity) is Σ b[n] · box(x − n), so its
    /// spectrum is the periodic B(f) times this envelope.
    pub fn mirror_envelope(&self, fx: f64, fy: f64) -> f64 {
        self.mirror_envelope_along(fx) * self.mirror_envelope_along(fy)
    }

    /// The envelope's factor along one axis (it is separable).
    pub fn mirror_envelope_along(&self, f: f64) -> f64 {
        sinc(self.fill_factor.sqrt() * f)
    }

    /// The binary pattern the DMD shows for a grey `target` (values in [0, 1], `width × height`).
    /// `passband` (cycles per mirror) is used by the in-band feedback method.
    pub fn display(&self, target: &[f32], passband: Passband) -> Vec<f32> {
        dither(
            target,
            self.width,
            self.height,
            self.dither,
            self.bayer_tile,
            passband,
            self.feedback_iterations,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use specmux_core::fft::dft_at;

    #[test]
    fn binary_grating_orders_match_the_square_wave_series() {
        // A 50 % duty grating of period 8 mirrors with fill factor 1 is the continuous square
        // wave; its orders are c_n = sin(πn/2)/(πn) (c_0 = ½). The sampled DFT times the mirror
        // envelope must reproduce them, including orders past the array's Nyquist (n = 5, 7: the
        // DMD's replicas at f mod 1).
        let dmd = DmdConfig {
            width: 64,
            height: 8,
            fill_factor: 1.0,
            dither: DitherMethod::Threshold,
            ..Default::default()
        };
        let period = 8.0;
        // Phase π/8 centres the "on" half-period on mirrors 0, 1, 6, 7 (no mirror at exactly ½).
        let target: Vec<f32> = (0..64 * 8)
            .map(|p| {
                (0.5 + 0.5 * (std::f64::consts::TAU * ((p % 64) as f64 + 0.5) / period).cos())
                    as f32
            })
            .collect();
        let b = dmd.display(&target, &|_, _| 1.0);
        assert_eq!(b.iter().filter(|&&v| v == 1.0).count(), 64 * 8 / 2);
        for n in 0..8i64 {
            let f = n as f64 / period;
            // Bin of f mod 1 on the 64-mirror axis; the box centre sits at (x + ½) for phase.
            let k = (n * 8).rem_euclid(64);
            let c = dft_at(&b, 64, 8, k, 0) * dmd.mirror_envelope(f, 0.0);
            let want = if n == 0 {
                0.5
            } else {
                (std::f64::consts::FRAC_PI_2 * n as f64).sin() / (std::f64::consts::PI * n as f64)
            };
            // The grating is centred on x = −½, which multiplies c_n by e^{iπf}; undo it.
            let got =
                (c * rustfft::num_complex::Complex64::from_polar(1.0, -std::f64::consts::PI * f))
                    .re;
            assert!((got - want).abs() < 1e-6, "order {n}: {got} vs {want}");
        }
    }

    #[test]
    fn bad_fill_factor_is_named() {
        let d = DmdConfig {
            fill_factor: 1.3,
            ..Default::default()
        };
        let e = d.validate("x.toml").unwrap_err().to_string();
        assert!(
            e.contains("rig.dmd.fill_factor") && e.contains("1.3"),
            "{e}"
        );
    }
}
