//! The dual active-set method of Goldfarb and Idnani (Math. Programming 27, 1983) for one pixel:
//! min ½αᵀHα − gᵀα s.t. Bα ≥ 0. It starts at the unconstrained minimiser (already computed for
//! the fast path) and adds the most violated band, dropping a band whose multiplier would turn
//! negative, so a pixel with k binding bands takes about k steps. Each step updates the
//! factorisation J = L⁻ᵀQ, JᵀN = [R; 0] (H = LLᵀ, N the active band rows) by Givens rotations.

use crate::error::Error;
use crate::error::Result;
use crate::unmix::SolveInfo;
use crate::unmix::Unmixer;
use crate::unmix::MAX_BANDS;
use crate::unmix::MAX_BASIS;
use crate::unmix::MAX_ITERATIONS;

type Vector = [f64; MAX_BASIS];
type Square = [Vector; MAX_BASIS];

/// Relative size below which the primal step direction counts as zero (the new band depends
/// on the active ones): ‖d₂‖² ≤ DEPENDENT·‖d‖².
const DEPENDENT: f64 = 1e-13;

fn dot(a: &Vector, b: &Vector) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The Givens rotation (c, s, h) that takes (x, y) to (h, 0).
fn givens(x: f64, y: f64) -> Option<(f64, f64, f64)> {
    let h = (x * x + y * y).sqrt();
    let inv = 1.0 / h;
    (h > 0.0).then_some((x * inv, y * inv, h))
}

/// Rotate columns `a` and `b` of the column-major `m` by (c, s): a ← c·a + s·b, b ← c·b − s·a.
fn rotate_columns(m: &mut Square, a: usize, b: usize, c: f64, s: f64) {
    let (x, y) = (m[a], m[b]);
    for i in 0..MAX_BASIS {
        m[a][i] = c * x[i] + s * y[i];
        m[b][i] = c * y[i] - s * x[i];
    }
}

/// The working state of one solve.
struct State {
    /// J = L⁻ᵀQ (n × n, zero beyond), column-major: `j[col][row]`.
    j: Square,
    /// R, upper triangular q × q: `r[i][k]`, i ≤ k.
    r: Square,
    /// Active bands, in the order of R's columns.
    active: [usize; MAX_BASIS],
    /// Their multipliers.
    u: [f64; MAX_BASIS],
    q: usize,
}

impl State {
    /// Add band `band` with multiplier `mu`, given d = Jᵀb_band: rotate d's tail into d[q].
    fn add(&mut self, n: usize, d: &mut [f64; MAX_BASIS], band: usize, mu: f64) {
        let q = self.q;
        for i in (q + 1..n).rev() {
            if let Some((c, s, h)) = givens(d[i - 1], d[i]) {
                d[i - 1] = h;
                d[i] = 0.0;
                rotate_columns(&mut self.j, i - 1, i, c, s);
            }
        }
        for i in 0..=q {
            self.r[i][q] = d[i];
        }
        self.active[q] = band;
        self.u[q] = mu;
        self.q += 1;
    }

    /// Drop the active band at position `l`: remove R's column, restore the triangle by Givens
    /// rotations of R's rows and the matching columns of J.
    fn drop(&mut self, l: usize) {
        let q = self.q;
        for k in l..q - 1 {
            for i in 0..=k + 1 {
                self.r[i][k] = self.r[i][k + 1];
            }
            self.active[k] = self.active[k + 1];
            self.u[k] = self.u[k + 1];
        }
        for i in l..q - 1 {
            let Some((c, s, _)) = givens(self.r[i][i], self.r[i + 1][i]) else {
                continue;
            };
            for k in i..q - 1 {
                let (a, b) = (self.r[i][k], self.r[i + 1][k]);
                self.r[i][k] = c * a + s * b;
                self.r[i + 1][k] = c * b - s * a;
            }
            rotate_columns(&mut self.j, i, i + 1, c, s);
        }
        self.q -= 1;
    }
}

