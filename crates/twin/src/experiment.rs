//! The experiment file (TOML): a scene, a rig, the calibration captures and the reconstruction
//! settings. Each section is the configuration type of the module it configures; this file only
//! composes them. A section that is absent is a stage that is left out; a key that is absent
//! takes the 2019 prototype's value.

use crate::captures::CaptureConfig;
use crate::device::OpenDevice;
use crate::optics::alignment::AlignmentConfig;
use crate::optics::dmd::DmdConfig;
use crate::optics::fourier_filter::FourierFilterConfig;
use crate::optics::imaging::OpticsConfig;
use crate::optics::psf::LensConfig;
use crate::optics::wheel::WheelConfig;
use crate::scene::{self, SceneConfig};
use crate::sensor::{CameraConfig, SensorConfig};
use crate::timing::TimingConfig;
use serde::{Deserialize, Serialize};
use specmux_core::carriers::{self, Carrier, CarrierConfig};
use specmux_core::gap::Method;
use specmux_core::reconstructor::{ComputeDevice, ReconConfig};
use specmux_core::spectral::{Curve, Library};
use specmux_core::{Error, Result};
use specmux_io::toml_file::read_toml;
use std::path::Path;

/// A whole experiment.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Experiment {
    pub scene: SceneConfig,
    pub rig: RigConfig,
    pub calibration: CaptureConfig,
    pub reconstruct: ReconConfig,
    /// Where the reconstruction runs (`[compute]`).
    pub compute: ComputeConfig,
    /// The file it came from (for messages and relative paths); not part of the TOML.
    #[serde(skip)]
    pub file: String,
    /// The keys the file wrote, to tell a value the user set from a default (`wrote`).
    #[serde(skip)]
    pub written: toml::Table,
}

/// The keys whose value `[reconstruct.gap] method = "auto"` chooses.
const AUTO_CHOSEN: [&str; 2] = ["reconstruct.gap.iterations", "reconstruct.joint.iterations"];

