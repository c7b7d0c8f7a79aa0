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
fn flags(estimate: &Cube, (lo, hi): (f32, f32), sam_undefined: usize) -> Vec<String> {
    let mut out = Vec::new();
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
    estimate.check_same_shape(truth, "estimate against truth")?;
    if truth.data.is_empty() {
        return Err(Error::Shape(format!(
            "comparing empty cubes ({}×{}×{}): no pixel to measure",
            truth.width, truth.height, truth.planes
        )));
    }
    let (t, e) = (value_range(&truth.data), value_range(&estimate.data));
    let (Some((_, peak)), Some(est_range)) = (t, e) else {
        return Err(Error::Numerical(
            "NaN or infinite values in a compared cube".into(),
        ));
    };
    let peak = peak as f64;
    if peak.is_nan() || peak <= 0.0 {
        return Err(Error::Numerical(format!(
            "the truth's peak is {peak}: PSNR and SSIM need a positive peak"
        )));
    }
    let n = truth.pixels() as f64;
    let planes: Vec<PlaneStats> = (0..truth.planes)
        .into_par_iter()
        .map(|k| {
            plane_stats(
                truth.plane(k),
                estimate.plane(k),
                truth.width,
                truth.height,
                peak,
            )
        })
        .collect();
    let mse: Vec<f64> = planes.iter().map(|p| p.sq_err / n).collect();
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
    let ssim_per_plane: Vec<f64> = planes.iter().map(|p| p.ssim).collect();
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
        flags: flags(estimate, est_range, sam_undefined),
    })
}

/// (min, max) of the values in one parallel pass, None when one is NaN or infinite
/// (Σ 0·v is 0 exactly when every v is finite: 0·∞ and 0·NaN are NaN). Kept in 16 lanes so that it vectorises.
fn value_range(data: &[f32]) -> Option<(f32, f32)> {
    const L: usize = 16;
    let (lo, hi, bad) = data
        .par_chunks(1 << 16)
        .map(|c| {
            let (mut lo, mut hi, mut bad) = ([f32::INFINITY; L], [f32::NEG_INFINITY; L], [0.0; L]);
            let mut lanes = c.chunks_exact(L);
            for v in &mut lanes {
                for i in 0..L {
                    lo[i] = if v[i] < lo[i] { v[i] } else { lo[i] };
                    hi[i] = if v[i] > hi[i] { v[i] } else { hi[i] };
                    bad[i] += 0.0 * v[i];
                }
            }
            for &v in lanes.remainder() {
                (lo[0], hi[0], bad[0]) = (lo[0].min(v), hi[0].max(v), bad[0] + 0.0 * v);
            }
            let min = lo.iter().fold(f32::INFINITY, |a, &b| a.min(b));
            let max = hi.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
            (min, max, bad.iter().sum::<f32>())
        })
        .reduce(
            || (f32::INFINITY, f32::NEG_INFINITY, 0.0),
            |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 + b.2),
        );
    (bad == 0.0).then_some((lo, hi))
}

/// Σ v in four interleaved partial sums (a reduction the compiler can keep in vector lanes).
fn lane_sum(v: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut lanes = v.chunks_exact(4);
    for c in &mut lanes {
        for i in 0..4 {
            acc[i] += c[i];
        }
    }
    (acc[0] + acc[2]) + (acc[1] + acc[3]) + lanes.remainder().iter().sum::<f64>()
}

