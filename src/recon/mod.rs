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
use crate::recon::gap::{Gap, GapStats, Method};
use crate::recon::qp::{UnmixStats, Unmixer};
use crate::rig::Rig;
use crate::scene::{Cube, Experiment};

/// Demultiplexer and unmixer for one rig, built once and applied to every frame.
pub struct Reconstructor {
    pub demux: Demux,
    /// GAP de-aliasing on the patterns (given, else the ideal ones); None for `method = "fourier"`.
    pub gap: Option<Gap>,
    pub unmixer: Unmixer,
    /// Per-band gains L̃ of a radiance scene's light (`Rig::light_gains`): r̂ = diag(L̃)·Bα.
    pub light: Option<Vec<f32>>,
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
        let unmixer = Unmixer::new(&rig.system_matrix(), &rig.basis.vectors, eta)?;
        let gap = match exp.reconstruct.gap.method {
            Method::Fourier => None,
            _ => {
                let ideal;
                let s = match patterns {
                    Some(p) => p,
                    None => {
                        let data = rig
                            .carriers
                            .iter()
                            .flat_map(|c| c.ideal_pattern(rig.width, rig.height))
                            .collect();
                        ideal = Cube::from_vec(rig.width, rig.height, rig.carriers.len(), data)?;
                        &ideal
                    }
                };
                Some(Gap::new(s, &exp.reconstruct.gap, &exp.file)?)
            }
        };
        let light = rig
            .light_gains()
            .map(|g| g.iter().map(|&v| v as f32).collect());
        Ok(Reconstructor {
            demux,
            gap,
            unmixer,
            light,
        })
    }

    /// x̂: one plane per wheel channel.
    pub fn demultiplex(&self, frame: &Cube) -> Result<Cube> {
        self.demux.run(frame)
    }

    /// GAP de-aliasing of x̂ (x̂ itself for `fourier`); with `truth`, PSNR per iteration.
    pub fn dealias(
        &self,
        frame: &Cube,
        xhat: &Cube,
        truth: Option<&Cube>,
    ) -> Result<(Cube, GapStats)> {
        match &self.gap {
            Some(g) => g.run(frame, xhat, truth),
            None => Ok((xhat.clone(), GapStats::default())),
        }
    }

    /// r̂ = B α per pixel, non-negative (times the light gains L̃ for a lit radiance scene).
    pub fn unmix(&self, xhat: &Cube) -> Result<(Cube, UnmixStats)> {
        let (mut cube, stats) = self.unmixer.unmix(xhat)?;
        for (plane, g) in cube.planes_mut().zip(self.light.iter().flatten()) {
            plane.iter_mut().for_each(|v| *v *= g);
        }
        Ok((cube, stats))
    }
}
