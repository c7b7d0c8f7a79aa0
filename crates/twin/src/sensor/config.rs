//! The `[rig.sensor]` section: the EMVA 1288 parameters of the camera, with defaults for a CMOS
//! machine-vision camera of the JAI GO-5000 class (the prototype's camera).

use serde::{Deserialize, Serialize};
use specmux_core::error::check_count;
use specmux_core::error::Error;
use specmux_core::error::Result;

/// EMVA 1288 camera parameters. Where no published EMVA 1288 sheet of the GO-5000 was at hand,
/// the default is the one of the reference simulator of the `emva1288` Python package
/// (`emva1288/camera/camera.py`, class `Camera`) and says so.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// Saturation capacity μ_e.sat (e⁻): the pixel signal is clipped here.
    /// Default 15000 e⁻: `u_esat` of the emva1288 reference simulator.
    pub full_well_e: f64,
    /// Shortcut when radiometry is not modelled: the noiseless frame's full-scale value means
    /// this many photo-electrons. Default 10000 e⁻ (two thirds of the full well: an exposure set
    /// with headroom, as an operator would set it; a design choice, not a datasheet value).
    pub electrons_at_full_scale: f64,
    /// Overall system gain K (DN/e⁻). Default 0.25 DN/e⁻: maps the 15000 e⁻ full well to 3750 DN,
    /// 92 % of the 12-bit range, as a camera at 0 dB gain is set up (the full well, not the ADC,
    /// saturates first). The emva1288 simulator's default is 0.1 DN/e⁻ at 8 bit.
    pub gain_dn_per_e: f64,
    /// Temporal read (dark) noise σ_d (e⁻ rms), Gaussian. Default √10 ≈ 3.16 e⁻: `sigma2_dark_0
    /// = 10` e⁻² of the emva1288 reference simulator.
    pub read_noise_e: f64,
    /// Mean dark current at `reference_temperature_c` (e⁻/s). Default 30 e⁻/s:
    /// `dark_current_ref` of the emva1288 reference simulator.
    pub dark_current_e_per_s: f64,
    /// Temperature step (°C) that doubles the dark current. Default 8 °C:
    /// `temperature_doubling` of the emva1288 reference simulator.
    pub dark_doubling_c: f64,
    /// Sensor temperature (°C). Default 22 °C: `temperature` of the emva1288 reference simulator.
    pub temperature_c: f64,
    /// Temperature at which `dark_current_e_per_s` holds (°C). Default 30 °C: `temperature_ref`
    /// of the emva1288 reference simulator.
    pub reference_temperature_c: f64,
    /// Black offset added before the ADC (DN). Default 132 DN: JAI GO-series manuals give a
    /// default black level of 33 LSB at 10-bit output, i.e. 132 DN at 12 bit.
    pub black_offset_dn: f64,
    /// ADC bit depth; output DN lie in [0, 2^bits − 1]. Default 12: the GO-5000 delivers Mono12
    /// at up to 30.9 fps at full frame (GO-5000 manual), enough for the prototype's 24 fps.
    pub bits: u32,
    /// Photo-response non-uniformity: relative standard deviation of the per-pixel gain map.
    /// Default 0.01 (1 %): the usual order of PRNU1288 for CMOS machine-vision sensors.
    pub prnu_fraction: f64,
    /// Dark-signal non-uniformity: standard deviation of the per-pixel offset map (e⁻).
    /// Default 2 e⁻: the usual order of DSNU1288 for CMOS machine-vision sensors.
    pub dsnu_e: f64,
    /// Exposure time (s). Default 40 ms, the same as `[rig.timing].camera.exposure_s`: 40 whole
    /// wheel turns, the longest that fits the prototype's 24 fps frame period (paper, section 4);
    /// the GO-5000 allows 10 µs–8 s. With both sections present the two must agree.
    pub exposure_s: f64,
    /// Pixel pitch (µm), for the radiometric path. Default 5.0 µm: the GO-5000's 2560 × 2048
    /// pixels on a 1-inch (12.8 mm × 10.24 mm) sensor.
    pub pixel_pitch_um: f64,
    /// Seed of the camera: the PRNU/DSNU maps and every frame's noise derive from it.
    /// Default 1288.
    pub seed: u64,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            full_well_e: 15000.0,
            electrons_at_full_scale: 10000.0,
            gain_dn_per_e: 0.25,
            read_noise_e: 10f64.sqrt(),
            dark_current_e_per_s: 30.0,
            dark_doubling_c: 8.0,
            temperature_c: 22.0,
            reference_temperature_c: 30.0,
            black_offset_dn: 132.0,
            bits: 12,
            prnu_fraction: 0.01,
            dsnu_e: 2.0,
            exposure_s: 0.040,
            pixel_pitch_um: 5.0,
            seed: 1288,
        }
    }
}

