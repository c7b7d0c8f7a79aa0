//! The spectral basis: an uncentred PCA (SVD) of a reflectance library on the cube's grid, as in
//! the paper (r(λ) = Σ_j α_j b_j(λ), J = 6).

use crate::error::Error;
use crate::error::Result;
use crate::spectral::curve::Curve;
use crate::spectral::grid::Grid;
use nalgebra::DMatrix;
use serde::Serialize;

/// J basis vectors sampled on a grid; `vectors[(band, j)]`.
#[derive(Clone, Debug)]
pub struct Basis {
    pub grid: Grid,
    pub vectors: DMatrix<f64>,
    /// Fraction of the training set's energy Σ r² that the J vectors capture.
    pub energy_captured: f64,
    /// Mean square of each coefficient α_j = b_jᵀr over the training spectra (the kept
    /// eigenvalues of R Rᵀ over the sample count): the prior variances of the trained prior.
    pub variances: Vec<f64>,
    /// Mean of r⊥r⊥ᵀ over the training spectra (bands × bands), r⊥ the part outside the basis:
    /// the spectra's misfit that no choice of α removes.
    pub residual: DMatrix<f64>,
}

/// How well a basis represents a set of spectra.
#[derive(Clone, Debug, Serialize)]
pub struct BasisFit {
    pub samples: usize,
    pub energy_captured: f64,
    /// RMSE of the projection onto the basis, in reflectance units, over all samples and bands.
    pub rmse: f64,
    pub max_abs_error: f64,
}

/// Spectra as the columns of a (bands × samples) matrix, point-sampled on `grid`.
pub fn sample_matrix(spectra: &[Curve], grid: &Grid) -> Result<DMatrix<f64>> {
    for c in spectra {
        let (lo, hi) = c.support();
        if lo > grid.start_nm + 1e-9 || hi < grid.end_nm() - 1e-9 {
            return Err(Error::Curve {
                name: c.name.clone(),
                msg: format!(
                    "covers {lo}–{hi} nm, the grid needs {}–{} nm",
                    grid.start_nm,
                    grid.end_nm()
                ),
            });
        }
    }
    Ok(DMatrix::from_fn(grid.count, spectra.len(), |b, s| {
        spectra[s].eval(grid.wavelength(b))
    }))
}

impl Basis {
    /// Train J vectors on `spectra`: the leading eigenvectors of R Rᵀ (uncentred PCA), each
    /// signed so that its sum is non-negative.
    pub fn train(spectra: &[Curve], grid: &Grid, j: usize) -> Result<Basis> {
        if j == 0 || j > grid.count || j > spectra.len() {
            return Err(Error::config(
                "reconstruct",
                "basis",
                j,
                &format!(
                    "must be between 1 and min(bands = {}, spectra = {})",
                    grid.count,
                    spectra.len()
                ),
            ));
        }
        let r = sample_matrix(spectra, grid)?;
        let gram = &r * r.transpose();
        let eig = nalgebra::SymmetricEigen::new(gram);
        let mut order: Vec<usize> = (0..grid.count).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let total: f64 = eig.eigenvalues.iter().map(|v| v.max(0.0)).sum();
        let kept: f64 = order[..j]
            .iter()
            .map(|&k| eig.eigenvalues[k].max(0.0))
            .sum();
        let mut vectors = DMatrix::zeros(grid.count, j);
        for (col, &k) in order[..j].iter().enumerate() {
            let v = eig.eigenvectors.column(k);
            let sign = if v.sum() < 0.0 { -1.0 } else { 1.0 };
            vectors.set_column(col, &(v * sign));
        }
        let samples = spectra.len() as f64;
        let mut residual = DMatrix::zeros(grid.count, grid.count);
        for &k in &order[j..] {
            let v = eig.eigenvectors.column(k);
            residual += v * v.transpose() * (eig.eigenvalues[k].max(0.0) / samples);
        }
        Ok(Basis {
            grid: *grid,
            vectors,
            energy_captured: if total > 0.0 { kept / total } else { 0.0 },
            variances: order[..j]
                .iter()
                .map(|&k| eig.eigenvalues[k].max(0.0) / samples)
                .collect(),
            residual,
        })
    }

