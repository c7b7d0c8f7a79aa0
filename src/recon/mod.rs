//! The reconstruction core, the same code on the twin and on the rig: Fourier demultiplexing
//! and per-pixel spectral unmixing.

pub mod crosstalk;
pub mod demux;
pub mod fft2;
pub mod gap;
pub mod qp;
pub mod tv;
pub mod wavelet;

pub use demux::Demux;

use crate::error::Result;
use crate::optics::Carrier;
use crate::recon::gap::{Gap, GapStats, Method};
use crate::recon::qp::{UnmixStats, Unmixer};
use crate::rig::Rig;
use crate::scene::experiment::CrosstalkCorrection;
use crate::scene::{Cube, Experiment};
use crate::sensor::{self, Sensor};
use crate::timing;
use std::time::Instant;

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
    /// Seconds of calibration + demultiplexing + crosstalk, of de-aliasing, of unmixing.
    pub seconds: [f64; 3],
}

/// Dark and flat frames of the camera and the DN of one frame unit: raw DN → the noiseless
/// frame's units, as the real rig corrects its raw frames (sensor/calibration.rs).
pub struct Calibration {
    pub dark: Cube,
    pub flat: Cube,
    /// DN per frame unit: K · electrons_at_full_scale / full scale.
    pub dn_per_unit: f64,
}

impl Calibration {
    /// (raw − dark)/(flat − dark)·mean(flat − dark) / dn_per_unit.
    pub fn apply(&self, raw: &Cube) -> Result<Cube> {
        let mut c = sensor::calibrate(raw, &self.dark, &self.flat)?;
        let s = (1.0 / self.dn_per_unit) as f32;
        c.data.iter_mut().for_each(|v| *v *= s);
        Ok(c)
    }
}

/// Demultiplexer and unmixer for one rig, built once and applied to every frame.
pub struct Reconstructor {
    pub demux: Demux,
    /// GAP de-aliasing on the patterns (given, else the ideal ones); None for `method = "fourier"`.
    pub gap: Option<Gap>,
    pub unmixer: Unmixer,
    /// The exposure weights w_ik (filter i, pattern k) the frame was taken with, if modelled.
    pub weights: Option<Vec<Vec<f64>>>,
    /// M = (Wᵀ)⁻¹: x_i = Σ_k M_ik z_k undoes the exposure crosstalk (None: not corrected).
    pub demix: Option<Vec<Vec<f64>>>,
    /// Dark/flat correction of raw frames when the rig has a sensor.
    pub calibration: Option<Calibration>,
}

impl Reconstructor {
    /// Build from the rig; with `patterns` (the patterns as imaged, or as calibrated on the rig)
    /// the carrier gains are measured on them instead of taken from the design.
    pub fn new(exp: &Experiment, rig: &Rig, patterns: Option<&Cube>) -> Result<Reconstructor> {
        let mut demux = Demux::new(rig.width, rig.height, &rig.carriers, exp.reconstruct.crop)
            .with_window(exp.reconstruct.window, demux::SUPER_GAUSSIAN_ORDER)?;
        if let Some(p) = patterns {
            demux = demux.with_measured_gains(p)?;
        }
        // The paper's penalty is η‖∂²r/∂λ²‖² with λ in nm: the discrete D₂ divided by Δλ².
        let eta = exp.reconstruct.eta / rig.grid.step_nm.powi(4);
        let mut unmixer = Unmixer::new(&rig.system_matrix(), &rig.basis.vectors, eta)?;
        // A lit radiance scene: the cube is diag(L̃)·Bα (`Rig::light_gains`).
        if let Some(light) = rig.light_gains() {
            unmixer = unmixer.with_output_gains(&light)?;
        }
        // The patterns GAP and the calibration work with: as given, else the design sinusoids
        // (computed only when one of them is asked for).
        let needs_patterns =
            exp.reconstruct.gap.method != Method::Fourier || exp.rig.sensor.is_some();
        let ideal = (patterns.is_none() && needs_patterns)
            .then(|| Carrier::ideal_patterns(&rig.carriers, rig.width, rig.height));
        let s = patterns.or(ideal.as_ref());
        let gap = match (exp.reconstruct.gap.method, s) {
            (Method::Fourier, _) | (_, None) => None,
            (_, Some(s)) => Some(Gap::new(s, &exp.reconstruct.gap, &exp.file)?),
        };
        let r = &exp.reconstruct;
        let weights = match (&r.crosstalk_weights, &exp.rig.timing) {
            (Some(w), _) => Some(w.clone()),
            (None, Some(t)) => Some(timing::weights(t)?.w),
            (None, None) => None,
        };
        let demix = match (r.crosstalk, &weights) {
            (CrosstalkCorrection::Timing, Some(w)) => Some(timing::crosstalk_inverse(w)?),
            _ => None,
        };
        let calibration = match (&exp.rig.sensor, s) {
            (Some(cfg), Some(s)) => {
                let cam = Sensor::new(cfg, rig.width, rig.height)?;
                let white = crate::forward::exposed_white(rig, weights.as_deref());
                let fs = crate::forward::full_scale(&white, s) as f64;
                // The flat is taken with its own bright uniform source at half the full well,
                // whatever the scene's exposure: bright enough for a low-noise gain map.
                let level = 0.5 * cfg.full_well_e;
                Some(Calibration {
                    dark: cam.dark_frame(r.calibration_frames)?,
                    flat: cam.flat_frame(level, r.calibration_frames)?,
                    dn_per_unit: cfg.gain_dn_per_e * cfg.electrons_at_full_scale / fs,
                })
            }
            _ => None,
        };
        Ok(Reconstructor {
            demux,
            gap,
            unmixer,
            weights,
            demix,
            calibration,
        })
    }

    /// The frame in the noiseless frame's units: dark- and flat-corrected when it is raw.
    pub fn prepare(&self, frame: &Cube) -> Result<Cube> {
        match &self.calibration {
            Some(c) => c.apply(frame),
            None => Ok(frame.clone()),
        }
    }

    /// The whole chain on one frame: calibrate, demultiplex, de-alias (on what each pattern saw,
    /// z; `z_truth` gives GAP's per-iteration PSNR), undo the crosstalk, unmix.
    pub fn run(&self, frame: &Cube, z_truth: Option<&Cube>) -> Result<Reconstruction> {
        let t = Instant::now();
        let measured = self.prepare(frame)?;
        let zhat = self.demultiplex(&measured)?;
        let xhat = self.demix(&zhat)?;
        let t1 = t.elapsed().as_secs_f64();
        let (xgap, gap) = match &self.gap {
            Some(g) => {
                let (z, stats) = g.run(&measured, &zhat, z_truth)?;
                (self.demix(&z)?, stats)
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

    /// x = M·z per pixel (M = (Wᵀ)⁻¹); z unchanged without a correction.
    pub fn demix(&self, z: &Cube) -> Result<Cube> {
        match &self.demix {
            Some(m) => z.mix(m),
            None => Ok(z.clone()),
        }
    }

    /// x̂: one plane per wheel channel.
    pub fn demultiplex(&self, frame: &Cube) -> Result<Cube> {
        self.demux.run(frame)
    }

    /// r̂ = B α per pixel, non-negative (times the light gains L̃ for a lit radiance scene).
    pub fn unmix(&self, xhat: &Cube) -> Result<(Cube, UnmixStats)> {
        self.unmixer.unmix(xhat)
    }
}
