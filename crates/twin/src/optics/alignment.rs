//! The alignment of the DMD's image on the sensor as built: a small rotation and a relay
//! magnification off its nominal value turn each designed carrier ω into R(θ)·ω / m on the
//! sensor. The design does not know it; the calibration must find it (core::calibration).

use glam::{DMat2, DVec2};
use serde::{Deserialize, Serialize};
use specmux_core::{Carrier, Error, Result};

/// `[rig.alignment]`: how the rig as built departs from the design's DMD-to-sensor mapping.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AlignmentConfig {
    /// Rotation of the DMD's image on the sensor, degrees (counter-clockwise, x towards y).
    pub rotation_deg: f64,
    /// Sensor pixels per DMD pixel relative to the design (1 = as designed).
    pub magnification: f64,
}

impl Default for AlignmentConfig {
    fn default() -> Self {
        AlignmentConfig {
            rotation_deg: 0.0,
            magnification: 1.0,
        }
    }
}

impl AlignmentConfig {
    /// A misalignment a calibration can still find: within ±5° and 0.9–1.1.
    pub fn validate(&self, f: &str) -> Result<()> {
        if !(self.rotation_deg.is_finite() && self.rotation_deg.abs() <= 5.0) {
            return Err(Error::config(
                f,
                "rig.alignment.rotation_deg",
                self.rotation_deg,
                "must be within ±5° (a larger rotation is a different design)",
            ));
        }
        if !(self.magnification.is_finite() && (0.9..=1.1).contains(&self.magnification)) {
            return Err(Error::config(
                f,
                "rig.alignment.magnification",
                self.magnification,
                "must be 0.9 to 1.1",
            ));
        }
        Ok(())
    }

    /// The carriers as they reach the sensor: ω' = R(θ)·ω / m, the phase at pixel (0, 0) kept.
    pub fn imaged(&self, design: &[Carrier]) -> Vec<Carrier> {
        let r = DMat2::from_angle(self.rotation_deg.to_radians());
        design
            .iter()
            .map(|c| {
                let f = r * DVec2::new(c.fx, c.fy) / self.magnification;
                Carrier {
                    fx: f.x,
                    fy: f.y,
                    phase_rad: c.phase_rad,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quarter_turn_and_a_doubling_by_hand() {
        let c = [Carrier {
            fx: 0.25,
            fy: 0.0,
            phase_rad: 0.3,
        }];
        let a = AlignmentConfig {
            rotation_deg: 90.0,
            magnification: 2.0,
        };
        let out = a.imaged(&c)[0];
        assert!(
            out.fx.abs() < 1e-15 && (out.fy - 0.125).abs() < 1e-15,
            "{out:?}"
        );
        assert_eq!(out.phase_rad, 0.3);
        // The default is the identity, bit for bit.
        assert_eq!(AlignmentConfig::default().imaged(&c)[0], c[0]);
    }

    #[test]
    fn out_of_range_is_refused_by_key() {
        let a = AlignmentConfig {
            rotation_deg: 7.0,
            ..Default::default()
        };
        let e = a.validate("x.toml").unwrap_err().to_string();
        assert!(
            e.contains("rig.alignment.rotation_deg") && e.contains('7'),
            "{e}"
        );
    }
}
