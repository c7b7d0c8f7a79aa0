//! Binarisation of a grey target t ∈ [0, 1] into mirror states b ∈ {0, 1}: plain threshold,
//! ordered (Bayer) dithering, serpentine error diffusion (Floyd–Steinberg, Jarvis–Judice–Ninke,
//! Stucki), and our in-band feedback method, which re-dithers a pre-compensated target until the
//! quantisation error inside the Fourier filter's passband is small.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use specmux_core::fft::Fft2;

/// How the DMD turns a grey pattern into a binary one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DitherMethod {
    /// b = [t > ½]: a square wave, all of the error in harmonics.
    Threshold,
    /// Ordered dithering against a recursive Bayer matrix (`bayer_tile` × `bayer_tile`).
    Bayer,
    /// Serpentine Floyd–Steinberg error diffusion (4 neighbours, weights 7, 3, 5, 1 / 16).
    FloydSteinberg,
    /// Serpentine Jarvis–Judice–Ninke error diffusion (12 neighbours / 48).
    Jarvis,
    /// Serpentine Stucki error diffusion (12 neighbours / 42).
    Stucki,
    /// Ours: Floyd–Steinberg on a target pre-compensated by the in-band error of the previous
    /// binary pattern, iterated; keeps the iterate with the least in-band error.
    InBandFeedback,
}

impl DitherMethod {
    pub const ALL: [DitherMethod; 6] = [
        DitherMethod::Threshold,
        DitherMethod::Bayer,
        DitherMethod::FloydSteinberg,
        DitherMethod::Jarvis,
        DitherMethod::Stucki,
        DitherMethod::InBandFeedback,
    ];

    /// The name used in the experiment file.
    pub fn name(&self) -> &'static str {
        match self {
            DitherMethod::Threshold => "threshold",
            DitherMethod::Bayer => "bayer",
            DitherMethod::FloydSteinberg => "floyd-steinberg",
            DitherMethod::Jarvis => "jarvis",
            DitherMethod::Stucki => "stucki",
            DitherMethod::InBandFeedback => "in-band-feedback",
        }
    }
}

/// An error-diffusion kernel: (dx along the scan direction, dy, weight); weights sum to 1.
type Kernel = [(i32, i32, f32)];

const FLOYD_STEINBERG: [(i32, i32, f32); 4] = [
    (1, 0, 7.0 / 16.0),
    (-1, 1, 3.0 / 16.0),
    (0, 1, 5.0 / 16.0),
    (1, 1, 1.0 / 16.0),
];

const JARVIS: [(i32, i32, f32); 12] = [
    (1, 0, 7.0 / 48.0),
    (2, 0, 5.0 / 48.0),
    (-2, 1, 3.0 / 48.0),
    (-1, 1, 5.0 / 48.0),
    (0, 1, 7.0 / 48.0),
    (1, 1, 5.0 / 48.0),
    (2, 1, 3.0 / 48.0),
    (-2, 2, 1.0 / 48.0),
    (-1, 2, 3.0 / 48.0),
    (0, 2, 5.0 / 48.0),
    (1, 2, 3.0 / 48.0),
    (2, 2, 1.0 / 48.0),
];

const STUCKI: [(i32, i32, f32); 12] = [
    (1, 0, 8.0 / 42.0),
    (2, 0, 4.0 / 42.0),
    (-2, 1, 2.0 / 42.0),
    (-1, 1, 4.0 / 42.0),
    (0, 1, 8.0 / 42.0),
    (1, 1, 4.0 / 42.0),
    (2, 1, 2.0 / 42.0),
    (-2, 2, 1.0 / 42.0),
    (-1, 2, 2.0 / 42.0),
    (0, 2, 4.0 / 42.0),
    (1, 2, 2.0 / 42.0),
    (2, 2, 1.0 / 42.0),
];

