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
//! theory covers it. Bα ≥ 0 is not enforced: the cube is clipped and the violation reported.

use super::{from_pixel_major, prox_pixel, Joint, JointStats, MAX_J};
use crate::denoise::GraphSmoother;
use crate::error::{Error, Result};
use crate::Cube;
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
}

/// Run `joint`'s configured iterations of plug-and-play ADMM from `seed`; α = z at the end.
pub fn run(
    joint: &Joint,
    frame: &Cube,
    seed: &Cube,
    omega: Option<&Cube>,
) -> Result<(Cube, JointStats)> {
    let t0 = Instant::now();
    let cfg = &joint.cfg;
    let (w, h, j) = (joint.w, joint.h, joint.j);
    let mut st = joint.start(frame, seed, omega)?;
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
    let (mat, m, tck) = joint.prox_tables(tau, &st.y, &st.omega)?;
    let mut s = Admm {
        x: st.alpha.clone(),
        z: st.alpha.clone(),
        u: vec![0.0; st.alpha.len()],
        scratch: vec![0.0; st.alpha.len()],
        tmp: vec![0.0; st.alpha.len()],
    };
    let freeze = cfg.iterations / 2;
    let mut smoother = None;
    let mut fixed_point = Vec::with_capacity(cfg.iterations);
    for it in 0..cfg.iterations {
        crate::interrupt::check("the plug-and-play joint reconstruction")?;
        s.x.par_chunks_mut(j)
            .zip(s.z.par_chunks(j).zip(s.u.par_chunks(j)))
            .zip(m.par_chunks(j).zip(tck.par_iter()))
            .for_each(|((xp, (zp, up)), (mp, &t))| {
                let mut v = [0.0f32; MAX_J];
                for ((vk, zk), uk) in v.iter_mut().zip(zp).zip(up) {
                    *vk = zk - uk;
                }
                prox_pixel(&mat, mp, t, &v[..j], xp);
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
        fixed_point.push(update(&mut s));
    }
    st.alpha.copy_from_slice(&s.z);
    let last = joint.objective(&mut st);
    let mut stats = joint.finish(&st, vec![first, last], t0, omega.is_some())?;
    stats.steps = [tau, 0.0];
    stats.lambda = 0.0;
    stats.fixed_point = fixed_point;
    Ok((from_pixel_major(&st.alpha, w, h, j), stats))
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
