//! Second-order total generalised variation (TGV², Bredies, Kunisch & Pock 2010) as the joint
//! method's spatial prior, with the same data and smoothness terms and constraint as TV:
//!
//!   min_{α, v}  f(α) + λ Σ_p ‖∇α − v‖₂ + λ₀ Σ_p ‖∇v‖₂   s.t. Bα ≥ 0,   λ₀ = `tgv_ratio`·λ,
//!
//! v a vector field per coefficient (2J per pixel), both norms joint over the coefficients (and
//! ‖∇v‖ over the full Jacobian of v, which vanishes on affine α as the symmetrised one does). A
//! ramp costs nothing where TV charges its slope; an edge costs λ times its jump, as in TV.
//!
//! Chambolle–Pock on the primal (α, v) and the duals (p, w, r) of K = [[∇, −I], [0, ∇], [βB, 0]]
//! with ‖K‖² ≤ 2·8 + 8 = 24 (α) and 2 + 8 (v), over-relaxed as the TV iteration is. v is kept at
//! zero where the gradient it stands for is zero by the boundary (vx in the last column, vy in
//! the last row), so every dual is zero there and `row_divergence` stays ∇'s exact adjoint.

use super::{
    from_pixel_major, relax, row_divergence, row_gradients, with_basis_len, Joint, JointState,
    JointStats, PrimalRow, MAX_J,
};
use crate::error::Result;
use crate::Cube;
use rayon::prelude::*;
use std::time::Instant;

/// The bound on ‖K‖ the steps use: √24 ([`Joint::power_iteration`]'s counterpart for this K is
/// checked in the tests).
pub const NORM_K: f64 = 4.898_979_485_566_356;

/// The TV state (α, ᾱ, the dual p of ∇α − v in qx/qy, r, the tables) and TGV's own fields.
pub(super) struct TgvState {
    pub base: JointState,
    /// v = (vx, vy) and its extrapolation v̄, pixel-major (J per pixel each).
    v: [Vec<f32>; 2],
    vbar: [Vec<f32>; 2],
    /// Duals of ∇v: (Dx vx, Dy vx, Dx vy, Dy vy), pixel-major.
    w: [Vec<f32>; 4],
}

/// Run `joint`'s configured iterations with the TGV prior from `seed` (v starts at 0).
pub fn run(
    joint: &Joint,
    frame: &Cube,
    seed: &Cube,
    omega: Option<&Cube>,
) -> Result<(Cube, JointStats)> {
    let t0 = Instant::now();
    let mut st = start(joint, frame, seed, omega)?;
    let mut objective = vec![objective(joint, &st)];
    for _ in 0..joint.cfg.iterations {
        crate::interrupt::check("the joint reconstruction (TGV)")?;
        step(joint, &mut st);
        if joint.cfg.trace_objective {
            objective.push(self::objective(joint, &st));
        }
    }
    if !joint.cfg.trace_objective {
        objective.push(self::objective(joint, &st));
    }
    let stats = joint.finish(&st.base, objective, t0, omega.is_some())?;
    Ok((
        from_pixel_major(&st.base.alpha, joint.w, joint.h, joint.j),
        stats,
    ))
}

/// The state: TV's start (λ, the steps for ‖K‖ = √24, the tables) with v = v̄ = 0, w = 0.
pub(super) fn start(
    joint: &Joint,
    frame: &Cube,
    seed: &Cube,
    omega: Option<&Cube>,
) -> Result<TgvState> {
    let base = joint.start(frame, seed, omega)?;
    let zero = || vec![0.0f32; base.alpha.len()];
    Ok(TgvState {
        v: [zero(), zero()],
        vbar: [zero(), zero()],
        w: [zero(), zero(), zero(), zero()],
        base,
    })
}

/// One over-relaxed Chambolle–Pock iteration: the duals on K(ᾱ, v̄), then the primal steps.
pub(super) fn step(joint: &Joint, st: &mut TgvState) {
    dual_step(joint, st);
    primal_step(joint, st);
}