/// Serpentine error diffusion: even rows left to right, odd rows right to left with the kernel
/// mirrored. Error pushed past the image border is lost (the mean drifts by at most a border's
/// worth of error).
fn error_diffusion(target: &[f32], w: usize, h: usize, kernel: &Kernel) -> Vec<f32> {
    let mut buf = target.to_vec();
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        let forward = y % 2 == 0;
        for i in 0..w {
            let x = if forward { i } else { w - 1 - i };
            let v = buf[y * w + x];
            let b = if v > 0.5 { 1.0 } else { 0.0 };
            out[y * w + x] = b;
            let err = v - b;
            for &(dx, dy, wt) in kernel {
                let xx = x as i64 + if forward { dx as i64 } else { -(dx as i64) };
                let yy = y + dy as usize;
                if xx >= 0 && (xx as usize) < w && yy < h {
                    buf[yy * w + xx as usize] += err * wt;
                }
            }
        }
    }
    out
}

/// The n × n Bayer index matrix (n a power of two), entries 0..n².
fn bayer_matrix(n: usize) -> Vec<u32> {
    let mut m = vec![0u32];
    let mut size = 1;
    while size < n {
        let mut next = vec![0u32; 4 * size * size];
        for y in 0..size {
            for x in 0..size {
                let v = 4 * m[y * size + x];
                let s2 = 2 * size;
                next[y * s2 + x] = v;
                next[y * s2 + x + size] = v + 2;
                next[(y + size) * s2 + x] = v + 3;
                next[(y + size) * s2 + x + size] = v + 1;
            }
        }
        m = next;
        size *= 2;
    }
    m
}

/// Ordered dithering: b = [t > (index + ½)/n²] with the index tiled over the image.
fn ordered(target: &[f32], w: usize, tile: usize) -> Vec<f32> {
    let m = bayer_matrix(tile);
    let n2 = (tile * tile) as f32;
    target
        .iter()
        .enumerate()
        .map(|(p, &t)| {
            let (x, y) = (p % w, p / w);
            let thr = (m[(y % tile) * tile + x % tile] as f32 + 0.5) / n2;
            if t > thr {
                1.0
            } else {
                0.0
            }
        })
        .collect()
}

/// A passband on the pattern's frequency grid: weight (0 or 1) at (fx, fy) in cycles per pixel.
pub type Passband<'a> = &'a (dyn Fn(f64, f64) -> f64 + Sync);

/// Binary pattern of `target` (`w × h`, values in [0, 1]) by `method`. `passband` is only used
/// by `InBandFeedback` (`iterations` re-dithers); `tile` only by `Bayer` (a power of two).
pub fn dither(
    target: &[f32],
    w: usize,
    h: usize,
    method: DitherMethod,
    tile: usize,
    passband: Passband,
    iterations: usize,
) -> Vec<f32> {
    match method {
        DitherMethod::Threshold => target
            .iter()
            .map(|&t| if t > 0.5 { 1.0 } else { 0.0 })
            .collect(),
        DitherMethod::Bayer => ordered(target, w, tile),
        DitherMethod::FloydSteinberg => error_diffusion(target, w, h, &FLOYD_STEINBERG),
        DitherMethod::Jarvis => error_diffusion(target, w, h, &JARVIS),
        DitherMethod::Stucki => error_diffusion(target, w, h, &STUCKI),
        DitherMethod::InBandFeedback => in_band_feedback(target, w, h, passband, iterations),
    }
}

/// The passband at every bin of a `w × h` half spectrum (`HalfSpectrum`'s column-major
/// order), evaluated once so that repeated band passes only multiply.
fn passband_weights(w: usize, h: usize, passband: Passband) -> Vec<f32> {
    let mut weights = vec![0.0f32; (w / 2 + 1) * h];
    weights.par_chunks_mut(h).enumerate().for_each(|(kx, col)| {
        let fx = kx as f64 / w as f64;
        for (ky, v) in col.iter_mut().enumerate() {
            *v = passband(fx, signed_bin(ky, h) as f64 / h as f64) as f32;
        }
    });
    weights
}

