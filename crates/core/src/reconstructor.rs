//! The reconstruction of one rig, built once from its design, its configuration and its
//! calibration, then applied to every frame: linearise (dark/flat), demultiplex with the
//! calibrated carriers, de-alias (GAP on the calibrated patterns), undo the exposure
//! crosstalk, unmix per pixel. It uses what a real rig knows and nothing else.

use crate::auto::{self, Choice};
use crate::calibration::{Calibration, MeasuredCarrier};
use crate::carriers::Carrier;
use crate::demux::{Demux, WindowShape, SUPER_GAUSSIAN_ORDER};
use crate::error::{Error, Result};
use crate::gap::{Gap, GapConfig, GapStats, Method};
use crate::joint::{Joint, JointConfig, JointStats, SpectralPrior, WeightRule};
use crate::noise::NoiseModel;
use crate::unmix::{curvature, UnmixStats, Unmixer};
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
    /// The camera's temporal noise (EMVA 1288 gain and dark noise, from its photon-transfer
    /// measurement); None when the frames are noiseless or the camera is not characterised.
    pub noise: Option<NoiseModel>,
    /// The basis's trained Gaussian prior as a J × J quadratic term in the unmixer's units
    /// (`Basis::coefficient_prior`); None when the basis has none.
    pub spectral_prior: Option<DMatrix<f64>>,
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

/// Where the reconstruction runs (`[compute] device`): the GPU backend is the crate
/// specmux-gpu, behind the binary's `gpu` feature.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ComputeDevice {
    /// The CPU (this crate).
    #[default]
    Cpu,
    /// The GPU; an error where no adapter opens.
    Gpu,
    /// The GPU where an adapter opens, else the CPU (said in one line).
    Auto,
}

impl ComputeDevice {
    /// The refusal of `device = "gpu"` by a build without the GPU backend (the `gpu` feature),
    /// naming `file`'s key and how to build one.
    pub fn not_built(file: &str) -> Error {
        Error::config(
            file,
            "compute.device",
            "\"gpu\"",
            "this specmux was built without the GPU backend: cargo build --release --features gpu (the Python package: MATURIN_PEP517_ARGS=\"--features gpu\" pip install ./python)",
        )
    }
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
    /// The joint reconstruction (`[reconstruct.joint]`), used when `gap.method = "joint"`.
    pub joint: JointConfig,
    /// Undo the exposure crosstalk between channels before unmixing.
    pub crosstalk: CrosstalkCorrection,
    /// Measured weights w_ik (filter i, pattern k); they replace the design's when given.
    pub crosstalk_weights: Option<Vec<Vec<f64>>>,
    /// Time budget of `gap.method = "auto"` in seconds (default 1 s per 768² frame, scaled by
    /// pixel count).
    pub budget_s: Option<f64>,
    /// `gap.method = "auto"`: a `specmux bench` report (bench.json) measured on the machine that
    /// runs the reconstruction, read in place of the committed tables (path relative to the
    /// experiment file).
    pub auto_table: Option<String>,
    /// The rows of `auto_table` (crop 0.25, square window, TV prior, no noise weights), loaded
    /// with the experiment; not a key of the file.
    #[serde(skip)]
    pub measured_table: Option<Vec<auto::Entry>>,
}

