//! The experiment file (TOML): a scene, a rig and reconstruction settings. A section that is
//! absent is a stage that is left out; a key that is absent takes the 2019 prototype's value.

use crate::error::{Error, Result};
use crate::optics::carriers::{self, Carrier};
use crate::optics::dmd::DmdConfig;
use crate::optics::fourier_filter::FourierFilterConfig;
use crate::optics::imaging::OpticsConfig;
use crate::optics::psf::LensConfig;
use crate::sensor::SensorConfig;
use crate::timing::TimingConfig;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A whole experiment.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Experiment {
    pub scene: SceneConfig,
    pub rig: RigConfig,
    pub reconstruct: ReconstructConfig,
    /// The file it came from (for messages and relative paths); not part of the TOML.
    #[serde(skip)]
    pub file: String,
}

/// What is imaged.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneConfig {
    /// `dead-leaves`, `shaded-objects`, `exr:<path>` (a reflectance or radiance cube), or
    /// `mitsuba:<prefix>` (a Mitsuba render `<prefix>_truth.exr`, radiance; scene/mitsuba.rs).
    pub source: String,
    /// Width and height in pixels (procedural scenes; the prototype's 768 × 768).
    pub size: [usize; 2],
    /// Illuminant curve under spectra/ for a reflectance scene; for a radiance scene the light
    /// that lit it (the basis is lit by it, rig.rs), `""` for none.
    pub illuminant: String,
    /// `reflectance` (lit by `illuminant`) or `radiance` (used as it is).
    pub quantity: Quantity,
    /// Seed of the scene's random draws.
    pub seed: u64,
    /// Band grid: first and last band centre and the step, in nm (the CAVE grid 400–700/10).
    pub wavelengths_nm: [f64; 3],
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Quantity {
    Reflectance,
    Radiance,
}

impl Default for SceneConfig {
    fn default() -> Self {
        SceneConfig {
            source: "dead-leaves".into(),
            size: [768, 768],
            illuminant: "illuminants/D65".into(),
            quantity: Quantity::Reflectance,
            seed: 7,
            wavelengths_nm: [400.0, 700.0, 10.0],
        }
    }
}

/// The rig, one field per module of the light path. An absent optional section is a stage that
/// is not simulated: no `dmd`, `fourier_filter` or `lens` gives ideal grey sinusoids, no `timing`
/// equal exposure weights, no `sensor` a noiseless, unquantised frame.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigConfig {
    pub wheel: WheelConfig,
    pub camera: CameraConfig,
    pub carriers: CarrierConfig,
    pub dmd: Option<DmdConfig>,
    pub fourier_filter: Option<FourierFilterConfig>,
    pub lens: Option<LensConfig>,
    pub timing: Option<TimingConfig>,
    pub sensor: Option<SensorConfig>,
}

impl RigConfig {
    /// The optical stages between the carriers and the sensor.
    pub fn optics(&self) -> OpticsConfig {
        OpticsConfig {
            dmd: self.dmd.clone(),
            fourier_filter: self.fourier_filter.clone(),
            lens: self.lens.clone(),
        }
    }

    /// True when any optical stage is asked for (the patterns are then simulated, not ideal).
    pub fn has_optics(&self) -> bool {
        self.dmd.is_some() || self.fourier_filter.is_some() || self.lens.is_some()
    }
}

/// The colour wheel's segments, as curve names under spectra/.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WheelConfig {
    pub filters: Vec<String>,
}

impl Default for WheelConfig {
    fn default() -> Self {
        // Section 4 of the paper: three dichroic R/G/B segments and three broadband colour papers.
        WheelConfig {
            filters: [
                "wheel/red",
                "wheel/green",
                "wheel/blue",
                "paper/a",
                "paper/b",
                "paper/c",
            ]
            .map(String::from)
            .to_vec(),
        }
    }
}

/// The monochrome camera's spectral response.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    pub qe: String,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            qe: "camera/mono_qe".into(),
        }
    }
}

/// Carrier frequencies (cycles/pixel, [fx, fy]) and phases; absent = the default 4×4-grid layout.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CarrierConfig {
    pub frequencies: Option<Vec<[f64; 2]>>,
    pub phases_deg: Option<Vec<f64>>,
}

/// Window shape for the Fourier crop: how the bins of the crop·N box around a carrier are weighed
/// before the inverse FFT (src/recon/demux.rs, docs/results.md). Every shape stays inside the box,
/// so the layout check holds for all of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WindowShape {
    /// Every bin of the box at weight 1 (the paper's crop).
    Square,
    /// The disc (ellipse for a non-square frame) inscribed in the box: diameter crop·N bins per axis.
    Circular,
    /// A flat-topped taper: per axis exp(−|d/r0|^(2p)), r0 = the box's half-extent to the outer edge
    /// of its outermost bin, p = `demux::SUPER_GAUSSIAN_ORDER` (4); tends to `Square` as p → ∞.
    SuperGaussian,
}