/// The in-band part of an image: IFFT(P · FFT(img)), and the energy Σ|P · FFT|², P given by
/// its [`passband_weights`].
fn band_pass(fft: &Fft2, img: &[f32], weights: &[f32]) -> (Vec<f32>, f64) {
    let (w, h) = (fft.w, fft.h);
    let mut spec = fft.forward(img);
    let energy: f64 = spec
        .data
        .par_chunks_mut(h)
        .zip(weights.par_chunks(h))
        .enumerate()
        .map(|(kx, (col, p))| {
            // Columns 1..w/2 (excluding a Nyquist column) stand for themselves and their mirror.
            let mult = if kx == 0 || 2 * kx == w { 1.0 } else { 2.0 };
            let mut e = 0.0;
            for (v, &p) in col.iter_mut().zip(p) {
                *v *= p;
                e += mult * v.norm_sqr() as f64;
            }
            e
        })
        .sum();
    let mut out = vec![0.0f32; w * h];
    fft.inverse_into(spec.data, &mut out);
    (out, energy)
}

/// Bin index in −n/2..n/2 for a stored index 0..n.
pub(crate) fn signed_bin(k: usize, n: usize) -> i64 {
    if 2 * k > n {
        k as i64 - n as i64
    } else {
        k as i64
    }
}

/// Σ|P·FFT(img)|² over the whole frequency plane (unnormalised DFT).
pub fn in_band_energy(img: &[f32], w: usize, h: usize, passband: Passband) -> f64 {
    band_pass(&Fft2::new(w, h), img, &passband_weights(w, h, passband)).1
}

/// Relative in-band error ‖P·(B − T)‖ / ‖P·T‖: the quantisation error that the Fourier filter
/// lets through, relative to the in-band part of the target (DC and the carrier orders).
pub fn in_band_error(
    binary: &[f32],
    target: &[f32],
    w: usize,
    h: usize,
    passband: Passband,
) -> f64 {
    let diff: Vec<f32> = binary.iter().zip(target).map(|(b, t)| b - t).collect();
    let e = in_band_energy(&diff, w, h, passband);
    let t = in_band_energy(target, w, h, passband);
    (e / t.max(f64::MIN_POSITIVE)).sqrt()
}

/// Ours, "error diffusion with in-band feedback": start from Floyd–Steinberg, then repeatedly
/// measure the in-band error e = P·(b − t) and toggle mirrors to cancel it. Toggling mirror p
/// by δ = ±1 changes the in-band error energy by 2δN·e(p) + |P| (N pixels, |P| passband bins),
/// so the wanted toggle density is −e(p); it is itself error-diffused into a sparse toggle
/// field q ∈ {−1, 0, +1} (only 0 → 1 or 1 → 0 allowed), which puts the selection's own error
/// outside the passband. Returns the iterate with the least in-band error; stops early at zero
/// in-band error or when no mirror toggles (on the full rig's six patterns after 0, 0, 0, 1, 1
/// and 8 of the 8 re-dithers allowed).
fn in_band_feedback(
    target: &[f32],
    w: usize,
    h: usize,
    passband: Passband,
    iterations: usize,
) -> Vec<f32> {
    let fft = Fft2::new(w, h);
    let weights = passband_weights(w, h, passband);
    let mut b = error_diffusion(target, w, h, &FLOYD_STEINBERG);
    let mut best: Option<(f64, Vec<f32>)> = None;
    for it in 0..=iterations {
        let diff: Vec<f32> = b.iter().zip(target).map(|(b, t)| b - t).collect();
        let (err_in_band, energy) = band_pass(&fft, &diff, &weights);
        if best.as_ref().map_or(true, |(e, _)| energy < *e) {
            best = Some((energy, b.clone()));
        }
        if it == iterations || energy == 0.0 {
            break;
        }
        // No toggle: every later iterate would repeat this one.
        if diffuse_toggles(&mut b, &err_in_band, w, h) == 0 {
            break;
        }
    }
    best.map(|(_, b)| b).unwrap_or_default()
}

