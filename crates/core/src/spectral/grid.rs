//! Uniform wavelength grids: the band centres of a hyperspectral cube.

use crate::error::Error;
use crate::error::Result;
use serde::{Deserialize, Serialize};

/// A uniform grid of band centres `start_nm + k·step_nm`, k = 0..count.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    pub start_nm: f64,
    pub step_nm: f64,
    pub count: usize,
}

impl Grid {
    /// The default visible grid of the CAVE data and of the paper: 400–700 nm in 10 nm steps.
    pub const VISIBLE: Grid = Grid {
        start_nm: 400.0,
        step_nm: 10.0,
        count: 31,
    };

    /// A checked grid: finite positive wavelengths, positive step, at least two bands.
    pub fn new(start_nm: f64, step_nm: f64, count: usize) -> Result<Grid> {
        let bad = |key: &str, v: String, why: &str| Error::config("grid", key, v, why);
        if !(start_nm.is_finite() && start_nm > 0.0) {
            return Err(bad(
                "start_nm",
                start_nm.to_string(),
                "must be a positive wavelength",
            ));
        }
        if !(step_nm.is_finite() && step_nm > 0.0) {
            return Err(bad("step_nm", step_nm.to_string(), "must be positive"));
        }
        if count < 2 {
            return Err(bad("count", count.to_string(), "needs at least two bands"));
        }
        Ok(Grid {
            start_nm,
            step_nm,
            count,
        })
    }

    /// Wavelength of band `k` in nm.
    pub fn wavelength(&self, k: usize) -> f64 {
        self.start_nm + self.step_nm * k as f64
    }

    /// All band centres in nm.
    pub fn wavelengths(&self) -> Vec<f64> {
        (0..self.count).map(|k| self.wavelength(k)).collect()
    }

    /// Last band centre in nm.
    pub fn end_nm(&self) -> f64 {
        self.wavelength(self.count - 1)
    }
}
