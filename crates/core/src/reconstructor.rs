//! The reconstruction of one rig, built once from its design, its configuration and its
//! calibration, then applied to every frame: linearise (dark/flat), demultiplex with the
//! calibrated carriers, de-alias (GAP on the calibrated patterns), undo the exposure
//! crosstalk, unmix per pixel. It uses what a real rig knows and nothing else.

use crate::calibration::Calibration;
use crate::carriers::Carrier;
use crate::demux::{Demux, WindowShape, SUPER_GAUSSIAN_ORDER};
use crate::error::{Error, Result};
use crate::gap::{Gap, GapConfig, GapStats, Method};
use crate::unmix::{UnmixStats, Unmixer};
use crate::Cube;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// What the rig was designed to be: everything the reconstruction knows before any frame.
#[derive(Clone, Debug)]
pub struct Design {
    pub width: usize,
    pub height: usize,
    /// The carriers ω_i the DMD was programmed with (on the FFT bin grid).
    pub carriers: Vec<Carrier>,
    /// F (channels × J): F_ij = ∫ T_i L QE b_j dλ.
    pub system: DMatrix<f64>,
    /// B (bands × J): the spectral basis.
    pub basis: DMatrix<f64>,
    /// Per-band gains of a lit radiance scene (the cube is diag(L̃)·Bα); None otherwise.
    pub output_gains: Option<Vec<f64>>,
    /// Band spacing in nm (η weighs the curvature per nm²).
    pub band_step_nm: f64,
    /// x_i of a white reflector: the channel values the white calibration target gives.
    pub white: Vec<f64>,
    /// w_ik (filter i, pattern k) of one exposure as the programmed timing predicts; None when
    /// each pattern sees only its own filter.
    pub exposure_weights: Option<Vec<Vec<f64>>>,
}

/// Where the reconstruction takes the exposure weights w_ik from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CrosstalkCorrection {
    /// The design's weights (or `crosstalk_weights` when given): x = (Wᵀ)⁻¹ z.
    Timing,
    /// Demultiplexed carriers are taken as the channels (W = I).
    None,
}

/// Reconstruction settings (`[reconstruct]`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReconConfig {
    /// Crop window size as a fraction of the width and height (the paper's 0.25).
    pub crop: f64,
    pub window: WindowShape,
    /// Weight of the spectral smoothness term ‖D₂Bα‖² (the paper's η = 200).
    pub eta: f64,
    /// Number of basis vectors J (the paper's 6).
    pub basis: usize,
    /// GAP de-aliasing of the Fourier estimates (`[reconstruct.gap]`; docs/gap.md).
    pub gap: GapConfig,
    /// Undo the exposure crosstalk between channels before unmixing.
    pub crosstalk: CrosstalkCorrection,
    /// Measured weights w_ik (filter i, pattern k); they replace the design's when given.
    pub crosstalk_weights: Option<Vec<Vec<f64>>>,
}

impl Default for ReconConfig {
    fn default() -> Self {
        ReconConfig {
            crop: 0.25,
            window: WindowShape::Square,
            eta: 200.0,
            basis: 6,
            gap: Default::default(),
            crosstalk: CrosstalkCorrection::Timing,
            crosstalk_weights: None,
        }
    }
}