/// Toggles that cancel the in-band error `e`: the densities of switching on (−e where a mirror
/// is off) and off (e where it is on) are each error-diffused into a sparse set of mirrors.
/// Diffusing the two signs separately matters: a carrier-frequency error alternates in sign
/// within a few pixels and would cancel itself in a single diffusion. Returns how many mirrors
/// toggled.
fn diffuse_toggles(b: &mut [f32], e: &[f32], w: usize, h: usize) -> usize {
    let density = |on: f32| -> Vec<f32> {
        b.iter()
            .zip(e)
            .map(|(&bv, &ev)| {
                if bv == on {
                    0.0
                } else {
                    (if on == 1.0 { -ev } else { ev }).max(0.0)
                }
            })
            .collect()
    };
    let up = error_diffusion(&density(1.0), w, h, &FLOYD_STEINBERG);
    let down = error_diffusion(&density(0.0), w, h, &FLOYD_STEINBERG);
    let mut toggled = 0;
    for ((bv, u), d) in b.iter_mut().zip(&up).zip(&down) {
        if *bv == 0.0 && *u == 1.0 {
            *bv = 1.0;
            toggled += 1;
        } else if *bv == 1.0 && *d == 1.0 {
            *bv = 0.0;
            toggled += 1;
        }
    }
    toggled
}

#[cfg(test)]
mod tests {
    use super::*;
    use specmux_core::carriers::Carrier;

    fn target(c: &Carrier, w: usize, h: usize) -> Vec<f32> {
        c.ideal_pattern(w, h).iter().map(|v| v / 2.0).collect()
    }

    /// Holes of radius `r` at 0 and ±(fx, fy).
    fn holes(fx: f64, fy: f64, r: f64) -> impl Fn(f64, f64) -> f64 + Sync {
        move |x: f64, y: f64| {
            let near = |cx: f64, cy: f64| (x - cx).hypot(y - cy) <= r;
            if near(0.0, 0.0) || near(fx, fy) || near(-fx, -fy) {
                1.0
            } else {
                0.0
            }
        }
    }

    #[test]
    fn bayer_matrix_is_a_permutation_with_the_classic_2x2() {
        assert_eq!(bayer_matrix(2), vec![0, 2, 3, 1]);
        let mut m = bayer_matrix(8);
        m.sort();
        assert_eq!(m, (0..64).collect::<Vec<u32>>());
    }

    #[test]
    fn dithered_patterns_are_binary_and_keep_the_mean() {
        let (w, h) = (128, 96);
        let c = Carrier {
            fx: 0.13,
            fy: 0.07,
            phase_rad: 0.4,
        };
        let t = target(&c, w, h);
        let mean_t = t.iter().map(|&v| v as f64).sum::<f64>() / t.len() as f64;
        let pb = holes(c.fx, c.fy, 0.03);
        for m in DitherMethod::ALL {
            let b = dither(&t, w, h, m, 8, &pb, 6);
            assert!(b.iter().all(|&v| v == 0.0 || v == 1.0), "{m:?}");
            let mean_b = b.iter().map(|&v| v as f64).sum::<f64>() / b.len() as f64;
            // Error diffusion loses at most the error pushed off one border row/column.
            assert!(
                (mean_b - mean_t).abs() < 2.0 / w as f64,
                "{m:?}: {mean_b} vs {mean_t}"
            );
        }
    }

    /// The passband `holes` without the exact bins of DC and ±ω: what is left is spurious.
    fn spurs_only(fx: f64, fy: f64, r: f64, bin: f64) -> impl Fn(f64, f64) -> f64 + Sync {
        let pb = holes(fx, fy, r);
        move |x: f64, y: f64| {
            let at = |cx: f64, cy: f64| (x - cx).hypot(y - cy) < 0.5 * bin;
            if at(0.0, 0.0) || at(fx, fy) || at(-fx, -fy) {
                0.0
            } else {
                pb(x, y)
            }
        }
    }

