//! What makes a filter set good. The paper minimises the largest pairwise correlation of the
//! transmittances; the reconstruction, though, is the regularised unmixing
//! r̂ = B H⁻¹Fᵀ x̂ (H = FᵀF + η BᵀD₂ᵀD₂B), so its error is better predicted by
//! - cond(F): how the system matrix amplifies any error of the channels;
//! - the noise gain: the RMS cube noise per unit of channel noise, √(tr(P Pᵀ)/bands), P = B H⁻¹Fᵀ;
//! - the library error: the RMS spectral error of the held-out reflectances reconstructed
//!   through the set without noise (the spectral limit of the set);
//! - the predicted cube RMSE: √(library MSE + cube noise variance at the given light level),
//!   with the channel noise of an FSM frame (below).
//!
//! Every quantity is computed in closed form from per-candidate precomputations (the rows of the
//! projection W, their Gram matrix through the library's second moment G = R Rᵀ/n), so one set
//! costs a few 6 × 6 products: every combination of a 40-curve catalogue can be scored.
//!
//! Channel noise of an FSM frame: the frame y = Σ x_i (1 + cos ω_i·p) is scaled so a white target
//! peaks at `electrons` e⁻ (the twin's `rig.sensor.electrons_at_full_scale`); its shot and read
//! noise is white, and a channel estimate keeps crop² of the bins, doubled for the carrier
//! amplitude ½ and halved by taking the real part: var(x̂_i) = 2·crop²·(ȳ·Y/E + σ_r²·Y²/E²), with
//! ȳ the library's mean frame and Y = 2 Σ white_i the white frame's peak, both in channel units.

use crate::small;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use specmux_core::spectral::basis::sample_matrix;
use specmux_core::spectral::{Curve, Grid};
use specmux_core::unmix::{second_difference, MAX_BASIS};
use specmux_core::{Error, Result};

/// Largest set scored (the unmixer's channel limit).
pub use crate::small::MAX_K;

/// The light level and sampling of the noise model.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct NoiseModel {
    /// Electrons at the white frame's peak.
    pub electrons: f64,
    /// Read noise, e⁻ rms.
    pub read_noise_e: f64,
    /// The crop fraction of the demultiplexer.
    pub crop: f64,
}

/// The scores of one set; smaller is better for every field.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct Scores {
    /// The paper's criterion: the largest Pearson correlation between two transmittances.
    pub max_corr: f64,
    pub cond: f64,
    pub noise_gain: f64,
    /// RMS spectral error of the held-out library, noiseless (reflectance units).
    pub library_rmse: f64,
    /// √(library MSE + cube noise variance) at the noise model's light level.
    pub predicted_rmse: f64,
}

/// The criteria, in report order.
pub const CRITERIA: [&str; 5] = [
    "max_corr",
    "cond",
    "noise_gain",
    "library_rmse",
    "predicted_rmse",
];

impl Scores {
    /// The score of criterion `k` of [`CRITERIA`].
    pub fn get(&self, k: usize) -> f64 {
        [
            self.max_corr,
            self.cond,
            self.noise_gain,
            self.library_rmse,
            self.predicted_rmse,
        ][k]
    }
}

/// Everything a set's scores need, precomputed per candidate and per pair.
pub struct Evaluator {
    n: usize,
    j: usize,
    bands: usize,
    /// Pearson correlation of the transmittances, n × n row-major.
    pub corr: Vec<f64>,
    /// Per candidate: x of a white reflector (row sum of W), of the library mean, and w_c·B.
    white: Vec<f64>,
    mean_x: Vec<f64>,
    fb: Vec<DVector<f64>>,
    /// w_c G w_dᵀ, n × n, and Bᵀ G w_cᵀ per candidate.
    q: Vec<f64>,
    u: Vec<DVector<f64>>,
    /// BᵀB, η BᵀD₂ᵀD₂B (η per band-index²) and tr(G).
    k: DMatrix<f64>,
    reg: DMatrix<f64>,
    trace_g: f64,
    pub noise: NoiseModel,
}

