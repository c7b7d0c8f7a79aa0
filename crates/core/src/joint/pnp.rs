//! Plug-and-play joint reconstruction: ADMM on min_α f(α) + g(α) with f the joint method's data
//! and smoothness terms (its per-pixel closed-form proximal step) and the prior's proximal step
//! replaced by the guided graph smoother Wⁿ of `denoise.rs`:
//!
//!   x = prox_{τf}(z − u),   z⁺ = Wⁿ(x + u),   u⁺ = u + x − z⁺,   τ = 1/(pnp_weight·mean ω‖a‖²).
//!
//! The smoother's guide is x + u, refreshed every `REFRESH` iterations during the first half of
//! the run and then frozen: from there Wⁿ is a fixed symmetric matrix with eigenvalues in
//! [0, 1], the proximal operator of a convex quadratic, so the rest is ADMM on a convex problem
//! (it converges, and ‖Δz‖² + ‖Δu‖² never increases: He & Yuan 2015). Before the freeze no
//! theory covers it. With `pnp_nonnegative` (default) Bα ≥ 0 is a third term ι_C handled by a
//! second copy z₂ = P_C(x + u₂) (consensus ADMM: x against (z, z₂), still two blocks, so the
//! same argument holds); the output is then z₂, feasible.

use super::lane::Scalar;
use super::{prox, with_basis_len, Joint, JointStats, MAX_J};
use crate::denoise::GraphSmoother;
use crate::error::{Error, Result};
use crate::noise::DataWeights;
use crate::unmix::Unmixer;
use crate::Cube;
use nalgebra::DMatrix;
use rayon::prelude::*;
use std::time::Instant;

/// Iterations between refreshes of the smoother's guide before the freeze.
const REFRESH: usize = 5;

/// The ADMM iterates (pixel-major, J per pixel): x, z, u and two scratch fields.
struct Admm {
    x: Vec<f32>,
    z: Vec<f32>,
    u: Vec<f32>,
    scratch: Vec<f32>,
    tmp: Vec<f32>,
    /// The constraint's copy z₂ = P_C(x + u₂) and its scaled dual u₂ (empty when off).
    z2: Vec<f32>,
    u2: Vec<f32>,
}

