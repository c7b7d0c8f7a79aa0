//! The rig as an experiment resolves it: curves loaded, the projection cube → channels and the
//! spectral basis computed. The forward model, the reconstruction and the controller share it.

use crate::budget;
use crate::experiment::Experiment;
use crate::optics::imaging::Chain;
use crate::optics::imaging::MIN_PINHOLE_BINS;
use crate::optics::light::PatternLight;
use crate::optics::wheel::ColorWheel;
use crate::optics::wheel::Projection;
use crate::scene::Materials;
use crate::scene::Quantity;
use crate::sensor::SensorConfig;
use crate::timing;
use specmux_core::carriers;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::noise::NoiseModel;
use specmux_core::reconstructor::Design;
use specmux_core::spectral::Basis;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;
use specmux_core::spectral::Library;
use specmux_core::Carrier;

/// Everything the experiment's rig resolves to: curves loaded, projection and basis computed.
#[derive(Clone, Debug)]
pub struct Rig {
    pub grid: Grid,
    pub wheel: ColorWheel,
    pub qe: Curve,
    /// The illuminant of a reflectance scene; None for a radiance scene.
    pub illuminant: Option<Curve>,
    /// The light that lit a radiance scene (`scene.illuminant`, None if ""): lights the prior.
    pub radiance_light: Option<Curve>,
    /// x = W r: cube bands → wheel channels, normalised (see `ColorWheel::projection`).
    pub projection: Projection,
    /// The carriers as designed (what the DMD is programmed with).
    pub carriers: Vec<Carrier>,
    /// The carriers as they reach the sensor (`[rig.alignment]`; the design's without it).
    pub imaged_carriers: Vec<Carrier>,
    pub basis: Basis,
    pub width: usize,
    pub height: usize,
    /// w_ik of one exposure as the programmed timing predicts (`[rig.timing]`), None without.
    pub exposure_weights: Option<Vec<Vec<f64>>>,
    /// What the operator should know about the rig as built (snapped carriers, timing).
    pub warnings: Vec<String>,
    /// The camera's noise as its photon-transfer measurement gives it; None without `[rig.sensor]`.
    pub noise: Option<NoiseModel>,
}

/// K, σ_y.dark and the saturation level of a camera, the figures an EMVA 1288 measurement
/// reports: σ_y.dark² = K²(σ_d² + μ_dark) + 1/12 DN² (read noise, dark-current shot noise at
/// the exposure, uniform quantisation).
pub fn noise_model(s: &SensorConfig) -> NoiseModel {
    let k = s.gain_dn_per_e;
    NoiseModel {
        gain_dn_per_e: k,
        dark_noise_dn: (k * k * (s.read_noise_e.powi(2) + s.dark_electrons()) + 1.0 / 12.0).sqrt(),
        saturation_dn: Some(s.saturation_dn()),
    }
}

/// Refuse a channel that sees no light on the cube's bands, naming its cause: an illuminant
/// or a QE that is zero on every band, else the filter.
fn dark_channel(
    exp: &Experiment,
    grid: &Grid,
    light: [(&str, Option<&Curve>); 2],
    wheel: &ColorWheel,
    p: &Projection,
) -> Result<()> {
    let Some(i) =
        p.w.row_iter()
            .position(|r| r.sum().is_nan() || r.sum() <= 0.0)
    else {
        return Ok(());
    };
    let span = format!("{}–{} nm", grid.start_nm, grid.end_nm());
    let zero = |c: &Curve| grid.wavelengths().iter().all(|&w| c.eval(w) <= 0.0);
    let (key, value) = match light.iter().find(|(_, c)| c.is_some_and(zero)) {
        Some((key, Some(c))) => (key.to_string(), c.name.clone()),
        _ => (
            format!("rig.wheel.filters[{i}]"),
            wheel.filters[i].name.clone(),
        ),
    };
    let why = format!("no light reaches the camera through it on {span}");
    Err(Error::config(&exp.file, &key, format!("\"{value}\""), &why))
}

