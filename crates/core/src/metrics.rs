//! Error against the truth: PSNR, SSIM, RMSE/NRMSE and the spectral angle (SAM).
//! Conventions: the peak of PSNR and the dynamic range L of SSIM are the truth's maximum over the
//! whole cube (one figure for all planes, as for data scaled to [0, 1]); per-plane figures are
//! averaged over planes.

use crate::error::Error;
use crate::error::Result;
use crate::Cube;
use rayon::prelude::*;
use serde::Serialize;

/// Figures of one estimate against its truth.
#[derive(Clone, Debug, Serialize)]
pub struct Metrics {
    /// Mean of the per-plane PSNR over planes with a non-zero error, in dB.
    pub psnr_db: f64,
    /// Per plane; +∞ (written as null in JSON) where the plane is exact.
    pub psnr_per_plane: Vec<f64>,
    /// Planes reproduced exactly (left out of the mean PSNR).
    pub exact_planes: usize,
    pub ssim: f64,
    pub ssim_per_plane: Vec<f64>,
    /// RMSE over all values, in the data's units.
    pub rmse: f64,
    /// RMSE divided by the peak.
    pub nrmse: f64,
    /// Mean spectral angle in degrees over pixels where both spectra are non-zero; None (null
    /// in JSON, "undefined" in tables) when there is no such pixel.
    pub sam_deg: Option<f64>,
    /// Pixels where the angle is undefined because a spectrum is zero (left out of SAM).
    pub sam_undefined: usize,
    pub peak: f64,
    /// What makes these figures less than they seem: a degenerate estimate (all zero,
    /// constant) or SAM undefined on part of the image. Empty when nothing is amiss.
    pub flags: Vec<String>,
}

/// A figure for a table: `undefined` for None, else with `digits` decimals.
pub fn show(value: Option<f64>, digits: usize) -> String {
    value.map_or_else(|| "undefined".into(), |v| format!("{v:.digits$}"))
}

/// The warnings an estimate deserves whatever its error: degenerate content, undefined angles.
fn flags(estimate: &Cube, sam_undefined: usize) -> Vec<String> {
    let mut out = Vec::new();
    let (lo, hi) = estimate
        .data
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    if hi == 0.0 && lo == 0.0 {
        out.push("the estimate is zero everywhere".into());
    } else if hi == lo {
        out.push(format!("the estimate is constant ({hi})"));
    }
    if sam_undefined > 0 {
        out.push(format!(
            "SAM undefined at {sam_undefined} of {} pixels (a zero spectrum has no angle)",
            estimate.pixels()
        ));
    }
    out
}

