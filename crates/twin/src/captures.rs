//! Simulated calibration captures: the frames a real rig records before an acquisition — dark
//! frames, flat frames (white target, every mirror on) and each pattern on the white target —
//! made through the same multiplexing and the same camera as the scene's frame, each with its
//! own noise. The reconstruction core sees these frames and nothing else of the simulator. The
//! oracle (the simulator's exact patterns and scale, noiseless) is kept for comparison only.

use crate::multiplex::multiplex;
use crate::sensor::Sensor;
use serde::{Deserialize, Serialize};
use specmux_core::calibration::CalibrationFrames;
use specmux_core::error::check_count;
use specmux_core::{Cube, Result};

/// Where the reconstruction's calibration comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CalibrationSource {
    /// Simulated captures, as the real rig records them (the default).
    Captures,
    /// The simulator's exact patterns and frame scale, noiseless: an oracle no rig has.
    Oracle,
}

/// `[calibration]`: how the twin makes the calibration frames.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaptureConfig {
    pub source: CalibrationSource,
    /// Exposures averaged into each calibration frame (dark, flat, each pattern).
    pub frames: usize,
    /// How far from its design bin each carrier is looked for, in FFT bins.
    pub search_bins: usize,
}

impl Default for CaptureConfig {
    fn default() -> Self {
        CaptureConfig {
            source: CalibrationSource::Captures,
            frames: 16,
            search_bins: 4,
        }
    }
}

impl CaptureConfig {
    pub fn validate(&self, f: &str) -> Result<()> {
        check_count(f, "calibration.frames", self.frames, 1..=1024, "frames")?;
        check_count(
            f,
            "calibration.search_bins",
            self.search_bins,
            1..=64,
            "bins",
        )
    }
}

/// What the white target meets on the simulated rig: the patterns as imaged, the exposed
/// white per pattern slot, and the frame value the camera's full scale refers to.
pub struct WhiteTarget<'a> {
    pub patterns: &'a Cube,
    pub exposed_white: &'a [f64],
    pub full_scale: f32,
}

/// The calibration frames of the simulated rig: captured (with the camera's noise, averaged
/// over `frames` exposures) or the oracle.
pub fn calibration_frames(
    cfg: &CaptureConfig,
    sim: &WhiteTarget,
    sensor: Option<&Sensor>,
) -> Result<CalibrationFrames> {
    let patterns = white_target_patterns(sim)?;
    let Some(cam) = sensor else {
        // No camera: frames are linear and noiseless, the captures equal the oracle.
        return Ok(CalibrationFrames {
            dark: None,
            flat: None,
            patterns,
            patterns_linear: true,
            frames_averaged: 1,
            source: source_name(cfg.source).into(),
        });
    };
    // The flat is taken with its own bright uniform source at half the full well, whatever the
    // scene's exposure: bright enough for a low-noise gain map.
    let dark = cam.dark_frame(cfg.frames)?;
    let flat = cam.flat_frame(0.5 * cam.config().full_well_e, cfg.frames)?;
    let (patterns, patterns_linear) = match cfg.source {
        CalibrationSource::Captures => {
            (captured(cam, &patterns, sim.full_scale, cfg.frames)?, false)
        }
        CalibrationSource::Oracle => (
            scaled(&patterns, oracle_dn_per_unit(cam, sim.full_scale)),
            true,
        ),
    };
    Ok(CalibrationFrames {
        dark: Some(dark),
        flat: Some(flat),
        patterns,
        patterns_linear,
        frames_averaged: cfg.frames,
        source: source_name(cfg.source).into(),
    })
}

fn source_name(s: CalibrationSource) -> &'static str {
    match s {
        CalibrationSource::Captures => "captures",
        CalibrationSource::Oracle => "oracle",
    }
}

/// P_k = z_k(white)·s̃_k: the white target while the DMD shows pattern k in its own slot and
/// is dark in the others — the multiplexing of a white scene with one pattern on.
fn white_target_patterns(sim: &WhiteTarget) -> Result<Cube> {
    let s = sim.patterns;
    let (w, h, n) = (s.width, s.height, s.planes);
    let mut out = Cube::zeros(w, h, n);
    for k in 0..n {
        let mut z = Cube::zeros(w, h, n);
        z.plane_mut(k).fill(sim.exposed_white[k] as f32);
        out.plane_mut(k).copy_from_slice(&multiplex(&z, s)?.data);
    }
    Ok(out)
}

/// Each white-target frame through the camera at the scene's exposure, averaged.
fn captured(cam: &Sensor, frames: &Cube, full_scale: f32, n: usize) -> Result<Cube> {
    let mut out = Cube::zeros(frames.width, frames.height, frames.planes);
    for k in 0..frames.planes {
        let e = cam.electrons_from_relative(&frames.extract(k), full_scale)?;
        let raw = cam.averaged_capture(&e, n, k as u64)?;
        out.plane_mut(k).copy_from_slice(&raw.data);
    }
    Ok(out)
}

/// The simulator's own scale from frame units to dark/flat-corrected DN: K · e⁻(full scale) /
/// full scale. Only the oracle uses it.
fn oracle_dn_per_unit(cam: &Sensor, full_scale: f32) -> f64 {
    let c = cam.config();
    c.gain_dn_per_e * c.electrons_at_full_scale / full_scale as f64
}

fn scaled(c: &Cube, k: f64) -> Cube {
    let mut out = c.clone();
    out.data
        .iter_mut()
        .for_each(|v| *v = (*v as f64 * k) as f32);
    out
}
