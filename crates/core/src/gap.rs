//! GAP de-aliasing (paper eq. (GAP); Liao, Li & Carin 2014; Yuan 2016): starting from the
//! Fourier estimates x̂, alternate the exact projection onto {X : Y = S X} with a denoising step
//! — group shrinkage of orthogonal wavelet coefficients (weighted ℓ2,1, groups = the J channel
//! coefficients at one position) or, for the GAP-TV baseline, vectorial TV denoising.
//!
//! S = [S_1 … S_J] with S_k = diag(s_k): the effective pattern of channel k as imaged (for a
//! timing mixture y = Σ_i Σ_k w_ik x_i ⊙ s̃_k pass `patterns.mix(w)`), so S Sᵀ = diag(Σ_k s_k²)
//! and the projection is pointwise.

use crate::error::check_count;
use crate::error::Error;
use crate::error::Result;
use crate::tv::TvDenoiser;
use crate::wavelet::Dwt2;
use crate::wavelet::Wavelet;
use crate::Cube;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// Which estimate the reconstruction returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The Fourier crop estimate x̂ as it is (no de-aliasing).
    Fourier,
    /// GAP with weighted group-ℓ2,1 wavelet shrinkage (the paper's method).
    Gap,
    /// GAP with a TV denoiser in place of the wavelet shrinkage (Yuan 2016's GAP-TV).
    GapTv,
    /// No GAP: the joint spectral–spatial reconstruction of α from the frame (`joint.rs`,
    /// `[reconstruct.joint]`), seeded by the Fourier estimate unmixed.
    Joint,
    /// The best of the others for `[reconstruct] budget_s`, from the measured table (`auto.rs`).
    Auto,
}

impl std::fmt::Display for Method {
    /// The name an experiment file gives it (`reconstruct.gap.method`).
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(match self {
            Method::Fourier => "fourier",
            Method::Gap => "gap",
            Method::GapTv => "gap-tv",
            Method::Joint => "joint",
            Method::Auto => "auto",
        })
    }
}

/// Settings of `[reconstruct.gap]`. The paper gives no parameter values; the defaults are the
/// values tuned on the dead-leaves test frames of this module (docs/gap.md has the sweep).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GapConfig {
    /// Estimator (default `auto`: the best measured method for `[reconstruct] budget_s`).
    pub method: Method,
    /// GAP iterations (one projection + one denoising step each).
    pub iterations: usize,
    /// Accelerated GAP: project onto Y_acc, Y_acc ← Y_acc + (Y − S V) (Liao 2014 §III-C).
    pub accelerate: bool,
    /// Mother wavelet of T.
    pub wavelet: Wavelet,
    /// Wavelet levels.
    pub levels: usize,
    /// Fraction of wavelet groups that survive each shrinkage (Liao's m*/m): the threshold λ is
    /// the weighted norm of the (m*+1)-th largest group, so the step is scale free.
    pub keep: f64,
    /// Weight ratio β_{l+1}/β_l between a detail level and the next finer one (β_1 = 1 at the
    /// finest); < 1 shrinks coarse levels less. The scaling band is never shrunk.
    pub level_ratio: f64,
    /// GAP-TV weight λ as a fraction of the mean |x̂| of the seed.
    pub tv_weight: f64,
    /// Chambolle dual steps per GAP-TV iteration (warm-started across iterations).
    pub tv_iterations: usize,
    /// Floor of Σ_k s_k² relative to its mean, so pixels the patterns barely light do not
    /// blow up the projection's division.
    pub floor: f64,
}

impl Default for GapConfig {
    fn default() -> Self {
        GapConfig {
            method: Method::Auto,
            iterations: 20,
            accelerate: true,
            wavelet: Wavelet::Daubechies4,
            levels: 4,
            keep: 0.2,
            level_ratio: 0.5,
            tv_weight: 0.1,
            tv_iterations: 5,
            floor: 1e-3,
        }
    }
}

impl GapConfig {
    /// GAP's wavelet transform of a `w` × `h` frame: an error naming `reconstruct.gap.levels`
    /// in `file` where the levels cannot split it (GAP-TV and the other methods take any side).
    pub fn wavelet_for(&self, w: usize, h: usize, file: &str) -> Result<Dwt2> {
        Dwt2::new(w, h, self.levels, self.wavelet, file)
    }

