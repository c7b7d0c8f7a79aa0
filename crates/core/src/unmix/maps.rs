//! Working-set maps: for a fixed set A of bands held at zero, the minimiser of the QP restricted
//! to B_A α = 0 is a linear map of x̂ (α = K_A x̂, its multipliers μ = U_A x̂). Neighbouring
//! pixels of an image end with the same or a nearby working set, so a pixel starts from the set
//! of the pixel before it and takes a few primal active-set steps between cached maps (drop the
//! most negative multiplier, else add the most violated band). A set with μ ≥ 0 and every band
//! of B K_A x̂ ≥ 0 (the KKT conditions, checked exactly, no tolerance) gives the QP's unique
//! minimiser (H is positive definite); a pixel that reaches none in `MAX_WALK` steps goes to the
//! dual method.

use crate::unmix::{SolveInfo, Unmixer, MAX_BANDS, MAX_BASIS, MAX_CHANNELS};
use nalgebra::DMatrix;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// Largest number of working sets kept per unmixer (each map is a few kB).
const MAX_MAPS: usize = 4096;
/// Primal active-set steps a pixel may take from its neighbour's working set.
const MAX_WALK: usize = 4;
/// Largest ratio of the diagonal of R (B_Aᵀ = Q₁R) for which a map is built: a nearly
/// dependent working set is left to the dual method, which handles it.
const MAX_SET_CONDITION: f64 = 1e10;

/// Maps by working-set bit mask; None marks a set that has no safe map.
pub(super) type Maps = HashMap<u64, Option<Arc<ActiveMap>>>;
/// The maps built so far, shared by the threads (each keeps a local copy of those it used).
pub(super) type MapCache = Arc<Mutex<Maps>>;

/// Why a working set is not optimal for a pixel: the step to take.
enum Step {
    /// Drop the band at this position of the set (its multiplier is negative).
    Drop(usize),
    /// Add this band (its value is negative).
    Add(usize),
}

/// The solution map of one working set.
#[derive(Debug)]
pub(super) struct ActiveMap {
    /// Bit k set for band k in the working set.
    pub(super) mask: u64,
    active: Vec<usize>,
    /// B K_A by channel: `r_cols[j][k]` is band k's weight on channel j.
    r_cols: Vec<[f64; MAX_BANDS]>,
    /// U_A row by row (|A| × channels): μ = U_A x̂.
    mu_rows: Vec<[f64; MAX_CHANNELS]>,
}

impl ActiveMap {
    /// Band values r = B K_A x̂ into `r` (the set's bands as exact zeros) if this working set
    /// is optimal for `x`, else the active-set step to take: the most negative multiplier is
    /// dropped first, else the band most negative relative to ‖b_k‖ is added.
    fn check(&self, u: &Unmixer, x: &[f64], r: &mut [f64; MAX_BANDS]) -> Option<Step> {
        let mut drop = None;
        let mut worst = 0.0;
        for (i, row) in self.mu_rows.iter().enumerate() {
            let mu: f64 = row.iter().zip(x).map(|(a, b)| a * b).sum();
            if !(mu >= worst) {
                (worst, drop) = (mu, Some(i));
            }
        }
        if let Some(i) = drop {
            return Some(Step::Drop(i));
        }
        let r = &mut r[..u.m];
        r.fill(0.0);
        for (col, &xj) in self.r_cols.iter().zip(x) {
            for (rk, ck) in r.iter_mut().zip(col) {
                *rk += ck * xj;
            }
        }
        for &k in &self.active {
            r[k] = 0.0;
        }
        if r.iter().all(|&v| v >= 0.0) {
            return None;
        }
        let (mut add, mut worst) = (0, 0.0);
        for (k, (&v, &inv)) in r.iter().zip(&u.b_inv_norm).enumerate() {
            if v * inv < worst {
                (add, worst) = (k, v * inv);
            }
        }
        Some(Step::Add(add))
    }
}
impl Unmixer {
    /// From the working set `start`, the map of the optimal set for `x` (its bands in `r`),
    /// found in at most `MAX_WALK` active-set steps through maps held in `local` or the shared
    /// cache; None if none was reached.
    pub(super) fn walk(
        &self,
        start: &Arc<ActiveMap>,
        x: &[f64],
        r: &mut [f64; MAX_BANDS],
        local: &mut Maps,
    ) -> Option<Arc<ActiveMap>> {
        let mut map = start.clone();
        for _ in 0..=MAX_WALK {
            let mask = match map.check(self, x, r) {
                None => return Some(map),
                Some(Step::Drop(i)) => map.mask & !(1 << map.active[i]),
                Some(Step::Add(k)) => map.mask | 1 << k,
            };
            map = self.map(mask, local)?;
        }
        None
    }

