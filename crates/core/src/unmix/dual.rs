//! The dual active-set method of Goldfarb and Idnani (Math. Programming 27, 1983) for one pixel:
//! min ½αᵀHα − gᵀα s.t. Bα ≥ 0. It starts at the unconstrained minimiser (already computed for
//! the fast path) and adds the most violated band, dropping a band whose multiplier would turn
//! negative, so a pixel with k binding bands takes about k steps. It runs in band space: with
//! G = B H⁻¹ Bᵀ the step moves the band values by G_·p − G_·A G_AA⁻¹ G_Ap and the multipliers by
//! G_AA⁻¹ G_Ap, so a step costs two small triangular solves and one pass over the bands, and
//! G_AA = LDLᵀ gains a row per added band where the factorisation J = L⁻ᵀQ of the textbook
//! method needs a Givens rotation per free direction (a square root and a division each). The
//! band values are those the steps carried (B α to round-off, the working set's exactly 0), not
//! B α formed again (186 multiply-adds, 5 % of the real-time path; docs/speed.md), and
//! α = α_u + H⁻¹B_Aᵀμ is formed only where it is asked for (`Unmixer::solve_pixel`). A pixel of a
//! cube starts from the previous pixel's final working set (`warm_start`), not the empty one.

use crate::error::Error;
use crate::error::Result;

/// Largest number of basis vectors J (stack arrays in the per-pixel solver).
pub const MAX_BASIS: usize = 8;
/// Largest number of bands (constraints) in the per-pixel solver.
pub const MAX_BANDS: usize = 64;
/// Active-set iterations allowed per pixel before the solver gives up with an error.
pub const MAX_ITERATIONS: usize = 500;
/// Bands per register block of the solver's band sums ([`band_blocks`]).
pub(super) const BAND_BLOCK: usize = 8;

type Vector = [f64; MAX_BASIS];

/// One rig's QP in band space, shared by all pixels: G = B H⁻¹ Bᵀ by rows and the bands'
/// 1/‖b_k‖_{H⁻¹}, for J basis vectors and m bands.
#[derive(Clone, Debug)]
pub(super) struct BandQp {
    /// J and the number of bands (the `Unmixer`'s, which holds this).
    pub(super) n: usize,
    pub(super) m: usize,
    /// G by rows, each zero-padded to `MAX_BANDS`: the band values' response to the multipliers.
    pub(super) g_bands: Vec<[f64; MAX_BANDS]>,
    /// 1/‖b_k‖_{H⁻¹} = 1/‖L⁻¹b_kᵀ‖ for each row of B (0 for a zero row, which no α can
    /// violate): a band's violation times it is its distance from the constraint in the metric
    /// of H, so the method adds the band whose first step raises the objective most (13 % fewer
    /// steps on dead-leaves than with 1/‖b_k‖; docs/speed.md). Zero-padded to `MAX_BANDS`, so
    /// the per-pixel copy has a size known when compiling.
    pub(super) b_inv_norm: [f64; MAX_BANDS],
}

/// Relative size below which the step's curvature counts as zero (the new band depends on the
/// active ones): G_pp − G_pA G_AA⁻¹ G_Ap ≤ DEPENDENT·G_pp.
const DEPENDENT: f64 = 1e-13;

/// The working set: its bands, their multipliers and the factor G_AA = L D Lᵀ (L unit lower
/// triangular), whose solves divide only by D, independently of each other, where a Cholesky
/// factor's divisions by its diagonal sit on the solves' chain of multiply-adds. A pixel's final
/// set is the next pixel's start (`BandQp::solve`).
#[derive(Clone, Copy)]
pub(super) struct WorkingSet {
    /// L below its unit diagonal, q × q, row-major: `l[i][k]`, k < i.
    l: [Vector; MAX_BASIS],
    d: Vector,
    bands: [usize; MAX_BASIS],
    mu: Vector,
    q: usize,
}

impl WorkingSet {
    /// No band held at zero: the start at the unconstrained minimiser.
    pub(super) fn empty() -> WorkingSet {
        WorkingSet {
            l: [[0.0; MAX_BASIS]; MAX_BASIS],
            d: [0.0; MAX_BASIS],
            bands: [0; MAX_BASIS],
            mu: [0.0; MAX_BASIS],
            q: 0,
        }
    }

    /// The bands held at zero, in the order they were added.
    pub(super) fn bands(&self) -> &[usize] {
        &self.bands[..self.q]
    }