/// Reconstruction settings.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReconstructConfig {
    /// Crop window size as a fraction of the width and height (the paper's 0.25).
    pub crop: f64,
    pub window: WindowShape,
    /// Weight of the spectral smoothness term ‖D₂Bα‖² (the paper's η = 200).
    pub eta: f64,
    /// Number of basis vectors J (the paper's 6).
    pub basis: usize,
    /// GAP de-aliasing of the Fourier estimates (`[reconstruct.gap]`; docs/gap.md).
    pub gap: crate::recon::gap::GapConfig,
    /// Undo the exposure crosstalk between channels before unmixing (x = (Wᵀ)⁻¹ z per pixel):
    /// `timing` uses the weights of `[rig.timing]` (nothing to undo without it), `none` leaves
    /// the demultiplexed carriers as they are.
    pub crosstalk: CrosstalkCorrection,
    /// Measured weights w_ik (filter i, pattern k) from a calibration; they replace the timing
    /// model's when given.
    pub crosstalk_weights: Option<Vec<Vec<f64>>>,
    /// Frames averaged for the dark and the flat calibration frames when `[rig.sensor]` is set.
    pub calibration_frames: usize,
}

/// Where the reconstruction takes the exposure weights w_ik from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CrosstalkCorrection {
    Timing,
    None,
}

impl Default for ReconstructConfig {
    fn default() -> Self {
        ReconstructConfig {
            crop: 0.25,
            window: WindowShape::Square,
            eta: 200.0,
            basis: 6,
            gap: Default::default(),
            crosstalk: CrosstalkCorrection::Timing,
            crosstalk_weights: None,
            calibration_frames: 16,
        }
    }
}