    /// Range checks; errors name `reconstruct.gap.<field>` and the value.
    pub fn validate(&self, file: &str) -> Result<()> {
        let key = |f: &str| format!("reconstruct.gap.{f}");
        check_count(
            file,
            &key("iterations"),
            self.iterations,
            0..=100_000,
            "iterations",
        )?;
        check_count(file, &key("levels"), self.levels, 1..=16, "levels")?;
        if !(self.keep > 0.0 && self.keep <= 1.0) {
            return Err(Error::config(
                file,
                &key("keep"),
                self.keep,
                "must be in (0, 1]",
            ));
        }
        if !(self.level_ratio.is_finite() && self.level_ratio > 0.0) {
            return Err(Error::config(
                file,
                &key("level_ratio"),
                self.level_ratio,
                "must be finite and > 0",
            ));
        }
        if !(self.tv_weight.is_finite() && self.tv_weight >= 0.0) {
            return Err(Error::config(
                file,
                &key("tv_weight"),
                self.tv_weight,
                "must be finite and ≥ 0",
            ));
        }
        if !(1..=10_000).contains(&self.tv_iterations) {
            return Err(Error::config(
                file,
                &key("tv_iterations"),
                self.tv_iterations,
                "must be 1 to 10000",
            ));
        }
        if !(self.floor > 0.0 && self.floor <= 1.0) {
            return Err(Error::config(
                file,
                &key("floor"),
                self.floor,
                "must be in (0, 1]",
            ));
        }
        Ok(())
    }
}

/// What a run did: per-iteration residual and (given a truth) PSNR, and its wall time.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GapStats {
    pub iterations: usize,
    /// PSNR (dB, peak = max of the truth) of the seed, then after each iteration; empty without truth.
    pub psnr_db: Vec<f64>,
    /// RMS of Y − S V (frame units) before each iteration's projection.
    pub residual_rms: Vec<f64>,
    pub seconds: f64,
}

/// The solver for one pattern set and configuration: the patterns, 1/max(Σ s², floor·mean)
/// and the wavelet plan, shared by every frame.
pub struct Gap {
    w: usize,
    h: usize,
    j: usize,
    cfg: GapConfig,
    patterns: Vec<f32>,
    inv_energy: Vec<f32>,
    /// The wavelet transform of GAP's shrinkage; None for GAP-TV, which denoises without it
    /// and so takes any frame size.
    dwt: Option<Dwt2>,
    /// Group weight β per coefficient position; 0 in the scaling band (never shrunk); empty
    /// without the wavelet.
    beta: Vec<f32>,
}

/// What one run of a `Gap` reads, for a mirror of it on another device (specmux-gpu).
pub struct GapTables<'a> {
    pub w: usize,
    pub h: usize,
    /// Channels J.
    pub planes: usize,
    pub config: &'a GapConfig,
    /// The J pattern planes S.
    pub patterns: &'a [f32],
    /// 1 / max(Σ_k s_k², floor) per pixel.
    pub inv_energy: &'a [f32],
    /// Group weight β per coefficient position; 0 in the scaling band (empty for GAP-TV).
    pub beta: &'a [f32],
    /// The wavelet transform of the shrinkage (None for GAP-TV).
    pub dwt: Option<&'a Dwt2>,
}

/// The iterate and the buffers one run reuses (no allocation per iteration).
pub struct GapState {
    /// The current estimate V (after the denoising step).
    pub estimate: Cube,
    y: Vec<f32>,
    y_acc: Vec<f32>,
    /// (Y_acc − S V) / Σ s² per pixel, reused as the shrink factor per group.
    t: Vec<f32>,
    scratch: Vec<f32>,
    select: Vec<f32>,
    row_sums: Vec<f64>,
    tv: Option<TvDenoiser>,
    tv_lambda: f32,
}

