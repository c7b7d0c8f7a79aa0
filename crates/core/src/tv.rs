//! Total-variation denoising by Chambolle's dual projection (Chambolle 2004), isotropic and joint
//! across channels: u = argmin ½‖u − f‖² + λ Σ_p (Σ_k |∇u_k(p)|²)^½. It is the denoising step of
//! the GAP-TV baseline (Yuan 2016); forward differences with Neumann boundaries.

use rayon::prelude::*;

/// Chambolle's step; 1/4 is the step the method is used with in practice (1/8 is the proven bound).
pub const TAU: f32 = 0.25;

/// The dual field p = (px, py) of one `w × h × planes` cube, kept between calls (warm start).
pub struct TvDenoiser {
    w: usize,
    h: usize,
    px: Vec<f32>,
    py: Vec<f32>,
    /// div p − f/λ, one value per cube sample.
    g: Vec<f32>,
    /// 1 / (1 + τ|∇g|) per pixel, joint over the planes.
    shrink: Vec<f32>,
}

impl TvDenoiser {
    pub fn new(w: usize, h: usize, planes: usize) -> TvDenoiser {
        TvDenoiser {
            w,
            h,
            px: vec![0.0; w * h * planes],
            py: vec![0.0; w * h * planes],
            g: vec![0.0; w * h * planes],
            shrink: vec![0.0; w * h],
        }
    }

    /// Replace `f` (planes of w·h, plane-major) by its TV-denoised version after `iters` dual
    /// steps; `lambda` ≤ 0 leaves `f` unchanged.
    pub fn denoise(&mut self, f: &mut [f32], lambda: f32, iters: usize) {
        if lambda <= 0.0 || iters == 0 {
            return;
        }
        let (w, h, n) = (self.w, self.h, self.w * self.h);
        let inv_l = 1.0 / lambda;
        for _ in 0..iters {
            self.g
                .par_chunks_mut(n)
                .zip(f.par_chunks(n))
                .zip(self.px.par_chunks(n).zip(self.py.par_chunks(n)))
                .for_each(|((g, f), (px, py))| {
                    divergence(px, py, w, h, g);
                    for (gv, &fv) in g.iter_mut().zip(f) {
                        *gv -= fv * inv_l;
                    }
                });
            let g = &self.g;
            self.shrink
                .par_chunks_mut(w)
                .enumerate()
                .for_each(|(y, row)| {
                    for (x, s) in row.iter_mut().enumerate() {
                        let mut m = 0.0f32;
                        for plane in g.chunks_exact(n) {
                            let (gx, gy) = gradient(plane, w, h, x, y);
                            m += gx * gx + gy * gy;
                        }
                        *s = 1.0 / (1.0 + TAU * m.sqrt());
                    }
                });
            let shrink = &self.shrink;
            self.px
                .par_chunks_mut(n)
                .zip(self.py.par_chunks_mut(n))
                .zip(g.par_chunks(n))
                .for_each(|((px, py), plane)| {
                    for y in 0..h {
                        for x in 0..w {
                            let p = y * w + x;
                            let (gx, gy) = gradient(plane, w, h, x, y);
                            px[p] = (px[p] + TAU * gx) * shrink[p];
                            py[p] = (py[p] + TAU * gy) * shrink[p];
                        }
                    }
                });
        }
        f.par_chunks_mut(n)
            .zip(self.g.par_chunks_mut(n))
            .zip(self.px.par_chunks(n).zip(self.py.par_chunks(n)))
            .for_each(|((f, d), (px, py))| {
                divergence(px, py, w, h, d);
                for (fv, &dv) in f.iter_mut().zip(d.iter()) {
                    *fv -= lambda * dv;
                }
            });
    }
}

/// Forward differences with a zero difference across the last column and row (Neumann).
#[inline]
fn gradient(u: &[f32], w: usize, h: usize, x: usize, y: usize) -> (f32, f32) {
    let p = y * w + x;
    let gx = if x + 1 < w { u[p + 1] - u[p] } else { 0.0 };
    let gy = if y + 1 < h { u[p + w] - u[p] } else { 0.0 };
    (gx, gy)
}

/// div p = −∇ᵀp for the forward differences of `gradient`.
fn divergence(px: &[f32], py: &[f32], w: usize, h: usize, out: &mut [f32]) {
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            let dx = if x + 1 < w { px[p] } else { 0.0 } - if x > 0 { px[p - 1] } else { 0.0 };
            let dy = if y + 1 < h { py[p] } else { 0.0 } - if y > 0 { py[p - w] } else { 0.0 };
            out[p] = dx + dy;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    #[test]
    fn divergence_is_minus_the_adjoint_of_the_gradient() {
        let (w, h) = (7, 5);
        let mut rng = Pcg64::seed_from_u64(1);
        let u: Vec<f32> = (0..w * h).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let px: Vec<f32> = (0..w * h).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let py: Vec<f32> = (0..w * h).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let mut div = vec![0.0; w * h];
        divergence(&px, &py, w, h, &mut div);
        let mut lhs = 0.0f64;
        for y in 0..h {
            for x in 0..w {
                let (gx, gy) = gradient(&u, w, h, x, y);
                lhs += (gx * px[y * w + x] + gy * py[y * w + x]) as f64;
            }
        }
        let rhs: f64 = -u.iter().zip(&div).map(|(a, b)| (a * b) as f64).sum::<f64>();
        assert!((lhs - rhs).abs() < 1e-5, "{lhs} vs {rhs}");
    }

    #[test]
    fn constant_image_is_a_fixed_point_and_noise_loses_variation() {
        let (w, h) = (16, 16);
        let mut c = vec![3.0f32; w * h * 2];
        TvDenoiser::new(w, h, 2).denoise(&mut c, 0.5, 50);
        assert!(c.iter().all(|&v| (v - 3.0).abs() < 1e-6));
        // Noise: TV decreases and the mean is kept (div p sums to zero).
        let mut rng = Pcg64::seed_from_u64(2);
        let f: Vec<f32> = (0..w * h * 2).map(|_| rng.gen_range(0.0..1.0)).collect();
        let mut u = f.clone();
        TvDenoiser::new(w, h, 2).denoise(&mut u, 0.2, 100);
        let tv = |v: &[f32]| -> f64 {
            (0..w * h)
                .map(|p| {
                    let (x, y) = (p % w, p / w);
                    v.chunks(w * h)
                        .map(|pl| {
                            let (a, b) = gradient(pl, w, h, x, y);
                            (a * a + b * b) as f64
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .sum()
        };
        assert!(tv(&u) < 0.5 * tv(&f), "{} vs {}", tv(&u), tv(&f));
        let mean = |v: &[f32]| v.iter().map(|&a| a as f64).sum::<f64>() / v.len() as f64;
        assert!((mean(&u) - mean(&f)).abs() < 1e-5);
    }
}
