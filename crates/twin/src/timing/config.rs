//! The timing section of the rig (`[rig.timing]`): the wheel's rotation and geometry, the DMD's
//! pattern schedule and the camera's exposure. Defaults are the 2019 prototype (paper §4).

use serde::{Deserialize, Serialize};
use specmux_core::error::Error;
use specmux_core::error::Result;

/// Wheel, DMD and camera timing; `validate` checks every value and the DMD schedule.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TimingConfig {
    pub wheel: WheelTiming,
    pub dmd: DmdTiming,
    pub camera: CameraTiming,
}

/// The spinning colour wheel. Segment i spans wheel angles [θ_i, θ_i + Δ_i), θ_0 = 0; the beam
/// spot sits at wheel angle α(t) = 360°·rate_hz·t + index_offset_deg (the index pulse is t = 0).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WheelTiming {
    /// Angular extent Δ_i of each segment in degrees, summing to 360. Default 6 × 60°: the
    /// prototype's off-the-shelf six-segment wheel (paper §4); equal extents are assumed.
    pub segments_deg: Vec<f64>,
    /// Revolutions per second. Default 1000: the prototype's 60k rpm motor (paper §4).
    pub rate_hz: f64,
    /// Diameter of the beam spot on the wheel in mm. Default 0 (a point): the paper says the spot
    /// is small enough that the overlap of two segments can be neglected; give the measured spot
    /// to model the mixing of neighbouring segments during spoke crossings.
    pub spot_diameter_mm: f64,
    /// Distance from the wheel's axis to the spot centre in mm. Default 20 mm: an assumed radius
    /// typical of projector colour wheels (the paper does not give it); it matters only with a
    /// spot of non-zero diameter.
    pub spot_radius_mm: f64,
    /// Angle of the spot on the wheel when the index pulse fires (a misaligned index sensor).
    /// Default 0: the pulse fires as the spot enters segment 0.
    pub index_offset_deg: f64,
}

impl Default for WheelTiming {
    fn default() -> Self {
        WheelTiming {
            segments_deg: vec![60.0; 6],
            rate_hz: 1000.0,
            spot_diameter_mm: 0.0,
            spot_radius_mm: 20.0,
            index_offset_deg: 0.0,
        }
    }
}

/// The DMD's pattern schedule: pattern k starts at the nominal start of segment k (from the
/// index pulse) plus `delays_s[k]` and lasts the segment's time minus `dark_time_s`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DmdTiming {
    /// Highest binary picture rate; every picture (pattern or dark gap) must last at least
    /// 1/max_rate_hz. Default 20 000: the prototype's 20 kHz modulation (paper §4), within the
    /// ≈ 23 kHz binary rate of a DLP7000-class device (ViALUX V-7000).
    pub max_rate_hz: f64,
    /// Per-pattern delay after the nominal segment start, in seconds, each in [0, 1/rate_hz).
    /// Empty (the default) means no delay for every pattern, as the prototype's trigger chain.
    pub delays_s: Vec<f64>,
    /// Dark picture at the end of each pattern's slot, in seconds. Default 0 (none).
    pub dark_time_s: f64,
}

impl Default for DmdTiming {
    fn default() -> Self {
        DmdTiming {
            max_rate_hz: 20_000.0,
            delays_s: Vec::new(),
            dark_time_s: 0.0,
        }
    }
}

/// The camera, triggered from the DMD (itself triggered by the wheel's index pulse).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraTiming {
    /// Exposure length in seconds. Default 40 ms: 40 whole turns at 1000 rev/s, the longest
    /// whole-turn exposure that fits the prototype's 24 fps frame period (41.7 ms).
    pub exposure_s: f64,
    /// Exposure start after the index pulse in seconds (trigger latency). Default 0.
    pub start_s: f64,
    /// Frames per second. Default 24: the prototype's setting (paper §4).
    pub frame_rate_hz: f64,
    /// Sensor read-out time after each exposure, in seconds. Default 1 ms: assumed (the paper
    /// does not name the camera); exposure + read-out must fit one frame period.
    pub readout_s: f64,
    /// The camera's highest frame rate. Default 100: the paper quotes "∼100 Hz" for its camera.
    pub max_frame_rate_hz: f64,
}

impl Default for CameraTiming {
    fn default() -> Self {
        CameraTiming {
            exposure_s: 0.040,
            start_s: 0.0,
            frame_rate_hz: 24.0,
            readout_s: 0.001,
            max_frame_rate_hz: 100.0,
        }
    }
}

const KEY: &str = "rig.timing";

fn key(field: &str) -> String {
    format!("{KEY}.{field}")
}