impl Gap {
    /// `patterns`: J planes, the effective pattern of each channel. `file` names the config.
    pub fn new(patterns: &Cube, cfg: &GapConfig, file: &str) -> Result<Gap> {
        cfg.validate(file)?;
        let (w, h, j, n) = (
            patterns.width,
            patterns.height,
            patterns.planes,
            patterns.pixels(),
        );
        if j == 0 || n == 0 {
            return Err(Error::Shape(format!("patterns {w}×{h}×{j} are empty")));
        }
        if !patterns.all_finite() {
            return Err(Error::Numerical(
                "the patterns contain NaN or infinite values".into(),
            ));
        }
        let dwt = (cfg.method == Method::Gap)
            .then(|| cfg.wavelet_for(w, h, file))
            .transpose()?;
        let energy: Vec<f64> = (0..n)
            .map(|p| {
                (0..j)
                    .map(|k| (patterns.data[k * n + p] as f64).powi(2))
                    .sum()
            })
            .collect();
        let mean = energy.iter().sum::<f64>() / n as f64;
        if !(mean > 0.0 && mean.is_finite()) {
            return Err(Error::Numerical(format!(
                "the patterns carry no usable energy (mean Σ s² = {mean:.3e}); nothing can be projected"
            )));
        }
        let floor = cfg.floor * mean;
        let inv_energy = energy
            .iter()
            .map(|&e| (1.0 / e.max(floor)) as f32)
            .collect();
        let beta = dwt.as_ref().map_or_else(Vec::new, |d| {
            d.level_map()
                .iter()
                .map(|&l| match l {
                    0 => 0.0,
                    l => cfg.level_ratio.powi(l as i32 - 1) as f32,
                })
                .collect()
        });
        Ok(Gap {
            w,
            h,
            j,
            cfg: cfg.clone(),
            patterns: patterns.data.clone(),
            inv_energy,
            dwt,
            beta,
        })
    }

