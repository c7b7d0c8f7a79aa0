//! The 4f relay with a pinhole mask in its Fourier plane: openings at 0 and ±ω_i pass the
//! pattern's DC and carrier orders and block the dither noise and the DMD's grating orders.
//! A point ξ (µm) of the Fourier plane holds the spatial frequency ξ·pitch/(λ·f) cycles per
//! mirror; the mask is cut for a design wavelength, so at another λ its openings move.

use crate::error::{Error, Result};
use crate::recon::fft2::{Fft2, HalfSpectrum};
use rayon::prelude::*;
use rustfft::num_complex::Complex32;
use serde::{Deserialize, Serialize};

/// How the light that forms the pattern is filtered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Illumination {
    /// Laser-like: the mask filters the field; the intensity is |field|², so the passed orders
    /// −1, 0, +1 beat into a 2ω_i harmonic.
    Coherent,
    /// Extended source: the intensity is filtered by the mask's OTF (its normalised
    /// autocorrelation), which also passes 2ω_i.
    Incoherent,
}

/// Shape of each opening.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PinholeShape {
    Circle,
    /// A square of side 2 × radius, aligned with the mirror axes.
    Square,
}

/// `[rig.fourier_filter]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FourierFilterConfig {
    /// Focal length of the Fourier lens in mm (100 mm: assumed; the paper's concave mirror is
    /// not specified). At 532 nm and 13.68 µm pitch, 1 cycle/mirror lies 3.89 mm off axis.
    pub focal_length_mm: f64,
    /// Wavelength of the light forming the pattern, nm (532 nm: a green laser line; for a wheel
    /// segment, its band's centroid).
    pub wavelength_nm: f64,
    /// Wavelength the openings were placed for, nm (532 nm).
    pub design_wavelength_nm: f64,
    /// Radius of each opening in µm (25 µm: 0.0064 cycles/mirror at the defaults, 4.9 bins
    /// of a 768-mirror pattern, so the carrier passes with margin and the noise floor is low).
    pub pinhole_radius_um: f64,
    pub shape: PinholeShape,
    pub illumination: Illumination,
}

impl Default for FourierFilterConfig {
    fn default() -> Self {
        FourierFilterConfig {
            focal_length_mm: 100.0,
            wavelength_nm: 532.0,
            design_wavelength_nm: 532.0,
            pinhole_radius_um: 25.0,
            shape: PinholeShape::Circle,
            illumination: Illumination::Coherent,
        }
    }
}

impl FourierFilterConfig {
    pub fn validate(&self, file: &str) -> Result<()> {
        let k = "rig.fourier_filter.";
        if !(self.focal_length_mm.is_finite()
            && self.focal_length_mm >= 1.0
            && self.focal_length_mm <= 10_000.0)
        {
            return Err(Error::config(
                file,
                &format!("{k}focal_length_mm"),
                self.focal_length_mm,
                "must be 1–10000 mm",
            ));
        }
        for (name, v) in [
            ("wavelength_nm", self.wavelength_nm),
            ("design_wavelength_nm", self.design_wavelength_nm),
        ] {
            if !(v.is_finite() && (200.0..=2000.0).contains(&v)) {
                return Err(Error::config(
                    file,
                    &format!("{k}{name}"),
                    v,
                    "must be a wavelength of 200–2000 nm",
                ));
            }
        }
        if !(self.pinhole_radius_um.is_finite()
            && self.pinhole_radius_um > 0.0
            && self.pinhole_radius_um <= 1e5)
        {
            return Err(Error::config(
                file,
                &format!("{k}pinhole_radius_um"),
                self.pinhole_radius_um,
                "must be a radius of (0, 100000] µm",
            ));
        }
        Ok(())
    }

    /// A Fourier-plane distance `length_um` in cycles per mirror at the working wavelength:
    /// f = ξ·pitch/(λ·F).
    pub fn cycles_per_mirror(&self, length_um: f64, pitch_um: f64) -> f64 {
        length_um * pitch_um / (self.wavelength_nm * 1e-3 * self.focal_length_mm * 1e3)
    }

    /// The mask for one carrier (in cycles per mirror): openings at 0 and ±ω·λ_design/λ.
    pub fn mask(&self, pitch_um: f64, fx: f64, fy: f64) -> Mask {
        let s = self.design_wavelength_nm / self.wavelength_nm;
        Mask {
            centres: vec![(0.0, 0.0), (fx * s, fy * s), (-fx * s, -fy * s)],
            radius: self.cycles_per_mirror(self.pinhole_radius_um, pitch_um),
            shape: self.shape,
        }
    }
}

/// The mask's openings in frequency units (cycles per mirror).
#[derive(Clone, Debug)]
pub struct Mask {
    pub centres: Vec<(f64, f64)>,
    pub radius: f64,
    pub shape: PinholeShape,
}

impl Mask {
    /// Transmittance (0 or 1) at (fx, fy).
    pub fn at(&self, fx: f64, fy: f64) -> f64 {
        let inside = |&(cx, cy): &(f64, f64)| match self.shape {
            PinholeShape::Circle => (fx - cx).hypot(fy - cy) <= self.radius,
            PinholeShape::Square => {
                (fx - cx).abs() <= self.radius && (fy - cy).abs() <= self.radius
            }
        };
        if self.centres.iter().any(inside) {
            1.0
        } else {
            0.0
        }
    }