impl Default for ReconConfig {
    fn default() -> Self {
        ReconConfig {
            crop: 0.25,
            window: WindowShape::Square,
            eta: 200.0,
            basis: 6,
            gap: Default::default(),
            joint: Default::default(),
            crosstalk: CrosstalkCorrection::Timing,
            crosstalk_weights: None,
            budget_s: None,
            auto_table: None,
            measured_table: None,
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
        self.joint.validate(f)?;
        if let Some(b) = self.budget_s.filter(|b| !(b.is_finite() && *b > 0.0)) {
            return Err(Error::config(
                f,
                "reconstruct.budget_s",
                b,
                "must be finite and > 0",
            ));
        }
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
    /// The joint reconstruction's run (None for the other methods).
    pub joint: Option<JointStats>,
    pub unmix: UnmixStats,
    /// Seconds of linearisation + demultiplexing + crosstalk, of de-aliasing, of unmixing.
    pub seconds: [f64; 3],
}

/// Demultiplexer, de-aliaser and unmixer for one rig, built once and applied to every frame.
pub struct Reconstructor {
    pub demux: Demux,
    /// GAP on the calibrated patterns; None for `method = "fourier"` and `"joint"`.
    pub gap: Option<Gap>,
    /// The joint reconstruction on the calibrated patterns (`method = "joint"`).
    pub joint: Option<Joint>,
    /// Per-band output gains of a lit radiance scene (the joint method's cube is diag(g)·Bα).
    gains: Option<Vec<f64>>,
    /// The noise model the joint method weighs its data term by (None: ω = 1).
    noise: Option<NoiseModel>,
    /// The design's camera noise model, whatever the method (the frame's SNR).
    camera: Option<NoiseModel>,
    /// What `method = "auto"` picked and why (None for the other methods).
    pub auto: Option<Choice>,
    pub unmixer: Unmixer,
    /// M = (Wᵀ)⁻¹: x_i = Σ_k M_ik z_k undoes the exposure crosstalk (None: not corrected).
    pub demix: Option<Vec<Vec<f64>>>,
    /// z_k(white) = Σ_i w_ik·white_i: the white target's exposed value in each pattern's slot.
    pub exposed_white: Vec<f64>,
    pub calibration: Calibration,
}

impl Reconstructor {
    /// Build from the design, the settings and the calibration; `file` names the experiment.
    /// `method = "auto"` reads the CPU's table ([`Reconstructor::for_device`] another's).
    pub fn new(
        cfg: &ReconConfig,
        design: &Design,
        calibration: &Calibration,
        file: &str,
    ) -> Result<Reconstructor> {
        Reconstructor::for_device(cfg, design, calibration, file, auto::CPU)
    }

    /// [`Reconstructor::new`] for the device `table` was measured on: `method = "auto"` picks
    /// from it.
    pub fn for_device(
        cfg: &ReconConfig,
        design: &Design,
        calibration: &Calibration,
        file: &str,
        table: auto::Table<'_>,
    ) -> Result<Reconstructor> {
        if cfg.gap.method == Method::Auto {
            let pixels = design.width * design.height;
            let measured = measured_table(cfg, file)?;
            let table = match &measured {
                Some((report, entries)) => auto::Table {
                    device: report,
                    scene: "its scene",
                    entries,
                },
                None => table,
            };
            let choice = auto::pick_from(
                table,
                cfg.budget_s.unwrap_or_else(|| auto::default_budget(pixels)),
                pixels,
            )
            .ok_or_else(|| {
                let path = cfg.auto_table.as_deref().unwrap_or("the committed table");
                Error::config(
                    file,
                    "reconstruct.auto_table",
                    path,
                    "holds no rows to pick from",
                )
            })?;
            let mut resolved = cfg.clone();
            resolved.gap.method = choice.method;
            match choice.method {
                Method::Joint => resolved.joint.iterations = choice.iterations,
                Method::Fourier => {}
                _ => resolved.gap.iterations = choice.iterations,
            }
            let mut r = Reconstructor::new(&resolved, design, calibration, file)?;
            r.auto = Some(choice);
            return Ok(r);
        }
        let weights = match cfg.crosstalk {
            CrosstalkCorrection::Timing => cfg
                .crosstalk_weights
                .as_ref()
                .or(design.exposure_weights.as_ref()),
            CrosstalkCorrection::None => None,
        };
        let source = match (&cfg.crosstalk_weights, &design.exposure_weights) {
            (Some(_), _) => "reconstruct.crosstalk_weights",
            (None, _) => "rig.timing",
        };
        let (demix, exposed_white) = demixing(&design.white, weights)
            .map_err(|e| e.within(file, source, "the exposure weights w_ik it gives"))?;
        let carriers = in_exposed_units(&calibration.carriers, &exposed_white);
        let demux = Demux::new(design.width, design.height, &design.carriers, cfg.crop)
            .with_window(cfg.window, SUPER_GAUSSIAN_ORDER)?
            .with_calibration(&carriers)?;
        let inv: Vec<f64> = exposed_white.iter().map(|v| 1.0 / v).collect();
        let gap = match cfg.gap.method {
            Method::Fourier | Method::Joint | Method::Auto => None,
            _ => Some(Gap::new(
                &calibration.patterns.scaled_planes(&inv)?,
                &cfg.gap,
                file,
            )?),
        };
        let joint = match cfg.gap.method {
            Method::Joint => {
                // S'_i = Σ_k w_ik s̃_k: the pattern each channel's light is modulated by.
                let z_patterns = calibration.patterns.scaled_planes(&inv)?;
                let channel_patterns = match weights {
                    Some(w) => z_patterns.mix(w)?,
                    None => z_patterns,
                };
                let (prior, used) = joint_prior(cfg, design, file)?;
                let joint_cfg = JointConfig {
                    spectral_prior: Some(used),
                    ..cfg.joint.clone()
                };
                Some(
                    Joint::new(
                        &channel_patterns,
                        &design.system,
                        &design.basis,
                        &prior,
                        &joint_cfg,
                        file,
                    )
                    .map_err(|e| e.within(file, "reconstruct.gap.method", "\"joint\""))?,
                )
            }
            _ => None,
        };
        let noise = match joint {
            Some(_) => joint_noise(&cfg.joint, design.noise, file)?,
            None => None,
        };
        Ok(Reconstructor {
            demux,
            gap,
            joint,
            gains: design.output_gains.clone(),
            noise,
            camera: design.noise,
            auto: None,
            unmixer: unmixer(cfg, design).map_err(|e| {
                e.within(
                    file,
                    "rig.wheel.filters",
                    "the system matrix F of these filters, basis and η",
                )
            })?,
            demix,
            exposed_white,
            calibration: calibration.clone(),
        })
    }

    /// The camera noise model the joint method weighs its data term by (None: ω = 1).
    pub fn joint_noise(&self) -> Option<&NoiseModel> {
        self.noise.as_ref()
    }

    /// The raw frame's mean signal over its noise ([`NoiseModel::mean_snr`]) when the design
    /// has the camera's noise model and the calibration a dark frame; None otherwise.
    pub fn frame_snr(&self, raw: &Cube) -> Result<Option<f64>> {
        match (&self.camera, &self.calibration.dark_flat) {
            (Some(nm), Some(df)) => nm.mean_snr(raw, &df.dark).map(Some),
            _ => Ok(None),
        }
    }

    /// What to say before trusting a reconstruction of a frame whose [`Reconstructor::frame_snr`]
    /// is `mean_snr`: an oracle calibration's label, the calibration's carriers that do not stand
    /// out of their captures' noise, and a frame whose mean signal is under its noise.
    pub fn warnings(&self, mean_snr: Option<f64>) -> Vec<String> {
        let dim = mean_snr.and_then(crate::noise::snr_warning);
        self.calibration.notes().chain(dim).collect()
    }

    /// The whole chain on one frame: linearise, demultiplex, de-alias (on what each pattern
    /// saw, z; `z_truth` gives GAP's per-iteration PSNR), undo the crosstalk, unmix.
    pub fn run(&self, frame: &Cube, z_truth: Option<&Cube>) -> Result<Reconstruction> {
        let t = Instant::now();
        let measured = self.calibration.linearise(frame)?;
        let zhat = self.demux.run(&measured)?;
        let xhat = self.to_channels(&zhat)?;
        let t1 = t.elapsed().as_secs_f64();
        if let Some(j) = &self.joint {
            let omega = match &self.noise {
                Some(nm) => Some(
                    nm.weights(frame, &measured, self.calibration.dark_flat.as_ref())
                        .map_err(|e| e.within(j.file(), "reconstruct.joint.noise_weights", true))?,
                ),
                None => None,
            };
            let seed = self.unconstrained_alpha(&xhat)?;
            let (alpha, mut stats) = j.run(&measured, &seed, omega.as_ref())?;
            let t2 = t.elapsed().as_secs_f64();
            let (cube, violation) = j.cube(&alpha, self.gains.as_deref())?;
            stats.violation = violation;
            let xgap = j.channels(&alpha)?;
            let t3 = t.elapsed().as_secs_f64();
            return Ok(Reconstruction {
                xhat,
                xgap,
                cube,
                gap: GapStats::default(),
                joint: Some(stats),
                unmix: UnmixStats::default(),
                seconds: [t1, t2 - t1, t3 - t2],
            });
        }
        let (xgap, gap) = match &self.gap {
            Some(g) => {
                let (z, stats) = g.run(&measured, &zhat, z_truth)?;
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
            joint: None,
            unmix,
            seconds: [t1, t2 - t1, t3 - t2],
        })
    }

    /// The calibrated carriers with amplitudes in the units of z (as this demultiplexer uses
    /// them), for a demultiplexer of another crop.
    pub fn demux_carriers(&self) -> Vec<MeasuredCarrier> {
        in_exposed_units(&self.calibration.carriers, &self.exposed_white)
    }

    /// x̂: the frame linearised, demultiplexed and mixed back to channels (the real-time path's
    /// first half, without de-aliasing).
    pub fn demultiplex(&self, frame: &Cube) -> Result<Cube> {
        let mut out = Cube::zeros(frame.width, frame.height, self.demux.windows.len());
        self.demultiplex_into(frame, &mut out)?;
        Ok(out)
    }

    /// [`Reconstructor::demultiplex`] into a cube of the right size that the caller keeps from
    /// frame to frame (every value overwritten): the real-time loop's first half.
    pub fn demultiplex_into(&self, frame: &Cube, out: &mut Cube) -> Result<()> {
        let measured = self.calibration.linearise(frame)?;
        self.demux.run_into(&measured, out)?;
        match &self.demix {
            Some(m) => out.mix_in_place(m),
            None => Ok(()),
        }
    }

    /// α = H⁻¹Fᵀx per pixel: the unmixing without its constraint (the joint method's seed).
    pub fn unconstrained_alpha(&self, x: &Cube) -> Result<Cube> {
        let m = self.unmixer.tables().unconstrained;
        let c = self.unmixer.channels();
        x.mix(&m.chunks_exact(c).map(|r| r.to_vec()).collect::<Vec<_>>())
    }

    /// x = M·z per pixel (M = (Wᵀ)⁻¹); z unchanged without a correction.
    pub fn to_channels(&self, z: &Cube) -> Result<Cube> {
        match &self.demix {
            Some(m) => z.mix(m),
            None => Ok(z.clone()),
        }
    }

    /// r̂ = B α per pixel, non-negative (times the light gains L̃ for a lit radiance scene).
    pub fn unmix(&self, xhat: &Cube) -> Result<(Cube, UnmixStats)> {
        self.unmixer.unmix(xhat)
    }
}

/// `[reconstruct] auto_table`'s rows and how the reason names them ("the bench report PATH");
/// None without the key.
fn measured_table<'a>(
    cfg: &'a ReconConfig,
    file: &str,
) -> Result<Option<(String, &'a [auto::Entry])>> {
    match (&cfg.auto_table, &cfg.measured_table) {
        (None, _) => Ok(None),
        (Some(path), Some(entries)) => Ok(Some((format!("the bench report {path}"), entries))),
        (Some(path), None) => Err(Error::config(
            file,
            "reconstruct.auto_table",
            path,
            "was not read (the experiment loader reads it; set measured_table when building the settings by hand)",
        )),
    }
}

/// Condition number of F above which the filters are taken not to separate the basis: beyond
/// it the smoothness prior alone decides the spectrum (real filter sets are 1e1–1e4).
pub const MAX_SYSTEM_CONDITION: f64 = 1e8;

/// The per-pixel unmixer of a design: F, B, η per nm⁴ and the output gains of a lit radiance scene.
pub fn unmixer(cfg: &ReconConfig, design: &Design) -> Result<Unmixer> {
    let sv = design.system.clone().svd(false, false).singular_values;
    let cond = sv.max() / sv.min();
    if cond.is_nan() || cond > MAX_SYSTEM_CONDITION {
        return Err(Error::Numerical(format!(
            "the filters do not separate the {} basis vectors: the system matrix F has condition \
             number {cond:.2e} > {MAX_SYSTEM_CONDITION:.0e} (two filters alike, or fewer distinct filters than reconstruct.basis)",
            design.system.ncols()
        )));
    }
    let unmixer = Unmixer::new(&design.system, &design.basis, band_eta(cfg, design))?;
    match &design.output_gains {
        Some(g) => unmixer.with_output_gains(g),
        None => Ok(unmixer),
    }
}

/// The paper's penalty is η‖∂²r/∂λ²‖² with λ in nm: the discrete D₂ divided by Δλ², so the
/// weight per band index is η/Δλ⁴.
fn band_eta(cfg: &ReconConfig, design: &Design) -> f64 {
    cfg.eta / design.band_step_nm.powi(4)
}

/// The joint method's spectral prior and its name: the paper's curvature penalty (η) or the
/// basis's trained Gaussian prior (the design's; refused naming the key when the design has
/// none). Unset: the trained one where the design has it, else the curvature.
fn joint_prior(
    cfg: &ReconConfig,
    design: &Design,
    file: &str,
) -> Result<(DMatrix<f64>, SpectralPrior)> {
    let trained_if_any = match design.spectral_prior {
        Some(_) => SpectralPrior::Trained,
        None => SpectralPrior::Curvature,
    };
    let used = cfg.joint.spectral_prior.unwrap_or(trained_if_any);
    let prior = match used {
        SpectralPrior::Curvature => Ok(curvature(&design.basis, band_eta(cfg, design))),
        SpectralPrior::Trained => design.spectral_prior.clone().ok_or_else(|| {
            Error::config(
                file,
                "reconstruct.joint.spectral_prior",
                "\"trained\"",
                "needs the design's trained prior, and a basis coefficient never varies over the training spectra (use \"curvature\")",
            )
        }),
    }?;
    Ok((prior, used))
}

/// The noise model the joint method uses: the design's when `noise_weights` is on; the
/// discrepancy rule without one is refused (there is no noise level for the residual to match).
fn joint_noise(
    cfg: &JointConfig,
    noise: Option<NoiseModel>,
    file: &str,
) -> Result<Option<NoiseModel>> {
    let used = noise.filter(|_| cfg.noise_weights);
    if let Some(nm) = &used {
        nm.validate(file)?;
    }
    if cfg.weight_rule == WeightRule::Discrepancy && used.is_none() {
        let why = match noise {
            None => "needs the camera's noise model ([rig.sensor] in the twin): without it there is no noise level for the residual to match",
            Some(_) => "needs noise_weights = true (the residual is matched in units of the noise)",
        };
        return Err(Error::config(
            file,
            "reconstruct.joint.weight_rule",
            "\"discrepancy\"",
            why,
        ));
    }
    Ok(used)
}

/// The white target gives z_k(white)·s̃_k: divided by the design's z_k(white), the carriers
/// come out in the units of the exposed channels z_k.
fn in_exposed_units(measured: &[MeasuredCarrier], exposed_white: &[f64]) -> Vec<MeasuredCarrier> {
    measured
        .iter()
        .zip(exposed_white)
        .map(|(m, zw)| m.scaled(1.0 / zw))
        .collect()
}

/// The demixing matrix M (None without weights) and the white level z(white) of each pattern.
type Demixing = (Option<Vec<Vec<f64>>>, Vec<f64>);

/// M = (Wᵀ)⁻¹ (None without weights) and z(white) = Wᵀ white (= white without weights).
fn demixing(white: &[f64], weights: Option<&Vec<Vec<f64>>>) -> Result<Demixing> {
    let n = white.len();
    let Some(w) = weights else {
        return Ok((None, white.to_vec()));
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
    if let Some(k) = zw.iter().position(|v| v.is_nan() || *v <= 0.0) {
        return Err(Error::Numerical(format!(
            "pattern {k} sees no white light through the exposure weights (Σ_i w_ik·white_i = {})",
            zw[k]
        )));
    }
    Ok((Some(m), zw))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A design with a 31-band basis of two columns and the given trained prior.
    fn two_vector_design(prior: Option<DMatrix<f64>>) -> Design {
        Design {
            width: 8,
            height: 8,
            carriers: Vec::new(),
            system: DMatrix::identity(2, 2),
            basis: DMatrix::from_fn(31, 2, |b, j| if j == 0 { 1.0 } else { b as f64 / 30.0 }),
            output_gains: None,
            band_step_nm: 10.0,
            white: vec![1.0, 1.0],
            exposure_weights: None,
            noise: None,
            spectral_prior: prior,
        }
    }

    /// The joint method's prior: the curvature at η/Δλ⁴ (zero for a basis linear in the band,
    /// which has no curvature), the design's trained prior as given, and without one a refusal
    /// naming the file, the key and the value.
    #[test]
    fn the_joint_prior_is_the_curvature_or_the_designs_trained_one() {
        let mut cfg = ReconConfig::default();
        let p = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![0.5, 4.0]));
        let design = two_vector_design(Some(p.clone()));
        let untrained = two_vector_design(None);
        // Unset: the trained prior where the design has one, else the curvature.
        let trained = (p.clone(), SpectralPrior::Trained);
        assert_eq!(joint_prior(&cfg, &design, "rig.toml").unwrap(), trained);
        let curv = curvature(&design.basis, cfg.eta / 1e4);
        let by_default = joint_prior(&cfg, &untrained, "rig.toml").unwrap();
        assert_eq!(by_default, (curv.clone(), SpectralPrior::Curvature));
        cfg.joint.spectral_prior = Some(SpectralPrior::Curvature);
        assert_eq!(joint_prior(&cfg, &design, "rig.toml").unwrap().0, curv);
        assert!(
            curv.amax() < 1e-12,
            "a linear basis has no curvature: {curv}"
        );
        cfg.joint.spectral_prior = Some(SpectralPrior::Trained);
        assert_eq!(joint_prior(&cfg, &design, "rig.toml").unwrap(), trained);
        let e = joint_prior(&cfg, &untrained, "rig.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("rig.toml")
                && e.contains("reconstruct.joint.spectral_prior")
                && e.contains("\"trained\""),
            "{e}"
        );
    }

    /// The discrepancy rule needs a noise model with its weights on; the errors name the file,
    /// the key and the reason.
    #[test]
    fn the_discrepancy_rule_without_a_noise_model_is_refused() {
        let cfg = JointConfig {
            weight_rule: WeightRule::Discrepancy,
            noise_weights: true,
            ..Default::default()
        };
        let e = joint_noise(&cfg, None, "rig.toml").unwrap_err().to_string();
        assert!(
            e.contains("rig.toml")
                && e.contains("reconstruct.joint.weight_rule")
                && e.contains("[rig.sensor]"),
            "{e}"
        );
        let nm = NoiseModel {
            gain_dn_per_e: 0.25,
            dark_noise_dn: 0.8,
            saturation_dn: None,
        };
        assert_eq!(joint_noise(&cfg, Some(nm), "rig.toml").unwrap(), Some(nm));
        let off = JointConfig {
            noise_weights: false,
            ..cfg
        };
        let e = joint_noise(&off, Some(nm), "rig.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("noise_weights = true"), "{e}");
        let fixed = JointConfig {
            noise_weights: false,
            ..Default::default()
        };
        assert_eq!(joint_noise(&fixed, Some(nm), "rig.toml").unwrap(), None);
    }
}