    /// The solver's tables, as its steps read them.
    pub fn tables(&self) -> GapTables<'_> {
        GapTables {
            w: self.w,
            h: self.h,
            planes: self.j,
            config: &self.cfg,
            patterns: &self.patterns,
            inv_energy: &self.inv_energy,
            beta: &self.beta,
            dwt: self.dwt.as_ref(),
        }
    }

    /// Index, in ascending order of the detail groups' scores ‖W_G‖/β_G, of the score that is
    /// the shrinkage threshold λ; None when every detail group is kept (λ = 0).
    pub fn threshold_rank(&self) -> Option<usize> {
        let detail = self.beta.iter().filter(|&&b| b != 0.0).count();
        let kept = ((self.cfg.keep * detail as f64).ceil() as usize).min(detail);
        (kept < detail).then(|| detail - kept - 1)
    }

    /// The state seeded by `seed` (J planes) for measurement `frame` (one plane).
    pub fn start(&self, frame: &Cube, seed: &Cube) -> Result<GapState> {
        if (frame.width, frame.height, frame.planes) != (self.w, self.h, 1) {
            return Err(Error::Shape(format!(
                "frame {}×{}×{} for patterns {}×{}",
                frame.width, frame.height, frame.planes, self.w, self.h
            )));
        }
        if (seed.width, seed.height, seed.planes) != (self.w, self.h, self.j) {
            return Err(Error::Shape(format!(
                "seed {}×{}×{} for patterns {}×{}×{}",
                seed.width, seed.height, seed.planes, self.w, self.h, self.j
            )));
        }
        if !frame.all_finite() || !seed.all_finite() {
            return Err(Error::Numerical(
                "the frame or the seed contains NaN or infinite values".into(),
            ));
        }
        let tv =
            (self.cfg.method == Method::GapTv).then(|| TvDenoiser::new(self.w, self.h, self.j));
        let mean_abs =
            seed.data.iter().map(|v| v.abs() as f64).sum::<f64>() / seed.data.len() as f64;
        let n = self.w * self.h;
        Ok(GapState {
            estimate: seed.clone(),
            y: frame.data.clone(),
            y_acc: frame.data.clone(),
            t: vec![0.0; n],
            scratch: vec![0.0; n * self.j],
            select: vec![0.0; n],
            row_sums: vec![0.0; self.h],
            tv,
            tv_lambda: (self.cfg.tv_weight * mean_abs) as f32,
        })
    }

    /// One GAP iteration: project onto {Y = S X} (or onto Y_acc, accelerated), then denoise.
    /// Returns the RMS of Y − S V before the projection.
    pub fn step(&self, st: &mut GapState) -> f64 {
        let rms = self.project(st);
        match (self.cfg.method, &self.dwt) {
            (Method::Gap, Some(dwt)) => self.shrink(st, dwt),
            (Method::Fourier | Method::Joint | Method::Auto | Method::Gap, _) => {}
            (Method::GapTv, _) => {
                if let Some(tv) = st.tv.as_mut() {
                    tv.denoise(&mut st.estimate.data, st.tv_lambda, self.cfg.tv_iterations);
                }
            }
        }
        rms
    }

    /// X = V + Sᵀ((Y_acc − S V) ⊘ max(Σ s², floor)), in place on the estimate.
    fn project(&self, st: &mut GapState) -> f64 {
        let (w, n, j) = (self.w, self.w * self.h, self.j);
        let acc = self.cfg.accelerate;
        let (v, s) = (&st.estimate.data, &self.patterns);
        st.t.par_chunks_mut(w)
            .zip(st.y_acc.par_chunks_mut(w))
            .zip(st.y.par_chunks(w).zip(self.inv_energy.par_chunks(w)))
            .zip(st.row_sums.par_iter_mut())
            .enumerate()
            .for_each(|(r, (((t, ya), (y, inv)), sum))| {
                let mut e2 = 0.0f64;
                for x in 0..w {
                    let p = r * w + x;
                    let sv: f32 = (0..j).map(|k| s[k * n + p] * v[k * n + p]).sum();
                    let e = y[x] - sv;
                    e2 += e as f64 * e as f64;
                    t[x] = if acc {
                        ya[x] += e;
                        (ya[x] - sv) * inv[x]
                    } else {
                        e * inv[x]
                    };
                }
                *sum = e2;
            });
        let t = &st.t;
        let h = self.h;
        st.estimate
            .data
            .par_chunks_mut(w)
            .zip(s.par_chunks(w))
            .enumerate()
            .for_each(|(i, (row, srow))| {
                let tr = &t[(i % h) * w..(i % h + 1) * w];
                for ((x, &sv), &tv) in row.iter_mut().zip(srow).zip(tr) {
                    *x += sv * tv;
                }
            });
        (st.row_sums.iter().sum::<f64>() / n as f64).sqrt()
    }

    /// W = Tᵀ X; keep the m* groups of largest ‖W_G‖/β_G, shrinking each by λβ_G (λ = the
    /// (m*+1)-th largest ‖W_G‖/β_G); V = T W.
    fn shrink(&self, st: &mut GapState, dwt: &Dwt2) {
        let (w, n, j) = (self.w, self.w * self.h, self.j);
        st.estimate
            .data
            .par_chunks_mut(n)
            .zip(st.scratch.par_chunks_mut(n))
            .for_each(|(plane, scr)| dwt.forward(plane, scr));
        // Weighted group norms (the scaling band scores +∞: always kept whole).
        let c = &st.estimate.data;
        st.t.par_chunks_mut(w)
            .zip(self.beta.par_chunks(w))
            .enumerate()
            .for_each(|(r, (score, beta))| {
                for x in 0..w {
                    let p = r * w + x;
                    score[x] = if beta[x] == 0.0 {
                        f32::INFINITY
                    } else {
                        (0..j)
                            .map(|k| c[k * n + p] * c[k * n + p])
                            .sum::<f32>()
                            .sqrt()
                            / beta[x]
                    };
                }
            });
        // The scaling band scores +∞: it sorts above every detail group.
        let lambda = match self.threshold_rank() {
            None => 0.0,
            Some(idx) => {
                st.select.copy_from_slice(&st.t);
                *st.select.select_nth_unstable_by(idx, f32::total_cmp).1
            }
        };
        st.t.par_iter_mut().for_each(|s| {
            *s = if *s > lambda { 1.0 - lambda / *s } else { 0.0 };
        });
        let (t, h) = (&st.t, self.h);
        st.estimate
            .data
            .par_chunks_mut(w)
            .enumerate()
            .for_each(|(i, row)| {
                let f = &t[(i % h) * w..(i % h + 1) * w];
                for (c, &fv) in row.iter_mut().zip(f) {
                    *c *= fv;
                }
            });
        st.estimate
            .data
            .par_chunks_mut(n)
            .zip(st.scratch.par_chunks_mut(n))
            .for_each(|(plane, scr)| dwt.inverse(plane, scr));
    }

    /// Run `cfg.iterations` iterations from `seed`; with `truth`, track the PSNR.
    pub fn run(&self, frame: &Cube, seed: &Cube, truth: Option<&Cube>) -> Result<(Cube, GapStats)> {
        let t0 = Instant::now();
        let mut st = self.start(frame, seed)?;
        if let Some(tr) = truth {
            seed.check_same_shape(tr, "GAP truth")?;
        }
        let mut stats = GapStats::default();
        let track = |est: &Cube, stats: &mut GapStats| {
            if let Some(tr) = truth {
                stats.psnr_db.push(psnr(est, tr));
            }
        };
        track(&st.estimate, &mut stats);
        let iterations = if matches!(
            self.cfg.method,
            Method::Fourier | Method::Joint | Method::Auto
        ) {
            0
        } else {
            self.cfg.iterations
        };
        for i in 0..iterations {
            crate::interrupt::check(&format!("GAP iteration {}", i + 1))?;
            let r = self.step(&mut st);
            stats.residual_rms.push(r);
            track(&st.estimate, &mut stats);
        }
        if !st.estimate.all_finite() {
            return Err(Error::Numerical(format!(
                "GAP produced non-finite values after {iterations} iterations"
            )));
        }
        stats.iterations = iterations;
        stats.seconds = t0.elapsed().as_secs_f64();
        Ok((st.estimate, stats))
    }
}