    /// The map of the working set the dual method ended with (None for the empty set).
    pub(super) fn map_for(&self, info: &SolveInfo, local: &mut Maps) -> Option<Arc<ActiveMap>> {
        let mask = info
            .active_bands()
            .iter()
            .fold(0u64, |acc, &k| acc | (1 << k));
        self.map(mask, local)
    }

    /// The map of the set `mask` from `local`, else the shared cache, else built now; None for
    /// the empty set or a set without a well-conditioned map.
    fn map(&self, mask: u64, local: &mut Maps) -> Option<Arc<ActiveMap>> {
        if mask == 0 {
            return None;
        }
        if let Some(found) = local.get(&mask) {
            return found.clone();
        }
        let mut cache = self.maps.lock().unwrap_or_else(|e| e.into_inner());
        let map = match cache.get(&mask) {
            Some(found) => found.clone(),
            None => {
                let map = self.build_map(mask).map(Arc::new);
                if cache.len() < MAX_MAPS {
                    cache.insert(mask, map.clone());
                }
                map
            }
        };
        drop(cache);
        local.insert(mask, map.clone());
        map
    }

    /// By the null-space method, which stays as well conditioned as H however close the set's
    /// bands are: Q = [Q₁ Q₂] from the QR factors of [B_Aᵀ | I] (Q₁R = B_Aᵀ, Q₂ spans the null
    /// space of B_A), K_A = Q₂(Q₂ᵀHQ₂)⁻¹Q₂ᵀ H M and, from Hα − g = B_Aᵀμ with g = H M x̂,
    /// U_A = R⁻¹Q₁ᵀ H (K_A − M). A set whose R is near singular gets no map.
    fn build_map(&self, mask: u64) -> Option<ActiveMap> {
        let (n, m, c) = (self.n, self.m, self.c);
        let active: Vec<usize> = (0..m).filter(|k| mask >> k & 1 == 1).collect();
        let q = active.len();
        if q > n {
            return None;
        }
        let h = DMatrix::from_row_slice(n, n, &self.h);
        let mmat = DMatrix::from_row_slice(n, c, &self.mx);
        let b = DMatrix::from_fn(m, n, |k, j| self.bt[j][k]);
        let augmented = DMatrix::from_fn(n, q + n, |i, j| {
            if j < q {
                self.bt[i][active[j]]
            } else {
                (i == j - q) as u8 as f64
            }
        });
        let qr = augmented.qr();
        let (qm, rm) = (qr.q(), qr.r());
        let r = rm.view((0, 0), (q, q)).clone_owned();
        let diag = r.diagonal().map(f64::abs);
        if q > 0 && !(diag.max() <= MAX_SET_CONDITION * diag.min()) {
            return None;
        }
        let (q1, q2) = (qm.columns(0, q), qm.columns(q, n - q));
        let hm = &h * &mmat;
        let k = if q == n {
            DMatrix::zeros(n, c)
        } else {
            let reduced = (q2.transpose() * &h * q2).cholesky()?;
            q2 * reduced.solve(&(q2.transpose() * &hm))
        };
        let u = r.solve_upper_triangular(&(q1.transpose() * (&h * &k - &hm)))?;
        let rk = b * k;
        debug_assert!(n <= MAX_BASIS);
        Some(ActiveMap {
            mask,
            r_cols: (0..c)
                .map(|j| std::array::from_fn(|band| if band < m { rk[(band, j)] } else { 0.0 }))
                .collect(),
            mu_rows: (0..active.len())
                .map(|i| std::array::from_fn(|j| if j < c { u[(i, j)] } else { 0.0 }))
                .collect(),
            active,
        })
    }
}