/// p ← P_λ(p + σ(∇ᾱ − v̄)), w ← P_λ₀(w + σ∇v̄) per pixel (each joint over its fields), r as
/// in TV; every result stored relaxed.
fn dual_step(joint: &Joint, st: &mut TgvState) {
    let (w, h, j, nb) = (joint.w, joint.h, joint.j, joint.nbp);
    let row = w * j;
    let b = &mut st.base;
    let (bar, vbar, sigma, over) = (&b.bar, &st.vbar, b.sigma, joint.cfg.relaxation as f32 - 1.0);
    let (lam1, lam0) = (b.lambda, b.lambda * joint.cfg.tgv_ratio as f32);
    let [w0, w1, w2, w3] = &mut st.w;
    b.qx.par_chunks_mut(row)
        .zip(b.qy.par_chunks_mut(row))
        .zip(b.r.par_chunks_mut(w * nb).zip(b.active.par_chunks_mut(w)))
        .zip(w0.par_chunks_mut(row).zip(w1.par_chunks_mut(row)))
        .zip(w2.par_chunks_mut(row).zip(w3.par_chunks_mut(row)))
        .enumerate()
        .for_each_init(
            || vec![vec![0.0f32; row]; 6],
            |g, (yy, ((((qx, qy), (rrow, act)), (w0, w1)), (w2, w3)))| {
                let [gx, gy, g0, g1, g2, g3] = &mut g[..] else {
                    unreachable!("six scratch rows")
                };
                row_gradients(bar, w, h, j, yy, gx, gy);
                let px = yy * row..(yy + 1) * row;
                sub(gx, &vbar[0][px.clone()]);
                sub(gy, &vbar[1][px.clone()]);
                ball_row([qx, qy], [gx, gy], j, sigma, lam1, over);
                row_gradients(&vbar[0], w, h, j, yy, g0, g1);
                row_gradients(&vbar[1], w, h, j, yy, g2, g3);
                ball_row([w0, w1, w2, w3], [g0, g1, g2, g3], j, sigma, lam0, over);
                let pixels = bar[px].chunks_exact(j).zip(rrow.chunks_exact_mut(nb));
                for ((bp, rp), a) in pixels.zip(act.iter_mut()) {
                    joint.constraint_dual(bp, rp, a, sigma, over);
                }
            },
        );
}

/// g ← g − v.
fn sub(g: &mut [f32], v: &[f32]) {
    g.iter_mut().zip(v).for_each(|(a, b)| *a -= b);
}

/// Per pixel of a row: t = d + σg over the K fields (J values each), projected on the ball
/// ‖t‖₂ ≤ λ jointly over its K·J values, stored relaxed (t + (γ − 1)(t − d)).
fn ball_row<const K: usize>(
    mut duals: [&mut [f32]; K],
    grads: [&mut [f32]; K],
    j: usize,
    sigma: f32,
    lambda: f32,
    over: f32,
) {
    let mut t = [0.0f32; 4 * MAX_J];
    for p in 0..duals[0].len() / j {
        let px = p * j..(p + 1) * j;
        let mut n2 = 0.0f32;
        for (k, (d, g)) in duals.iter().zip(&grads).enumerate() {
            for (tv, (dv, gv)) in t[k * j..(k + 1) * j]
                .iter_mut()
                .zip(d[px.clone()].iter().zip(&g[px.clone()]))
            {
                *tv = dv + sigma * gv;
                n2 += *tv * *tv;
            }
        }
        let f = match n2 > lambda * lambda {
            true if lambda > 0.0 => lambda / n2.sqrt(),
            true => 0.0,
            false => 1.0,
        };
        t[..K * j].iter_mut().for_each(|v| *v *= f);
        for (k, d) in duals.iter_mut().enumerate() {
            relax(&mut d[px.clone()], &t[k * j..(k + 1) * j], over);
        }
    }
}

