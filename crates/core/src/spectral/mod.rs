//! Wavelength grids, sampled curves and their exact integration, the CSV library, the PCA basis.

pub mod basis;
pub mod csv;
pub mod curve;
pub mod grid;
pub mod library;

pub use basis::Basis;
pub use curve::{integrate_product, Curve};
pub use grid::Grid;
pub use library::Library;