/// `[compute]`: the device the reconstruction runs on ("cpu", the default; "gpu"; "auto").
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ComputeConfig {
    pub device: ComputeDevice,
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
    /// The DMD's image on the sensor as built (absent: exactly as designed).
    pub alignment: Option<AlignmentConfig>,
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

impl Experiment {
    /// Open `[compute] device` ([`OpenDevice::open`]); a failure names the file, the key and
    /// its value.
    pub fn open_device(&self) -> Result<OpenDevice> {
        OpenDevice::open(self.compute.device).map_err(|e| self.on_device(e))
    }

    /// `e`, a failure of the device `[compute] device` names, naming the file, the key and its
    /// value.
    pub fn on_device(&self, e: Error) -> Error {
        let device = format!("{:?}", self.compute.device).to_lowercase();
        e.in_file(&self.file)
            .within(&self.file, "compute.device", device)
    }

    /// Parse an experiment from TOML text; errors carry `file` and the line of the fault.
    pub fn from_toml(text: &str, file: &str) -> Result<Experiment> {
        Experiment::from_text(text, file, true)
    }

    /// An experiment from a document built in code (a sweep's point, a Python dict), read as
    /// the same file would be; a parse error names `file` alone, since the user never saw the
    /// generated text whose line it would give.
    pub fn from_table(doc: &toml::Table, file: &str) -> Result<Experiment> {
        let text = toml::to_string(doc).map_err(|e| Error::Toml {
            file: file.to_string(),
            msg: e.to_string(),
        })?;
        Experiment::from_text(&text, file, false)
    }

    /// [`Experiment::from_toml`], a parse error's line given when `lines`.
    fn from_text(text: &str, file: &str, lines: bool) -> Result<Experiment> {
        let mut e: Experiment = read_toml(text, file, lines)?;
        e.file = file.to_string();
        e.written = text.parse().unwrap_or_default();
        if e.scene.source.starts_with("exr:") {
            let wrote = |k: &str| e.wrote(k);
            let adopted = scene::exr_geometry(&e.scene, file, wrote)?;
            e.scene = adopted;
        }
        e.validate()?;
        if let Some(rel) = e.reconstruct.auto_table.clone() {
            let path = e.scene.path(&rel, &e.file);
            let entries = crate::auto_table::load(&path, &rel, &e.file)?;
            e.reconstruct.measured_table = Some(entries);
        }
        Ok(e)
    }

    /// True when the experiment file wrote `key` (dotted: `scene.size`, `reconstruct.gap.levels`).
    pub fn wrote(&self, key: &str) -> bool {
        let mut table = &self.written;
        let mut parts = key.split('.').peekable();
        while let Some(p) = parts.next() {
            match (table.get(p), parts.peek()) {
                (Some(_), None) => return true,
                (Some(toml::Value::Table(t)), Some(_)) => table = t,
                _ => return false,
            }
        }
        false
    }

    /// A curve the experiment names: a library name (`wheel/red`), or a CSV file of one's own
    /// when the name ends in `.csv`, relative to the experiment file's folder.
    pub fn curve(&self, lib: &Library, name: &str) -> Result<Curve> {
        if !name.ends_with(".csv") {
            return lib.curve(name);
        }
        let path = self.scene.path(name, &self.file);
        specmux_core::spectral::library::curve_file(&path, name)
    }

    /// The experiment as a TOML table that reads back to the same experiment (what a sweep
    /// edits and the design tools write): with `method = "auto"`, the iteration counts that
    /// auto chooses are left out unless the file wrote them.
    pub fn to_table(&self) -> Result<toml::Table> {
        let mut doc = toml::Table::try_from(self).map_err(|e| Error::Toml {
            file: self.file.clone(),
            msg: e.to_string(),
        })?;
        if self.reconstruct.gap.method == Method::Auto {
            for key in AUTO_CHOSEN.iter().filter(|k| !self.wrote(k)) {
                let (section, name) = key.rsplit_once('.').expect("a dotted key");
                let mut t = Some(&mut doc);
                for p in section.split('.') {
                    t = t.and_then(|t| t.get_mut(p)).and_then(|v| v.as_table_mut());
                }
                if let Some(t) = t {
                    t.remove(name);
                }
            }
        }
        Ok(doc)
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

    /// How many carriers the rig has: `rig.carriers.frequencies`, else the default layout's 6.
    pub fn carrier_count(&self) -> usize {
        (self.rig.carriers.frequencies.as_ref()).map_or(carriers::default_layout().len(), Vec::len)
    }

    /// The design carriers on the frame's FFT bin grid, and a note per default carrier snapped.
    pub fn carriers(&self) -> Result<(Vec<Carrier>, Vec<String>)> {
        let [w, h] = self.scene.size;
        self.rig.carriers.on_grid(w, h, &self.file)
    }

    /// Check every value's range; the error names the key and the value.
    pub fn validate(&self) -> Result<()> {
        let f = self.file.as_str();
        scene::validate(&self.scene, f)?;
        let n = self.rig.wheel.filters.len();
        if n == 0 || n > 16 {
            return Err(Error::config(
                f,
                "rig.wheel.filters",
                n,
                "needs 1 to 16 filters",
            ));
        }
        self.validate_carrier_count(n)?;
        self.reconstruct.validate(f, n)?;
        self.validate_auto_keys()?;
        self.calibration.validate(f)?;
        self.validate_rig(n)?;
        let [w, h] = self.scene.size;
        let crop = self.reconstruct.crop;
        // As written (band, overlap), then as placed on the bin grid.
        carriers::check_layout(&self.rig.carriers.carriers(), crop, w, h, f)?;
        let (design, _) = self.carriers()?;
        carriers::check_layout(&design, crop, w, h, f)
    }

    /// `method = "auto"` (the default) chooses the iteration count itself, so an iteration
    /// count written beside it would be silently overridden: refused, naming the method to set.
    fn validate_auto_keys(&self) -> Result<()> {
        if self.reconstruct.gap.method != Method::Auto {
            return Ok(());
        }
        let (gap, joint) = (&self.reconstruct.gap, &self.reconstruct.joint);
        for (key, value, methods) in [
            (AUTO_CHOSEN[0], gap.iterations, "\"gap\" or \"gap-tv\""),
            (AUTO_CHOSEN[1], joint.iterations, "\"joint\""),
        ] {
            if self.wrote(key) {
                return Err(Error::config(
                    &self.file,
                    key,
                    value,
                    &format!(
                        "is chosen by reconstruct.gap.method = \"auto\" (the default); set the method to {methods} to fix it"
                    ),
                ));
            }
        }
        Ok(())
    }

    fn validate_carrier_count(&self, n: usize) -> Result<()> {
        let f = self.file.as_str();
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
        Ok(())
    }

    fn validate_rig(&self, n: usize) -> Result<()> {
        let f = self.file.as_str();
        if let Some(a) = &self.rig.alignment {
            a.validate(f)?;
        }
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
        Ok(())
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
        assert_eq!(e.carriers().unwrap().0.len(), 6);
    }

    #[test]
    fn unknown_keys_and_bad_values_name_the_key() {
        let e =
            Experiment::from_toml("[reconstruct]\ncrop = 0.25\netaa = 3\n", "t.toml").unwrap_err();
        let s = e.to_string();
        assert!(s.contains("t.toml:3") && s.contains("etaa"), "{s}");
        let e = Experiment::from_toml("[compute]\ndevice = \"tpu\"\n", "t.toml").unwrap_err();
        assert!(e.to_string().contains("tpu"), "{e}");
        let e = Experiment::from_toml("[compute]\ndevice = \"auto\"\n", "t.toml").unwrap();
        assert_eq!(e.compute.device, ComputeDevice::Auto);
        let e = Experiment::from_toml("[reconstruct]\neta = -1\n", "t.toml").unwrap_err();
        assert!(e.to_string().contains("reconstruct.eta"), "{e}");
        let e = Experiment::from_toml("[scene]\nwavelengths_nm = [400, 700, -10]\n", "t.toml")
            .unwrap_err();
        assert!(e.to_string().contains("scene.wavelengths_nm[2]"), "{e}");
        let e = Experiment::from_toml("[reconstruct]\ncrop = 0.3\n", "t.toml").unwrap_err();
        assert!(e.to_string().contains("overlap"), "{e}");
    }

    /// A value serde cannot read is named by its file and line, its key path and what was
    /// written; a document built in code (a sweep, a Python dict) by its name, key and value.
    #[test]
    fn unreadable_values_name_the_line_the_key_and_the_value() {
        let err = |text: &str| {
            Experiment::from_toml(text, "t.toml")
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            err("[scene]\nseed = 1\nsize = [64]\n"),
            "t.toml:3: `scene.size` = [64]: invalid length 1, expected an array of length 2"
        );
        let e = err("[rig.wheel]\nfilters = [\"wheel/red\", 7]\n");
        assert!(
            e.starts_with("t.toml:2: `rig.wheel.filters[1]` = 7: invalid type"),
            "{e}"
        );
        let e = err("[scne]\nsize = 3\n");
        assert!(
            e.starts_with("t.toml:1: `scne` = { size = 3 }: unknown field"),
            "{e}"
        );
        // Not TOML at all: the file, the line and the parser's words.
        assert!(err("[scene\n").starts_with("t.toml:1: "));
        let doc: toml::Table = "[scene]\nseed = -1\n".parse().unwrap();
        let e = Experiment::from_table(&doc, "<dict>")
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("<dict>: `scene.seed` = -1: invalid value"),
            "{e}"
        );
    }

    #[test]
    fn carriers_off_the_bin_grid_are_refused_or_snapped() {
        // 0.2 cycles/px on 256 pixels is bin 51.2: the user's value is refused, the nearest named.
        let e = Experiment::from_toml(
            "[scene]\nsize = [256, 256]\n[reconstruct]\ncrop = 0.2\n[rig.carriers]\nfrequencies = [[0.2, 0], [0, 0.2], [0.2, 0.2], [-0.2, 0.2], [0.4, 0.2], [0.2, 0.4]]\n",
            "t.toml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("rig.carriers.frequencies[0]")
                && e.contains("0.19921875")
                && e.contains("51/256"),
            "{e}"
        );
        // The default layout on a 257-pixel frame: 0.25 is bin 64.25, snapped and reported.
        let exp = Experiment::from_toml("[scene]\nsize = [257, 257]\n", "t.toml").unwrap();
        let (c, notes) = exp.carriers().unwrap();
        assert!(c
            .iter()
            .all(|c| (c.fx * 257.0 - (c.fx * 257.0).round()).abs() < 1e-9
                && (c.fy * 257.0 - (c.fy * 257.0).round()).abs() < 1e-9));
        assert!(
            !notes.is_empty() && notes[0].contains("snapped"),
            "{notes:?}"
        );
        // On the grid nothing moves and nothing is said.
        let exp = Experiment::from_toml("[scene]\nsize = [256, 256]\n", "t.toml").unwrap();
        assert!(exp.carriers().unwrap().1.is_empty());
    }
}