    /// Their multipliers μ ≥ 0 (Hα − g = Σ μ_k b_kᵀ).
    pub(super) fn multipliers(&self) -> &[f64] {
        &self.mu[..self.q]
    }

    /// The band `values` at the working set's bands, in its order (0 past them): G_Ap from G's
    /// row p, s_A from the band values.
    fn gather(&self, values: &[f64; MAX_BANDS]) -> Vector {
        std::array::from_fn(|i| {
            if i < self.q {
                values[self.bands[i]]
            } else {
                0.0
            }
        })
    }

    /// r = G_AA⁻¹ g given g = G_Ap, y = L⁻¹g and z = D⁻¹y (the new row of L if p is added).
    fn solve(&self, g: &Vector) -> (Vector, Vector, Vector) {
        let q = self.q;
        let mut y = [0.0; MAX_BASIS];
        for i in 0..q {
            let acc: f64 = (0..i).map(|k| self.l[i][k] * y[k]).sum();
            y[i] = g[i] - acc;
        }
        let z: Vector = std::array::from_fn(|i| if i < q { y[i] / self.d[i] } else { 0.0 });
        let mut r = [0.0; MAX_BASIS];
        for i in (0..q).rev() {
            let acc: f64 = (i + 1..q).map(|k| self.l[k][i] * r[k]).sum();
            r[i] = z[i] - acc;
        }
        (r, y, z)
    }

    /// Add band `band` with multiplier `mu`: L's new row is z, D's new entry the Schur complement.
    fn add(&mut self, band: usize, mu: f64, z: &Vector, schur: f64) {
        let q = self.q;
        self.l[q][..q].copy_from_slice(&z[..q]);
        self.d[q] = schur;
        self.bands[q] = band;
        self.mu[q] = mu;
        self.q += 1;
    }

    /// Drop the band at position `at`: remove its row and column of L and D, whose part below
    /// and right of it, d_at·w wᵀ with w the removed column, goes back into the trailing factor
    /// by a rank-one update (Gill, Golub, Murray & Saunders 1974, method C1).
    fn drop(&mut self, at: usize) {
        let q = self.q;
        let mut w: Vector =
            std::array::from_fn(|i| if at < i && i < q { self.l[i][at] } else { 0.0 });
        let mut a = self.d[at];
        for i in at..q - 1 {
            self.bands[i] = self.bands[i + 1];
            self.mu[i] = self.mu[i + 1];
            self.d[i] = self.d[i + 1];
            w[i] = w[i + 1];
            let row = self.l[i + 1];
            self.l[i][..at].copy_from_slice(&row[..at]);
            self.l[i][at..i].copy_from_slice(&row[at + 1..i + 1]);
        }
        for j in at..q - 1 {
            let p = w[j];
            let dj = self.d[j] + a * p * p;
            let beta = p * a / dj;
            a *= self.d[j] / dj;
            self.d[j] = dj;
            for i in j + 1..q - 1 {
                w[i] -= p * self.l[i][j];
                self.l[i][j] += beta * w[i];
            }
        }
        self.q -= 1;
    }
}

