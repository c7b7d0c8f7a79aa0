//! Error of an estimated cube against the truth: PSNR, SSIM (Wang et al. 2004), RMSE/NRMSE and
//! the spectral angle (SAM). Planes are bands or channels alike.
//!
//! One peak serves every figure: the truth's maximum over the whole cube, so that the planes of a
//! cube share one dynamic range (a dim band is not flattered by its own small maximum).

// `!(x > 0.0)` is deliberate: it is true for NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::error::{Error, Result};
use crate::scene::Cube;
use rayon::prelude::*;
use serde::Serialize;

/// SSIM window: Gaussian, 11 × 11 samples, σ = 1.5 pixels (Wang et al. 2004).
pub const SSIM_WINDOW: usize = 11;
pub const SSIM_SIGMA: f64 = 1.5;
/// SSIM stabilising constants C₁ = (K₁L)², C₂ = (K₂L)².
pub const SSIM_K1: f64 = 0.01;
pub const SSIM_K2: f64 = 0.03;

/// The error figures of one estimate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Metrics {
    /// The truth's maximum over the whole cube: the peak of PSNR, the L of SSIM, the NRMSE unit.
    pub peak: f64,
    /// Mean of the finite per-plane PSNRs in dB; `None` when every plane is exact.
    pub psnr_db: Option<f64>,
    /// PSNR of each plane, 10·log₁₀(peak² / MSE); `f64::INFINITY` for an exact plane
    /// (serde_json writes it as `null`).
    pub psnr_per_plane: Vec<f64>,
    /// Planes with MSE = 0, left out of `psnr_db`.
    pub psnr_exact_planes: usize,
    /// Mean SSIM over planes; `None` when a plane is smaller than the 11 × 11 window.
    pub ssim: Option<f64>,
    pub ssim_per_plane: Vec<f64>,
    /// Root-mean-square error over all values, in the cube's units.
    pub rmse: f64,
    /// `rmse / peak`.
    pub nrmse: f64,
    /// Mean spectral angle in degrees over the pixels where both spectra are non-zero; `None`
    /// when there is none.
    pub sam_deg: Option<f64>,
    pub sam_pixels: usize,
    /// Pixels left out of SAM because the truth's or the estimate's spectrum is all zero.
    pub sam_skipped_pixels: usize,
}