impl Rig {
    /// Load the rig's curves from the library and precompute the projection and the basis.
    pub fn build(exp: &Experiment, lib: &Library, materials: &Materials) -> Result<Rig> {
        // Refuse a run that would not fit before anything is allocated.
        budget::check(exp, budget::available_memory())?;
        let grid = exp.scene.grid(&exp.file)?;
        let (carriers, mut warnings) = exp.carriers()?;
        let [w, h] = exp.scene.size;
        warnings.extend(carriers::harmonic_collisions(
            &carriers,
            exp.reconstruct.crop,
            w,
            h,
        ));
        let exposure_weights = match &exp.rig.timing {
            Some(t) => {
                let tw = timing::weights(t)?;
                if let Some(k) = (0..tw.w.len()).find(|&k| tw.w.iter().all(|row| row[k] <= 0.0)) {
                    return Err(Error::config(
                        &exp.file,
                        "rig.timing.camera.exposure_s",
                        t.camera.exposure_s,
                        &format!("pattern {k} is never shown while the camera exposes; expose whole wheel turns"),
                    ));
                }
                warnings.extend(tw.warnings);
                Some(tw.w)
            }
            None => None,
        };
        // Transmittances, QE and light are physical quantities: never negative; a transmittance
        // or a QE (`fraction`) is at most 1.
        let named = |key: &str, name: &str, fraction: bool| {
            let bad = |why: &str| Error::config(&exp.file, key, format!("\"{name}\""), why);
            let c = exp.curve(lib, name).map_err(|e| bad(&e.to_string()))?;
            let samples = || c.wavelengths().iter().zip(c.values());
            if let Some((w, v)) = samples().find(|(_, &v)| v < 0.0) {
                return Err(bad(&format!(
                    "value {v} at {w} nm is negative: a transmittance, QE or light cannot be"
                )));
            }
            match samples().find(|(_, &v)| fraction && v > 1.0) {
                Some((w, v)) => Err(bad(&format!(
                    "value {v} at {w} nm is above 1: a transmittance or QE is a fraction 0..1"
                ))),
                None => Ok(c),
            }
        };
        let filters = exp
            .rig
            .wheel
            .filters
            .iter()
            .enumerate()
            .map(|(i, n)| named(&format!("rig.wheel.filters[{i}]"), n, true))
            .collect::<Result<Vec<_>>>()?;
        let qe = named("rig.camera.qe", &exp.rig.camera.qe, true)?;
        let illuminant = match exp.scene.quantity {
            Quantity::Reflectance => Some(named("scene.illuminant", &exp.scene.illuminant, false)?),
            Quantity::Radiance => None,
        };
        let radiance_light = match exp.scene.quantity {
            Quantity::Radiance if !exp.scene.illuminant.is_empty() => {
                let l = named("scene.illuminant", &exp.scene.illuminant, false)?;
                if let Some(wl) = grid.wavelengths().into_iter().find(|&w| l.eval(w) <= 0.0) {
                    let why = format!("must be positive on every band; it is not at {wl} nm");
                    return Err(Error::config(&exp.file, "scene.illuminant", &l.name, &why));
                }
                Some(l)
            }
            _ => None,
        };
        let wheel = ColorWheel { filters };
        let projection = wheel.projection(&grid, illuminant.as_ref(), &qe)?;
        let light = [
            ("scene.illuminant", illuminant.as_ref()),
            ("rig.camera.qe", Some(&qe)),
        ];
        dark_channel(exp, &grid, light, &wheel, &projection)?;
        let basis = Basis::train(&materials.train, &grid, exp.reconstruct.basis)?;
        let mut rig = Rig {
            grid,
            wheel,
            qe,
            illuminant,
            radiance_light,
            projection,
            imaged_carriers: match &exp.rig.alignment {
                Some(a) => a.imaged(&carriers),
                None => carriers.clone(),
            },
            carriers,
            basis,
            width: exp.scene.size[0],
            height: exp.scene.size[1],
            exposure_weights,
            warnings,
            noise: exp.rig.sensor.as_ref().map(noise_model),
        };
        rig.warnings.extend(rig.periodic_relay_warning(exp)?);
        Ok(rig)
    }

    /// The warning for patterns whose relay treats the DMD as periodic ([`Chain::periodic_patterns`]).
    fn periodic_relay_warning(&self, exp: &Experiment) -> Result<Option<String>> {
        let Some(f) = exp.rig.fourier_filter.as_ref() else {
            return Ok(None);
        };
        let periodic = self
            .chain(exp)?
            .periodic_patterns()
            .map_err(|e| e.in_file(&exp.file))?;
        let Some(blur) = periodic.iter().map(|p| p.1).reduce(f64::max) else {
            return Ok(None);
        };
        let which: Vec<String> = periodic.iter().map(|p| p.0.to_string()).collect();
        Ok(Some(format!(
            "`rig.fourier_filter.pinhole_radius_um` = {}: the openings of patterns {} span at least \
             {MIN_PINHOLE_BINS} frequency bins, so their relay runs unpadded, treating the DMD as one \
             period of a periodic pattern; within their blur (up to {blur:.0} mirrors) of the DMD's \
             edges the patterns are not a finite DMD's (20–30 % RMS on the prototype at 27 µm; \
             docs/optics.md, \"Known defect\")",
            f.pinhole_radius_um,
            which.join(", ")
        )))
    }