/// Compare an estimate with the truth (same shape).
pub fn compare(truth: &Cube, estimate: &Cube) -> Result<Metrics> {
    truth.check_same_shape(estimate, "estimate against truth")?;
    if !estimate.all_finite() || !truth.all_finite() {
        return Err(Error::Numerical(
            "NaN or infinite values in a compared cube".into(),
        ));
    }
    let peak = truth.max() as f64;
    if peak.is_nan() || peak <= 0.0 {
        return Err(Error::Numerical(format!(
            "the truth's peak is {peak}: PSNR and SSIM need a positive peak"
        )));
    }
    let n = truth.pixels() as f64;
    let mse: Vec<f64> = (0..truth.planes)
        .into_par_iter()
        .map(|k| {
            let s: f64 = truth
                .plane(k)
                .iter()
                .zip(estimate.plane(k))
                .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
                .sum();
            s / n
        })
        .collect();
    let psnr_per_plane: Vec<f64> = mse
        .iter()
        .map(|&m| {
            if m > 0.0 {
                10.0 * (peak * peak / m).log10()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let finite: Vec<f64> = psnr_per_plane
        .iter()
        .cloned()
        .filter(|v| v.is_finite())
        .collect();
    let exact_planes = psnr_per_plane.len() - finite.len();
    let psnr_db = if finite.is_empty() {
        f64::INFINITY
    } else {
        finite.iter().sum::<f64>() / finite.len() as f64
    };
    let ssim_per_plane: Vec<f64> = (0..truth.planes)
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
        .collect();
    let ssim = ssim_per_plane.iter().sum::<f64>() / ssim_per_plane.len() as f64;
    let rmse = (mse.iter().sum::<f64>() / mse.len() as f64).sqrt();
    let (sam_sum, sam_count) = sam(truth, estimate);
    let sam_undefined = truth.pixels() - sam_count;
    Ok(Metrics {
        psnr_db,
        psnr_per_plane,
        exact_planes,
        ssim,
        ssim_per_plane,
        rmse,
        nrmse: rmse / peak,
        sam_deg: (sam_count > 0).then(|| (sam_sum / sam_count as f64).to_degrees()),
        sam_undefined,
        peak,
        flags: flags(estimate, sam_undefined),
    })
}

/// Sum of spectral angles (radians) and the number of pixels counted.
fn sam(truth: &Cube, est: &Cube) -> (f64, usize) {
    (0..truth.pixels())
        .into_par_iter()
        .with_min_len(4096)
        .map(|p| {
            let (mut d, mut a2, mut b2) = (0.0f64, 0.0f64, 0.0f64);
            for k in 0..truth.planes {
                let (a, b) = (truth.plane(k)[p] as f64, est.plane(k)[p] as f64);
                d += a * b;
                a2 += a * a;
                b2 += b * b;
            }
            if a2 > 0.0 && b2 > 0.0 {
                ((d / (a2 * b2).sqrt()).clamp(-1.0, 1.0).acos(), 1)
            } else {
                (0.0, 0)
            }
        })
        .reduce(|| (0.0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
}

/// The 11-tap Gaussian of σ = 1.5, normalised to sum 1.
fn gaussian_taps() -> [f64; 11] {
    let mut g = [0.0; 11];
    for (i, v) in g.iter_mut().enumerate() {
        let x = i as f64 - 5.0;
        *v = (-x * x / (2.0 * 1.5 * 1.5)).exp();
    }
    let s: f64 = g.iter().sum();
    g.map(|v| v / s)
}

/// 'Valid' filtering of one row with the 11-tap window (output `src.len() − 10` values),
/// accumulated tap by tap in the order of the direct sum Σ_t g_t·src[x + t].
fn filter_row(src: &[f64], g: &[f64; 11], dst: &mut [f64]) {
    dst.fill(0.0);
    for (t, &gt) in g.iter().enumerate() {
        for (d, &s) in dst.iter_mut().zip(&src[t..]) {
            *d += gt * s;
        }
    }
}

/// Mean SSIM of one plane (Wang et al. 2004) over the valid region; a plane smaller than the
/// window gives the single-window SSIM of the whole plane with uniform weights. The Gaussian
/// window is applied as rows then columns, streaming: the row-filtered moments of the last 11
/// rows are kept in a ring, so each plane is read once and nothing plane-sized is allocated.
pub fn ssim_plane(a: &[f32], b: &[f32], w: usize, h: usize, range: f64) -> f64 {
    let (c1, c2) = ((0.01 * range).powi(2), (0.03 * range).powi(2));
    let formula = |ma: f64, mb: f64, va: f64, vb: f64, cov: f64| {
        ((2.0 * ma * mb + c1) * (2.0 * cov + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
    };
    if w < 11 || h < 11 {
        let a: Vec<f64> = a.iter().map(|&v| v as f64).collect();
        let b: Vec<f64> = b.iter().map(|&v| v as f64).collect();
        let n = a.len() as f64;
        let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
        let va = a.iter().map(|v| (v - ma).powi(2)).sum::<f64>() / n;
        let vb = b.iter().map(|v| (v - mb).powi(2)).sum::<f64>() / n;
        let cov = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - ma) * (y - mb))
            .sum::<f64>()
            / n;
        return formula(ma, mb, va, vb, cov);
    }
    const TAPS: usize = 11;
    const MOMENTS: usize = 5; // a, b, a², b², ab
    let g = gaussian_taps();
    let ow = w - 10;
    // ring[(slot·5 + moment)·ow ..]: row-filtered moment of input row y, slot = y mod 11.
    let mut ring = vec![0.0f64; TAPS * MOMENTS * ow];
    let mut src = vec![0.0f64; MOMENTS * w];
    let mut col = vec![0.0f64; MOMENTS * ow];
    let mut total = 0.0;
    for y in 0..h {
        let (ra, rb) = (&a[y * w..(y + 1) * w], &b[y * w..(y + 1) * w]);
        let (sa, rest) = src.split_at_mut(w);
        let (sb, rest) = rest.split_at_mut(w);
        let (saa, rest) = rest.split_at_mut(w);
        let (sbb, sab) = rest.split_at_mut(w);
        for x in 0..w {
            let (p, q) = (ra[x] as f64, rb[x] as f64);
            (sa[x], sb[x], saa[x], sbb[x], sab[x]) = (p, q, p * p, q * q, p * q);
        }
        let slot = &mut ring[(y % TAPS) * MOMENTS * ow..][..MOMENTS * ow];
        for (s, d) in src.chunks_exact(w).zip(slot.chunks_exact_mut(ow)) {
            filter_row(s, &g, d);
        }
        if y + 1 < TAPS {
            continue;
        }
        // Output row y − 10 from input rows y − 10 ..= y, tap t on row y − 10 + t.
        let y0 = y + 1 - TAPS;
        col.fill(0.0);
        for (t, &gt) in g.iter().enumerate() {
            let slot = &ring[((y0 + t) % TAPS) * MOMENTS * ow..][..MOMENTS * ow];
            for (c, &r) in col.iter_mut().zip(slot) {
                *c += gt * r;
            }
        }
        let (ma, rest) = col.split_at(ow);
        let (mb, rest) = rest.split_at(ow);
        let (saa, rest) = rest.split_at(ow);
        let (sbb, sab) = rest.split_at(ow);
        for x in 0..ow {
            let (m1, m2) = (ma[x], mb[x]);
            total += formula(m1, m2, saa[x] - m1 * m1, sbb[x] - m2 * m2, sab[x] - m1 * m2);
        }
    }
    total / (ow * (h - 10)) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cube(w: usize, h: usize, planes: usize, f: impl Fn(usize) -> f32) -> Cube {
        Cube::from_vec(w, h, planes, (0..w * h * planes).map(f).collect()).unwrap()
    }

    #[test]
    fn psnr_and_nrmse_of_a_constant_error() {
        // Peak 1, error 0.1 everywhere: MSE 0.01, PSNR = 10·log10(1/0.01) = 20 dB, NRMSE 0.1.
        let t = cube(16, 16, 2, |i| if i == 0 { 1.0 } else { 0.5 });
        let e = cube(16, 16, 2, |i| if i == 0 { 1.1 } else { 0.6 });
        let m = compare(&t, &e).unwrap();
        assert!((m.psnr_db - 20.0).abs() < 1e-5, "{}", m.psnr_db);
        assert!((m.nrmse - 0.1).abs() < 1e-6);
    }

    #[test]
    fn ssim_of_constants_by_hand() {
        // Two constant images a and b: σ = 0, SSIM = (2ab + C1)/(a² + b² + C1).
        let (a, b, l) = (0.5f32, 0.25f32, 1.0f64);
        let s = ssim_plane(&[a; 400], &[b; 400], 20, 20, l);
        let c1 = (0.01 * l).powi(2);
        let want = (2.0 * 0.5 * 0.25 + c1) / (0.25 + 0.0625 + c1);
        assert!((s - want).abs() < 1e-12, "{s} vs {want}");
        assert!((ssim_plane(&[a; 400], &[a; 400], 20, 20, l) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ssim_of_a_contrast_change_by_hand() {
        // A zero-mean ±1 checkerboard against a version scaled by k: in every window the Gaussian
        // means are equal for both (μ_b = k·μ_a), σ_b² = k²σ_a², σ_ab = kσ_a², so with μ ≈ 0 the
        // SSIM is (C1)(2kσ² + C2)/((C1)(σ²(1+k²) + C2)) = (2kσ² + C2)/((1 + k²)σ² + C2), σ² ≈ 1.
        let (w, h, k) = (41usize, 41usize, 0.5f32);
        let a: Vec<f32> = (0..w * h)
            .map(|i| if (i % w + i / w) % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let b: Vec<f32> = a.iter().map(|v| v * k).collect();
        let s = ssim_plane(&a, &b, w, h, 2.0);
        let c2 = (0.03f64 * 2.0).powi(2);
        let g = gaussian_taps();
        // Exact local moments of the checkerboard under the Gaussian window.
        let alt: f64 = (0..11)
            .map(|i| g[i] * if i % 2 == 0 { 1.0 } else { -1.0 })
            .sum();
        let mu2 = alt * alt * alt * alt; // μ_a² = (Σ±g)⁴ for the separable window
        let var = 1.0 - mu2;
        let c1 = (0.01f64 * 2.0).powi(2);
        let kk = k as f64;
        let want = ((2.0 * kk * mu2 + c1) * (2.0 * kk * var + c2))
            / (((1.0 + kk * kk) * mu2 + c1) * ((1.0 + kk * kk) * var + c2));
        assert!((s - want).abs() < 1e-9, "{s} vs {want}");
    }

    /// The direct definition: the 11×11 window g_i·g_j summed in full at every valid pixel.
    fn ssim_direct(a: &[f32], b: &[f32], w: usize, h: usize, range: f64) -> f64 {
        let (c1, c2) = ((0.01 * range).powi(2), (0.03 * range).powi(2));
        let g = gaussian_taps();
        let mut total = 0.0;
        for y in 0..h - 10 {
            for x in 0..w - 10 {
                let mut m = [0.0f64; 5];
                for i in 0..11 {
                    for j in 0..11 {
                        let wt = g[i] * g[j];
                        let (p, q) = (a[(y + i) * w + x + j] as f64, b[(y + i) * w + x + j] as f64);
                        for (acc, v) in m.iter_mut().zip([p, q, p * p, q * q, p * q]) {
                            *acc += wt * v;
                        }
                    }
                }
                let [ma, mb, saa, sbb, sab] = m;
                let (va, vb, cov) = (saa - ma * ma, sbb - mb * mb, sab - ma * mb);
                total += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                    / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            }
        }
        total / ((w - 10) * (h - 10)) as f64
    }

    #[test]
    fn streamed_separable_ssim_matches_the_direct_window() {
        // Rectangular planes (w ≠ h, both above 11) of unrelated content and a noisy copy.
        for (w, h, seed) in [(37usize, 23usize, 1u64), (11, 40, 2), (64, 12, 3)] {
            let a: Vec<f32> = (0..w * h)
                .map(|i| (((i as u64 * 2654435761 + seed * 97) % 1009) as f32) / 1009.0)
                .collect();
            let b: Vec<f32> = a
                .iter()
                .enumerate()
                .map(|(i, v)| 0.8 * v + 0.3 * (((i * 31 + 7) % 13) as f32 / 13.0))
                .collect();
            let (fast, direct) = (
                ssim_plane(&a, &b, w, h, 1.0),
                ssim_direct(&a, &b, w, h, 1.0),
            );
            assert!(
                (fast - direct).abs() <= 1e-9 * direct.abs(),
                "{w}×{h}: {fast} vs {direct}"
            );
        }
    }

    #[test]
    fn sam_of_orthogonal_and_scaled_spectra() {
        let t = Cube::from_vec(2, 1, 2, vec![1.0, 3.0, 0.0, 1.0]).unwrap();
        let e = Cube::from_vec(2, 1, 2, vec![0.0, 6.0, 2.0, 2.0]).unwrap();
        // Pixel 0: (1,0) vs (0,2) → 90°; pixel 1: (3,1) vs (6,2) → 0°.
        let m = compare(&t, &e).unwrap();
        assert!((m.sam_deg.unwrap() - 45.0).abs() < 1e-9);
        assert!(m.flags.is_empty(), "{:?}", m.flags);
    }

    #[test]
    fn a_zero_estimate_cannot_flatter() {
        // An all-zero cube (what η = 1e300 gives) has no spectral angle anywhere: undefined, not 0°.
        let t = cube(4, 4, 3, |i| 0.1 + i as f32);
        let m = compare(&t, &cube(4, 4, 3, |_| 0.0)).unwrap();
        assert_eq!(m.sam_deg, None);
        assert_eq!(m.sam_undefined, 16);
        assert!(
            m.flags.iter().any(|f| f.contains("zero everywhere")),
            "{:?}",
            m.flags
        );
        assert_eq!(show(m.sam_deg, 2), "undefined");
        let c = compare(&t, &cube(4, 4, 3, |_| 0.5)).unwrap();
        assert!(
            c.flags.iter().any(|f| f.contains("constant")),
            "{:?}",
            c.flags
        );
        assert!(c.sam_deg.is_some());
    }

    #[test]
    fn bad_inputs_are_errors() {
        let t = cube(4, 4, 1, |_| 0.0);
        assert!(compare(&t, &t).is_err());
        let t = cube(4, 4, 1, |i| i as f32);
        let e = cube(4, 4, 1, |i| if i == 3 { f32::NAN } else { 0.0 });
        assert!(compare(&t, &e).is_err());
        assert!(compare(&t, &cube(4, 2, 1, |_| 0.0)).is_err());
        let m = compare(&t, &t).unwrap();
        assert_eq!(m.exact_planes, 1);
        assert!(m.psnr_db.is_infinite() && m.ssim == 1.0);
    }

    proptest! {
        #[test]
        fn ssim_is_symmetric_and_at_most_one(seed in 0u64..1000, amp in 0.0f32..0.5) {
            let a: Vec<f32> = (0..24 * 24).map(|i| (((i as u64 * 2654435761 + seed) % 97) as f32) / 97.0).collect();
            let b: Vec<f32> = a.iter().enumerate().map(|(i, v)| v + amp * (((i * 31) % 7) as f32 / 7.0 - 0.5)).collect();
            let s1 = ssim_plane(&a, &b, 24, 24, 1.0);
            let s2 = ssim_plane(&b, &a, 24, 24, 1.0);
            prop_assert!((s1 - s2).abs() < 1e-12);
            prop_assert!(s1 <= 1.0 + 1e-12);
        }

        #[test]
        fn psnr_falls_as_noise_grows(k in 1.1f32..4.0) {
            let t = cube(16, 16, 1, |i| (i % 13) as f32 / 13.0 + 0.1);
            let noise = |s: f32| cube(16, 16, 1, |i| (i % 13) as f32 / 13.0 + 0.1 + s * (((i * 7) % 5) as f32 - 2.0) / 10.0);
            let p1 = compare(&t, &noise(0.1)).unwrap().psnr_db;
            let p2 = compare(&t, &noise(0.1 * k)).unwrap().psnr_db;
            prop_assert!(p2 < p1);
        }
    }
}