impl ReconConfig {
    /// Check every value for a rig of `channels` filters; the error names the key and value.
    pub fn validate(&self, f: &str, channels: usize) -> Result<()> {
        if !(self.crop > 0.0 && self.crop <= 0.5) {
            return Err(Error::config(
                f,
                "reconstruct.crop",
                self.crop,
                "must be in (0, 0.5]",
            ));
        }
        if !(self.eta.is_finite() && self.eta >= 0.0) {
            return Err(Error::config(
                f,
                "reconstruct.eta",
                self.eta,
                "must be finite and ≥ 0",
            ));
        }
        if self.basis == 0 || self.basis > channels {
            return Err(Error::config(
                f,
                "reconstruct.basis",
                self.basis,
                &format!("must be 1 to the number of filters ({channels})"),
            ));
        }
        self.gap.validate(f)?;
        if let Some(w) = &self.crosstalk_weights {
            let n = channels;
            if w.len() != n
                || w.iter()
                    .any(|row| row.len() != n || row.iter().any(|v| !v.is_finite()))
            {
                return Err(Error::config(
                    f,
                    "reconstruct.crosstalk_weights",
                    format!("{w:?}"),
                    &format!("needs {n} rows of {n} finite weights (filter × pattern)"),
                ));
            }
        }
        Ok(())
    }
}

/// Everything one frame's reconstruction produced, with the wall time of each step.
pub struct Reconstruction {
    /// x̂: the Fourier estimates of the channels (crosstalk undone).
    pub xhat: Cube,
    /// x̂ after de-aliasing (= `xhat` for `fourier`).
    pub xgap: Cube,
    /// r̂: the cube.
    pub cube: Cube,
    pub gap: GapStats,
    pub unmix: UnmixStats,
    /// Seconds of linearisation + demultiplexing + crosstalk, of de-aliasing, of unmixing.
    pub seconds: [f64; 3],
}

/// Demultiplexer, de-aliaser and unmixer for one rig, built once and applied to every frame.
pub struct Reconstructor {
    pub demux: Demux,
    /// GAP on the calibrated patterns; None for `method = "fourier"`.
    pub gap: Option<Gap>,
    pub unmixer: Unmixer,
    /// Q: x_i = Σ_k Q_ik ζ_k, from the white-relative carriers ζ_k = z_k / z_k(white) to the
    /// channels: (Wᵀ)⁻¹·diag(Wᵀ white), or diag(white) without crosstalk correction.
    pub to_channels: Vec<Vec<f64>>,
    /// z_k(white): the exposed value of the white target in each pattern's slot.
    pub exposed_white: Vec<f64>,
    pub calibration: Calibration,
}

impl Reconstructor {
    /// Build from the design, the settings and the calibration; `file` names the experiment.
    pub fn new(
        cfg: &ReconConfig,
        design: &Design,
        calibration: &Calibration,
        file: &str,
    ) -> Result<Reconstructor> {
        let demux = Demux::new(design.width, design.height, &design.carriers, cfg.crop)
            .with_window(cfg.window, SUPER_GAUSSIAN_ORDER)?
            .with_calibration(&calibration.carriers)?;
        let unmixer = unmixer(cfg, design)?;
        let gap = match cfg.gap.method {
            Method::Fourier => None,
            _ => Some(Gap::new(&calibration.patterns, &cfg.gap, file)?),
        };
        let weights = match cfg.crosstalk {
            CrosstalkCorrection::Timing => cfg
                .crosstalk_weights
                .as_ref()
                .or(design.exposure_weights.as_ref()),
            CrosstalkCorrection::None => None,
        };
        let (to_channels, exposed_white) = white_to_channels(&design.white, weights)?;
        Ok(Reconstructor {
            demux,
            gap,
            unmixer,
            to_channels,
            exposed_white,
            calibration: calibration.clone(),
        })
    }

    /// The whole chain on one frame: linearise, demultiplex, de-alias (on the white-relative
    /// carriers ζ; `z_truth`, the true exposed channels, gives GAP's per-iteration PSNR), undo
    /// the crosstalk, unmix.
    pub fn run(&self, frame: &Cube, z_truth: Option<&Cube>) -> Result<Reconstruction> {
        let t = Instant::now();
        let measured = self.calibration.linearise(frame)?;
        let zeta = self.demux.run(&measured)?;
        let xhat = self.to_channels(&zeta)?;
        let t1 = t.elapsed().as_secs_f64();
        let (xgap, gap) = match &self.gap {
            Some(g) => {
                let zeta_truth = z_truth.map(|z| self.relative_to_white(z)).transpose()?;
                let (z, stats) = g.run(&measured, &zeta, zeta_truth.as_ref())?;
                (self.to_channels(&z)?, stats)
            }
            None => (xhat.clone(), GapStats::default()),
        };
        let t2 = t.elapsed().as_secs_f64();
        let (cube, unmix) = self.unmix(&xgap)?;
        let t3 = t.elapsed().as_secs_f64();
        Ok(Reconstruction {
            xhat,
            xgap,
            cube,
            gap,
            unmix,
            seconds: [t1, t2 - t1, t3 - t2],
        })
    }