/// Pearson correlation of two sampled curves (0 when either is constant).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa > 0.0 && sbb > 0.0 {
        sab / (saa * sbb).sqrt()
    } else {
        0.0
    }
}

impl Evaluator {
    /// `w_raw`: the unnormalised projection (candidates × bands, ∫ T L QE hat_b); `filters` the
    /// transmittances (correlated on `grid`); `basis` B (bands × J); `library` the held-out
    /// reflectances; `eta_band` = η/Δλ⁴ as the unmixer uses it.
    pub fn new(
        w_raw: &DMatrix<f64>,
        filters: &[&Curve],
        grid: &Grid,
        basis: &DMatrix<f64>,
        library: &[Curve],
        eta_band: f64,
        noise: NoiseModel,
    ) -> Result<Evaluator> {
        let (n, bands, j) = (w_raw.nrows(), w_raw.ncols(), basis.ncols());
        if filters.len() != n || basis.nrows() != bands || library.is_empty() || j > MAX_BASIS {
            return Err(Error::Shape(format!(
                "{} filters for {n} projection rows, basis of {j} vectors (at most {MAX_BASIS}) on {} bands for {bands}, {} library spectra",
                filters.len(),
                basis.nrows(),
                library.len()
            )));
        }
        let t: Vec<Vec<f64>> = filters.iter().map(|c| c.sample(grid)).collect();
        let corr = (0..n * n).map(|p| pearson(&t[p / n], &t[p % n])).collect();
        let r = sample_matrix(library, grid)?;
        let g = &r * r.transpose() / library.len() as f64;
        let mean_r: DVector<f64> = r.column_mean();
        let rows: Vec<DVector<f64>> = (0..n).map(|c| w_raw.row(c).transpose()).collect();
        let gw: Vec<DVector<f64>> = rows.iter().map(|w| &g * w).collect();
        let q = (0..n * n).map(|p| rows[p / n].dot(&gw[p % n])).collect();
        let d2b = second_difference(bands) * basis;
        Ok(Evaluator {
            n,
            j,
            bands,
            corr,
            white: rows.iter().map(|w| w.sum()).collect(),
            mean_x: rows.iter().map(|w| w.dot(&mean_r)).collect(),
            fb: rows.iter().map(|w| basis.transpose() * w).collect(),
            u: gw.iter().map(|gw| basis.transpose() * gw).collect(),
            q,
            k: basis.transpose() * basis,
            reg: eta_band * d2b.transpose() * d2b,
            trace_g: g.trace(),
            noise,
        })
    }

    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.n
    }

    /// True for an empty catalogue.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Correlation of candidates a and b.
    pub fn corr(&self, a: usize, b: usize) -> f64 {
        self.corr[a * self.n + b]
    }

    /// The paper's criterion of a set.
    pub fn max_corr(&self, set: &[usize]) -> f64 {
        let mut m = f64::NEG_INFINITY;
        for (x, &a) in set.iter().enumerate() {
            for &b in &set[x + 1..] {
                m = m.max(self.corr(a, b));
            }
        }
        m
    }

    /// Every score of a set (candidate indices). The projection is normalised per set as the
    /// twin's colour wheel does (brightest white channel = 1). A singular system scores ∞.
    /// Allocation-free: fixed arrays of at most `MAX_K` channels and `MAX_BASIS` vectors.
    pub fn score(&self, set: &[usize]) -> Scores {
        let (k, j) = (set.len().min(MAX_K), self.j);
        let s = 1.0 / set.iter().map(|&c| self.white[c]).fold(0.0, f64::max);
        let mut f = [[0.0; MAX_BASIS]; MAX_K];
        for (row, &c) in f.iter_mut().zip(set) {
            for (v, b) in row.iter_mut().zip(self.fb[c].iter()) {
                *v = s * b;
            }
        }
        let mut ftf = [[0.0; MAX_BASIS]; MAX_BASIS];
        for a in 0..j {
            for b in 0..j {
                ftf[a][b] = (0..k).map(|i| f[i][a] * f[i][b]).sum();
            }
        }
        let (lo, hi) = small::eigen_range(ftf, j);
        let cond = (hi / lo.max(0.0)).sqrt();
        let max_corr = self.max_corr(set);
        let mut h = ftf;
        for a in 0..j {
            for b in 0..j {
                h[a][b] += self.reg[(a, b)];
            }
        }
        let Some(m) = small::solve_spd(h, j, &f, k) else {
            let inf = f64::INFINITY;
            return Scores {
                max_corr,
                cond,
                noise_gain: inf,
                library_rmse: inf,
                predicted_rmse: inf,
            };
        };
        // m[a][i] = (H⁻¹Fᵀ)_{a i}; MQ, then tr(K M Q Mᵀ), tr(K M Mᵀ) and tr(M U).
        let mut mq = [[0.0; MAX_K]; MAX_BASIS];
        for a in 0..j {
            for b in 0..k {
                mq[a][b] = (0..k)
                    .map(|i| m[a][i] * self.q[set[i] * self.n + set[b]])
                    .sum::<f64>()
                    * s
                    * s;
            }
        }
        let (mut fit, mut kmm, mut mu) = (0.0, 0.0, 0.0);
        for a in 0..j {
            for b in 0..j {
                let mqm: f64 = (0..k).map(|i| mq[a][i] * m[b][i]).sum();
                let mm: f64 = (0..k).map(|i| m[a][i] * m[b][i]).sum();
                fit += self.k[(b, a)] * mqm;
                kmm += self.k[(b, a)] * mm;
            }
            mu += (0..k).map(|i| m[a][i] * s * self.u[set[i]][a]).sum::<f64>();
        }
        let lib_mse = ((fit - 2.0 * mu + self.trace_g) / self.bands as f64).max(0.0);
        let y_mean: f64 = set.iter().map(|&c| s * self.mean_x[c]).sum();
        let peak: f64 = 2.0 * set.iter().map(|&c| s * self.white[c]).sum::<f64>();
        let nm = &self.noise;
        let var_x = 2.0
            * nm.crop
            * nm.crop
            * (y_mean * peak / nm.electrons + (nm.read_noise_e * peak / nm.electrons).powi(2));
        let gain2 = kmm / self.bands as f64;
        Scores {
            max_corr,
            cond,
            noise_gain: gain2.sqrt(),
            library_rmse: lib_mse.sqrt(),
            predicted_rmse: (lib_mse + var_x * gain2).sqrt(),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use specmux_core::spectral::Library;
    use specmux_core::unmix::curvature;
    use specmux_twin::optics::wheel::ColorWheel;
    use specmux_twin::scene::Materials;
    use specmux_twin::{Experiment, Rig};

    /// The scores computed the slow, obvious way with nalgebra.
    fn score_dense(ev: &Evaluator, set: &[usize]) -> Scores {
        let s = 1.0 / set.iter().map(|&c| ev.white[c]).fold(0.0, f64::max);
        let k = set.len();
        let f = DMatrix::from_fn(k, ev.j, |i, jj| s * ev.fb[set[i]][jj]);
        let ftf = f.transpose() * &f;
        let eig = nalgebra::SymmetricEigen::new(ftf.clone()).eigenvalues;
        let cond = (eig.max() / eig.min().max(0.0)).sqrt();
        let m = nalgebra::Cholesky::new(ftf + &ev.reg)
            .map(|c| c.solve(&f.transpose()))
            .unwrap_or_else(|| DMatrix::from_element(ev.j, k, f64::INFINITY));
        let qs = DMatrix::from_fn(k, k, |a, b| s * s * ev.q[set[a] * ev.n + set[b]]);
        let us = DMatrix::from_fn(k, ev.j, |a, jj| s * ev.u[set[a]][jj]);
        let kmm = (&ev.k * &m * m.transpose()).trace();
        let fit = (&ev.k * &m * qs * m.transpose()).trace();
        let lib_mse = ((fit - 2.0 * (&m * us).trace() + ev.trace_g) / ev.bands as f64).max(0.0);
        let y_mean: f64 = set.iter().map(|&c| s * ev.mean_x[c]).sum();
        let peak: f64 = 2.0 * set.iter().map(|&c| s * ev.white[c]).sum::<f64>();
        let nm = &ev.noise;
        let var_x = 2.0
            * nm.crop
            * nm.crop
            * (y_mean * peak / nm.electrons + (nm.read_noise_e * peak / nm.electrons).powi(2));
        let gain2 = kmm / ev.bands as f64;
        Scores {
            max_corr: ev.max_corr(set),
            cond,
            noise_gain: gain2.sqrt(),
            library_rmse: lib_mse.sqrt(),
            predicted_rmse: (lib_mse + var_x * gain2).sqrt(),
        }
    }

    /// An evaluator on the catalogue of `spectra/` (six curves) plus a few generated ones.
    pub(crate) fn evaluator(extra: usize) -> (Evaluator, Vec<String>) {
        let lib = Library::default_root();
        let mut cat = crate::catalog::measured(&lib, &lib).unwrap();
        cat.extend(
            crate::catalog::Families::default()
                .generate("t")
                .unwrap()
                .into_iter()
                .step_by(3)
                .take(extra),
        );
        let exp = Experiment::prototype();
        let m = Materials::load(&lib).unwrap();
        let rig = Rig::build(&exp, &lib, &m).unwrap();
        let wheel = ColorWheel {
            filters: cat.iter().map(|c| c.curve.clone()).collect(),
        };
        let p = wheel
            .projection(&rig.grid, rig.illuminant.as_ref(), &rig.qe)
            .unwrap();
        let curves: Vec<_> = cat.iter().map(|c| &c.curve).collect();
        let noise = NoiseModel {
            electrons: 1e4,
            read_noise_e: 3.0,
            crop: 0.25,
        };
        let ev = Evaluator::new(
            &(p.w / p.scale),
            &curves,
            &rig.grid,
            &rig.basis.vectors,
            &m.held_out,
            200.0 / 1e4,
            noise,
        )
        .unwrap();
        (ev, cat.into_iter().map(|c| c.name).collect())
    }

    #[test]
    fn the_fast_scores_equal_the_dense_computation() {
        let (ev, _) = evaluator(6);
        for set in [
            vec![0, 1, 2, 3, 4, 5],
            vec![1, 3, 5, 6, 8, 11],
            vec![0, 2, 4, 6, 7, 9, 10],
        ] {
            let (a, b) = (ev.score(&set), score_dense(&ev, &set));
            for k in 0..CRITERIA.len() {
                let (x, y) = (a.get(k), b.get(k));
                assert!(
                    (x - y).abs() <= 1e-9 * y.abs().max(1.0),
                    "{} {x} {y}",
                    CRITERIA[k]
                );
            }
        }
    }

    #[test]
    fn library_error_matches_unmixing_the_library_through_the_set() {
        // The closed form tr(...) against reconstructing every held-out spectrum with the
        // unconstrained regularised unmixing, one by one.
        let (ev, _) = evaluator(0);
        let lib = Library::default_root();
        let exp = Experiment::prototype();
        let m = Materials::load(&lib).unwrap();
        let rig = Rig::build(&exp, &lib, &m).unwrap();
        let f = rig.system_matrix();
        let b = &rig.basis.vectors;
        let h = f.transpose() * &f + curvature(b, 200.0 / 1e4);
        let p = b * h.try_inverse().unwrap() * f.transpose();
        let r = sample_matrix(&m.held_out, &rig.grid).unwrap();
        let e = &p * &rig.projection.w * &r - &r;
        let rmse = (e.norm_squared() / e.len() as f64).sqrt();
        let s = ev.score(&[0, 1, 2, 3, 4, 5]);
        // The wheel order differs (catalogue sorted by name), which does not change the error.
        assert!(
            (s.library_rmse - rmse).abs() < 1e-9,
            "{} {rmse}",
            s.library_rmse
        );
    }
}