/// Sum of spectral angles (radians) and the number of pixels counted. Pixels are taken in
/// blocks, each plane's slice of a block read contiguously; block sums are added in order, so
/// the figure does not depend on the threads' schedule.
fn sam(truth: &Cube, est: &Cube) -> (f64, usize) {
    const BLOCK: usize = 4096;
    let n = truth.pixels();
    let blocks: Vec<(f64, usize)> = (0..n.div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| {
            let p = b * BLOCK..((b + 1) * BLOCK).min(n);
            let (mut ab, mut aa, mut bb) = (
                vec![0.0f64; p.len()],
                vec![0.0; p.len()],
                vec![0.0; p.len()],
            );
            for k in 0..truth.planes {
                let (ta, eb) = (&truth.plane(k)[p.clone()], &est.plane(k)[p.clone()]);
                for i in 0..p.len() {
                    let (a, b) = (ta[i] as f64, eb[i] as f64);
                    (ab[i], aa[i], bb[i]) = (ab[i] + a * b, aa[i] + a * a, bb[i] + b * b);
                }
            }
            (0..p.len())
                .filter(|&i| aa[i] > 0.0 && bb[i] > 0.0)
                .fold((0.0, 0), |(s, c), i| {
                    (
                        s + (ab[i] / (aa[i] * bb[i]).sqrt()).clamp(-1.0, 1.0).acos(),
                        c + 1,
                    )
                })
        })
        .collect();
    blocks
        .iter()
        .fold((0.0, 0), |(s, c), &(bs, bc)| (s + bs, c + bc))
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

/// Σ_t g_t·rows[t][x] for every x < dst.len(), using the window's symmetry g_t = g_{10−t}:
/// rows t and 10 − t are added before one multiply (six multiplies instead of eleven).
fn filter_symmetric(rows: [&[f64]; 11], g: &[f64; 11], dst: &mut [f64]) {
    let n = dst.len();
    let r = rows.map(|r| &r[..n]);
    for (x, d) in dst.iter_mut().enumerate() {
        *d = g[0] * (r[0][x] + r[10][x])
            + g[1] * (r[1][x] + r[9][x])
            + g[2] * (r[2][x] + r[8][x])
            + g[3] * (r[3][x] + r[7][x])
            + g[4] * (r[4][x] + r[6][x])
            + g[5] * r[5][x];
    }
}

/// SSIM of one plane and its summed squared error, from one read of each.
struct PlaneStats {
    ssim: f64,
    sq_err: f64,
}

/// Mean SSIM of one plane (Wang et al. 2004) over the valid region; a plane smaller than the
/// window gives the single-window SSIM of the whole plane with uniform weights.
pub fn ssim_plane(a: &[f32], b: &[f32], w: usize, h: usize, range: f64) -> f64 {
    plane_stats(a, b, w, h, range).ssim
}

/// SSIM's formula from the window moments of s = a + b and d = a − b: with μ_a = (μ_s + μ_d)/2,
/// μ_b = (μ_s − μ_d)/2, σ_a² + σ_b² = (v_s + v_d)/2 and 2σ_ab = (v_s − v_d)/2,
/// SSIM = (μ_s² − μ_d² + 2C1)(v_s − v_d + 2C2) / ((μ_s² + μ_d² + 2C1)(v_s + v_d + 2C2)).
#[inline]
fn ssim_of_sum_and_difference(ms: f64, md: f64, ss: f64, dd: f64, c1: f64, c2: f64) -> f64 {
    let (ms2, md2) = (ms * ms, md * md);
    let (vs, vd) = (ss - ms2, dd - md2);
    ((ms2 - md2 + 2.0 * c1) * (vs - vd + 2.0 * c2))
        / ((ms2 + md2 + 2.0 * c1) * (vs + vd + 2.0 * c2))
}

/// The single-window SSIM of a plane smaller than 11 × 11 (uniform weights) and its squared error.
fn small_plane_stats(a: &[f32], b: &[f32], c1: f64, c2: f64) -> PlaneStats {
    let n = a.len() as f64;
    let s: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(&p, &q)| p as f64 + q as f64)
        .collect();
    let d: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(&p, &q)| p as f64 - q as f64)
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / n;
    let mean_sq = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>() / n;
    let sq_err = d.iter().map(|x| x * x).sum();
    PlaneStats {
        ssim: ssim_of_sum_and_difference(mean(&s), mean(&d), mean_sq(&s), mean_sq(&d), c1, c2),
        sq_err,
    }
}