    /// x̂: the frame linearised, demultiplexed and mixed back to channels (the real-time path's
    /// first half, without de-aliasing).
    pub fn demultiplex(&self, frame: &Cube) -> Result<Cube> {
        let zeta = self.demux.run(&self.calibration.linearise(frame)?)?;
        self.to_channels(&zeta)
    }

    /// x = Q·ζ per pixel.
    pub fn to_channels(&self, zeta: &Cube) -> Result<Cube> {
        zeta.mix(&self.to_channels)
    }

    /// ζ_k = z_k / z_k(white).
    fn relative_to_white(&self, z: &Cube) -> Result<Cube> {
        let n = self.exposed_white.len();
        let d: Vec<Vec<f64>> = (0..n)
            .map(|k| {
                (0..n)
                    .map(|j| {
                        if j == k {
                            1.0 / self.exposed_white[k]
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect();
        z.mix(&d)
    }

    /// r̂ = B α per pixel, non-negative (times the light gains L̃ for a lit radiance scene).
    pub fn unmix(&self, xhat: &Cube) -> Result<(Cube, UnmixStats)> {
        self.unmixer.unmix(xhat)
    }
}

/// The per-pixel unmixer of a design: F, B, η per nm⁴ and the output gains of a lit radiance scene.
pub fn unmixer(cfg: &ReconConfig, design: &Design) -> Result<Unmixer> {
    // The paper's penalty is η‖∂²r/∂λ²‖² with λ in nm: the discrete D₂ divided by Δλ².
    let eta = cfg.eta / design.band_step_nm.powi(4);
    let unmixer = Unmixer::new(&design.system, &design.basis, eta)?;
    match &design.output_gains {
        Some(g) => unmixer.with_output_gains(g),
        None => Ok(unmixer),
    }
}

/// Q = (Wᵀ)⁻¹·diag(Wᵀ white) and Wᵀ white (or diag(white) and white without W).
fn white_to_channels(
    white: &[f64],
    weights: Option<&Vec<Vec<f64>>>,
) -> Result<(Vec<Vec<f64>>, Vec<f64>)> {
    let n = white.len();
    let Some(w) = weights else {
        let q = (0..n)
            .map(|i| {
                (0..n)
                    .map(|k| if i == k { white[i] } else { 0.0 })
                    .collect()
            })
            .collect();
        return Ok((q, white.to_vec()));
    };
    if w.len() != n || w.iter().any(|r| r.len() != n) {
        return Err(Error::Shape(format!(
            "exposure weights {}×{} for {n} channels",
            w.len(),
            w.first().map_or(0, |r| r.len())
        )));
    }
    let m = crate::crosstalk::crosstalk_inverse(w)?;
    let zw: Vec<f64> = (0..n)
        .map(|k| (0..n).map(|i| w[i][k] * white[i]).sum())
        .collect();
    if let Some(k) = zw.iter().position(|v| !(*v > 0.0)) {
        return Err(Error::Numerical(format!(
            "pattern {k} sees no white light through the exposure weights (Σ_i w_ik·white_i = {})",
            zw[k]
        )));
    }
    let q = (0..n)
        .map(|i| (0..n).map(|k| m[i][k] * zw[k]).collect())
        .collect();
    Ok((q, zw))
}