    /// The trained Gaussian prior of α as the unmixer's J × J quadratic term P = m·diag(1/v_j):
    /// v_j the coefficients' mean squares over the training spectra, m = trace(L Σ⊥ Lᵀ)/C the
    /// mean channel variance of their misfit through `light` (C × bands: what each band gives
    /// each channel). Then min ‖x − Fα‖² + αᵀPα is the MAP estimate under x = Fα + L r⊥ with
    /// α ~ N(0, diag v) and the misfit taken as white noise of variance m. None when a
    /// coefficient never varies in the training set (mean square ≤ 10⁻¹² of the largest: its
    /// prior would be infinitely stiff).
    pub fn coefficient_prior(&self, light: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        let largest = self.variances.iter().cloned().fold(0.0, f64::max);
        if self
            .variances
            .iter()
            .any(|&v| v.is_nan() || v <= 1e-12 * largest)
        {
            return None;
        }
        let misfit = (light * &self.residual * light.transpose()).trace() / light.nrows() as f64;
        let diag = self.variances.iter().map(|v| misfit.max(0.0) / v);
        Some(DMatrix::from_diagonal(&nalgebra::DVector::from_iterator(
            self.len(),
            diag,
        )))
    }

    pub fn len(&self) -> usize {
        self.vectors.ncols()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Basis vector j as a curve on the grid.
    pub fn curve(&self, j: usize) -> Curve {
        Curve::from_grid(
            format!("b{j}"),
            &self.grid,
            self.vectors.column(j).iter().cloned().collect(),
        )
        .expect("grid curves are valid")
    }

    /// Least-squares projection of `spectra` onto the basis, and the error it leaves.
    pub fn fit(&self, spectra: &[Curve]) -> Result<BasisFit> {
        let r = sample_matrix(spectra, &self.grid)?;
        let proj = &self.vectors * (self.vectors.transpose() * &r);
        let err = &r - &proj;
        let n = (r.nrows() * r.ncols()) as f64;
        Ok(BasisFit {
            samples: spectra.len(),
            energy_captured: proj.norm_squared() / r.norm_squared().max(f64::MIN_POSITIVE),
            rmse: (err.norm_squared() / n).sqrt(),
            max_abs_error: err.amax(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spectra_in_the_span_are_recovered_exactly() {
        let g = Grid::VISIBLE;
        // Spectra built from two smooth functions: a 2-vector basis must capture all energy.
        let f1: Vec<f64> = g.wavelengths().iter().map(|w| 1.0 + 0.001 * w).collect();
        let f2: Vec<f64> = g
            .wavelengths()
            .iter()
            .map(|w| ((w - 400.0) / 50.0).sin())
            .collect();
        let spectra: Vec<Curve> = (0..10)
            .map(|k| {
                let (a, b) = (0.3 + 0.05 * k as f64, 0.1 * (k as f64 - 4.0));
                let v = f1.iter().zip(&f2).map(|(x, y)| a * x + b * y).collect();
                Curve::from_grid(format!("s{k}"), &g, v).unwrap()
            })
            .collect();
        let basis = Basis::train(&spectra, &g, 2).unwrap();
        assert!((basis.energy_captured - 1.0).abs() < 1e-12);
        let fit = basis.fit(&spectra).unwrap();
        assert!(fit.rmse < 1e-12, "{}", fit.rmse);
        // Orthonormal columns.
        let gram = basis.vectors.transpose() * &basis.vectors;
        assert!((gram - DMatrix::identity(2, 2)).amax() < 1e-12);
    }

    /// Flat spectra c_s: one vector (1, …, 1)/√n carries them all, its coefficient is c_s·√n,
    /// so its mean square is n·mean(c²), and nothing is left outside it.
    #[test]
    fn the_variances_of_flat_spectra_by_hand() {
        let g = Grid::VISIBLE;
        let levels = [0.2, 0.5, 0.9];
        let spectra: Vec<Curve> = levels
            .iter()
            .map(|&c| Curve::constant("flat", 350.0, 800.0, c).unwrap())
            .collect();
        let basis = Basis::train(&spectra, &g, 1).unwrap();
        let n = g.count as f64;
        let mean_c2 = levels.iter().map(|c| c * c).sum::<f64>() / 3.0;
        assert!((basis.variances[0] - n * mean_c2).abs() < 1e-12 * n);
        assert!(basis.residual.amax() < 1e-12, "{}", basis.residual.amax());
    }

    /// Two spectra on two halves of the grid, a one-vector basis: the kept vector is the
    /// brighter spectrum's, the other one the whole misfit; through a light that sums the
    /// bands, m = Σ_b Σ_b' (Σ⊥)_bb' / 1 channel, and P = m / v.
    #[test]
    fn the_coefficient_prior_by_hand() {
        let g = Grid::VISIBLE;
        let half = |lo: bool, c: f64| {
            let v = (0..g.count)
                .map(|b| if (b < 15) == lo { c } else { 0.0 })
                .collect();
            Curve::from_grid("half", &g, v).unwrap()
        };
        let basis = Basis::train(&[half(true, 1.0), half(false, 0.5)], &g, 1).unwrap();
        // R Rᵀ has eigenvalues 15·1² and 16·0.5² = 4: kept 15, misfit 4, over 2 spectra.
        assert!((basis.variances[0] - 7.5).abs() < 1e-12);
        let sum = DMatrix::from_element(1, g.count, 1.0);
        let p = basis.coefficient_prior(&sum).unwrap();
        // The misfit spectrum (0, …, 0, 0.5, …) sums to 8 through the light: m = 64 / 2 = 32.
        assert!((p[(0, 0)] - 32.0 / 7.5).abs() < 1e-9, "{}", p[(0, 0)]);
    }

    #[test]
    fn a_coefficient_that_never_varies_has_no_prior() {
        let g = Grid::VISIBLE;
        let flat = Curve::constant("flat", 350.0, 800.0, 0.5).unwrap();
        let basis = Basis::train(&[flat.clone(), flat], &g, 2).unwrap();
        assert!(basis.variances[1] < 1e-12, "{}", basis.variances[1]);
        assert!(basis
            .coefficient_prior(&DMatrix::identity(31, 31))
            .is_none());
    }

    proptest::proptest! {
        /// The energy splits exactly: Σ_j variances + trace(residual) = mean ‖r‖², and the
        /// residual is orthogonal to the basis.
        #[test]
        fn the_energy_splits_between_basis_and_residual(
            seed in 0u64..1000, j in 1usize..6,
        ) {
            let g = Grid::VISIBLE;
            let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let mut next = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            let spectra: Vec<Curve> = (0..8)
                .map(|k| {
                    let v = (0..g.count).map(|_| next()).collect();
                    Curve::from_grid(format!("s{k}"), &g, v).unwrap()
                })
                .collect();
            let basis = Basis::train(&spectra, &g, j).unwrap();
            let r = sample_matrix(&spectra, &g).unwrap();
            let energy = r.norm_squared() / 8.0;
            let split = basis.variances.iter().sum::<f64>() + basis.residual.trace();
            proptest::prop_assert!((split - energy).abs() < 1e-9 * energy);
            let cross = (&basis.residual * &basis.vectors).amax();
            proptest::prop_assert!(cross < 1e-9 * energy, "{}", cross);
        }
    }

    #[test]
    fn short_spectra_are_refused() {
        let c = Curve::constant("short", 450.0, 700.0, 1.0).unwrap();
        assert!(Basis::train(&[c], &Grid::VISIBLE, 1).is_err());
    }
}