fn positive(file: &str, field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::config(
            file,
            &key(field),
            v,
            "must be a finite number > 0",
        ))
    }
}

fn non_negative(file: &str, field: &str, v: f64) -> Result<()> {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(Error::config(
            file,
            &key(field),
            v,
            "must be a finite number ≥ 0",
        ))
    }
}

impl TimingConfig {
    /// Check every value and the DMD schedule; the error names the key (`rig.timing.…`) and value.
    pub fn validate(&self, file: &str) -> Result<()> {
        self.validate_wheel(file)?;
        self.validate_dmd(file)?;
        self.validate_camera(file)
    }

    /// Number of wheel segments N (= number of patterns).
    pub fn segment_count(&self) -> usize {
        self.wheel.segments_deg.len()
    }
    /// Pattern k's slot on one turn: (start in [0, period), duration), from the config.
    pub fn pattern_slots(&self) -> Vec<(f64, f64)> {
        let period = self.period_s();
        let mut theta = 0.0;
        self.wheel
            .segments_deg
            .iter()
            .enumerate()
            .map(|(k, &deg)| {
                let start = (theta / 360.0 * period + self.delay_s(k)).rem_euclid(period);
                theta += deg;
                (start, deg / 360.0 * period - self.dmd.dark_time_s)
            })
            .collect()
    }

    /// One wheel turn in seconds.
    pub fn period_s(&self) -> f64 {
        1.0 / self.wheel.rate_hz
    }

    /// Delay of pattern k (an empty list means zero for all).
    pub fn delay_s(&self, k: usize) -> f64 {
        self.dmd.delays_s.get(k).copied().unwrap_or(0.0)
    }