/// De-alias the Fourier estimates `seed` of `frame` = Σ_k patterns_k ⊙ x_k (see `Gap`).
pub fn dealias(
    frame: &Cube,
    patterns: &Cube,
    seed: &Cube,
    cfg: &GapConfig,
    truth: Option<&Cube>,
) -> Result<(Cube, GapStats)> {
    if matches!(cfg.method, Method::Joint | Method::Auto) {
        return Err(Error::config(
            "<gap>",
            "reconstruct.gap.method",
            format!("{:?}", cfg.method),
            "dealias runs GAP only; the joint and auto methods run through the Reconstructor",
        ));
    }
    if cfg.method == Method::Fourier {
        cfg.validate("<gap>")?;
        let stats = GapStats {
            psnr_db: truth.map(|t| vec![psnr(seed, t)]).unwrap_or_default(),
            ..Default::default()
        };
        return Ok((seed.clone(), stats));
    }
    Gap::new(patterns, cfg, "<gap>")?.run(frame, seed, truth)
}

/// PSNR in dB with the truth's maximum as the peak (row sums in f64, summed in a fixed order).
pub fn psnr(est: &Cube, truth: &Cube) -> f64 {
    let w = truth.width.max(1);
    let rows: Vec<f64> = est
        .data
        .par_chunks(w)
        .zip(truth.data.par_chunks(w))
        .map(|(a, b)| {
            a.iter()
                .zip(b)
                .map(|(&p, &q)| (p as f64 - q as f64).powi(2))
                .sum()
        })
        .collect();
    let mse = rows.iter().sum::<f64>() / truth.data.len().max(1) as f64;
    let peak = truth.max() as f64;
    10.0 * (peak * peak / mse).log10()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::carriers::default_layout;
    use crate::carriers::Carrier;
    use crate::demux::Demux;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// J = 6 channels sharing dead-leaves edges (each leaf one random spectrum) under a smooth
    /// shading: edge-rich and spectrally correlated like a real scene.
    pub(crate) fn scene(w: usize, h: usize, seed: u64) -> Cube {
        let labels = crate::dead_leaves::labels(w, h, 16, seed);
        let mut rng = Pcg64::seed_from_u64(seed + 100);
        let spectra: Vec<[f32; 6]> = (0..16)
            .map(|_| std::array::from_fn(|_| rng.gen_range(0.05..1.0)))
            .collect();
        let mut c = Cube::zeros(w, h, 6);
        let tau = std::f32::consts::TAU;
        for (k, plane) in c.planes_mut().enumerate() {
            for (p, v) in plane.iter_mut().enumerate() {
                let (x, y) = ((p % w) as f32 / w as f32, (p / w) as f32 / h as f32);
                let shade = 0.8 + 0.2 * (tau * (x + 0.5 * y)).cos();
                *v = spectra[labels[p] as usize][k] * shade;
            }
        }
        c
    }

    pub(crate) fn patterns(w: usize, h: usize, carriers: &[Carrier]) -> Cube {
        let data = carriers
            .iter()
            .flat_map(|c| c.ideal_pattern(w, h))
            .collect();
        Cube::from_vec(w, h, carriers.len(), data).unwrap()
    }

    pub(crate) fn measure(x: &Cube, s: &Cube) -> Cube {
        let n = x.pixels();
        let y = (0..n)
            .map(|p| (0..x.planes).map(|k| x.plane(k)[p] * s.plane(k)[p]).sum())
            .collect();
        Cube::from_vec(x.width, x.height, 1, y).unwrap()
    }

    /// (truth, patterns, frame, Fourier seed) for the default layout.
    pub(crate) fn case(w: usize, h: usize, seed: u64) -> (Cube, Cube, Cube, Cube) {
        let carriers = default_layout();
        let x = scene(w, h, seed);
        let s = patterns(w, h, &carriers);
        let y = measure(&x, &s);
        let xh = Demux::new(w, h, &carriers, 0.25).run(&y).unwrap();
        (x, s, y, xh)
    }

    fn small(method: Method, iterations: usize) -> GapConfig {
        GapConfig {
            method,
            iterations,
            levels: 3,
            ..Default::default()
        }
    }

    fn max_abs(c: &Cube) -> f32 {
        c.data.iter().fold(0.0f32, |m, v| m.max(v.abs()))
    }

    #[test]
    fn projection_satisfies_the_measurement_exactly() {
        let (_, s, y, xh) = case(64, 64, 1);
        // Start from a wrong estimate so the projection has work to do.
        let start: Cube =
            Cube::from_vec(64, 64, 6, xh.data.iter().map(|v| 0.5 * v + 0.1).collect()).unwrap();
        let gap = Gap::new(
            &s,
            &GapConfig {
                accelerate: false,
                ..small(Method::Gap, 1)
            },
            "t",
        )
        .unwrap();
        let mut st = gap.start(&y, &start).unwrap();
        let before = gap.project(&mut st);
        assert!(before > 0.1, "the start already fits: {before}");
        let fitted = measure(&st.estimate, &s);
        let err = fitted
            .data
            .iter()
            .zip(&y.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 1e-5 * y.max(), "max |Y − S X| = {err}");
        // The correction is the least-norm one: it lies in the range of Sᵀ, i.e. X − V ∝ s_k per pixel.
        for p in [0usize, 77, 2049, 4095] {
            let d: Vec<f32> = (0..6)
                .map(|k| st.estimate.plane(k)[p] - start.plane(k)[p])
                .collect();
            let sk: Vec<f32> = (0..6).map(|k| s.plane(k)[p]).collect();
            let k0 = (0..6).max_by(|&a, &b| sk[a].total_cmp(&sk[b])).unwrap();
            for k in 0..6 {
                assert!(
                    (d[k] * sk[k0] - d[k0] * sk[k]).abs() < 1e-5,
                    "pixel {p} channel {k}"
                );
            }
        }
    }

    #[test]
    fn gap_and_gap_tv_beat_the_fourier_seed_on_an_edge_rich_scene() {
        // Measured (128×128, dead-leaves seed 7): seed 12.72 dB, GAP 15.0 dB, GAP-TV 16.0 dB.
        let (x, s, y, xh) = case(128, 128, 7);
        let seed_db = psnr(&xh, &x);
        let (_, g) = dealias(
            &y,
            &s,
            &xh,
            &GapConfig {
                method: Method::Gap,
                ..Default::default()
            },
            Some(&x),
        )
        .unwrap();
        let (_, t) = dealias(
            &y,
            &s,
            &xh,
            &GapConfig {
                method: Method::GapTv,
                ..Default::default()
            },
            Some(&x),
        )
        .unwrap();
        let (gd, td) = (g.psnr_db[20] - seed_db, t.psnr_db[20] - seed_db);
        assert!(gd > 2.0, "GAP gains {gd:.2} dB");
        assert!(td > 2.8, "GAP-TV gains {td:.2} dB");
        let (f, fs) = dealias(
            &y,
            &s,
            &xh,
            &GapConfig {
                method: Method::Fourier,
                ..Default::default()
            },
            Some(&x),
        )
        .unwrap();
        assert_eq!(f, xh);
        assert_eq!((fs.iterations, fs.psnr_db.len()), (0, 1));
    }

    #[test]
    fn zero_frame_gives_zero() {
        let s = patterns(64, 64, &default_layout());
        let z = Cube::zeros(64, 64, 1);
        for m in [Method::Gap, Method::GapTv] {
            let (out, st) = dealias(&z, &s, &Cube::zeros(64, 64, 6), &small(m, 30), None).unwrap();
            assert!(out.data.iter().all(|&v| v == 0.0), "{m:?}");
            assert!(st.residual_rms.iter().all(|&r| r == 0.0));
        }
    }

    #[test]
    fn mostly_saturated_frame_stays_finite_and_bounded() {
        let (_, s, y, _) = case(64, 64, 2);
        // Clip at the 30th percentile: 70 % of the frame is one constant (a saturated sensor).
        let mut sorted = y.data.clone();
        sorted.sort_by(f32::total_cmp);
        let clip = sorted[sorted.len() * 3 / 10];
        let yc = Cube::from_vec(64, 64, 1, y.data.iter().map(|v| v.min(clip)).collect()).unwrap();
        let xh = Demux::new(64, 64, &default_layout(), 0.25)
            .run(&yc)
            .unwrap();
        for m in [Method::Gap, Method::GapTv] {
            let (out, st) = dealias(&yc, &s, &xh, &small(m, 200), None).unwrap();
            assert!(out.all_finite());
            assert!(
                max_abs(&out) < 4.0 * max_abs(&xh),
                "{m:?}: {} vs seed {}",
                max_abs(&out),
                max_abs(&xh)
            );
            let r = &st.residual_rms;
            assert!(r[199] <= r[0], "{m:?}: residual grew {} → {}", r[0], r[199]);
        }
    }

    #[test]
    fn gap_tv_takes_sides_the_wavelet_cannot_split() {
        // 36 × 20: neither side divisible by 2³, so GAP's three wavelet levels are refused.
        let (x, s, y, xh) = case(36, 20, 3);
        let e = Gap::new(&s, &small(Method::Gap, 1), "x.toml")
            .err()
            .unwrap();
        assert!(e.to_string().contains("reconstruct.gap.levels"), "{e}");
        // Measured: 11.02 → 14.09 dB after 100 iterations.
        let (out, st) = dealias(&y, &s, &xh, &small(Method::GapTv, 100), Some(&x)).unwrap();
        assert!(out.all_finite());
        let (seed, end) = (st.psnr_db[0], st.psnr_db[100]);
        assert!(end > seed + 1.0, "GAP-TV {seed} → {end} dB");
    }

    #[test]
    fn carrier_near_nyquist_still_converges_and_helps() {
        // Measured: seed 9.21 dB, GAP 12.96 dB, GAP-TV 14.29 dB after 200 iterations.
        let carriers: Vec<Carrier> = default_layout()
            .into_iter()
            .enumerate()
            .map(|(i, c)| if i == 4 { Carrier { fx: 0.49, ..c } } else { c })
            .collect();
        let x = scene(64, 64, 5);
        let s = patterns(64, 64, &carriers);
        let y = measure(&x, &s);
        let xh = Demux::new(64, 64, &carriers, 0.25).run(&y).unwrap();
        for m in [Method::Gap, Method::GapTv] {
            let (out, st) = dealias(&y, &s, &xh, &small(m, 200), Some(&x)).unwrap();
            assert!(out.all_finite());
            assert!(
                st.psnr_db[200] > st.psnr_db[0] + 3.0,
                "{m:?}: {:?}",
                (st.psnr_db[0], st.psnr_db[200])
            );
        }
    }

    #[test]
    fn pattern_energy_near_zero_is_floored_not_divided_by() {
        let (x, mut s, _, _) = case(64, 64, 3);
        // A dead 8×8 block (all patterns exactly 0) and a row lit at 1e-20.
        for k in 0..6 {
            let pl = s.plane_mut(k);
            for yy in 8..16 {
                pl[yy * 64 + 8..yy * 64 + 16].fill(0.0);
            }
            pl[40 * 64..41 * 64].fill(1e-20);
        }
        let y = measure(&x, &s);
        let cfg = small(Method::Gap, 1);
        let gap = Gap::new(
            &s,
            &GapConfig {
                accelerate: false,
                ..cfg.clone()
            },
            "t",
        )
        .unwrap();
        // A seed far from the truth: the projection's correction there is s_k·r/floor, tiny.
        let seed = Cube::from_vec(64, 64, 6, vec![1.0; 64 * 64 * 6]).unwrap();
        let mut st = gap.start(&y, &seed).unwrap();
        gap.project(&mut st);
        for k in 0..6 {
            assert_eq!(st.estimate.plane(k)[12 * 64 + 12], 1.0, "dead pixel moved");
            assert!(
                (st.estimate.plane(k)[40 * 64 + 5] - 1.0).abs() < 1e-6,
                "dim pixel blew up"
            );
        }
        for m in [Method::Gap, Method::GapTv] {
            let (out, st) = dealias(&y, &s, &seed, &small(m, 500), Some(&x)).unwrap();
            assert!(out.all_finite(), "{m:?}");
            assert!(
                max_abs(&out) < 2.0 * max_abs(&x),
                "{m:?}: {}",
                max_abs(&out)
            );
            assert!(st.residual_rms[499] <= st.residual_rms[0], "{m:?}");
        }
        // Patterns with no energy at all cannot be projected on: a clear error, not NaN.
        let e = Gap::new(&Cube::zeros(64, 64, 6), &cfg, "t")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("no usable energy"), "{e}");
    }

    #[test]
    fn five_hundred_iterations_do_not_diverge() {
        // Measured on 64×64: accelerated GAP's PSNR wanders by < 0.009 dB per iteration after the
        // first 20 (12.95–13.08 dB); GAP-TV is monotone (drops < 1e-6 dB) and its residual falls to 2e-7.
        let (x, s, y, xh) = case(64, 64, 5);
        let (_, g) = dealias(&y, &s, &xh, &small(Method::Gap, 500), Some(&x)).unwrap();
        let p = &g.psnr_db;
        for i in 20..500 {
            assert!(
                p[i + 1] > p[i] - 0.02,
                "GAP iteration {i}: {} → {}",
                p[i],
                p[i + 1]
            );
        }
        assert!(
            p[500] >= p[20] - 0.01 && p[500] > p[0] + 2.0,
            "{} {} {}",
            p[0],
            p[20],
            p[500]
        );
        let (_, t) = dealias(&y, &s, &xh, &small(Method::GapTv, 500), Some(&x)).unwrap();
        let (p, r) = (&t.psnr_db, &t.residual_rms);
        for i in 20..499 {
            assert!(
                p[i + 1] >= p[i] - 1e-4,
                "GAP-TV iteration {i}: {} → {}",
                p[i],
                p[i + 1]
            );
            assert!(
                r[i + 1] <= r[i] + 1e-6,
                "GAP-TV residual {i}: {} → {}",
                r[i],
                r[i + 1]
            );
        }
        assert!(r[499] < 1e-3 * r[0], "{} → {}", r[0], r[499]);
    }

    #[test]
    fn same_bits_whatever_the_thread_count() {
        let (_, s, y, xh) = case(64, 64, 4);
        for m in [Method::Gap, Method::GapTv] {
            let run = |threads| {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                pool.install(|| dealias(&y, &s, &xh, &small(m, 10), None).unwrap())
            };
            let ((a, sa), (b, sb)) = (run(1), run(3));
            assert_eq!(a, b, "{m:?}");
            assert_eq!(sa.residual_rms, sb.residual_rms);
        }
    }

    #[test]
    fn config_parses_and_rejects_bad_values_by_key() {
        let c: GapConfig =
            toml::from_str("method = \"gap-tv\"\nkeep = 0.1\nwavelet = \"haar\"").unwrap();
        assert_eq!(
            (c.method, c.wavelet, c.keep, c.levels),
            (Method::GapTv, Wavelet::Haar, 0.1, 4)
        );
        assert!(toml::from_str::<GapConfig>("kep = 0.1").is_err());
        for (cfg, key) in [
            (
                GapConfig {
                    keep: 0.0,
                    ..Default::default()
                },
                "reconstruct.gap.keep",
            ),
            (
                GapConfig {
                    keep: f64::NAN,
                    ..Default::default()
                },
                "reconstruct.gap.keep",
            ),
            (
                GapConfig {
                    level_ratio: -1.0,
                    ..Default::default()
                },
                "reconstruct.gap.level_ratio",
            ),
            (
                GapConfig {
                    floor: 0.0,
                    ..Default::default()
                },
                "reconstruct.gap.floor",
            ),
            (
                GapConfig {
                    levels: 0,
                    ..Default::default()
                },
                "reconstruct.gap.levels",
            ),
            (
                GapConfig {
                    tv_weight: f64::INFINITY,
                    ..Default::default()
                },
                "reconstruct.gap.tv_weight",
            ),
            (
                GapConfig {
                    tv_iterations: 0,
                    ..Default::default()
                },
                "reconstruct.gap.tv_iterations",
            ),
        ] {
            let e = cfg.validate("x.toml").unwrap_err().to_string();
            assert!(e.contains(key) && e.contains("x.toml"), "{e}");
        }
        // A frame size the wavelet cannot split is refused with the levels key.
        let s = patterns(48, 48, &default_layout());
        let e = Gap::new(
            &s,
            &GapConfig {
                levels: 5,
                ..small(Method::Gap, 1)
            },
            "x.toml",
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("reconstruct.gap.levels"), "{e}");
        // NaN in the frame is an error, not a NaN cube.
        let (_, s, mut y, xh) = case(64, 64, 1);
        y.data[5] = f32::NAN;
        assert!(dealias(&y, &s, &xh, &small(Method::Gap, 2), None).is_err());
    }
}