impl BandQp {
    /// Goldfarb–Idnani from the unconstrained minimiser whose band values are in `s`, started
    /// from the working set `ws` (another pixel's final set, or empty); writes the final band
    /// values to `s` (B α to round-off, the working set's bands 0) and leaves the final working
    /// set and its multipliers (Hα − g = Σ μ_k b_kᵀ, μ ≥ 0) in `ws`; returns the steps taken.
    pub(super) fn solve(&self, s: &mut [f64; MAX_BANDS], ws: &mut WorkingSet) -> Result<usize> {
        let (n, m) = (self.n, self.m);
        let scale = fold8(&s[..padded_len(m)], 0.0, larger_magnitude);
        let tol = 1e-12 * scale;
        // 1/‖b_k‖_{H⁻¹} for the bands outside the working set, 0 for those in it.
        let mut weight = self.b_inv_norm;
        let mut iterations = self.warm_start(ws, s, &mut weight);
        // n independent homogeneous constraints meet only at α = 0 (`alpha_from`).
        while ws.q < n {
            let Some(p) = self.most_violated(s, &weight, tol) else {
                break;
            };
            let gp = &self.g_bands[p];
            let mut mu_p = 0.0;
            // Move towards satisfying band p, dropping bands whose multiplier reaches 0.
            loop {
                iterations += 1;
                if iterations > MAX_ITERATIONS {
                    return Err(Error::Numerical(format!(
                        "unmixing dual active set did not converge in {MAX_ITERATIONS} steps"
                    )));
                }
                let q = ws.q;
                let (r, y, z) = ws.solve(&ws.gather(gp));
                let schur = gp[p] - y[..q].iter().zip(&z).map(|(y, z)| y * z).sum::<f64>();
                // Partial step: the first active multiplier to reach zero.
                let mut t1 = f64::INFINITY;
                let mut drop = None;
                for k in 0..q {
                    if r[k] > 0.0 {
                        let t = ws.mu[k] / r[k];
                        if t < t1 {
                            t1 = t;
                            drop = Some(k);
                        }
                    }
                }
                // Full step: band p becomes exactly satisfied.
                let t2 = if schur <= DEPENDENT * gp[p] || !(schur > 0.0) {
                    f64::INFINITY
                } else {
                    -s[p] / schur
                };
                // The smaller step wins; on a tie band p is added (its violation is gone).
                let (t, drop) = if t1 < t2 { (t1, drop) } else { (t2, None) };
                if !t.is_finite() {
                    return Err(Error::Numerical(
                        "unmixing dual active set: the constraints B α ≥ 0 look infeasible".into(),
                    ));
                }
                for k in 0..q {
                    ws.mu[k] -= t * r[k];
                }
                mu_p += t;
                if t2.is_finite() {
                    // s += t·(G_·p − G_·A r).
                    let mut terms = [(p, t); MAX_BASIS + 1];
                    for (term, (&band, &rk)) in terms[1..].iter_mut().zip(ws.bands.iter().zip(&r)) {
                        *term = (band, -(t * rk));
                    }
                    self.move_bands(s, &terms[..q + 1]);
                }
                match drop {
                    Some(k) => {
                        weight[ws.bands[k]] = self.b_inv_norm[ws.bands[k]];
                        ws.drop(k);
                    }
                    None => {
                        ws.add(p, mu_p, &z, schur);
                        weight[p] = 0.0;
                        break;
                    }
                }
            }
        }
        // The bands held at zero are zero; at the vertex α = 0 every band is.
        if ws.q == n {
            s.fill(0.0);
        } else {
            for &b in &ws.bands[..ws.q] {
                s[b] = 0.0;
            }
        }
        self.check_feasible(s, scale)?;
        Ok(iterations)
    }

    /// Accept the active set's result: every band value r finite and ≥ −1e-9·scale.
    fn check_feasible(&self, r: &[f64], scale: f64) -> Result<()> {
        let worst = fold8(&r[..padded_len(self.m)], 0.0, lower);
        if !(worst >= -1e-9 * scale) || r[..self.m].iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "unmixing active set ended infeasible: min band value {worst:e} (scale {scale:e})"
            )));
        }
        Ok(())
    }

    /// Start from the working set `ws` at this pixel's unconstrained band values `s`: its
    /// multipliers μ = −G_AA⁻¹ s_A, the bands whose multiplier is negative dropped until none is
    /// (each drop a step, counted in the return), then s moved by G_·A μ (so s_A = 0). A set with
    /// μ ≥ 0 is a dual-feasible start, from which the method reaches the same minimiser; a
    /// neighbour's final set is most often close to the pixel's own (dead-leaves: 1.40 M steps a
    /// frame, these drops included, against 1.78 M from the empty set; docs/speed.md).
    fn warm_start(
        &self,
        ws: &mut WorkingSet,
        s: &mut [f64; MAX_BANDS],
        weight: &mut [f64; MAX_BANDS],
    ) -> usize {
        let mut drops = 0;
        while ws.q > 0 {
            let q = ws.q;
            let (r, _, _) = ws.solve(&ws.gather(s));
            let mu = r.map(|v| -v);
            if mu[..q].iter().all(|&v| !(v < 0.0)) {
                ws.mu = mu;
                break;
            }
            for k in (0..q).rev() {
                if mu[k] < 0.0 {
                    ws.drop(k);
                    drops += 1;
                }
            }
        }
        let q = ws.q;
        let terms: [(usize, f64); MAX_BASIS] = std::array::from_fn(|i| (ws.bands[i], ws.mu[i]));
        self.move_bands(s, &terms[..q]);
        for &b in &ws.bands[..q] {
            weight[b] = 0.0;
        }
        drops
    }

    /// The band outside the working set with the largest violation normalised by
    /// ‖b_k‖_{H⁻¹}, if it is beyond −`tol`: the normalised values (`weight` is 0 in the working
    /// set, so its bands give ±0, and past the last band 0) over whole blocks of eight, their
    /// minimum without branches (eight running minima, `fold8`), then the first band that attains
    /// it, from a bit mask of the bands equal to it (no branch per band either).
    fn most_violated(
        &self,
        s: &[f64; MAX_BANDS],
        weight: &[f64; MAX_BANDS],
        tol: f64,
    ) -> Option<usize> {
        let len = padded_len(self.m);
        let mut v = [0.0; MAX_BANDS];
        for ((vk, &sk), &w) in v[..len].iter_mut().zip(s).zip(weight) {
            *vk = sk * w;
        }
        let low = fold8(&v[..len], -tol, lower);
        if !(low < -tol) {
            return None;
        }
        let at = (v[..len].iter().enumerate())
            .fold(0u64, |mask, (k, &x)| mask | ((x == low) as u64) << k);
        Some(at.trailing_zeros() as usize)
    }

    /// s += Σ f·G_·b over the (band b, factor f) `terms`: the band values along a step, eight
    /// bands at a time in registers (each band's terms added in order, as one pass per term would).
    fn move_bands(&self, s: &mut [f64; MAX_BANDS], terms: &[(usize, f64)]) {
        for (at, out) in band_blocks(self.m, s) {
            let mut acc = [0.0; BAND_BLOCK];
            acc.copy_from_slice(out);
            for &(band, f) in terms {
                for (v, g) in acc.iter_mut().zip(&self.g_bands[band][at.clone()]) {
                    *v += f * g;
                }
            }
            out.copy_from_slice(&acc);
        }
    }
}

