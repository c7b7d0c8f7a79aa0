//! Simulated calibration captures: the frames a real rig records before an acquisition — dark
//! frames, flat frames (white target, every mirror on) and each pattern on the white target —
//! made through the same multiplexing and the same camera as the scene's frame, each with its
//! own noise. The reconstruction core sees these frames and nothing else of the simulator. The
//! oracle (the simulator's exact patterns and scale, noiseless) is kept for comparison only.

use crate::multiplex::multiplex;
use crate::pattern_cache::{self, Entry, PatternCache};
use crate::sensor::Sensor;
use serde::{Deserialize, Serialize};
use specmux_core::calibration::CalibrationFrames;
use specmux_core::error::check_count;
use specmux_core::{Cube, Result};

/// Version of what the captures compute from their inputs (the white-target frames and the
/// camera's draws). A change meant to change the captured frames records new checksums in
/// `captured_frames_match_the_recorded_checksums` and raises this with them, so that every
/// cached capture of the old model is a miss (pattern_cache.rs).
pub const MODEL: u32 = 1;

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

/// Where the captures of one rig and camera are kept in a pattern cache: their file's key, made
/// once (it hashes the patterns).
pub struct KeptCaptures<'a> {
    cache: &'a PatternCache,
    key: String,
    patterns: &'a Cube,
    frames: usize,
}

impl<'a> KeptCaptures<'a> {
    /// The place of the captures `cfg` makes of `sim` with `cam`; None for the oracle, which is
    /// not captured (it costs milliseconds).
    pub fn new(
        cache: &'a PatternCache,
        cfg: &CaptureConfig,
        sim: &WhiteTarget<'a>,
        cam: &Sensor,
    ) -> Option<KeptCaptures<'a>> {
        (cfg.source == CalibrationSource::Captures).then(|| KeptCaptures {
            cache,
            key: cache_key(cfg, sim, cam),
            patterns: sim.patterns,
            frames: cfg.frames,
        })
    }

    /// The frames an earlier run kept here, bit for bit; None when there are none. A damaged
    /// file is refused naming it.
    pub fn load(&self) -> Result<Option<CalibrationFrames>> {
        let Some(planes) = self.cache.load(Entry::Captures, &self.key)? else {
            return Ok(None);
        };
        let place = || self.cache.place(Entry::Captures, &self.key);
        from_planes(planes, self.patterns, self.frames)
            .map(Some)
            .map_err(|why| pattern_cache::damaged(&place(), why))
    }

    /// Keep captured `frames` here (frames without a dark and a flat, made without a camera,
    /// are not kept).
    pub fn store(&self, frames: &CalibrationFrames) -> Result<()> {
        match (&frames.dark, &frames.flat) {
            (Some(dark), Some(flat)) => {
                let planes = as_planes(dark, flat, &frames.patterns)?;
                self.cache.store(Entry::Captures, &self.key, &planes)
            }
            _ => Ok(()),
        }
    }
}

/// Everything the captures depend on: the model, the camera and its seed, the exposures
/// averaged, the white target's light and scale, and the patterns (by the FNV-1a hash of their
/// bits, which the key names; the patterns themselves would double the file).
fn cache_key(cfg: &CaptureConfig, sim: &WhiteTarget, cam: &Sensor) -> String {
    let p = sim.patterns;
    let bits = pattern_cache::fnv1a_f32(&p.data);
    format!(
        "specmux {} calibration captures model {MODEL}\nexposures averaged {}\ncamera {}x{} {:?}\nexposed white {:?}, full scale {:?}\npatterns {}x{}x{}, FNV-1a of their bits {bits:016x}",
        env!("CARGO_PKG_VERSION"),
        cfg.frames,
        cam.width(),
        cam.height(),
        cam.config(),
        sim.exposed_white,
        sim.full_scale,
        p.width,
        p.height,
        p.planes,
    )
}

