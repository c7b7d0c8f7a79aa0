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
        Ok(Basis {
            grid: *grid,
            vectors,
            energy_captured: if total > 0.0 { kept / total } else { 0.0 },
        })
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

    #[test]
    fn short_spectra_are_refused() {
        let c = Curve::constant("short", 450.0, 700.0, 1.0).unwrap();
        assert!(Basis::train(&[c], &Grid::VISIBLE, 1).is_err());
    }
}