/// The bands rounded up to whole eight-band blocks: the solver's arrays hold 0 past `m`
/// (zero-padded tables), which no extreme it takes over them can pick.
#[inline(always)]
pub(super) fn padded_len(m: usize) -> usize {
    m.next_multiple_of(BAND_BLOCK)
}

/// Bands eight at a time: each block's range and its values in `s` (zero-padded past the last
/// band, so the last block is whole), for sums kept in registers across a block.
pub(super) fn band_blocks(
    m: usize,
    s: &mut [f64; MAX_BANDS],
) -> impl Iterator<Item = (std::ops::Range<usize>, &mut [f64])> {
    (0..m)
        .step_by(BAND_BLOCK)
        .zip(s.chunks_exact_mut(BAND_BLOCK))
        .map(|(k0, out)| (k0..k0 + BAND_BLOCK, out))
}

/// `pick` folded over `values` (a whole number of eight-band blocks) from `init` in eight running
/// lanes, which vectorise where one chain of comparisons does not; for an extreme (a minimum, a
/// maximum) the order does not change the result.
#[inline(always)]
pub(super) fn fold8(values: &[f64], init: f64, pick: impl Fn(f64, f64) -> f64 + Copy) -> f64 {
    let mut lanes = [init; BAND_BLOCK];
    for chunk in values.chunks_exact(BAND_BLOCK) {
        for (a, &x) in lanes.iter_mut().zip(chunk) {
            *a = pick(*a, x);
        }
    }
    lanes.into_iter().fold(init, pick)
}

/// |x| where it is above `a`, else `a` (a NaN `x` is passed over): the largest magnitude.
#[inline(always)]
fn larger_magnitude(a: f64, x: f64) -> f64 {
    if x.abs() > a {
        x.abs()
    } else {
        a
    }
}

