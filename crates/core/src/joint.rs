//! Joint spectral–spatial reconstruction: the basis coefficients α (J per pixel) straight from
//! the linearised frame through the whole forward operator. With S'_i = Σ_k w_ik s̃_k the
//! effective pattern of channel i, the frame is y_p = a_pᵀα_p, a_p = Fᵀ S'(p), and
//!
//!   min_α ½Σ_p ω_p (y_p − a_pᵀα_p)² + ½η' Σ_p ‖D₂Bα_p‖² + λ Σ_p ‖∇α(p)‖₂   s.t. Bα ≥ 0
//!
//! (ω: per-pixel data weights, 1 or the inverse noise variance; the TV norm is joint over the J
//! coefficient images and both directions, so the channels share edges). Solved by
//! Chambolle–Pock (2011, Algorithm 1, θ = 1) with K = [∇; βB]: the TV and the constraint are
//! dualised, the quadratic's proximal step is per pixel and closed form (Sherman–Morrison on
//! (I + τη'Q)⁻¹), and τσ‖K‖² < 1 with ‖K‖² ≤ 8 + β²‖B‖² (tested against power iteration).

use crate::error::{Error, Result};
use crate::unmix::second_difference;
use crate::Cube;
use nalgebra::DMatrix;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// τσ‖K‖² of the step sizes: below the bound 1 of Chambolle–Pock's convergence theorem.
const STEP_PRODUCT: f64 = 0.98;

/// Settings of `[reconstruct.joint]`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JointConfig {
    /// Primal–dual iterations.
    pub iterations: usize,
    /// λ as a fraction of mean|y|·mean‖a‖ (the TV weight free of the frame's and the
    /// patterns' scale).
    pub tv_weight: f64,
    /// τ/σ balance: τ = ratio·s/L, σ = 1/(ratio·s·L), s = mean|α₀|/λ (α's scale over the dual's).
    pub step_ratio: f64,
}

impl Default for JointConfig {
    fn default() -> Self {
        JointConfig {
            iterations: 100,
            tv_weight: 0.02,
            step_ratio: 1.0,
        }
    }
}