impl Unmixer {
    /// Goldfarb–Idnani from the unconstrained minimiser `au` whose band values are in `s`;
    /// writes α, the final band values Bα to `s`, and the final working set and multipliers
    /// (Hα − g = Σ μ_k b_kᵀ, μ ≥ 0).
    pub(super) fn dual_active_set(
        &self,
        au: &[f64; MAX_BASIS],
        s: &mut [f64; MAX_BANDS],
        out_alpha: &mut [f64],
        info: &mut SolveInfo,
    ) -> Result<()> {
        let (n, m) = (self.n, self.m);
        let scale = s[..m].iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let tol = 1e-12 * scale;
        let mut st = State {
            j: self.linv_t,
            r: [[0.0; MAX_BASIS]; MAX_BASIS],
            active: [0; MAX_BASIS],
            u: [0.0; MAX_BASIS],
            q: 0,
        };
        let mut alpha = *au;
        let mut in_w = [false; MAX_BANDS];
        let mut iterations = 0;
        loop {
            // Step 1: the most violated band (values normalised by ‖b_k‖_{H⁻¹}), or optimal.
            let mut p = None;
            let mut worst = -tol;
            for k in 0..m {
                let v = s[k] * self.b_inv_norm[k];
                if !in_w[k] && v < worst {
                    worst = v;
                    p = Some(k);
                }
            }
            let Some(p) = p else { break };
            // Row p of B, zero-padded for the fixed-size kernels.
            let bp: &Vector = &std::array::from_fn(|j| self.bt.get(j).map_or(0.0, |c| c[p]));
            let mut mu_p = 0.0;
            // Step 2: move towards satisfying band p, dropping bands whose multiplier reaches 0.
            loop {
                iterations += 1;
                if iterations > MAX_ITERATIONS {
                    return Err(Error::Numerical(format!(
                        "unmixing dual active set did not converge in {MAX_ITERATIONS} steps"
                    )));
                }
                let q = st.q;
                let mut d: Vector = std::array::from_fn(|i| dot(&st.j[i], bp));
                // Primal direction z = J₂d₂, dual direction rr = R⁻¹d₁.
                let mut z = [0.0; MAX_BASIS];
                for i in q..n {
                    for (zl, jl) in z.iter_mut().zip(&st.j[i]) {
                        *zl += jl * d[i];
                    }
                }
                let mut rr = [0.0; MAX_BASIS];
                for i in (0..q).rev() {
                    let acc: f64 = (i + 1..q).map(|k| st.r[i][k] * rr[k]).sum();
                    rr[i] = (d[i] - acc) / st.r[i][i];
                }
                // Partial step: the first active multiplier to reach zero.
                let mut t1 = f64::INFINITY;
                let mut drop = None;
                for k in 0..q {
                    if rr[k] > 0.0 {
                        let t = st.u[k] / rr[k];
                        if t < t1 {
                            t1 = t;
                            drop = Some(k);
                        }
                    }
                }
                // Full step: band p becomes exactly satisfied.
                let dd = dot(&d, &d);
                let d2: f64 = d[q..n].iter().map(|v| v * v).sum();
                let zb = dot(&z, bp);
                let sp = dot(bp, &alpha);
                let t2 = if d2 <= DEPENDENT * dd || !(zb > 0.0) {
                    f64::INFINITY
                } else {
                    -sp / zb
                };
                // The smaller step wins; on a tie band p is added (its violation is gone).
                let (t, drop) = if t1 < t2 { (t1, drop) } else { (t2, None) };
                if !t.is_finite() {
                    return Err(Error::Numerical(
                        "unmixing dual active set: the constraints B α ≥ 0 look infeasible".into(),
                    ));
                }
                for k in 0..q {
                    st.u[k] -= t * rr[k];
                }
                mu_p += t;
                if t2.is_finite() {
                    for (a, zl) in alpha.iter_mut().zip(&z) {
                        *a += t * zl;
                    }
                }
                match drop {
                    Some(l) => {
                        in_w[st.active[l]] = false;
                        st.drop(l);
                    }
                    None => {
                        st.add(n, &mut d, p, mu_p);
                        in_w[p] = true;
                        if st.q == n {
                            // n independent homogeneous constraints meet only at α = 0.
                            alpha = [0.0; MAX_BASIS];
                        }
                        break;
                    }
                }
            }
            self.spectrum(&alpha, s);
        }
        self.check_feasible(&alpha, s, scale)?;
        out_alpha.copy_from_slice(&alpha[..n]);
        info.iterations = iterations;
        info.active = st.q;
        info.bands[..st.q].copy_from_slice(&st.active[..st.q]);
        info.multipliers[..st.q].copy_from_slice(&st.u[..st.q]);
        Ok(())
    }
}