    /// Transmittance seen by a bin of the mirror grid, which stands for f and its replicas f + n.
    pub fn at_periodic(&self, fx: f64, fy: f64) -> f64 {
        let mut v = 0.0f64;
        for nx in -1..=1 {
            for ny in -1..=1 {
                v = v.max(self.at(fx + nx as f64, fy + ny as f64));
            }
        }
        v
    }

    /// Largest |fx| and |fy| any opening reaches.
    pub fn extent(&self) -> (f64, f64) {
        self.centres.iter().fold((0.0, 0.0), |(x, y), &(cx, cy)| {
            (
                f64::max(x, cx.abs() + self.radius),
                f64::max(y, cy.abs() + self.radius),
            )
        })
    }
}

/// Incoherent OTF of a circular pupil at ν = f / f_cutoff (f_cutoff = pupil diameter in
/// frequency units): (2/π)(acos ν − ν√(1 − ν²)), zero beyond ν = 1.
pub fn circ_otf(nu: f64) -> f64 {
    let nu = nu.abs();
    if nu >= 1.0 {
        0.0
    } else {
        std::f64::consts::FRAC_2_PI * (nu.acos() - nu * (1.0 - nu * nu).sqrt())
    }
}

/// OTF of a real, even pupil given as half-spectrum columns on `fft`'s grid: FFT(|IFFT(P)|²)
/// normalised to 1 at DC, i.e. the pupil's normalised autocorrelation. The caller must size the
/// grid so the autocorrelation (twice the pupil's extent) does not wrap.
pub fn pupil_otf(fft: &Fft2, pupil: &[Complex32]) -> HalfSpectrum {
    let amp = fft.inverse(pupil);
    let psf: Vec<f32> = amp.par_iter().map(|a| a * a).collect();
    let mut otf = fft.forward(&psf);
    let dc = otf.data[0].re;
    let inv = if dc > 0.0 { 1.0 / dc } else { 0.0 };
    otf.data.par_iter_mut().for_each(|v| *v *= inv);
    otf
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::dither::signed_bin;

    #[test]
    fn fourier_plane_scale_by_hand() {
        // 25 µm · 13.68 µm / (0.532 µm · 100 000 µm) = 0.006429 cycles/mirror.
        let f = FourierFilterConfig::default();
        assert!((f.cycles_per_mirror(25.0, 13.68) - 342.0 / 53200.0).abs() < 1e-12);
        // At 600 nm the openings cut for 532 nm sit at ω · 532/600.
        let g = FourierFilterConfig {
            wavelength_nm: 600.0,
            ..f
        };
        let m = g.mask(13.68, 0.25, 0.0);
        assert!((m.centres[1].0 - 0.25 * 532.0 / 600.0).abs() < 1e-12);
    }

    #[test]
    fn circular_pupil_otf_matches_the_closed_form() {
        let n = 256;
        let fft = Fft2::new(n, n);
        let r = 30.0; // bins; the autocorrelation reaches 60 < n/2
        let cols: Vec<Complex32> = (0..(n / 2 + 1) * n)
            .map(|i| {
                let (kx, ky) = ((i / n) as f64, signed_bin(i % n, n) as f64);
                Complex32::new(if kx.hypot(ky) <= r { 1.0 } else { 0.0 }, 0.0)
            })
            .collect();
        let otf = pupil_otf(&fft, &cols);
        for k in [6i64, 15, 30, 45] {
            let want = circ_otf(k as f64 / (2.0 * r));
            for (kx, ky) in [(k, 0), (0, k)] {
                let got = otf.at(kx, ky).re as f64;
                // A sampled disk of 30 bins: its area and overlaps are right to ~1 %.
                assert!((got - want).abs() < 0.01, "lag {k}: {got} vs {want}");
            }
        }
        assert!(otf.at(61, 0).norm() < 1e-4, "beyond the cutoff");
    }

    #[test]
    fn three_openings_pass_the_carrier_at_two_thirds_incoherently() {
        // Autocorrelation of three equal disjoint disks at 0, ±ω: 3 overlaps at 0, 2 at ±ω,
        // 1 at ±2ω, so OTF(ω) = 2/3 and OTF(2ω) = 1/3 exactly when ω is a whole bin shift.
        let n = 128;
        let fft = Fft2::new(n, n);
        let m = Mask {
            centres: vec![(0.0, 0.0), (20.0, 0.0), (-20.0, 0.0)],
            radius: 4.0,
            shape: PinholeShape::Circle,
        };
        let cols: Vec<Complex32> = (0..(n / 2 + 1) * n)
            .map(|i| {
                Complex32::new(
                    m.at((i / n) as f64, signed_bin(i % n, n) as f64) as f32,
                    0.0,
                )
            })
            .collect();
        let otf = pupil_otf(&fft, &cols);
        assert!((otf.at(20, 0).re - 2.0 / 3.0).abs() < 1e-5);
        assert!((otf.at(40, 0).re - 1.0 / 3.0).abs() < 1e-5);
        assert!(otf.at(30, 0).norm() < 1e-5);
    }
}
