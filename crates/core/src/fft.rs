//! 2-D FFT of real images: realfft along rows, rustfft along columns, rayon over rows.
//! Spectra are kept as the half plane kx = 0..=w/2 in column-major ("transposed") order, so a
//! column transform works on contiguous memory and an inverse can skip all-zero columns.

use rayon::prelude::*;
use realfft::{ComplexToReal, RealFftPlanner, RealToComplex};
use rustfft::num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

/// Half spectrum of a `w × h` real image: `data[kx * h + ky]`, kx in 0..=w/2, ky in 0..h.
#[derive(Clone, Debug)]
pub struct HalfSpectrum {
    pub w: usize,
    pub h: usize,
    pub data: Vec<Complex32>,
}

impl HalfSpectrum {
    /// Number of stored kx columns (w/2 + 1).
    pub fn columns(&self) -> usize {
        self.w / 2 + 1
    }

    /// Y(kx, ky) for any integer frequency (negative or beyond w/2 via Hermitian symmetry).
    #[inline]
    pub fn at(&self, kx: i64, ky: i64) -> Complex32 {
        let (w, h) = (self.w as i64, self.h as i64);
        let (kx, ky) = (kx.rem_euclid(w), ky.rem_euclid(h));
        if kx <= w / 2 {
            self.data[(kx * h + ky) as usize]
        } else {
            self.data[((w - kx) * h + (h - ky) % h) as usize].conj()
        }
    }
}

/// Planned transforms for one image size.
pub struct Fft2 {
    pub w: usize,
    pub h: usize,
    r2c: Arc<dyn RealToComplex<f32>>,
    c2r: Arc<dyn ComplexToReal<f32>>,
    col_fwd: Arc<dyn Fft<f32>>,
    col_inv: Arc<dyn Fft<f32>>,
}

impl Fft2 {
    pub fn new(w: usize, h: usize) -> Fft2 {
        let mut rp = RealFftPlanner::<f32>::new();
        let mut cp = FftPlanner::<f32>::new();
        Fft2 {
            w,
            h,
            r2c: rp.plan_fft_forward(w),
            c2r: rp.plan_fft_inverse(w),
            col_fwd: cp.plan_fft_forward(h),
            col_inv: cp.plan_fft_inverse(h),
        }
    }

    /// Unnormalised forward transform of a real image (`w × h`, row-major).
    pub fn forward(&self, img: &[f32]) -> HalfSpectrum {
        let (w, h, cw) = (self.w, self.h, self.w / 2 + 1);
        assert_eq!(img.len(), w * h, "image size does not match the plan");
        let mut rows = vec![Complex32::default(); h * cw];
        rows.par_chunks_mut(cw)
            .zip(img.par_chunks(w))
            .for_each_init(
                || (self.r2c.make_input_vec(), self.r2c.make_scratch_vec()),
                |(inp, scratch), (out, src)| {
                    inp.copy_from_slice(src);
                    self.r2c
                        .process_with_scratch(inp, out, scratch)
                        .expect("buffer sizes come from the plan");
                },
            );
        let mut data = transpose(&rows, h, cw);
        data.par_chunks_mut(h).for_each_init(
            || vec![Complex32::default(); self.col_fwd.get_inplace_scratch_len()],
            |scratch, col| self.col_fwd.process_with_scratch(col, scratch),
        );
        HalfSpectrum { w, h, data }
    }

    /// Real image of a half spectrum given by its first `cols.len() / h` kx columns (the rest
    /// zero), normalised by 1/(w·h) so that `inverse(forward(x)) = x`. The Hermitian symmetry of
    /// the kx = 0 (and Nyquist) column is assumed; their imaginary parts are discarded.
    pub fn inverse(&self, cols: &[Complex32]) -> Vec<f32> {
        let mut out = vec![0.0f32; self.w * self.h];
        self.inverse_into(cols.to_vec(), &mut out);
        out
    }