/// α as in TV (the prox from the relaxed point with div p and βBᵀr); v⁺ = x_v + τ(p + div w)
/// from v's relaxed point x_v, v̄ = 2v⁺ − x_v, then v's boundary zeros restored.
fn primal_step(joint: &Joint, st: &mut TgvState) {
    let (w, h, j, nb) = (joint.w, joint.h, joint.j, joint.nbp);
    let row = w * j;
    let b = &mut st.base;
    let (qx, qy, r, act, tau) = (&b.qx, &b.qy, &b.r, &b.active, b.tau);
    let (mat, m, tck, ww) = (&b.mat, &b.m, &b.tck, &st.w);
    let over = joint.cfg.relaxation as f32 - 1.0;
    let [vx, vy] = &mut st.v;
    let [bx, by] = &mut st.vbar;
    b.alpha
        .par_chunks_mut(row)
        .zip(b.bar.par_chunks_mut(row))
        .zip(vx.par_chunks_mut(row).zip(bx.par_chunks_mut(row)))
        .zip(vy.par_chunks_mut(row).zip(by.par_chunks_mut(row)))
        .enumerate()
        .for_each_init(
            || vec![0.0f32; row],
            |div, (yy, (((arow, brow), (vxr, bxr)), (vyr, byr)))| {
                row_divergence(qx, qy, w, j, yy, div);
                let px = yy * w..(yy + 1) * w;
                let prow = PrimalRow {
                    alpha: arow,
                    bar: brow,
                    div,
                    active: &act[px.clone()],
                    r: &r[px.start * nb..px.end * nb],
                    m: &m[px.start * j..px.end * j],
                    tck: &tck[px],
                };
                with_basis_len!(j, J => joint.primal_row::<J>(prow, mat, tau));
                let q = yy * row..(yy + 1) * row;
                for (c, (v, vb), p) in [
                    (0, (&mut *vxr, &mut *bxr), qx),
                    (1, (&mut *vyr, &mut *byr), qy),
                ] {
                    row_divergence(&ww[2 * c], &ww[2 * c + 1], w, j, yy, div);
                    for (((vv, bv), pv), dv) in v
                        .iter_mut()
                        .zip(vb.iter_mut())
                        .zip(&p[q.clone()])
                        .zip(div.iter())
                    {
                        let x = *vv + over * (*bv - *vv);
                        let next = x + tau * (pv + dv);
                        *bv = 2.0 * next - x;
                        *vv = next;
                    }
                }
                // vx in the last column, vy in the last row: zero, as the gradients there.
                vxr[(w - 1) * j..].fill(0.0);
                bxr[(w - 1) * j..].fill(0.0);
                if yy + 1 == h {
                    vyr.fill(0.0);
                    byr.fill(0.0);
                }
            },
        );
}

/// f(α) + λΣ‖∇α − v‖ + λ₀Σ‖∇v‖ at the current (α, v), row sums in f64.
pub(super) fn objective(joint: &Joint, st: &TgvState) -> f64 {
    let (w, h, j) = (joint.w, joint.h, joint.j);
    let b = &st.base;
    let (lam1, lam0) = (b.lambda as f64, b.lambda as f64 * joint.cfg.tgv_ratio);
    let norms = |fields: &[&[f32]], p: usize| -> f64 {
        let sq: f64 = (fields.iter())
            .flat_map(|f| &f[p * j..(p + 1) * j])
            .map(|&v| (v as f64).powi(2))
            .sum();
        sq.sqrt()
    };
    let rows: Vec<f64> = (0..h)
        .into_par_iter()
        .map_init(
            || vec![vec![0.0f32; w * j]; 6],
            |g, yy| {
                let [gx, gy, g0, g1, g2, g3] = &mut g[..] else {
                    unreachable!("six scratch rows")
                };
                let fit = joint.row_cost(&b.alpha, &b.y, &b.omega, 0.0, yy, (gx, gy));
                let px = yy * w * j..(yy + 1) * w * j;
                sub(gx, &st.v[0][px.clone()]);
                sub(gy, &st.v[1][px]);
                row_gradients(&st.v[0], w, h, j, yy, g0, g1);
                row_gradients(&st.v[1], w, h, j, yy, g2, g3);
                let first: f64 = (0..w).map(|p| norms(&[gx, gy], p)).sum();
                let second: f64 = (0..w).map(|p| norms(&[g0, g1, g2, g3], p)).sum();
                fit + lam1 * first + lam0 * second
            },
        )
        .collect();
    // Summed in row order: the same value on any number of threads.
    rows.iter().sum()
}