    fn validate_wheel(&self, file: &str) -> Result<()> {
        let w = &self.wheel;
        let seg = &w.segments_deg;
        if seg.len() < 2 {
            return Err(Error::config(
                file,
                &key("wheel.segments_deg"),
                format!("{seg:?}"),
                "needs at least two segments",
            ));
        }
        if let Some((i, v)) = seg
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v > 0.0))
        {
            return Err(Error::config(
                file,
                &key(&format!("wheel.segments_deg[{i}]")),
                v,
                "each segment's extent must be a finite angle > 0°",
            ));
        }
        let sum: f64 = seg.iter().sum();
        if (sum - 360.0).abs() > 1e-9 * 360.0 {
            return Err(Error::config(
                file,
                &key("wheel.segments_deg"),
                format!("{seg:?}"),
                &format!("the segments must sum to 360° (they sum to {sum}°)"),
            ));
        }
        positive(file, "wheel.rate_hz", w.rate_hz)?;
        non_negative(file, "wheel.spot_diameter_mm", w.spot_diameter_mm)?;
        positive(file, "wheel.spot_radius_mm", w.spot_radius_mm)?;
        if !w.index_offset_deg.is_finite() {
            return Err(Error::config(
                file,
                &key("wheel.index_offset_deg"),
                w.index_offset_deg,
                "must be finite",
            ));
        }
        let r = w.spot_diameter_mm / 2.0;
        if r >= w.spot_radius_mm {
            return Err(Error::config(
                file,
                &key("wheel.spot_diameter_mm"),
                w.spot_diameter_mm,
                &format!(
                    "the spot must not cover the wheel's axis (radius {} mm)",
                    w.spot_radius_mm
                ),
            ));
        }
        // The spot may touch only one spoke at a time: its angular width 2·asin(r/R) must be less
        // than the narrowest segment.
        let width_deg = 2.0 * (r / w.spot_radius_mm).asin().to_degrees();
        let narrowest = seg.iter().cloned().fold(f64::INFINITY, f64::min);
        if width_deg >= narrowest {
            return Err(Error::config(
                file,
                &key("wheel.spot_diameter_mm"),
                w.spot_diameter_mm,
                &format!(
                    "the spot spans {width_deg:.3}° at radius {} mm, not less than the narrowest segment ({narrowest}°)",
                    w.spot_radius_mm
                ),
            ));
        }
        Ok(())
    }

    fn validate_dmd(&self, file: &str) -> Result<()> {
        let d = &self.dmd;
        let n = self.segment_count();
        let period = self.period_s();
        positive(file, "dmd.max_rate_hz", d.max_rate_hz)?;
        non_negative(file, "dmd.dark_time_s", d.dark_time_s)?;
        if !d.delays_s.is_empty() && d.delays_s.len() != n {
            return Err(Error::config(
                file,
                &key("dmd.delays_s"),
                format!("{} delays", d.delays_s.len()),
                &format!("needs one delay per segment ({n}) or none"),
            ));
        }
        for (k, &v) in d.delays_s.iter().enumerate() {
            if !(v.is_finite() && v >= 0.0 && v < period) {
                return Err(Error::config(
                    file,
                    &key(&format!("dmd.delays_s[{k}]")),
                    v,
                    &format!("must be in [0, one turn = {period} s)"),
                ));
            }
        }
        let min_picture = 1.0 / d.max_rate_hz;
        let eps = 1e-9 * period;
        if d.dark_time_s > 0.0 && d.dark_time_s < min_picture - eps {
            return Err(Error::config(
                file,
                &key("dmd.dark_time_s"),
                d.dark_time_s,
                &format!(
                    "a dark picture shorter than the DMD's minimum picture time {min_picture} s (1/max_rate_hz)"
                ),
            ));
        }
        for (k, &deg) in self.wheel.segments_deg.iter().enumerate() {
            let slot = deg / 360.0 * period;
            if slot < min_picture - eps {
                return Err(Error::config(
                    file,
                    &key("wheel.rate_hz"),
                    self.wheel.rate_hz,
                    &format!(
                        "segment {k} lasts {:.3} µs, shorter than the DMD's minimum picture time {:.3} µs \
                         (rig.timing.dmd.max_rate_hz = {}): lower the wheel rate",
                        slot * 1e6,
                        min_picture * 1e6,
                        d.max_rate_hz
                    ),
                ));
            }
            if slot - d.dark_time_s < min_picture - eps {
                return Err(Error::config(
                    file,
                    &key("dmd.dark_time_s"),
                    d.dark_time_s,
                    &format!(
                        "pattern {k} would be shown {:.3} µs, less than the DMD's minimum picture time {:.3} µs",
                        (slot - d.dark_time_s) * 1e6,
                        min_picture * 1e6
                    ),
                ));
            }
        }
        self.validate_pattern_order(file, min_picture, eps)
    }

    /// Patterns must not overlap, and a dark gap between two patterns must last a picture time.
    fn validate_pattern_order(&self, file: &str, min_picture: f64, eps: f64) -> Result<()> {
        let period = self.period_s();
        let slots = self.pattern_slots();
        let mut order: Vec<usize> = (0..slots.len()).collect();
        order.sort_by(|&a, &b| slots[a].0.total_cmp(&slots[b].0));
        for (pos, &a) in order.iter().enumerate() {
            let b = order[(pos + 1) % order.len()];
            let mut room = slots[b].0 - slots[a].0;
            if pos + 1 == order.len() {
                room += period;
            }
            let gap = room - slots[a].1;
            if gap < -eps {
                return Err(Error::config(
                    file,
                    &key("dmd.delays_s"),
                    format!("{:?}", self.dmd.delays_s),
                    &format!(
                        "pattern {a} (shown {:.3} µs) still shows when pattern {b} starts {:.3} µs later",
                        slots[a].1 * 1e6,
                        room * 1e6
                    ),
                ));
            }
            if gap > eps && gap < min_picture - eps {
                return Err(Error::config(
                    file,
                    &key("dmd.delays_s"),
                    format!("{:?}", self.dmd.delays_s),
                    &format!(
                        "the dark gap of {:.3} µs between pattern {a} and pattern {b} is shorter than the \
                         DMD's minimum picture time {:.3} µs",
                        gap * 1e6,
                        min_picture * 1e6
                    ),
                ));
            }
        }
        Ok(())
    }

    fn validate_camera(&self, file: &str) -> Result<()> {
        let c = &self.camera;
        positive(file, "camera.exposure_s", c.exposure_s)?;
        non_negative(file, "camera.start_s", c.start_s)?;
        positive(file, "camera.frame_rate_hz", c.frame_rate_hz)?;
        non_negative(file, "camera.readout_s", c.readout_s)?;
        positive(file, "camera.max_frame_rate_hz", c.max_frame_rate_hz)?;
        if c.frame_rate_hz > c.max_frame_rate_hz {
            return Err(Error::config(
                file,
                &key("camera.frame_rate_hz"),
                c.frame_rate_hz,
                &format!(
                    "above the camera's maximum frame rate {} Hz",
                    c.max_frame_rate_hz
                ),
            ));
        }
        let frame = 1.0 / c.frame_rate_hz;
        if c.exposure_s + c.readout_s > frame * (1.0 + 1e-12) {
            return Err(Error::config(
                file,
                &key("camera.exposure_s"),
                c.exposure_s,
                &format!(
                    "exposure + read-out ({} s) exceed the frame period {frame} s (frame_rate_hz = {})",
                    c.exposure_s + c.readout_s,
                    c.frame_rate_hz
                ),
            ));
        }
        Ok(())
    }
}