    /// The optics chain that images this rig's patterns under the experiment's optics (errors
    /// name the experiment file).
    pub fn chain(&self, exp: &Experiment) -> Result<Chain> {
        Chain::new(
            &exp.rig.optics(),
            &self.imaged_carriers,
            &self.pattern_lights(exp)?,
            self.width,
            self.height,
        )
        .map_err(|e| e.in_file(&exp.file))
    }

    /// What the reconstruction core knows of this rig before any frame: the design.
    pub fn design(&self) -> Design {
        Design {
            width: self.width,
            height: self.height,
            carriers: self.carriers.clone(),
            system: self.system_matrix(),
            basis: self.basis.vectors.clone(),
            output_gains: self.light_gains(),
            band_step_nm: self.grid.step_nm,
            white: self.white(),
            exposure_weights: self.exposure_weights.clone(),
            noise: self.noise,
            spectral_prior: self.basis.coefficient_prior(&self.lit_projection()),
        }
    }

    /// x_i of a white reflector: the projection's row sums.
    pub fn white(&self) -> Vec<f64> {
        self.projection.w.row_iter().map(|r| r.sum()).collect()
    }

    /// The light of each wheel channel as the camera weighs it on a flat reflector, T_i·L·QE,
    /// sampled every nanometre (or finer) over the cube's wavelengths; L is the radiance scene's
    /// light, flat without one. Pattern i is formed by this light (optics/light.rs).
    pub fn pattern_spectra(&self) -> Result<Vec<Curve>> {
        let (lo, hi) = (self.grid.start_nm, self.grid.end_nm());
        let n = (hi - lo).ceil().max(1.0) as usize + 1;
        let wl: Vec<f64> = (0..n)
            .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
            .collect();
        let light = self.illuminant.as_ref().or(self.radiance_light.as_ref());
        self.wheel
            .filters
            .iter()
            .map(|t| {
                let v = wl
                    .iter()
                    .map(|&l| t.eval(l) * self.qe.eval(l) * light.map_or(1.0, |c| c.eval(l)))
                    .collect();
                Curve::new(format!("{} light", t.name), wl.clone(), v)
            })
            .collect()
    }

    /// The light of each pattern under the experiment's optics (`OpticsConfig::pattern_lights`);
    /// a band that passes no light on the cube's wavelengths is refused by its segment's key (a
    /// laser line does not need the segment's light to form its pattern).
    pub fn pattern_lights(&self, exp: &Experiment) -> Result<Vec<PatternLight>> {
        let spectra = self.pattern_spectra()?;
        // A band that carries no power cannot form a pattern: name the segment's key.
        exp.rig.optics().pattern_lights(&spectra).map_err(|e| {
            match spectra.iter().position(|c| c.values().iter().all(|&v| v <= 0.0)) {
                Some(i) => Error::config(
                    &exp.file,
                    &format!("rig.wheel.filters[{i}]"),
                    format!("\"{}\"", self.wheel.filters[i].name),
                    &format!(
                        "passes no light on {}–{} nm with this camera and light, so the pattern it forms is dark",
                        self.grid.start_nm,
                        self.grid.end_nm()
                    ),
                ),
                None => e,
            }
        })
    }

    /// For a radiance scene lit by L: L at the band centres divided by its mean over the bands
    /// (unit mean, so that η weighs the reflectance curvature as in a reflectance scene); None
    /// otherwise. The reconstruction solves for the reflectance-like Bα and returns diag(L̃)·Bα.
    pub fn light_gains(&self) -> Option<Vec<f64>> {
        let light = self.radiance_light.as_ref()?;
        let l = light.sample(&self.grid);
        let mean = l.iter().sum::<f64>() / l.len() as f64;
        Some(l.iter().map(|v| v / mean).collect())
    }

    /// The basis as the cube sees it (bands × J): B for a reflectance scene; for a radiance
    /// scene lit by L, diag(L̃)·B — the reflectance prior lit by the scene's light (docs/mitsuba.md).
    pub fn prior(&self) -> nalgebra::DMatrix<f64> {
        let mut b = self.basis.vectors.clone();
        if let Some(g) = self.light_gains() {
            for (mut row, g) in b.row_iter_mut().zip(g) {
                row *= g;
            }
        }
        b
    }