impl Experiment {
    /// Parse an experiment from TOML text; errors carry `file` and the line of the fault.
    pub fn from_toml(text: &str, file: &str) -> Result<Experiment> {
        let mut e: Experiment = toml::from_str(text).map_err(|err| {
            let line = err
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1)
                .unwrap_or(0);
            Error::Toml {
                file: format!("{file}:{line}"),
                msg: err.message().replace('\n', " "),
            }
        })?;
        e.file = file.to_string();
        e.validate()?;
        Ok(e)
    }

    /// Read an experiment file.
    pub fn load(path: &Path) -> Result<Experiment> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Experiment::from_toml(&text, &path.display().to_string())
    }

    /// The built-in default experiment (the prototype on the dead-leaves scene).
    pub fn prototype() -> Experiment {
        Experiment {
            file: "<built-in prototype>".into(),
            ..Default::default()
        }
    }

    /// The carriers the rig uses.
    pub fn carriers(&self) -> Vec<Carrier> {
        let mut c = match &self.rig.carriers.frequencies {
            None => carriers::default_layout(),
            Some(f) => f
                .iter()
                .map(|&[fx, fy]| Carrier {
                    fx,
                    fy,
                    phase_rad: 0.0,
                })
                .collect(),
        };
        if let Some(p) = &self.rig.carriers.phases_deg {
            for (c, p) in c.iter_mut().zip(p) {
                c.phase_rad = p.to_radians();
            }
        }
        c
    }

    /// Path of an `exr:` scene source, relative to the experiment file's folder.
    pub fn scene_path(&self, rel: &str) -> PathBuf {
        let p = Path::new(rel);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        Path::new(&self.file)
            .parent()
            .map(|d| d.join(p))
            .unwrap_or_else(|| p.to_path_buf())
    }

    /// Check every value's range; the error names the key and the value.
    pub fn validate(&self) -> Result<()> {
        let f = self.file.as_str();
        let s = &self.scene;
        let known = ["dead-leaves", "shaded-objects"];
        let prefixed = ["exr:", super::mitsuba::PREFIX].map(|p| s.source.starts_with(p));
        if !known.contains(&s.source.as_str()) && !prefixed.contains(&true) {
            return Err(Error::config(
                f,
                "scene.source",
                format!("\"{}\"", s.source),
                "expected \"dead-leaves\", \"shaded-objects\", \"exr:<path>\" or \"mitsuba:<prefix>\"",
            ));
        }
        super::mitsuba::check(s, f)?;
        for (k, &n) in s.size.iter().enumerate() {
            if !(16..=8192).contains(&n) {
                return Err(Error::config(
                    f,
                    &format!("scene.size[{k}]"),
                    n,
                    "must be 16 to 8192 pixels",
                ));
            }
        }
        let [lo, hi, step] = s.wavelengths_nm;
        if !(step.is_finite() && step > 0.0) {
            return Err(Error::config(
                f,
                "scene.wavelengths_nm[2]",
                step,
                "the step must be positive",
            ));
        }
        if !(lo.is_finite() && lo > 0.0 && hi.is_finite() && hi > lo) {
            return Err(Error::config(
                f,
                "scene.wavelengths_nm",
                format!("[{lo}, {hi}, {step}]"),
                "needs 0 < first < last",
            ));
        }
        let n = self.rig.wheel.filters.len();
        if n == 0 || n > 16 {
            return Err(Error::config(
                f,
                "rig.wheel.filters",
                n,
                "needs 1 to 16 filters",
            ));
        }
        if let Some(fr) = &self.rig.carriers.frequencies {
            if fr.len() != n {
                return Err(Error::config(
                    f,
                    "rig.carriers.frequencies",
                    format!("{} carriers", fr.len()),
                    &format!("needs one carrier per wheel filter ({n})"),
                ));
            }
        } else if n != carriers::default_layout().len() {
            return Err(Error::config(
                f,
                "rig.wheel.filters",
                format!("{n} filters"),
                "the default carrier layout has 6 carriers; give rig.carriers.frequencies",
            ));
        }
        if let Some(p) = &self.rig.carriers.phases_deg {
            if p.len() != n || p.iter().any(|v| !v.is_finite()) {
                return Err(Error::config(
                    f,
                    "rig.carriers.phases_deg",
                    format!("{p:?}"),
                    "needs one finite phase per carrier",
                ));
            }
        }
        let r = &self.reconstruct;
        if !(r.crop > 0.0 && r.crop <= 0.5) {
            return Err(Error::config(
                f,
                "reconstruct.crop",
                r.crop,
                "must be in (0, 0.5]",
            ));
        }
        if !(r.eta.is_finite() && r.eta >= 0.0) {
            return Err(Error::config(
                f,
                "reconstruct.eta",
                r.eta,
                "must be finite and ≥ 0",
            ));
        }
        if r.basis == 0 || r.basis > n {
            return Err(Error::config(
                f,
                "reconstruct.basis",
                r.basis,
                &format!("must be 1 to the number of filters ({n})"),
            ));
        }
        r.gap.validate(f)?;
        self.rig.optics().validate(f)?;
        if let Some(t) = &self.rig.timing {
            t.validate(f)?;
            if t.segment_count() != n {
                return Err(Error::config(
                    f,
                    "rig.timing.wheel.segments_deg",
                    format!("{} segments", t.segment_count()),
                    &format!("needs one segment per wheel filter ({n})"),
                ));
            }
        }
        if let Some(s) = &self.rig.sensor {
            s.validate(f)?;
            if let Some(t) = &self.rig.timing {
                if (s.exposure_s - t.camera.exposure_s).abs() > 1e-12 * t.camera.exposure_s {
                    return Err(Error::config(
                        f,
                        "rig.sensor.exposure_s",
                        s.exposure_s,
                        &format!(
                            "differs from rig.timing.camera.exposure_s = {}: one camera, one exposure",
                            t.camera.exposure_s
                        ),
                    ));
                }
            }
        }
        if let Some(w) = &r.crosstalk_weights {
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
        if !(1..=1024).contains(&r.calibration_frames) {
            return Err(Error::config(
                f,
                "reconstruct.calibration_frames",
                r.calibration_frames,
                "must be 1 to 1024 frames",
            ));
        }
        carriers::check_layout(&self.carriers(), r.crop, s.size[0], s.size[1], f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_is_the_prototype() {
        let e = Experiment::from_toml("", "t.toml").unwrap();
        assert_eq!(e.scene.size, [768, 768]);
        assert_eq!(e.reconstruct.crop, 0.25);
        assert_eq!(e.reconstruct.eta, 200.0);
        assert_eq!(e.carriers().len(), 6);
    }

    #[test]
    fn unknown_keys_and_bad_values_name_the_key() {
        let e =
            Experiment::from_toml("[reconstruct]\ncrop = 0.25\netaa = 3\n", "t.toml").unwrap_err();
        let s = e.to_string();
        assert!(s.contains("t.toml:3") && s.contains("etaa"), "{s}");
        let e = Experiment::from_toml("[reconstruct]\neta = -1\n", "t.toml").unwrap_err();
        assert!(e.to_string().contains("reconstruct.eta"), "{e}");
        let e = Experiment::from_toml("[scene]\nwavelengths_nm = [400, 700, -10]\n", "t.toml")
            .unwrap_err();
        assert!(e.to_string().contains("scene.wavelengths_nm[2]"), "{e}");
        let e = Experiment::from_toml("[reconstruct]\ncrop = 0.3\n", "t.toml").unwrap_err();
        assert!(e.to_string().contains("overlap"), "{e}");
    }
}
