//! The 2-D FFT behind a backend trait: what the reconstruction asks of a transform — the half
//! spectrum of a real frame, and a real plane back from the first columns of a half spectrum —
//! so that another device computes it through the same calls and is checked by them. The CPU's
//! `Fft2` (realfft + rustfft) is one backend; specmux-gpu's Stockham kernels (feature `gpu`)
//! are another.

use crate::error::{Error, Result};
use crate::fft::{Fft2, HalfSpectrum};
use crate::Complex32;

/// A planned 2-D FFT of real `w × h` frames.
pub trait FftBackend {
    /// Width and height of the frames it transforms.
    fn size(&self) -> (usize, usize);

    /// Who computes it, for reports: "CPU (rustfft)", or the GPU adapter's name.
    fn device(&self) -> String;

    /// Unnormalised forward transform of a real frame (row-major, w·h values): its half
    /// spectrum, kx = 0..=w/2 in `HalfSpectrum`'s column-major layout.
    fn forward(&self, frame: &[f32]) -> Result<HalfSpectrum>;

    /// The real frame of a Hermitian spectrum given by its first `cols.len() / h` kx columns
    /// (the others zero; the imaginary parts of the kx = 0 and Nyquist columns' inverse are
    /// dropped), normalised by 1/(w·h) so that `inverse(forward(x)) = x`.
    fn inverse(&self, cols: &[Complex32]) -> Result<Vec<f32>>;
}

/// A frame of the wrong length for a `w × h` plan, as an error.
pub fn check_frame(frame: &[f32], (w, h): (usize, usize)) -> Result<()> {
    match frame.len() == w * h {
        true => Ok(()),
        false => Err(Error::Shape(format!(
            "a frame of {} values for an FFT of {w}×{h}",
            frame.len()
        ))),
    }
}

/// Columns that are not whole, or more than a half spectrum holds, as an error.
pub fn check_columns(cols: &[Complex32], (w, h): (usize, usize)) -> Result<()> {
    match cols.len() % h.max(1) == 0 && cols.len() <= (w / 2 + 1) * h {
        true => Ok(()),
        false => Err(Error::Shape(format!(
            "{} spectrum values are not whole columns of {h} for an FFT of {w}×{h} (at most {} columns)",
            cols.len(),
            w / 2 + 1
        ))),
    }
}

impl FftBackend for Fft2 {
    fn size(&self) -> (usize, usize) {
        (self.w, self.h)
    }

    fn device(&self) -> String {
        "CPU (rustfft)".into()
    }

    fn forward(&self, frame: &[f32]) -> Result<HalfSpectrum> {
        check_frame(frame, self.size())?;
        Ok(Fft2::forward(self, frame))
    }

    fn inverse(&self, cols: &[Complex32]) -> Result<Vec<f32>> {
        check_columns(cols, self.size())?;
        Ok(Fft2::inverse(self, cols))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fft::dft_at;

    /// Any backend: forward against the direct DFT, the round trip, a cropped inverse against
    /// the direct sum of its columns, and the size errors.
    fn conforms(b: &dyn FftBackend) {
        let (w, h) = b.size();
        let img: Vec<f32> = (0..w * h)
            .map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.3)
            .collect();
        let s = b.forward(&img).unwrap();
        for (kx, ky) in [(0, 0), (1, 0), (0, 3), (w as i64 / 2, 1), (2, h as i64 - 1)] {
            let want = dft_at(&img, w, h, kx, ky) * (w * h) as f64;
            let got = s.at(kx, ky);
            assert!(
                (got.re as f64 - want.re).abs() < 1e-4 && (got.im as f64 - want.im).abs() < 1e-4,
                "{}: bin ({kx}, {ky})",
                b.device()
            );
        }
        let back = b.inverse(&s.data).unwrap();
        assert!(img.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-5));
        // Only the DC column kept: the inverse is each row's mean over x, as a direct sum says.
        let dc = b.inverse(&s.data[..h]).unwrap();
        for y in 0..h {
            let mean = img[y * w..(y + 1) * w].iter().sum::<f32>() / w as f32;
            assert!((dc[y * w + 3] - mean).abs() < 1e-5, "row {y}");
        }
        assert!(b.forward(&img[1..]).is_err());
        assert!(b.inverse(&s.data[1..]).is_err());
        assert!(b
            .inverse(&[s.data.clone(), s.data.clone()].concat())
            .is_err());
    }

    #[test]
    fn the_cpu_backend_conforms() {
        conforms(&Fft2::new(12, 10));
        conforms(&Fft2::new(16, 9));
    }
}