/// Run `joint`'s configured iterations of plug-and-play ADMM from `seed`; α = z at the end.
pub fn run(
    joint: &Joint,
    frame: &Cube,
    seed: &Cube,
    weights: Option<&DataWeights>,
) -> Result<(Cube, JointStats)> {
    let t0 = Instant::now();
    let cfg = &joint.cfg;
    let (w, h, j) = (joint.w, joint.h, joint.j);
    let mut st = joint.start(frame, seed, weights)?;
    st.lambda = 0.0;
    let first = joint.objective(&mut st);
    let weight: f64 = joint
        .a
        .par_chunks(j)
        .zip(st.omega.par_iter())
        .map(|(ap, &om)| om as f64 * ap.iter().map(|&v| (v as f64).powi(2)).sum::<f64>())
        .sum::<f64>()
        / (w * h) as f64;
    if weight.is_nan() || weight <= 0.0 {
        return Err(Error::Numerical(
            "joint (plug-and-play): every data weight is zero; the frame says nothing of α".into(),
        ));
    }
    let tau = 1.0 / (cfg.pnp_weight * weight);
    // With the constraint's copy the x-step penalty is 2ρ: prox_{(τ/2)f} of the mean of the two.
    let projector = match cfg.pnp_nonnegative {
        true => Some(Unmixer::new(&DMatrix::identity(j, j), &joint.basis, 0.0)?),
        false => None,
    };
    let copies = if projector.is_some() { 2.0 } else { 1.0 };
    let (mat, m, tck) = joint.prox_tables(tau / copies, &st)?;
    let alpha = st.alpha();
    let n = alpha.len();
    let mut s = Admm {
        x: alpha.clone(),
        z: alpha.clone(),
        u: vec![0.0; n],
        scratch: vec![0.0; n],
        tmp: vec![0.0; n],
        z2: if projector.is_some() {
            alpha
        } else {
            Vec::new()
        },
        u2: if projector.is_some() {
            vec![0.0; n]
        } else {
            Vec::new()
        },
    };
    let freeze = cfg.iterations / 2;
    let mut smoother = None;
    let mut fixed_point = Vec::with_capacity(cfg.iterations);
    for it in 0..cfg.iterations {
        crate::interrupt::check("the plug-and-play joint reconstruction")?;
        let (z2, u2) = (&s.z2, &s.u2);
        s.x.par_chunks_mut(j)
            .enumerate()
            .zip(s.z.par_chunks(j).zip(s.u.par_chunks(j)))
            .zip(m.par_chunks(j).zip(tck.par_iter()))
            .for_each(|(((p, xp), (zp, up)), (mp, &t))| {
                let mut v = [0.0f32; MAX_J];
                for ((vk, zk), uk) in v.iter_mut().zip(zp).zip(up) {
                    *vk = zk - uk;
                }
                if !z2.is_empty() {
                    for (k, vk) in v[..j].iter_mut().enumerate() {
                        *vk = 0.5 * (*vk + z2[p * j + k] - u2[p * j + k]);
                    }
                }
                with_basis_len!(j, J => {
                    let mp = std::array::from_fn(|c| mp[c]);
                    let out = prox::<J, Scalar>(&mat, mp, t, std::array::from_fn(|c| v[c]));
                    xp.copy_from_slice(&out);
                });
            });
        // s.scratch = x + u: the smoother's input and, before the freeze, its guide.
        s.scratch
            .par_iter_mut()
            .zip(s.x.par_iter().zip(s.u.par_iter()))
            .for_each(|(o, (x, u))| *o = x + u);
        if smoother.is_none() || (it < freeze && it % REFRESH == 0) {
            smoother = Some(GraphSmoother::new(&s.scratch, w, h, j, cfg.pnp_edge)?);
        }
        if let Some(sm) = &smoother {
            sm.smooth(&mut s.scratch, j, cfg.pnp_passes, &mut s.tmp);
        }
        let mut change = update(&mut s);
        if let Some(pr) = &projector {
            change += project(&mut s, pr, j)?;
        }
        fixed_point.push(change);
    }
    let alpha = if projector.is_some() { s.z2 } else { s.z };
    st.set_alpha(&alpha);
    let last = joint.objective(&mut st);
    let mut stats = joint.finish(&st, vec![first, last], t0, weights.is_some())?;
    stats.steps = [tau, 0.0];
    stats.lambda = 0.0;
    stats.fixed_point = fixed_point;
    Ok((st.alpha_cube(), stats))
}

/// z⁺ = `s.scratch`: u ← u + x − z⁺, z ← z⁺; returns ‖z⁺ − z‖² + ‖Δu‖² (Δu = x − z⁺).
fn update(s: &mut Admm) -> f64 {
    let sum =
        s.u.par_iter_mut()
            .zip(s.x.par_iter())
            .zip(s.scratch.par_iter().zip(s.z.par_iter()))
            .map(|((u, &x), (&zn, &z))| {
                let du = x - zn;
                *u += du;
                (du as f64).powi(2) + ((zn - z) as f64).powi(2)
            })
            .sum();
    std::mem::swap(&mut s.z, &mut s.scratch);
    sum
}

/// z₂⁺ = P_C(x + u₂) per pixel (C = {α: Bα ≥ 0}, the exact Euclidean projection: the unmixer's
/// active-set QP with H = I), u₂ ← u₂ + x − z₂⁺; returns ‖Δz₂‖² + ‖Δu₂‖².
fn project(s: &mut Admm, projector: &Unmixer, j: usize) -> Result<f64> {
    let sums: Vec<f64> =
        s.z2.par_chunks_mut(j)
            .zip(s.u2.par_chunks_mut(j))
            .zip(s.x.par_chunks(j))
            .map(|((zp, up), xp)| {
                let mut v = [0.0f64; MAX_J];
                let mut out = [0.0f64; MAX_J];
                for k in 0..j {
                    v[k] = (xp[k] + up[k]) as f64;
                }
                projector.solve_pixel(&v[..j], &mut out[..j])?;
                let mut sum = 0.0;
                for k in 0..j {
                    let zn = out[k] as f32;
                    let du = xp[k] - zn;
                    up[k] += du;
                    sum += (du as f64).powi(2) + ((zn - zp[k]) as f64).powi(2);
                    zp[k] = zn;
                }
                Ok(sum)
            })
            .collect::<Result<Vec<f64>>>()?;
    Ok(sums.iter().sum())
}