/// Compare `estimate` with `truth` (same width, height and planes).
pub fn compare(truth: &Cube, estimate: &Cube) -> Result<Metrics> {
    truth.check_same_shape(estimate, "metrics: truth against estimate")?;
    if truth.data.is_empty() {
        return Err(Error::Shape("metrics: empty cube".into()));
    }
    for (cube, what) in [(truth, "truth"), (estimate, "estimate")] {
        if let Some(i) = cube.data.iter().position(|v| !v.is_finite()) {
            let (plane, p) = (i / cube.pixels(), i % cube.pixels());
            return Err(Error::Numerical(format!(
                "metrics: {what} holds {} at plane {plane}, pixel ({}, {})",
                cube.data[i],
                p % cube.width,
                p / cube.width
            )));
        }
    }
    let peak = truth.max() as f64;
    if !(peak > 0.0) {
        return Err(Error::Numerical(format!(
            "metrics: the truth's peak is {peak}; PSNR, SSIM and NRMSE need a positive peak"
        )));
    }
    let sse: Vec<f64> = (0..truth.planes)
        .into_par_iter()
        .map(|k| {
            truth
                .plane(k)
                .iter()
                .zip(estimate.plane(k))
                .map(|(&t, &e)| (t as f64 - e as f64).powi(2))
                .sum()
        })
        .collect();
    let npx = truth.pixels() as f64;
    let psnr_per_plane: Vec<f64> = sse
        .iter()
        .map(|&s| 10.0 * (peak * peak / (s / npx)).log10())
        .collect();
    let finite: Vec<f64> = psnr_per_plane
        .iter()
        .cloned()
        .filter(|v| v.is_finite())
        .collect();
    let rmse = (sse.iter().sum::<f64>() / truth.data.len() as f64).sqrt();
    let fits = truth.width >= SSIM_WINDOW && truth.height >= SSIM_WINDOW;
    let ssim_per_plane: Vec<f64> = if fits {
        (0..truth.planes)
            .into_par_iter()
            .map(|k| {
                ssim_plane(
                    truth.plane(k),
                    estimate.plane(k),
                    truth.width,
                    truth.height,
                    peak,
                )
            })
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let (sam_sum, sam_pixels) = spectral_angles(truth, estimate);
    Ok(Metrics {
        peak,
        psnr_db: (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64),
        psnr_exact_planes: psnr_per_plane.len() - finite.len(),
        psnr_per_plane,
        ssim: fits.then(|| ssim_per_plane.iter().sum::<f64>() / ssim_per_plane.len() as f64),
        ssim_per_plane,
        rmse,
        nrmse: rmse / peak,
        sam_deg: (sam_pixels > 0).then(|| sam_sum / sam_pixels as f64),
        sam_pixels,
        sam_skipped_pixels: truth.pixels() - sam_pixels,
    })
}

/// Sum of spectral angles (degrees) and the number of pixels where both spectra are non-zero.
/// The angle is 2·atan2(‖t̂ − ê‖, ‖t̂ + ê‖) of the unit spectra, accurate at 0° and 180° alike.
fn spectral_angles(truth: &Cube, estimate: &Cube) -> (f64, usize) {
    let (w, planes) = (truth.width, truth.planes);
    (0..truth.height)
        .into_par_iter()
        .map(|y| {
            let (mut sum, mut count) = (0.0, 0);
            for x in 0..w {
                let p = y * w + x;
                let (mut tt, mut ee) = (0.0f64, 0.0f64);
                for k in 0..planes {
                    tt += (truth.plane(k)[p] as f64).powi(2);
                    ee += (estimate.plane(k)[p] as f64).powi(2);
                }
                if tt == 0.0 || ee == 0.0 {
                    continue;
                }
                let (tn, en) = (tt.sqrt(), ee.sqrt());
                let (mut dif, mut add) = (0.0f64, 0.0f64);
                for k in 0..planes {
                    let (t, e) = (
                        truth.plane(k)[p] as f64 / tn,
                        estimate.plane(k)[p] as f64 / en,
                    );
                    dif += (t - e).powi(2);
                    add += (t + e).powi(2);
                }
                sum += 2.0 * dif.sqrt().atan2(add.sqrt()).to_degrees();
                count += 1;
            }
            (sum, count)
        })
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// The normalised 1-D Gaussian of the SSIM window; the 2-D window is its outer product.
fn gaussian_window() -> [f64; SSIM_WINDOW] {
    let half = (SSIM_WINDOW / 2) as f64;
    let mut g: [f64; SSIM_WINDOW] = std::array::from_fn(|i| {
        (-((i as f64 - half).powi(2)) / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp()
    });
    let s: f64 = g.iter().sum();
    g.iter_mut().for_each(|v| *v /= s);
    g
}

/// Mean SSIM of one plane over the 'valid' window positions (no padding): local Gaussian means,
/// variances and covariance by separable filtering in f64, L = `peak`.
pub fn ssim_plane(
    truth: &[f32],
    estimate: &[f32],
    width: usize,
    height: usize,
    peak: f64,
) -> Result<f64> {
    if width < SSIM_WINDOW
        || height < SSIM_WINDOW
        || truth.len() != width * height
        || estimate.len() != truth.len()
    {
        return Err(Error::Shape(format!(
            "SSIM needs two {width}×{height} planes of at least {SSIM_WINDOW}×{SSIM_WINDOW}; got {} and {} values",
            truth.len(),
            estimate.len()
        )));
    }
    let g = gaussian_window();
    let (ow, oh) = (width - SSIM_WINDOW + 1, height - SSIM_WINDOW + 1);
    // Horizontal pass: 5 moment maps (x, y, x², y², xy), each height × ow.
    let mut hmaps = vec![0.0f64; 5 * height * ow];
    let (mut xr, mut yr) = (vec![0.0f64; width], vec![0.0f64; width]);
    let mut prod = vec![0.0f64; 3 * width];
    for row in 0..height {
        let src = row * width..(row + 1) * width;
        for (d, &s) in xr.iter_mut().zip(&truth[src.clone()]) {
            *d = s as f64;
        }
        for (d, &s) in yr.iter_mut().zip(&estimate[src]) {
            *d = s as f64;
        }
        for i in 0..width {
            prod[i] = xr[i] * xr[i];
            prod[width + i] = yr[i] * yr[i];
            prod[2 * width + i] = xr[i] * yr[i];
        }
        let inputs: [&[f64]; 5] = [
            &xr,
            &yr,
            &prod[..width],
            &prod[width..2 * width],
            &prod[2 * width..],
        ];
        for (m, input) in inputs.iter().enumerate() {
            let dst = &mut hmaps[(m * height + row) * ow..(m * height + row + 1) * ow];
            dst.fill(0.0);
            for (t, &wt) in g.iter().enumerate() {
                for (d, &s) in dst.iter_mut().zip(&input[t..t + ow]) {
                    *d += wt * s;
                }
            }
        }
    }
    // Vertical pass, one output row at a time, then the SSIM map's sum.
    let (c1, c2) = ((SSIM_K1 * peak).powi(2), (SSIM_K2 * peak).powi(2));
    let mut mom = vec![0.0f64; 5 * ow];
    let mut total = 0.0;
    for orow in 0..oh {
        mom.fill(0.0);
        for m in 0..5 {
            let dst = &mut mom[m * ow..(m + 1) * ow];
            for (t, &wt) in g.iter().enumerate() {
                let src = &hmaps[(m * height + orow + t) * ow..(m * height + orow + t + 1) * ow];
                for (d, &s) in dst.iter_mut().zip(src) {
                    *d += wt * s;
                }
            }
        }
        for i in 0..ow {
            let (mx, my) = (mom[i], mom[ow + i]);
            let vx = mom[2 * ow + i] - mx * mx;
            let vy = mom[3 * ow + i] - my * my;
            let cxy = mom[4 * ow + i] - mx * my;
            total += ((2.0 * mx * my + c1) * (2.0 * cxy + c2))
                / ((mx * mx + my * my + c1) * (vx + vy + c2));
        }
    }
    Ok(total / (ow * oh) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    use rand_pcg::Pcg64;

    fn cube_from(
        w: usize,
        h: usize,
        planes: usize,
        f: impl Fn(usize, usize, usize) -> f32,
    ) -> Cube {
        let mut c = Cube::zeros(w, h, planes);
        for k in 0..planes {
            for y in 0..h {
                for x in 0..w {
                    c.plane_mut(k)[y * w + x] = f(x, y, k);
                }
            }
        }
        c
    }

    #[test]
    fn psnr_of_a_constant_offset() {
        // Peak 1 (one pixel of the truth), error 0.1 everywhere: MSE = 0.01, PSNR = 20 dB.
        let truth = cube_from(
            16,
            16,
            3,
            |x, y, k| if (x, y, k) == (3, 4, 1) { 1.0 } else { 0.5 },
        );
        let est = cube_from(16, 16, 3, |x, y, k| truth.plane(k)[y * 16 + x] + 0.1);
        let m = compare(&truth, &est).unwrap();
        assert_eq!(m.peak, 1.0);
        for p in &m.psnr_per_plane {
            assert!((p - 20.0).abs() < 1e-5, "{p}"); // 0.1 in f32 differs from 0.1 by 1e-8
        }
        assert!((m.psnr_db.unwrap() - 20.0).abs() < 1e-5);
        assert!((m.rmse - 0.1).abs() < 1e-7 && (m.nrmse - 0.1).abs() < 1e-7);
        assert_eq!(m.psnr_exact_planes, 0);
    }

    #[test]
    fn exact_planes_are_infinite_and_left_out_of_the_mean() {
        let truth = cube_from(12, 12, 2, |x, _, _| x as f32);
        let mut est = truth.clone();
        est.plane_mut(1).iter_mut().for_each(|v| *v += 1.1); // peak 11, error 1.1 → 20 dB
        let m = compare(&truth, &est).unwrap();
        assert_eq!(m.psnr_per_plane[0], f64::INFINITY);
        assert!((m.psnr_per_plane[1] - 20.0).abs() < 1e-5);
        assert!((m.psnr_db.unwrap() - 20.0).abs() < 1e-5);
        assert_eq!(m.psnr_exact_planes, 1);
        let same = compare(&truth, &truth).unwrap();
        assert_eq!((same.psnr_db, same.psnr_exact_planes), (None, 2));
        assert_eq!(same.ssim, Some(1.0));
        assert_eq!((same.rmse, same.sam_deg), (0.0, Some(0.0)));
        // The JSON stays valid: the infinite plane is written as null.
        let json = serde_json::to_string(&m).unwrap();
        assert!(json.contains("\"psnr_per_plane\":[null,"), "{json}");
    }

    #[test]
    fn nrmse_example() {
        // Truth peak 4; errors +1 on half the values and −3 on the other half: MSE = 5.
        let truth = cube_from(4, 2, 2, |_, _, _| 4.0);
        let est = cube_from(4, 2, 2, |x, _, _| if x % 2 == 0 { 5.0 } else { 1.0 });
        let m = compare(&truth, &est).unwrap();
        assert!((m.rmse - 5f64.sqrt()).abs() < 1e-12);
        assert!((m.nrmse - 5f64.sqrt() / 4.0).abs() < 1e-12);
        assert_eq!(m.ssim, None); // 4×2 is smaller than the SSIM window
    }

    #[test]
    fn ssim_of_constants_is_the_luminance_term() {
        // σ = 0 everywhere: SSIM = (2ab + C₁)/(a² + b² + C₁), here L = a = 0.8.
        let (a, b) = (0.8f32, 0.5f32);
        let t = vec![a; 20 * 15];
        let e = vec![b; 20 * 15];
        let (a, b) = (a as f64, b as f64);
        let c1 = (0.01 * a).powi(2);
        let want = (2.0 * a * b + c1) / (a * a + b * b + c1);
        let got = ssim_plane(&t, &e, 20, 15, a).unwrap();
        assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    }

    #[test]
    fn ssim_of_a_scaled_ramp_matches_the_closed_form() {
        // x = c + g·col: every window has mean c + g·col₀ and variance g²·Σ w(u)u² (constant);
        // y = s·x gives μ_y = sμ, σ_y² = s²σ², σ_xy = sσ², so each window's SSIM is
        // (2sμ² + C₁)(2sσ² + C₂) / (((1 + s²)μ² + C₁)((1 + s²)σ² + C₂)).
        let (w, h, c, g, s) = (40usize, 13usize, 0.2f64, 0.01f64, 0.7f64);
        let x: Vec<f32> = (0..w * h)
            .map(|p| (c + g * (p % w) as f64) as f32)
            .collect();
        let y: Vec<f32> = x.iter().map(|&v| (s * v as f64) as f32).collect();
        let peak = c + g * (w - 1) as f64;
        let win = gaussian_window();
        let var = g
            * g
            * win
                .iter()
                .enumerate()
                .map(|(i, wt)| wt * (i as f64 - 5.0).powi(2))
                .sum::<f64>();
        let (c1, c2) = ((0.01 * peak).powi(2), (0.03 * peak).powi(2));
        let mut want = 0.0;
        for col0 in 5..w - 5 {
            // Means from the f32 ramp exactly as stored.
            let mu: f64 = win
                .iter()
                .enumerate()
                .map(|(i, wt)| wt * x[col0 - 5 + i] as f64)
                .sum();
            want += (2.0 * s * mu * mu + c1) * (2.0 * s * var + c2)
                / (((1.0 + s * s) * mu * mu + c1) * ((1.0 + s * s) * var + c2));
        }
        want /= (w - 10) as f64;
        let got = ssim_plane(&x, &y, w, h, peak).unwrap();
        // f32 storage of x and y perturbs σ² ≈ 1e-4·… by ~1e-9 relative to peak²: 1e-5 suffices.
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        assert!(want < 0.99, "the case must be discriminating: {want}");
    }

    #[test]
    fn sam_of_orthogonal_and_scaled_spectra() {
        let truth = cube_from(3, 1, 2, |x, _, k| {
            [[1.0, 0.0], [1.0, 2.0], [0.0, 0.0]][x][k]
        });
        let est = cube_from(3, 1, 2, |x, _, k| {
            [[0.0, 5.0], [3.0, 6.0], [1.0, 1.0]][x][k]
        });
        let m = compare(&truth, &est).unwrap();
        // Pixel 0: 90°, pixel 1: 0°, pixel 2 skipped (zero truth).
        assert_eq!((m.sam_pixels, m.sam_skipped_pixels), (2, 1));
        assert!((m.sam_deg.unwrap() - 45.0).abs() < 1e-12, "{:?}", m.sam_deg);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let t = Cube::zeros(12, 12, 2);
        assert!(matches!(compare(&t, &t), Err(Error::Numerical(_)))); // peak 0
        let t = cube_from(12, 12, 2, |_, _, _| 1.0);
        assert!(matches!(
            compare(&t, &Cube::zeros(12, 12, 3)),
            Err(Error::Shape(_))
        ));
        let mut e = t.clone();
        e.plane_mut(1)[13] = f32::NAN;
        match compare(&t, &e) {
            Err(Error::Numerical(msg)) => assert!(msg.contains("plane 1, pixel (1, 1)"), "{msg}"),
            other => panic!("expected an error, got {other:?}"),
        }
    }

    fn noisy(truth: &Cube, sigma: f64, seed: u64) -> Cube {
        let mut rng = Pcg64::seed_from_u64(seed);
        let n = Normal::new(0.0, 1.0).unwrap();
        let mut e = truth.clone();
        e.data
            .iter_mut()
            .for_each(|v| *v += (sigma * n.sample(&mut rng)) as f32);
        e
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(32))]
        #[test]
        fn ssim_is_symmetric_and_at_most_one(seed in 0u64..10_000, w in 11usize..20, h in 11usize..16) {
            let mut rng = Pcg64::seed_from_u64(seed);
            let n = Normal::new(0.5, 0.3).unwrap();
            let a: Vec<f32> = (0..w * h).map(|_| n.sample(&mut rng) as f32).collect();
            let b: Vec<f32> = (0..w * h).map(|_| n.sample(&mut rng) as f32).collect();
            let ab = ssim_plane(&a, &b, w, h, 1.0).unwrap();
            let ba = ssim_plane(&b, &a, w, h, 1.0).unwrap();
            prop_assert!((ab - ba).abs() < 1e-12);
            prop_assert!(ab <= 1.0 + 1e-12);
        }

        #[test]
        fn psnr_falls_as_noise_grows(seed in 0u64..10_000, sigma in 1e-3f64..0.1) {
            let truth = cube_from(12, 11, 2, |x, y, k| 0.5 + 0.04 * x as f32 - 0.02 * y as f32 + 0.1 * k as f32);
            let lo = compare(&truth, &noisy(&truth, sigma, seed)).unwrap();
            let hi = compare(&truth, &noisy(&truth, 2.0 * sigma, seed)).unwrap();
            // The same noise pattern, doubled: MSE × 4, PSNR − 6.02 dB.
            prop_assert!(hi.psnr_db.unwrap() < lo.psnr_db.unwrap());
            prop_assert!((lo.psnr_db.unwrap() - hi.psnr_db.unwrap() - 20.0 * 2f64.log10()).abs() < 1e-3);
        }
    }
}