/// The lower of two values; a NaN `x` is passed over.
#[inline(always)]
pub(super) fn lower<T: PartialOrd>(a: T, x: T) -> T {
    if x < a {
        x
    } else {
        a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::unmix::padded;
    use crate::unmix::Unmixer;
    use nalgebra::DMatrix;

    /// Eleven bands (a whole block of eight and part of the next), J = 2.
    fn unmixer() -> Unmixer {
        let b = DMatrix::from_fn(11, 2, |k, j| if j == 0 { 1.0 } else { k as f64 / 10.0 });
        Unmixer::new(&DMatrix::identity(2, 2), &b, 0.0).unwrap()
    }

    #[test]
    fn the_most_violated_band_is_the_first_at_the_lowest_weighted_value() {
        let u = unmixer();
        let values = [0.5, -0.2, -0.7, 0.1, -0.7, 0.0, 0.3, 0.0, 0.2, -0.35, 0.0];
        let s = padded(11, |k| values[k]);
        let ones = padded(11, |_| 1.0);
        // A tie: the first of the two bands at −0.7.
        assert_eq!(u.qp.most_violated(&s, &ones, 1e-12), Some(2));
        // Band 2 in the working set (weight 0): band 4 ties no more.
        let mut w = ones;
        w[2] = 0.0;
        assert_eq!(u.qp.most_violated(&s, &w, 1e-12), Some(4));
        // The weights scale the violations: band 9 of the second block wins at weight 3.
        w[9] = 3.0;
        assert_eq!(u.qp.most_violated(&s, &w, 1e-12), Some(9));
        // Nothing beyond −tol: no band, whatever the zero padding past band 10.
        assert_eq!(u.qp.most_violated(&s, &ones, 0.8), None);
        let feasible = padded(11, |k| values[k].abs());
        assert_eq!(u.qp.most_violated(&feasible, &ones, 0.0), None);
    }

    /// The factor after adding `bands` one by one as the method does (row z, Schur complement).
    fn factored(u: &Unmixer, bands: &[usize]) -> WorkingSet {
        let mut ws = WorkingSet::empty();
        for &p in bands {
            let (_, y, z) = ws.solve(&ws.gather(&u.qp.g_bands[p]));
            let schur =
                u.qp.g_bands[p][p] - y[..ws.q].iter().zip(&z).map(|(y, z)| y * z).sum::<f64>();
            ws.add(p, 0.0, &z, schur);
        }
        ws
    }

    /// Largest |L D Lᵀ − G_AA| over the working set's bands, relative to G's largest entry.
    fn factor_error(u: &Unmixer, ws: &WorkingSet) -> f64 {
        let q = ws.q;
        let l = |i: usize, k: usize| match k.cmp(&i) {
            std::cmp::Ordering::Less => ws.l[i][k],
            std::cmp::Ordering::Equal => 1.0,
            std::cmp::Ordering::Greater => 0.0,
        };
        let gmax =
            u.qp.g_bands
                .iter()
                .flatten()
                .fold(0.0f64, |m, v| m.max(v.abs()));
        let mut worst = 0.0f64;
        for i in 0..q {
            for j in 0..q {
                let ldl: f64 = (0..q).map(|k| l(i, k) * ws.d[k] * l(j, k)).sum();
                worst = worst.max((ldl - u.qp.g_bands[ws.bands[i]][ws.bands[j]]).abs() / gmax);
            }
        }
        worst
    }

    #[test]
    fn adding_and_dropping_bands_keeps_the_factor_of_the_working_sets_block() {
        // 31 bands, J = 6 polynomial basis vectors: any six distinct bands are independent.
        let b = DMatrix::from_fn(31, 6, |k, j| (k as f64 / 30.0 - 0.5).powi(j as i32));
        let u = Unmixer::new(&DMatrix::identity(6, 6), &b, 0.0).unwrap();
        let bands = [3, 17, 8, 29, 0, 12];
        let full = factored(&u, &bands);
        let check = |ws: &WorkingSet, what: &str| {
            let e = factor_error(&u, ws);
            assert!(e <= 1e-13, "{what}: L D Lᵀ off G_AA by {e:e}");
        };
        check(&full, "six bands added");
        // Each position dropped, then a second one: the rest keep their order and their factor.
        for at in 0..6 {
            let mut ws = full;
            ws.drop(at);
            let mut rest = bands.to_vec();
            rest.remove(at);
            assert_eq!(&ws.bands[..5], &rest[..]);
            check(&ws, &format!("position {at} dropped"));
            ws.drop(at.min(3));
            rest.remove(at.min(3));
            assert_eq!(&ws.bands[..ws.q], &rest[..]);
            check(&ws, &format!("position {at}, then {} dropped", at.min(3)));
        }
        // The downdated factor solves G_AA r = g (the dropped band's column) to round-off.
        let mut ws = full;
        ws.drop(2);
        let p = bands[2];
        let g = ws.gather(&u.qp.g_bands[p]);
        let (r, _, _) = ws.solve(&g);
        for i in 0..ws.q {
            let back: f64 = (0..ws.q)
                .map(|k| u.qp.g_bands[ws.bands[i]][ws.bands[k]] * r[k])
                .sum();
            assert!((back - g[i]).abs() <= 1e-10 * g.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        }
    }
}