impl JointConfig {
    /// Range checks; errors name `reconstruct.joint.<field>` and the value.
    pub fn validate(&self, file: &str) -> Result<()> {
        let key = |f: &str| format!("reconstruct.joint.{f}");
        if self.iterations > 100_000 {
            return Err(Error::config(
                file,
                &key("iterations"),
                self.iterations,
                "must be 0 to 100000",
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
        if !(self.step_ratio.is_finite() && self.step_ratio > 0.0) {
            return Err(Error::config(
                file,
                &key("step_ratio"),
                self.step_ratio,
                "must be finite and > 0",
            ));
        }
        Ok(())
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct JointStats {
    pub iterations: usize,
    /// The objective (data + smoothness + TV) at the seed, then after each iteration.
    pub objective: Vec<f64>,
    /// λ in the units of the objective.
    pub lambda: f64,
    /// Primal and dual steps τ, σ.
    pub steps: [f64; 2],
    /// Largest −(Bα)_k over the pixels and bands, relative to the largest (Bα)_k: the
    /// constraint's violation left by the last iterate (zero at the limit; clipped in the cube).
    pub violation: f64,
    pub seconds: f64,
}

/// The solver for one rig: the per-pixel operator a_p, the basis and the smoothness form.
pub struct Joint {
    w: usize,
    h: usize,
    j: usize,
    bands: usize,
    cfg: JointConfig,
    /// a_p = Fᵀ S'(p), pixel-major (J per pixel).
    a: Vec<f32>,
    /// βB, row-major bands × J.
    bb: Vec<f32>,
    /// η'Q = η'(D₂B)ᵀ(D₂B), J × J.
    eq: DMatrix<f64>,
    /// ‖K‖ bound: √(8 + β²λmax(BᵀB)).
    norm_k: f64,
    system: DMatrix<f64>,
    basis: DMatrix<f64>,
    mean_a_norm: f64,
}

/// The iterate, the dual variables and the per-frame tables of one run.
pub struct JointState {
    /// α, pixel-major.
    pub alpha: Vec<f32>,
    bar: Vec<f32>,
    /// TV dual, pixel-major: (qx_j, qy_j) for j = 0..J.
    q: Vec<f32>,
    /// Constraint dual r ≤ 0, pixel-major (bands per pixel).
    r: Vec<f32>,
    /// Proximal tables: M = (I + τη'Q)⁻¹, m_p = M a_p (J per pixel), t_p = τω_p y_p,
    /// c_p = τω_p / (1 + τω_p a_pᵀm_p), k_p = a_pᵀ m_p.
    mat: Vec<f32>,
    m: Vec<f32>,
    tck: Vec<[f32; 3]>,
    y: Vec<f32>,
    omega: Vec<f32>,
    pub lambda: f32,
    pub tau: f32,
    pub sigma: f32,
    row_sums: Vec<f64>,
}

impl Joint {
    /// `patterns`: the C effective channel patterns S'_i (planes); `system` F (C × J);
    /// `basis` B (bands × J); `eta` the unmixer's smoothness weight in band-index units.
    pub fn new(
        patterns: &Cube,
        system: &DMatrix<f64>,
        basis: &DMatrix<f64>,
        eta: f64,
        cfg: &JointConfig,
        file: &str,
    ) -> Result<Joint> {
        cfg.validate(file)?;
        let (w, h, n) = (patterns.width, patterns.height, patterns.pixels());
        let (c, j, bands) = (system.nrows(), system.ncols(), basis.nrows());
        if patterns.planes != c || basis.ncols() != j || n == 0 || j == 0 {
            return Err(Error::Shape(format!(
                "joint: {} pattern planes of {w}×{h}, F {c}×{j}, B {bands}×{}",
                patterns.planes,
                basis.ncols()
            )));
        }
        if j > MAX_J {
            return Err(Error::Shape(format!("joint: J = {j} basis vectors, at most {MAX_J}")));
        }
        if !patterns.all_finite() || system.iter().chain(basis.iter()).any(|v| !v.is_finite())
        {
            return Err(Error::Numerical(
                "joint: the patterns, F or B hold a non-finite value".into(),
            ));
        }
        if !(eta.is_finite() && eta >= 0.0) {
            return Err(Error::Numerical(format!("joint: η = {eta} must be ≥ 0")));
        }
        let a = patterns.mix(
            &(0..j)
                .map(|jj| (0..c).map(|i| system[(i, jj)]).collect())
                .collect::<Vec<Vec<f64>>>(),
        )?;
        let a = to_pixel_major(&a);
        let mean_a2 = a.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / n as f64;
        if !(mean_a2 > 0.0 && mean_a2.is_finite()) {
            return Err(Error::Numerical(format!(
                "joint: the patterns through F carry no energy (mean ‖a‖² = {mean_a2:.3e}); the frame says nothing of α"
            )));
        }
        let mean_a_norm = a
            .chunks_exact(j)
            .map(|ap| ap.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt())
            .sum::<f64>()
            / n as f64;
        let btb = basis.transpose() * basis;
        let lmax = nalgebra::SymmetricEigen::new(btb).eigenvalues.max();
        if !(lmax > 0.0) {
            return Err(Error::Numerical("joint: the basis B is zero".into()));
        }
        // β scales the constraint's block of K to the gradient's norm (‖∇‖² ≤ 8).
        let beta = (8.0 / lmax).sqrt();
        let d2b = second_difference(bands) * basis;
        // The unmixer weighs ‖x − Fα‖² (data Hessian FᵀF) against η‖D₂Bα‖²; here the data
        // Hessian is a aᵀ, so η is scaled by mean‖a‖² / ‖F‖²_F to keep the same balance.
        let eta_joint = eta * mean_a2 / system.norm_squared();
        Ok(Joint {
            w,
            h,
            j,
            bands,
            cfg: cfg.clone(),
            a,
            bb: (0..bands)
                .flat_map(|k| (0..j).map(move |jj| (beta * basis[(k, jj)]) as f32))
                .collect(),
            eq: eta_joint * d2b.transpose() * &d2b,
            norm_k: 4.0,
            system: system.clone(),
            basis: basis.clone(),
            mean_a_norm,
        })
    }

    /// The state for `frame` (one plane) seeded by `seed` (J planes of α₀), with per-pixel
    /// data weights ω (None: 1).
    pub fn start(&self, frame: &Cube, seed: &Cube, omega: Option<&Cube>) -> Result<JointState> {
        let (w, h, j, n) = (self.w, self.h, self.j, self.w * self.h);
        if (frame.width, frame.height, frame.planes) != (w, h, 1)
            || (seed.width, seed.height, seed.planes) != (w, h, j)
            || omega.is_some_and(|o| (o.width, o.height, o.planes) != (w, h, 1))
        {
            return Err(Error::Shape(format!(
                "joint: frame {}×{}×{}, seed {}×{}×{} for {w}×{h} and J = {j}",
                frame.width, frame.height, frame.planes, seed.width, seed.height, seed.planes
            )));
        }
        if !frame.all_finite() || !seed.all_finite() || omega.is_some_and(|o| !o.all_finite()) {
            return Err(Error::Numerical(
                "joint: the frame, the seed or the weights contain NaN or infinite values".into(),
            ));
        }
        let omega: Vec<f32> = match omega {
            Some(o) if o.data.iter().any(|&v| v < 0.0) => {
                return Err(Error::Numerical("joint: a data weight is negative".into()))
            }
            Some(o) => o.data.clone(),
            None => vec![1.0; n],
        };
        let mean_y = frame.data.iter().map(|v| v.abs() as f64).sum::<f64>() / n as f64;
        let lambda = self.cfg.tv_weight * mean_y * self.mean_a_norm;
        let alpha = to_pixel_major(seed);
        let mean_alpha = alpha.iter().map(|v| v.abs() as f64).sum::<f64>() / alpha.len() as f64;
        let scale = if lambda > 0.0 && mean_alpha > 0.0 {
            mean_alpha / lambda
        } else {
            1.0
        };
        let tau = self.cfg.step_ratio * scale * STEP_PRODUCT.sqrt() / self.norm_k;
        let sigma = STEP_PRODUCT.sqrt() / (self.cfg.step_ratio * scale * self.norm_k);
        let mat = (DMatrix::identity(j, j) + tau * &self.eq)
            .try_inverse()
            .ok_or_else(|| Error::Numerical("joint: I + τη'Q is singular".into()))?;
        let mat32: Vec<f32> = mat.iter().map(|&v| v as f32).collect();
        let mut m = vec![0.0f32; n * j];
        let mut tck = vec![[0.0f32; 3]; n];
        m.par_chunks_mut(j)
            .zip(tck.par_iter_mut())
            .zip(self.a.par_chunks(j))
            .zip(frame.data.par_iter().zip(omega.par_iter()))
            .for_each(|(((mp, t), ap), (&y, &om))| {
                mat_vec(&mat32, ap, mp);
                let k: f32 = ap.iter().zip(mp.iter()).map(|(a, b)| a * b).sum();
                let tw = tau as f32 * om;
                *t = [tw * y, tw / (1.0 + tw * k), k];
            });
        Ok(JointState {
            bar: alpha.clone(),
            alpha,
            q: vec![0.0; n * 2 * j],
            r: vec![0.0; n * self.bands],
            mat: mat32,
            m,
            tck,
            y: frame.data.clone(),
            omega,
            lambda: lambda as f32,
            tau: tau as f32,
            sigma: sigma as f32,
            row_sums: vec![0.0; h],
        })
    }

    /// One Chambolle–Pock iteration: the dual steps on ∇ᾱ and βBᾱ, then the primal
    /// proximal step and the extrapolation ᾱ = 2α⁺ − α.
    pub fn step(&self, st: &mut JointState) {
        self.dual_step(st);
        self.primal_step(st);
    }

    /// q ← P_{‖·‖≤λ}(q + σ∇ᾱ) per pixel (joint over J and both directions); r ← min(r + σβBᾱ, 0).
    fn dual_step(&self, st: &mut JointState) {
        let (w, h, j, nb) = (self.w, self.h, self.j, self.bands);
        let (bar, sigma, lambda, bb) = (&st.bar, st.sigma, st.lambda, &self.bb);
        st.q.par_chunks_mut(w * 2 * j)
            .zip(st.r.par_chunks_mut(w * nb))
            .enumerate()
            .for_each(|(yy, (qrow, rrow))| {
                for x in 0..w {
                    let p = yy * w + x;
                    let qp = &mut qrow[x * 2 * j..(x + 1) * 2 * j];
                    let mut norm2 = 0.0f32;
                    for jj in 0..j {
                        let (gx, gy) = gradient(bar, w, h, j, x, yy, jj);
                        qp[2 * jj] += sigma * gx;
                        qp[2 * jj + 1] += sigma * gy;
                        norm2 += qp[2 * jj].powi(2) + qp[2 * jj + 1].powi(2);
                    }
                    let norm = norm2.sqrt();
                    if norm > lambda {
                        let s = if lambda > 0.0 { lambda / norm } else { 0.0 };
                        qp.iter_mut().for_each(|v| *v *= s);
                    }
                    let bp = &bar[p * j..(p + 1) * j];
                    for (k, rk) in rrow[x * nb..(x + 1) * nb].iter_mut().enumerate() {
                        let v: f32 = bb[k * j..(k + 1) * j]
                            .iter()
                            .zip(bp)
                            .map(|(b, a)| b * a)
                            .sum();
                        *rk = (*rk + sigma * v).min(0.0);
                    }
                }
            });
    }

    /// α⁺ = prox_{τf}(α − τ(∇ᵀq + βBᵀr)); ᾱ = 2α⁺ − α.
    fn primal_step(&self, st: &mut JointState) {
        let (w, h, j, nb) = (self.w, self.h, self.j, self.bands);
        let (q, r, bb, tau) = (&st.q, &st.r, &self.bb, st.tau);
        let (mat, m, tck) = (&st.mat, &st.m, &st.tck);
        st.alpha
            .par_chunks_mut(w * j)
            .zip(st.bar.par_chunks_mut(w * j))
            .enumerate()
            .for_each(|(yy, (arow, brow))| {
                let mut v = [0.0f32; MAX_J];
                let mut mv = [0.0f32; MAX_J];
                for x in 0..w {
                    let p = yy * w + x;
                    let rp = &r[p * nb..(p + 1) * nb];
                    let ap = &mut arow[x * j..(x + 1) * j];
                    for jj in 0..j {
                        let div = divergence(q, w, h, j, x, yy, jj);
                        let btr: f32 = rp.iter().enumerate().map(|(k, rk)| bb[k * j + jj] * rk).sum();
                        v[jj] = ap[jj] - tau * (btr - div);
                    }
                    mat_vec(mat, &v[..j], &mut mv[..j]);
                    let mp = &m[p * j..(p + 1) * j];
                    let [t, c, k] = tck[p];
                    let mtv: f32 = mp.iter().zip(&v[..j]).map(|(a, b)| a * b).sum();
                    let coef = t - c * (mtv + t * k);
                    for jj in 0..j {
                        let new = mv[jj] + coef * mp[jj];
                        brow[x * j + jj] = 2.0 * new - ap[jj];
                        ap[jj] = new;
                    }
                }
            });
    }

    /// ½Σω(y − aᵀα)² + ½Σ αᵀη'Qα + λΣ‖∇α‖ at the current α (row sums in f64, fixed order).
    pub fn objective(&self, st: &mut JointState) -> f64 {
        let (w, h, j) = (self.w, self.h, self.j);
        let eq = &self.eq;
        let (alpha, a, y, om, lambda) = (&st.alpha, &self.a, &st.y, &st.omega, st.lambda as f64);
        st.row_sums
            .par_iter_mut()
            .enumerate()
            .for_each(|(yy, sum)| {
                let mut s = 0.0f64;
                for x in 0..w {
                    let p = yy * w + x;
                    let ap = &alpha[p * j..(p + 1) * j];
                    let fit: f64 = a[p * j..(p + 1) * j]
                        .iter()
                        .zip(ap)
                        .map(|(u, v)| *u as f64 * *v as f64)
                        .sum();
                    s += 0.5 * om[p] as f64 * (y[p] as f64 - fit).powi(2);
                    let mut quad = 0.0;
                    for r in 0..j {
                        for c in 0..j {
                            quad += ap[r] as f64 * eq[(r, c)] * ap[c] as f64;
                        }
                    }
                    let mut g2 = 0.0f64;
                    for jj in 0..j {
                        let (gx, gy) = gradient(alpha, w, h, j, x, yy, jj);
                        g2 += (gx as f64).powi(2) + (gy as f64).powi(2);
                    }
                    s += 0.5 * quad + lambda * g2.sqrt();
                }
                *sum = s;
            });
        st.row_sums.iter().sum()
    }

    /// Run the configured iterations from `seed`; the objective is stored per iteration.
    pub fn run(
        &self,
        frame: &Cube,
        seed: &Cube,
        omega: Option<&Cube>,
    ) -> Result<(Cube, JointStats)> {
        let t0 = Instant::now();
        let mut st = self.start(frame, seed, omega)?;
        let mut objective = vec![self.objective(&mut st)];
        for _ in 0..self.cfg.iterations {
            crate::interrupt::check("the joint reconstruction")?;
            self.step(&mut st);
            objective.push(self.objective(&mut st));
        }
        if !st.alpha.iter().all(|v| v.is_finite()) {
            return Err(Error::Numerical(format!(
                "joint: non-finite coefficients after {} iterations",
                self.cfg.iterations
            )));
        }
        let alpha = from_pixel_major(&st.alpha, self.w, self.h, self.j);
        Ok((
            alpha,
            JointStats {
                iterations: self.cfg.iterations,
                objective,
                lambda: st.lambda as f64,
                steps: [st.tau as f64, st.sigma as f64],
                violation: 0.0,
                seconds: t0.elapsed().as_secs_f64(),
            },
        ))
    }

    /// The squared M-norm ‖z⁺ − z‖²_M of one step (M = [[I/τ, −Kᵀ], [−K, I/σ]]): PDHG is a
    /// proximal-point method in this metric, so the value never increases along the iterations
    /// (He & Yuan 2012).
    pub fn step_residual(&self, before: &JointState, after: &JointState) -> f64 {
        let (w, h, j, nb) = (self.w, self.h, self.j, self.bands);
        let n = w * h;
        let da: Vec<f32> = after.alpha.iter().zip(&before.alpha).map(|(a, b)| a - b).collect();
        let sq = |u: &[f32], v: &[f32]| -> f64 {
            u.iter().zip(v).map(|(a, b)| ((a - b) as f64).powi(2)).sum()
        };
        let mut cross = 0.0f64;
        for p in 0..n {
            let (x, yy) = (p % w, p / w);
            for jj in 0..j {
                let (gx, gy) = gradient(&da, w, h, j, x, yy, jj);
                let i = p * 2 * j + 2 * jj;
                cross += gx as f64 * (after.q[i] - before.q[i]) as f64;
                cross += gy as f64 * (after.q[i + 1] - before.q[i + 1]) as f64;
            }
            for k in 0..nb {
                let bda: f64 = (0..j)
                    .map(|jj| self.bb[k * j + jj] as f64 * da[p * j + jj] as f64)
                    .sum();
                cross += bda * (after.r[p * nb + k] - before.r[p * nb + k]) as f64;
            }
        }
        sq(&after.alpha, &before.alpha) / after.tau as f64
            + (sq(&after.q, &before.q) + sq(&after.r, &before.r)) / after.sigma as f64
            - 2.0 * cross
    }

    /// ‖K‖² by power iteration on KᵀK (for checking the bound the steps use).
    pub fn power_iteration(&self, iterations: usize) -> f64 {
        let (w, h, j, nb) = (self.w, self.h, self.j, self.bands);
        let n = w * h;
        let mut v: Vec<f32> = (0..n * j).map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.5).collect();
        let mut est = 0.0;
        for _ in 0..iterations {
            let norm = v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
            v.iter_mut().for_each(|x| *x /= norm as f32);
            let mut q = vec![0.0f32; n * 2 * j];
            for p in 0..n {
                for jj in 0..j {
                    let (gx, gy) = gradient(&v, w, h, j, p % w, p / w, jj);
                    q[p * 2 * j + 2 * jj] = gx;
                    q[p * 2 * j + 2 * jj + 1] = gy;
                }
            }
            let mut out = vec![0.0f32; n * j];
            for p in 0..n {
                for jj in 0..j {
                    let mut s = -divergence(&q, w, h, j, p % w, p / w, jj);
                    for k in 0..nb {
                        let bv: f32 = (0..j).map(|i| self.bb[k * j + i] * v[p * j + i]).sum();
                        s += self.bb[k * j + jj] * bv;
                    }
                    out[p * j + jj] = s;
                }
            }
            est = out.iter().zip(&v).map(|(a, b)| (a * b) as f64).sum::<f64>();
            v = out;
        }
        est
    }

    /// The channels x = Fα (C planes) of coefficient planes α.
    pub fn channels(&self, alpha: &Cube) -> Result<Cube> {
        alpha.mix(&rows(&self.system))
    }

    /// The cube diag(gains)·Bα with its negative values (the constraint's violation left by the
    /// last iterate) set to zero, and that violation relative to the largest value.
    pub fn cube(&self, alpha: &Cube, gains: Option<&[f64]>) -> Result<(Cube, f64)> {
        let mut b = rows(&self.basis);
        if let Some(g) = gains {
            b.iter_mut().zip(g).for_each(|(row, g)| row.iter_mut().for_each(|v| *v *= g));
        }
        let mut cube = alpha.mix(&b)?;
        let (lo, hi) = cube
            .data
            .iter()
            .fold((0.0f32, 0.0f32), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        cube.data.par_iter_mut().for_each(|v| *v = v.max(0.0));
        let violation = if hi > 0.0 { (-lo / hi) as f64 } else { 0.0 };
        Ok((cube, violation))
    }

    /// The bound ‖K‖ the step sizes use.
    pub fn operator_norm(&self) -> f64 {
        self.norm_k
    }
}

/// Largest J the per-pixel kernels handle on the stack.
pub const MAX_J: usize = crate::unmix::MAX_BASIS;

/// out = M v for a J × J matrix stored column-major (nalgebra's order; M is symmetric anyway).
#[inline]
fn mat_vec(mat: &[f32], v: &[f32], out: &mut [f32]) {
    let j = v.len();
    for (r, o) in out.iter_mut().enumerate() {
        *o = (0..j).map(|c| mat[c * j + r] * v[c]).sum();
    }
}

/// Forward differences of coefficient `jj` (pixel-major, J per pixel), zero across the last
/// column and row (Neumann), as in `tv.rs`.
#[inline]
fn gradient(u: &[f32], w: usize, h: usize, j: usize, x: usize, y: usize, jj: usize) -> (f32, f32) {
    let p = (y * w + x) * j + jj;
    let gx = if x + 1 < w { u[p + j] - u[p] } else { 0.0 };
    let gy = if y + 1 < h { u[p + w * j] - u[p] } else { 0.0 };
    (gx, gy)
}

/// div q = −∇ᵀq of coefficient `jj` for `gradient`'s differences (q: (qx, qy) per coefficient).
#[inline]
fn divergence(q: &[f32], w: usize, h: usize, j: usize, x: usize, y: usize, jj: usize) -> f32 {
    let p = y * w + x;
    let at = |p: usize, d: usize| q[p * 2 * j + 2 * jj + d];
    let dx = if x + 1 < w { at(p, 0) } else { 0.0 } - if x > 0 { at(p - 1, 0) } else { 0.0 };
    let dy = if y + 1 < h { at(p, 1) } else { 0.0 } - if y > 0 { at(p - w, 1) } else { 0.0 };
    dx + dy
}

/// A matrix as rows of f64 (the mixing matrices of `Cube::mix`).
fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// Planes → pixel-major (the planes of one pixel contiguous).
fn to_pixel_major(c: &Cube) -> Vec<f32> {
    let (n, j) = (c.pixels(), c.planes);
    let mut out = vec![0.0f32; n * j];
    out.par_chunks_mut(j).enumerate().for_each(|(p, o)| {
        for (k, v) in o.iter_mut().enumerate() {
            *v = c.data[k * n + p];
        }
    });
    out
}

/// Pixel-major → planes.
fn from_pixel_major(v: &[f32], w: usize, h: usize, j: usize) -> Cube {
    let n = w * h;
    let mut c = Cube::zeros(w, h, j);
    c.data.par_chunks_mut(n).enumerate().for_each(|(k, plane)| {
        for (p, o) in plane.iter_mut().enumerate() {
            *o = v[p * j + k];
        }
    });
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::carriers::default_layout;

    const BANDS: usize = 16;

    /// Six sinusoidal patterns of the default layout on a w × h frame.
    fn patterns(w: usize, h: usize) -> Cube {
        let carriers = default_layout();
        let mut c = Cube::zeros(w, h, carriers.len());
        for (k, cr) in carriers.iter().enumerate() {
            let plane = c.plane_mut(k);
            for y in 0..h {
                for x in 0..w {
                    let ph = 2.0 * std::f64::consts::PI * (cr.fx * x as f64 + cr.fy * y as f64);
                    plane[y * w + x] = (0.5 * (1.0 + ph.cos())) as f32;
                }
            }
        }
        c
    }

    /// A smooth basis (bands × 4): constant, and three cosines across the bands.
    fn basis() -> DMatrix<f64> {
        DMatrix::from_fn(BANDS, 4, |k, j| {
            let t = k as f64 / (BANDS - 1) as f64;
            (std::f64::consts::PI * j as f64 * t).cos() / (BANDS as f64).sqrt()
        })
    }

    /// Six Gaussian filters across the bands seen through the basis: F = T B.
    fn system(b: &DMatrix<f64>) -> DMatrix<f64> {
        let t = DMatrix::from_fn(6, BANDS, |i, k| {
            let c = 1.0 + i as f64 * 2.6;
            (-((k as f64 - c) / 2.5).powi(2)).exp()
        });
        t * b
    }

    /// α: the first coefficient 1 (or 2 in the right half), the others a small pattern of
    /// three rectangles, so Bα > 0 everywhere.
    fn truth(w: usize, h: usize) -> Cube {
        let mut a = Cube::zeros(w, h, 4);
        for y in 0..h {
            for x in 0..w {
                let p = y * w + x;
                let right = x >= w / 2;
                let block = (w / 4..w / 2).contains(&y);
                a.data[p] = if right { 2.0 } else { 1.0 };
                a.data[w * h + p] = if block { 0.3 } else { -0.1 };
                a.data[2 * w * h + p] = if right && block { 0.2 } else { 0.0 };
                a.data[3 * w * h + p] = 0.05;
            }
        }
        a
    }

    /// y = Σ_j a_j ⊙ α_j with a = Fᵀ s.
    fn frame_of(j: &Joint, alpha: &Cube) -> Cube {
        let (w, h) = (alpha.width, alpha.height);
        let am = to_pixel_major(alpha);
        let y = (0..w * h)
            .map(|p| (0..j.j).map(|k| j.a[p * j.j + k] * am[p * j.j + k]).sum())
            .collect();
        Cube::from_vec(w, h, 1, y).unwrap()
    }

    fn solver(w: usize, eta: f64, cfg: JointConfig) -> Joint {
        let b = basis();
        Joint::new(&patterns(w, w), &system(&b), &b, eta, &cfg, "t.toml").unwrap()
    }

    /// The seed: every pixel the image-wide mean of the truth (what a blurry estimate gives).
    fn flat_seed(t: &Cube) -> Cube {
        let n = t.pixels();
        let mut s = t.clone();
        for plane in s.planes_mut() {
            let m = plane.iter().sum::<f32>() / n as f32;
            plane.iter_mut().for_each(|v| *v = m);
        }
        s
    }

    #[test]
    fn the_step_bound_holds_against_power_iteration() {
        let j = solver(16, 1.0, JointConfig::default());
        let est = j.power_iteration(200);
        assert!(est <= j.operator_norm().powi(2) * (1.0 + 1e-5), "{est}");
        // The bound is not loose by more than the gradient's boundary effect.
        assert!(est > 0.8 * j.operator_norm().powi(2), "{est}");
    }

    #[test]
    fn the_fixed_point_residual_never_increases_over_500_iterations() {
        let cfg = JointConfig {
            iterations: 500,
            tv_weight: 0.01,
            ..Default::default()
        };
        let j = solver(32, 1.0, cfg);
        let t = truth(32, 32);
        let y = frame_of(&j, &t);
        let mut st = j.start(&y, &flat_seed(&t), None).unwrap();
        let mut last = f64::INFINITY;
        let mut first = 0.0;
        for it in 0..500 {
            let before = clone_state(&st);
            j.step(&mut st);
            let r = j.step_residual(&before, &st);
            if it == 0 {
                first = r;
            }
            // f32 iterates: allow rounding at 1e-4 of the first step's residual.
            assert!(r <= last + 1e-4 * first, "iteration {it}: {r} after {last}");
            last = r;
        }
        assert!(last < 1e-3 * first, "{last} vs {first}");
        let obj = j.objective(&mut st);
        assert!(obj.is_finite() && obj > 0.0);
    }

    fn clone_state(s: &JointState) -> JointState {
        JointState {
            alpha: s.alpha.clone(),
            bar: s.bar.clone(),
            q: s.q.clone(),
            r: s.r.clone(),
            mat: s.mat.clone(),
            m: s.m.clone(),
            tck: s.tck.clone(),
            y: s.y.clone(),
            omega: s.omega.clone(),
            lambda: s.lambda,
            tau: s.tau,
            sigma: s.sigma,
            row_sums: s.row_sums.clone(),
        }
    }

    /// With η = 0 a constant α field fitting y = Aα exactly has objective 0, the least any
    /// field can have, and no other field reaches it (zero TV means constant, and the patterns
    /// vary enough across the frame that one constant fits): the exact minimiser.
    #[test]
    fn a_cube_in_the_range_is_recovered() {
        let cfg = JointConfig {
            iterations: 2000,
            tv_weight: 1e-3,
            ..Default::default()
        };
        let j = solver(32, 0.0, cfg);
        let mut t = Cube::zeros(32, 32, 4);
        for (plane, v) in t.planes_mut().zip([0.9f32, 0.2, -0.1, 0.05]) {
            plane.fill(v);
        }
        let y = frame_of(&j, &t);
        let seed = flat_seed(&truth(32, 32));
        let (est, stats) = j.run(&y, &seed, None).unwrap();
        let err = est
            .data
            .iter()
            .zip(&t.data)
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum::<f64>()
            .sqrt();
        let norm = t.data.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        eprintln!("relative error {:.3e}, objective {:?}", err / norm, &stats.objective[stats.objective.len() - 3..]);
        assert!(err / norm < 1e-4, "relative error {:.3e}", err / norm);
        assert!(stats.objective.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn stiff_cases_stay_finite_or_are_refused() {
        let cfg = JointConfig {
            iterations: 200,
            ..Default::default()
        };
        let j = solver(32, 1.0, cfg.clone());
        // Zero frame, zero seed: zero out, objective zero throughout.
        let zero = Cube::zeros(32, 32, 1);
        let (est, st) = j.run(&zero, &Cube::zeros(32, 32, 4), None).unwrap();
        assert!(est.data.iter().all(|&v| v == 0.0) && st.objective.iter().all(|&v| v == 0.0));
        // 70 % of the frame clipped to one value: finite, and the objective falls below the seed's.
        let t = truth(32, 32);
        let mut y = frame_of(&j, &t);
        let top = y.max() * 0.6;
        y.data.iter_mut().take(32 * 22).for_each(|v| *v = top);
        let (est, st) = j.run(&y, &flat_seed(&t), None).unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
        assert!(st.objective.last().unwrap() < &st.objective[0], "{:?}", st.objective);
        // Two filters alike to 1e-9 (F near-singular): the prior keeps the problem posed.
        let b = basis();
        let mut f = system(&b);
        let row = f.row(0).clone_owned();
        f.set_row(1, &(row * (1.0 + 1e-9)));
        let near = Joint::new(&patterns(32, 32), &f, &b, 1.0, &cfg, "t.toml").unwrap();
        let (est, st) = near.run(&frame_of(&near, &t), &flat_seed(&t), None).unwrap();
        assert!(est.all_finite() && st.objective.iter().all(|v| v.is_finite()));
        // F = 0: the frame says nothing of α; refused with the reason.
        let e = Joint::new(&patterns(32, 32), &(f * 0.0), &b, 1.0, &cfg, "t.toml")
            .err()
            .unwrap();
        assert!(e.to_string().contains("no energy"), "{e}");
        // Bad settings name their key.
        let bad = JointConfig {
            tv_weight: -1.0,
            ..cfg
        };
        let e = Joint::new(&patterns(32, 32), &system(&b), &b, 1.0, &bad, "t.toml")
            .err()
            .unwrap();
        assert!(e.to_string().contains("reconstruct.joint.tv_weight"), "{e}");
    }

}