    /// F_ij = Σ_b W_ib P_bj with P = `prior()`: ∫ T_i L QE b_j dλ, exact for a basis piecewise
    /// linear on the grid.
    pub fn system_matrix(&self) -> nalgebra::DMatrix<f64> {
        &self.projection.w * self.prior()
    }

    /// What each band of a reflectance-like spectrum gives each channel (channels × bands):
    /// W, times diag(L̃) for a lit radiance scene, so that F = this · B.
    pub fn lit_projection(&self) -> nalgebra::DMatrix<f64> {
        let mut w = self.projection.w.clone();
        if let Some(g) = self.light_gains() {
            for (mut col, g) in w.column_iter_mut().zip(g) {
                col *= g;
            }
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Sensor;

    /// The default camera by hand: K = 0.25 DN/e⁻, σ_d² = 10 e⁻², dark current 30 e⁻/s ×
    /// 2^((22 − 30)/8) × 0.04 s = 0.6 e⁻, so σ_y.dark² = 0.0625 × 10.6 + 1/12 = 0.745833 DN²;
    /// saturation 0.25 × 15000 + 132 = 3882 DN (under the 12-bit ADC's 4095; at 10 bit its 1023).
    #[test]
    fn the_noise_model_of_the_default_camera_by_hand() {
        let m = noise_model(&SensorConfig::default());
        assert_eq!(m.gain_dn_per_e, 0.25);
        assert_eq!(m.saturation_dn, Some(3882.0));
        let ten_bit = SensorConfig {
            bits: 10,
            black_offset_dn: 33.0,
            ..Default::default()
        };
        assert_eq!(noise_model(&ten_bit).saturation_dn, Some(1023.0));
        assert!(
            (m.dark_noise_dn.powi(2) - 0.745_833_3).abs() < 1e-6,
            "{m:?}"
        );
    }

    /// The warnings of the prototype at 768² with a DMD and a pinhole of `radius` µm.
    fn prototype_warnings(radius: f64) -> Vec<String> {
        let text = format!(
            "[scene]\nsize = [768, 768]\n[rig.dmd]\n[rig.fourier_filter]\npinhole_radius_um = {radius}\n"
        );
        let exp = Experiment::from_toml(&text, "t.toml").unwrap();
        let lib = Library::default_root();
        let materials = Materials::load(&lib).unwrap();
        Rig::build(&exp, &lib, &materials).unwrap().warnings
    }

    /// 25 µm is 3.8 bins at 700 nm on 768 mirrors, so the relay pads (no warning); 27 µm is 4.1
    /// bins, unpadded: the periodic model is named, with the 0.61/radius blur of its openings.
    #[test]
    fn an_unpadded_relay_is_named_in_the_warnings() {
        let periodic = |w: &Vec<String>| w.iter().any(|s| s.contains("periodic pattern"));
        assert!(!periodic(&prototype_warnings(25.0)));
        let w = prototype_warnings(27.0);
        let line = w
            .iter()
            .find(|s| s.contains("periodic pattern"))
            .expect("a warning");
        assert!(
            line.contains("pinhole_radius_um` = 27") && line.contains("patterns 0, 1, 2, 3, 4, 5"),
            "{line}"
        );
        // 25 µm is 3.8 bins at 700 nm, so 27 µm is 4.10/768 cycles/mirror there: a blur of
        // 0.61 × 768/4.10 = 114 mirrors, growing with λ (the widest band ends near 710 nm).
        let blur: f64 = line
            .split("up to ")
            .nth(1)
            .and_then(|t| t.split(' ').next())
            .unwrap()
            .parse()
            .unwrap();
        assert!((114.0..=118.0).contains(&blur), "{line}");
    }

    /// The model against the simulated camera: the temporal variance of dark exposures (half
    /// the variance of the difference of two, which removes the DSNU) is σ_y.dark² within 3 %.
    #[test]
    fn the_noise_model_matches_the_simulated_dark_frames() {
        let cfg = SensorConfig::default();
        let s = Sensor::new(&cfg, 256, 256).unwrap();
        let (a, b) = (s.dark_exposure(0), s.dark_exposure(1));
        let d: Vec<f64> = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| (x - y) as f64)
            .collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (d.len() - 1) as f64 / 2.0;
        let model = noise_model(&cfg).dark_noise_dn.powi(2);
        assert!(
            (var / model - 1.0).abs() < 0.03,
            "sample {var:.4} against {model:.4} DN²"
        );
    }
}