    /// [`Fft2::inverse`] written into `out` (w·h values), transforming the columns in place:
    /// each row's c2r input is gathered from the columns, so nothing is copied or transposed.
    pub fn inverse_into(&self, mut cols: Vec<Complex32>, out: &mut [f32]) {
        let (w, h, cw) = (self.w, self.h, self.w / 2 + 1);
        assert_eq!(out.len(), w * h, "output size does not match the plan");
        let kx_end = (cols.len() / h).min(cw);
        cols.truncate(kx_end * h);
        cols.par_chunks_mut(h).for_each_init(
            || vec![Complex32::default(); self.col_inv.get_inplace_scratch_len()],
            |scratch, col| self.col_inv.process_with_scratch(col, scratch),
        );
        let norm = 1.0 / (w * h) as f32;
        out.par_chunks_mut(w).enumerate().for_each_init(
            || (self.c2r.make_input_vec(), self.c2r.make_scratch_vec()),
            |(inp, scratch), (y, row)| {
                for (kx, v) in inp[..kx_end].iter_mut().enumerate() {
                    *v = cols[kx * h + y] * norm;
                }
                inp[kx_end..].fill(Complex32::default());
                inp[0].im = 0.0;
                if w % 2 == 0 {
                    inp[cw - 1].im = 0.0;
                }
                self.c2r
                    .process_with_scratch(inp, row, scratch)
                    .expect("imaginary parts of DC and Nyquist were zeroed");
            },
        );
    }
}

/// Transpose a `rows × cols` matrix into `cols × rows`, in cache-sized blocks.
fn transpose(src: &[Complex32], rows: usize, cols: usize) -> Vec<Complex32> {
    const B: usize = 32;
    let mut dst = vec![Complex32::default(); rows * cols];
    dst.par_chunks_mut(rows * B)
        .enumerate()
        .for_each(|(cb, block)| {
            let c0 = cb * B;
            let c1 = (c0 + B).min(cols);
            for r0 in (0..rows).step_by(B) {
                for r in r0..(r0 + B).min(rows) {
                    for c in c0..c1 {
                        block[(c - c0) * rows + r] = src[r * cols + c];
                    }
                }
            }
        });
    dst
}

/// (1/N) Σ_p s(p) e^{−2πi(kx·x/w + ky·y/h)}: the complex amplitude of one frequency bin.
pub fn dft_at(plane: &[f32], w: usize, h: usize, kx: i64, ky: i64) -> Complex64 {
    dtft_at(plane, w, h, kx as f64 / w as f64, ky as f64 / h as f64)
}

/// (1/N) Σ_p s(p) e^{−2πi(fx·x + fy·y)} at any frequency (cycles/px): the DTFT, for carriers
/// that are not on the bin grid.
pub fn dtft_at(plane: &[f32], w: usize, h: usize, fx: f64, fy: f64) -> Complex64 {
    let tau = std::f64::consts::TAU;
    let ex: Vec<Complex64> = (0..w)
        .map(|x| Complex64::from_polar(1.0, -tau * fx * x as f64))
        .collect();
    let mut acc = Complex64::default();
    for (y, row) in plane.chunks_exact(w).enumerate().take(h) {
        let ey = Complex64::from_polar(1.0, -tau * fy * y as f64);
        let r: Complex64 = row.iter().zip(&ex).map(|(&v, e)| e * v as f64).sum();
        acc += r * ey;
    }
    acc / (w * h) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_dft(img: &[f32], w: usize, h: usize, kx: usize, ky: usize) -> (f64, f64) {
        let (mut re, mut im) = (0.0, 0.0);
        for y in 0..h {
            for x in 0..w {
                let a = -std::f64::consts::TAU
                    * (kx as f64 * x as f64 / w as f64 + ky as f64 * y as f64 / h as f64);
                re += img[y * w + x] as f64 * a.cos();
                im += img[y * w + x] as f64 * a.sin();
            }
        }
        (re, im)
    }

    fn test_image(w: usize, h: usize) -> Vec<f32> {
        (0..w * h)
            .map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.3)
            .collect()
    }

    #[test]
    fn forward_matches_naive_dft_everywhere() {
        let (w, h) = (12, 10);
        let img = test_image(w, h);
        let s = Fft2::new(w, h).forward(&img);
        for ky in 0..h {
            for kx in 0..w {
                let (re, im) = naive_dft(&img, w, h, kx, ky);
                let v = s.at(kx as i64, ky as i64);
                assert!(
                    (v.re as f64 - re).abs() < 1e-4 && (v.im as f64 - im).abs() < 1e-4,
                    "({kx},{ky})"
                );
            }
        }
    }

    #[test]
    fn inverse_round_trips() {
        let (w, h) = (16, 9);
        let img = test_image(w, h);
        let f = Fft2::new(w, h);
        let back = f.inverse(&f.forward(&img).data);
        for (a, b) in img.iter().zip(&back) {
            assert!((a - b).abs() < 1e-5);
        }
    }
}