/// The captured frames as one cube for the cache: dark, flat, then the patterns.
fn as_planes(dark: &Cube, flat: &Cube, patterns: &Cube) -> Result<Cube> {
    let data = [&dark.data, &flat.data, &patterns.data]
        .map(|d| d.as_slice())
        .concat();
    Cube::from_vec(patterns.width, patterns.height, patterns.planes + 2, data)
}

/// The frames [`as_planes`] kept for patterns shaped `like`; Err(why) for another shape.
fn from_planes(
    c: Cube,
    like: &Cube,
    frames: usize,
) -> std::result::Result<CalibrationFrames, String> {
    let (w, h, n) = (like.width, like.height, like.planes);
    if (c.width, c.height, c.planes) != (w, h, n + 2) {
        return Err(format!(
            "{}×{}×{} values, not a dark, a flat and {n} patterns of {w}×{h}",
            c.width, c.height, c.planes
        ));
    }
    let n = w * h;
    let patterns = Cube::from_vec(c.width, c.height, c.planes - 2, c.data[2 * n..].to_vec())
        .map_err(|e| e.to_string())?;
    Ok(CalibrationFrames {
        dark: Some(c.extract(0)),
        flat: Some(c.extract(1)),
        patterns,
        patterns_linear: false,
        frames_averaged: frames,
        source: source_name(CalibrationSource::Captures).into(),
    })
}

fn source_name(s: CalibrationSource) -> &'static str {
    match s {
        CalibrationSource::Captures => "captures",
        CalibrationSource::Oracle => specmux_core::calibration::ORACLE,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pattern_cache::fnv1a_f32;
    use crate::sensor::SensorConfig;

    /// Three 16 × 12 patterns of values in [0.1, 0.9].
    fn patterns() -> Cube {
        let data = (0..16 * 12 * 3)
            .map(|i| 0.1 + 0.8 * ((i * 37 % 101) as f32 / 100.0))
            .collect();
        Cube::from_vec(16, 12, 3, data).unwrap()
    }

    #[test]
    fn captured_frames_match_the_recorded_checksums() {
        // These belong to version 1 of the captures' model: a change meant to change the frames
        // records new checksums and raises MODEL with them, so that cached captures miss.
        assert_eq!(MODEL, 1);
        let cam = Sensor::new(&SensorConfig::default(), 16, 12).unwrap();
        let p = patterns();
        let target = WhiteTarget {
            patterns: &p,
            exposed_white: &[0.5, 0.7, 0.9],
            full_scale: 1.25,
        };
        let f = calibration_frames(&CaptureConfig::default(), &target, Some(&cam)).unwrap();
        let sum = |c: &Cube| fnv1a_f32(&c.data);
        let got = [
            f.dark.as_ref().unwrap(),
            f.flat.as_ref().unwrap(),
            &f.patterns,
        ]
        .map(sum);
        // Recorded at the commit that added the capture cache.
        let want = [
            0xbf60_7d97_6459_c313,
            0xde17_f4ab_9b40_ef4c,
            0x7fc2_6d55_aad5_0c4e,
        ];
        assert_eq!(got, want, "{got:#x?}");
    }

    #[test]
    fn kept_planes_give_back_the_frames_or_refuse_another_shape() {
        let p = patterns();
        let dark = Cube::from_vec(16, 12, 1, vec![1.0; 192]).unwrap();
        let flat = Cube::from_vec(16, 12, 1, vec![2.0; 192]).unwrap();
        let planes = as_planes(&dark, &flat, &p).unwrap();
        let f = from_planes(planes.clone(), &p, 7).unwrap();
        assert_eq!(f.dark.unwrap().data, dark.data);
        assert_eq!(f.flat.unwrap().data, flat.data);
        assert_eq!(f.patterns.data, p.data);
        assert_eq!((f.frames_averaged, f.source.as_str()), (7, "captures"));
        assert!(!f.patterns_linear);
        let two = Cube::from_vec(16, 12, 2, p.data[..384].to_vec()).unwrap();
        let why = from_planes(planes, &two, 7).unwrap_err();
        assert!(
            why.contains("not a dark, a flat and 2 patterns of 16×12"),
            "{why}"
        );
    }
}