/// SSIM and squared error of one plane. The Gaussian window is applied as rows then columns,
/// streaming: the row-filtered moments (s, d, s², d²) of the last 11 rows are kept in a ring, so
/// each plane is read once and nothing plane-sized is allocated.
fn plane_stats(a: &[f32], b: &[f32], w: usize, h: usize, range: f64) -> PlaneStats {
    let (c1, c2) = ((0.01 * range).powi(2), (0.03 * range).powi(2));
    if w < 11 || h < 11 {
        return small_plane_stats(a, b, c1, c2);
    }
    const TAPS: usize = 11;
    const MOMENTS: usize = 4; // s, d, s², d²
    let g = gaussian_taps();
    let ow = w - 10;
    // ring[(slot·4 + moment)·ow ..]: row-filtered moment of input row y, slot = y mod 11.
    let mut ring = vec![0.0f64; TAPS * MOMENTS * ow];
    let mut src = vec![0.0f64; MOMENTS * w];
    let mut col = vec![0.0f64; MOMENTS * ow];
    let mut out = vec![0.0f64; ow];
    let (mut total, mut sq_err) = (0.0, 0.0);
    for y in 0..h {
        let (ra, rb) = (&a[y * w..(y + 1) * w], &b[y * w..(y + 1) * w]);
        let (s, rest) = src.split_at_mut(w);
        let (d, rest) = rest.split_at_mut(w);
        let (ss, dd) = rest.split_at_mut(w);
        for x in 0..w {
            let (p, q) = (ra[x] as f64, rb[x] as f64);
            (s[x], d[x]) = (p + q, p - q);
            (ss[x], dd[x]) = (s[x] * s[x], d[x] * d[x]);
        }
        sq_err += lane_sum(dd);
        let slot = &mut ring[(y % TAPS) * MOMENTS * ow..][..MOMENTS * ow];
        for (m, dst) in src.chunks_exact(w).zip(slot.chunks_exact_mut(ow)) {
            filter_symmetric(std::array::from_fn(|t| &m[t..]), &g, dst);
        }
        if y + 1 < TAPS {
            continue;
        }
        // Output row y − 10 from input rows y − 10 ..= y, tap t on row y − 10 + t.
        let y0 = y + 1 - TAPS;
        for (m, dst) in col.chunks_exact_mut(ow).enumerate() {
            let rows =
                std::array::from_fn(|t| &ring[(((y0 + t) % TAPS) * MOMENTS + m) * ow..][..ow]);
            filter_symmetric(rows, &g, dst);
        }
        let (ms, rest) = col.split_at(ow);
        let (md, rest) = rest.split_at(ow);
        let (ss, dd) = rest.split_at(ow);
        for x in 0..ow {
            out[x] = ssim_of_sum_and_difference(ms[x], md[x], ss[x], dd[x], c1, c2);
        }
        total += lane_sum(&out);
    }
    PlaneStats {
        ssim: total / (ow * (h - 10)) as f64,
        sq_err,
    }
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

    /// PSNR per plane, SSIM per plane and SAM by their definitions, one pixel at a time.
    fn direct_figures(t: &Cube, e: &Cube) -> (Vec<f64>, Vec<f64>, f64) {
        let peak = t.max() as f64;
        let n = t.pixels();
        let psnr = (0..t.planes)
            .map(|k| {
                let se: f64 = (0..n)
                    .map(|p| (t.plane(k)[p] as f64 - e.plane(k)[p] as f64).powi(2))
                    .sum();
                10.0 * (peak * peak / (se / n as f64)).log10()
            })
            .collect();
        let ssim = (0..t.planes)
            .map(|k| ssim_direct(t.plane(k), e.plane(k), t.width, t.height, peak))
            .collect();
        let angles: Vec<f64> = (0..n)
            .map(|p| {
                let (mut d, mut a2, mut b2) = (0.0, 0.0, 0.0);
                for k in 0..t.planes {
                    let (a, b) = (t.plane(k)[p] as f64, e.plane(k)[p] as f64);
                    (d, a2, b2) = (d + a * b, a2 + a * a, b2 + b * b);
                }
                (d / (a2 * b2).sqrt()).clamp(-1.0, 1.0).acos()
            })
            .collect();
        let sam = angles.iter().sum::<f64>() / n as f64;
        (psnr, ssim, sam.to_degrees())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(8))]
        /// The fused, blocked figures (SAM over 4096-pixel blocks, the squared error summed in
        /// the SSIM pass) agree with the definitions on cubes that span several SAM blocks.
        #[test]
        fn fused_figures_match_their_definitions(
            seed in 0u64..1000, w in 11usize..90, h in 50usize..90, amp in 0.01f32..0.5,
        ) {
            let f = |i: usize, s: u64| (((i as u64 * 2654435761 + s * 7919) % 1009) as f32) / 1009.0;
            let t = cube(w, h, 3, |i| 0.1 + f(i, seed));
            let e = cube(w, h, 3, |i| 0.1 + f(i, seed) + amp * (f(i, seed + 1) - 0.5));
            let m = compare(&t, &e).unwrap();
            let (psnr, ssim, sam) = direct_figures(&t, &e);
            for k in 0..3 {
                prop_assert!((m.psnr_per_plane[k] - psnr[k]).abs() < 1e-9, "{k}: {} vs {}", m.psnr_per_plane[k], psnr[k]);
                prop_assert!((m.ssim_per_plane[k] - ssim[k]).abs() < 1e-9 * ssim[k].abs(), "{k}: {} vs {}", m.ssim_per_plane[k], ssim[k]);
            }
            prop_assert!((m.sam_deg.unwrap() - sam).abs() < 1e-9, "{:?} vs {sam}", m.sam_deg);
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
        // Past the 16 lanes of the range pass: index 20 of 25 lies in the remainder.
        let nan = cube(5, 5, 1, |i| if i == 20 { f32::NAN } else { 1.0 });
        assert!(compare(&nan, &nan).is_err());
        let inf = cube(4, 4, 1, |i| if i == 5 { f32::NEG_INFINITY } else { 1.0 });
        assert!(compare(&inf, &t).is_err() && compare(&t, &inf).is_err());
        // The shapes in the order the message names them: the estimate's, then the truth's.
        let e = compare(&t, &cube(4, 2, 1, |_| 0.0))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("estimate against truth: 4 wide × 2 high × 1 planes against 4 wide × 4 high × 1 planes"),
            "{e}"
        );
        let m = compare(&t, &t).unwrap();
        assert_eq!(m.exact_planes, 1);
        assert!(m.psnr_db.is_infinite() && m.ssim == 1.0);
        // No pixel: said so, not "the truth's peak is -inf".
        let empty = Cube::zeros(0, 4, 3);
        let e = compare(&empty, &empty).unwrap_err().to_string();
        assert!(e.contains("comparing empty cubes (0×4×3)"), "{e}");
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