    #[test]
    fn bayer_has_no_in_band_spurs_when_the_period_divides_the_tile_but_strong_ones_otherwise() {
        let (w, h) = (320, 256);
        // Holes of 0.04 cycles/pixel: wide enough to pass the 1/32 intermodulation offsets.
        let r = 0.04;
        // Period 8 px divides the 8 × 8 tile: the output is periodic with the tile, so all of
        // its error sits on the carrier bins (a gain error) and on harmonics outside the holes.
        // Period 6.4 px does not: the tile frequency 1/8 intermodulates with the carrier.
        for (period, divides) in [(8.0, true), (6.4, false)] {
            let c = Carrier {
                fx: 1.0 / period,
                fy: 0.0,
                phase_rad: 0.3,
            };
            let t = target(&c, w, h);
            let spur = spurs_only(c.fx, c.fy, r, 1.0 / 320.0);
            let reference = in_band_energy(&t, w, h, &holes(c.fx, c.fy, r));
            let rel = |m: DitherMethod| {
                let b = dither(&t, w, h, m, 8, &spur, 1);
                let d: Vec<f32> = b.iter().zip(&t).map(|(b, t)| b - t).collect();
                (in_band_energy(&d, w, h, &spur) / reference).sqrt()
            };
            let (eb, ef) = (rel(DitherMethod::Bayer), rel(DitherMethod::FloydSteinberg));
            eprintln!("period {period}: spurs bayer {eb:.4}, floyd-steinberg {ef:.4}");
            if divides {
                assert!(eb < 1e-4, "{eb}");
            } else {
                assert!(eb > 5.0 * ef, "bayer {eb} vs fs {ef}");
            }
        }
    }

    /// The toggle count that stops the feedback is the number of mirrors that changed: a random
    /// pattern and error toggle some mirrors, and the count says how many; no error, none.
    #[test]
    fn the_toggle_count_is_the_number_of_mirrors_changed() {
        use rand::{Rng, SeedableRng};
        let (w, h) = (64, 48);
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let before: Vec<f32> = (0..w * h).map(|_| rng.gen_range(0..2) as f32).collect();
        let e: Vec<f32> = (0..w * h).map(|_| rng.gen_range(-0.3..0.3)).collect();
        let mut b = before.clone();
        let n = diffuse_toggles(&mut b, &e, w, h);
        let changed = b.iter().zip(&before).filter(|(x, y)| x != y).count();
        assert!(n > 0 && n == changed, "{n} toggles, {changed} changed");
        assert_eq!(diffuse_toggles(&mut b, &vec![0.0; w * h], w, h), 0);
    }

    #[test]
    fn in_band_feedback_beats_floyd_steinberg_on_in_band_error() {
        let (w, h) = (256, 256);
        for c in [
            Carrier {
                fx: 0.25,
                fy: 0.0,
                phase_rad: 0.3,
            },
            Carrier {
                fx: 1.0 / 6.4,
                fy: 0.0,
                phase_rad: 0.3,
            },
            Carrier {
                fx: -0.25,
                fy: 0.25,
                phase_rad: 1.0,
            },
            Carrier {
                fx: 0.5,
                fy: 0.25,
                phase_rad: 0.2,
            },
        ] {
            let t = target(&c, w, h);
            let pb = holes(c.fx, c.fy, 6.0 / 256.0);
            let errs: Vec<f64> = DitherMethod::ALL
                .iter()
                .map(|&m| in_band_error(&dither(&t, w, h, m, 8, &pb, 8), &t, w, h, &pb))
                .collect();
            eprintln!("{c:?}: {errs:.4?}");
            let (fs, ours) = (errs[2], errs[5]);
            assert!(ours < 0.5 * fs, "ours {ours} vs floyd-steinberg {fs}");
        }
    }
}