/// Largest PRNU accepted: beyond it the Gaussian gain map 1 + N(0, prnu) would reach negative
/// gains somewhere on a megapixel frame (10 σ away).
pub const MAX_PRNU_FRACTION: f64 = 0.1;

/// Temperatures accepted (°C): the range over which the doubling law of dark current is used.
const TEMPERATURE_RANGE_C: (f64, f64) = (-100.0, 150.0);

impl SensorConfig {
    /// Largest output value 2^bits − 1 (DN).
    pub fn max_dn(&self) -> f64 {
        ((1u64 << self.bits) - 1) as f64
    }

    /// The output of a pixel whose charge reached the full well (DN): round(K·μ_e.sat + offset),
    /// or the ADC's top rail when that comes first.
    pub fn saturation_dn(&self) -> f64 {
        (self.gain_dn_per_e * self.full_well_e + self.black_offset_dn)
            .round()
            .min(self.max_dn())
    }

    /// Mean dark-current electrons per frame: I_ref · 2^((T − T_ref)/T_d) · t_exp.
    pub fn dark_electrons(&self) -> f64 {
        self.dark_current_e_per_s
            * 2f64.powf((self.temperature_c - self.reference_temperature_c) / self.dark_doubling_c)
            * self.exposure_s
    }

    /// Check every field; errors name the key as `rig.sensor.<field>` and the value.
    pub fn validate(&self, file: &str) -> Result<()> {
        let bad = |field: &str, value: String, reason: &str| {
            Err(Error::config(
                file,
                &format!("rig.sensor.{field}"),
                value,
                reason,
            ))
        };
        let positive = [
            ("full_well_e", self.full_well_e),
            ("electrons_at_full_scale", self.electrons_at_full_scale),
            ("gain_dn_per_e", self.gain_dn_per_e),
            ("dark_doubling_c", self.dark_doubling_c),
            ("exposure_s", self.exposure_s),
            ("pixel_pitch_um", self.pixel_pitch_um),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(field, v.to_string(), "must be a finite number > 0");
            }
        }
        let non_negative = [
            ("read_noise_e", self.read_noise_e),
            ("dark_current_e_per_s", self.dark_current_e_per_s),
            ("dsnu_e", self.dsnu_e),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, v.to_string(), "must be a finite number ≥ 0");
            }
        }
        let (t_lo, t_hi) = TEMPERATURE_RANGE_C;
        for (field, v) in [
            ("temperature_c", self.temperature_c),
            ("reference_temperature_c", self.reference_temperature_c),
        ] {
            if !(v >= t_lo && v <= t_hi) {
                return bad(
                    field,
                    v.to_string(),
                    &format!("must lie in [{t_lo}, {t_hi}] °C, where the dark-current doubling law is used"),
                );
            }
        }
        check_count(
            file,
            "rig.sensor.bits",
            self.bits as usize,
            1..=16,
            "bits (ADC depth)",
        )?;
        if !(self.black_offset_dn >= 0.0 && self.black_offset_dn < self.max_dn()) {
            return bad(
                "black_offset_dn",
                self.black_offset_dn.to_string(),
                &format!(
                    "must lie in [0, {}) DN for {} bits",
                    self.max_dn(),
                    self.bits
                ),
            );
        }
        if !(self.prnu_fraction >= 0.0 && self.prnu_fraction <= MAX_PRNU_FRACTION) {
            return bad(
                "prnu_fraction",
                self.prnu_fraction.to_string(),
                &format!("must lie in [0, {MAX_PRNU_FRACTION}] (a relative gain spread)"),
            );
        }
        let dark = self.dark_electrons();
        if !dark.is_finite() {
            return bad(
                "dark_current_e_per_s",
                self.dark_current_e_per_s.to_string(),
                &format!(
                    "gives {dark} dark electrons per frame at the set temperature and exposure"
                ),
            );
        }
        Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    fn key_of(err: Error) -> String {
        match err {
            Error::Config { key, .. } => key,
            other => panic!("expected a config error, got {other}"),
        }
    }

    #[test]
    fn defaults_are_valid_and_full_well_fits_the_adc() {
        let c = SensorConfig::default();
        c.validate("t.toml").unwrap();
        assert!(c.gain_dn_per_e * c.full_well_e + c.black_offset_dn < c.max_dn());
        assert_eq!(c.max_dn(), 4095.0);
    }

    #[test]
    fn dark_current_doubles_every_doubling_temperature() {
        let mut c = SensorConfig {
            temperature_c: 30.0,
            exposure_s: 2.0,
            ..Default::default()
        };
        assert!((c.dark_electrons() - 60.0).abs() < 1e-9);
        c.temperature_c = 38.0;
        assert!((c.dark_electrons() - 120.0).abs() < 1e-9);
        c.temperature_c = 14.0;
        assert!((c.dark_electrons() - 15.0).abs() < 1e-9);
    }

    #[test]
    fn bad_values_name_their_key() {
        type Edit = fn(&mut SensorConfig);
        let cases: [(&str, Edit); 12] = [
            ("full_well_e", |c| c.full_well_e = 0.0),
            ("electrons_at_full_scale", |c| {
                c.electrons_at_full_scale = f64::NAN
            }),
            ("gain_dn_per_e", |c| c.gain_dn_per_e = -0.1),
            ("read_noise_e", |c| c.read_noise_e = -1.0),
            ("dark_current_e_per_s", |c| {
                c.dark_current_e_per_s = f64::INFINITY
            }),
            ("dark_doubling_c", |c| c.dark_doubling_c = 0.0),
            ("temperature_c", |c| c.temperature_c = -300.0),
            ("bits", |c| c.bits = 0),
            ("bits", |c| c.bits = 17),
            ("black_offset_dn", |c| c.black_offset_dn = 4095.0),
            ("prnu_fraction", |c| c.prnu_fraction = 0.5),
            ("exposure_s", |c| c.exposure_s = 0.0),
        ];
        for (field, edit) in cases {
            let mut c = SensorConfig::default();
            edit(&mut c);
            let err = c.validate("exp.toml").unwrap_err();
            let msg = err.to_string();
            assert_eq!(key_of(err), format!("rig.sensor.{field}"), "{msg}");
            assert!(msg.starts_with("exp.toml"), "{msg}");
        }
    }

    #[test]
    fn toml_keys_and_defaults() {
        let c: SensorConfig = toml::from_str("full_well_e = 20000\nbits = 10").unwrap();
        assert_eq!(c.full_well_e, 20000.0);
        assert_eq!(c.bits, 10);
        assert_eq!(c.gain_dn_per_e, SensorConfig::default().gain_dn_per_e);
        assert!(toml::from_str::<SensorConfig>("full_wel_e = 1").is_err());
    }
}
