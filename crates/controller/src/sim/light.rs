//! The light of one simulated exposure, from the twin. The energy E_ip (seconds of light through
//! wheel segment i while picture p is on the mirrors) is integrated over the turns the wheel
//! really made and the pictures the DMD really showed, so a missed pulse, an underrun or a
//! drifting wheel change the frame as they would on the rig (the spot is a point: spoke
//! crossings are instantaneous). The frame is y = Σ_p s̃_p ⊙ Σ_i (N/T)·E_ip·x_i — the twin's
//! y = Σ_k z_k ⊙ s̃_k with its weights w = (N/T)·E — in the twin's units, then the twin's camera.

use crate::devices::{BitPlane, Target};
use crate::error::Result;
use crate::patterns::{self, PictureOptics};
use crate::plan::{timing_of, DeviceLimits};
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::device::OpenDevice;
use specmux_twin::forward::Pipeline;
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::scene::{self, Materials};
use specmux_twin::sensor::Sensor;
use specmux_twin::{Experiment, Rig};
use std::collections::{HashMap, VecDeque};

use super::dmd::{Picture, Shown};

/// E_ip in seconds for every picture p lit during [a, b): light through segment i (point spot)
/// while p was on the mirrors. Dark pictures are left out.
pub(crate) fn energies(
    turns: &VecDeque<(u64, u64)>,
    segments: &[(f64, f64)],
    shown: &VecDeque<Shown>,
    a: u64,
    b: u64,
) -> Vec<(Picture, Vec<f64>)> {
    let mut out: Vec<(Picture, Vec<f64>)> = Vec::new();
    for s in shown.iter().filter(|s| s.picture != Picture::Dark) {
        let (u, v) = (s.start.max(a) as f64, s.end.min(b) as f64);
        if u >= v {
            continue;
        }
        let slot = match out.iter().position(|(p, _)| *p == s.picture) {
            Some(k) => k,
            None => {
                out.push((s.picture, vec![0.0; segments.len()]));
                out.len() - 1
            }
        };
        for &(t0, t1) in turns {
            let (t0, period) = (t0 as f64, (t1 - t0) as f64);
            for (i, &(f, l)) in segments.iter().enumerate() {
                let (c, d) = (t0 + f * period, t0 + (f + l) * period);
                let overlap = d.min(v) - c.max(u);
                if overlap > 0.0 {
                    out[slot].1[i] += overlap * 1e-9;
                }
            }
        }
    }
    out
}

/// The twin's side of the simulated rig: the scene through the wheel (x_i), the imaged patterns
/// s̃_k, the scale to electrons and the camera.
pub struct Light {
    exp: Experiment,
    materials: Materials,
    /// The projection cube → channels, one row per wheel filter.
    rows: Vec<Vec<f64>>,
    white: Vec<f64>,
    patterns: Cube,
    /// N / T: the twin's normalisation of the exposure weights.
    per_second: f64,
    electrons_per_unit: f32,
    sensor: Sensor,
    /// The scene and its channels when nothing moves.
    still: Option<(Cube, Cube)>,
    pictures: HashMap<BitPlane, Picture>,
    /// `[compute] device`, as the twin's forward model opened it.
    device: OpenDevice,
}

impl Light {
    /// Run the twin's forward model once for the patterns and scales; build the camera.
    pub fn new(exp: &Experiment, lib: &Library) -> Result<(Light, Rig)> {
        let materials = Materials::load(lib)?;
        let rig = Rig::build(exp, lib, &materials)?;
        let pipeline =
            Pipeline::build(exp, &rig, &materials)?.with_pattern_cache(PatternCache::from_env()?);
        let (sim, _) = pipeline.run()?;
        let timing = timing_of(exp);
        let mut cfg = exp.rig.sensor.clone().unwrap_or_default();
        cfg.exposure_s = timing.camera.exposure_s;
        let sensor = Sensor::new(&cfg, rig.width, rig.height)?;
        let rows: Vec<Vec<f64>> = rig
            .projection
            .w
            .row_iter()
            .map(|r| r.iter().cloned().collect())
            .collect();
        // The pictures the controller uploads (plan.rs), each to what the twin images it as.
        let limits = DeviceLimits::of_twin(exp);
        let optics = PictureOptics::of(exp, limits.dmd_width, limits.dmd_height);
        let mut pictures = HashMap::new();
        for (k, p) in patterns::carrier_pictures(&rig.carriers, &optics, rig.width, rig.height)?
            .into_iter()
            .enumerate()
        {
            pictures.entry(p).or_insert(Picture::Pattern(k));
        }
        let (dw, dh) = (optics.dmd.width, optics.dmd.height);
        pictures.insert(BitPlane::uniform(dw, dh, false), Picture::Dark);
        pictures.insert(BitPlane::uniform(dw, dh, true), Picture::Bright);
        let still = (!exp.scene.moves()).then(|| (sim.scene.cube.clone(), sim.channels.clone()));
        let light = Light {
            exp: exp.clone(),
            materials,
            rows,
            white: rig.white(),
            per_second: timing.segment_count() as f64 / timing.camera.exposure_s,
            electrons_per_unit: (cfg.electrons_at_full_scale / sim.full_scale as f64) as f32,
            patterns: sim.patterns,
            sensor,
            still,
            pictures,
            device: pipeline.device().clone(),
        };
        Ok((light, rig))
    }

    /// The device the twin's forward model opened (`[compute] device`).
    pub(crate) fn device(&self) -> &OpenDevice {
        &self.device
    }

    /// Which binary picture images to what (the DMD's lookup).
    pub(crate) fn picture_table(&self) -> HashMap<BitPlane, Picture> {
        self.pictures.clone()
    }

    /// The true cube at scene time `t_s`.
    pub fn truth_at(&self, t_s: f64) -> Result<Cube> {
        if let Some((cube, _)) = &self.still {
            return Ok(cube.clone());
        }
        Ok(scene::build_at(&self.exp.scene, &self.exp.file, &self.materials, t_s)?.cube)
    }

    /// x_i at scene time `t_s`.
    fn channels_at(&self, t_s: f64) -> Result<Cube> {
        if let Some((_, x)) = &self.still {
            return Ok(x.clone());
        }
        Ok(self.truth_at(t_s)?.mix(&self.rows)?)
    }

    /// The raw frame (DN) of an exposure with energies `e` of `target` at scene time `t_s`;
    /// frame `id` draws its own noise.
    pub fn frame(
        &self,
        e: &[(Picture, Vec<f64>)],
        target: Target,
        t_s: f64,
        id: u64,
    ) -> Result<Vec<u16>> {
        let (w, h) = (self.patterns.width, self.patterns.height);
        let mut y = Cube::zeros(w, h, 1);
        let x = match target {
            Target::Scene if !e.is_empty() => Some(self.channels_at(t_s)?),
            _ => None,
        };
        for (picture, ei) in e {
            let c: Vec<f32> = ei.iter().map(|v| (v * self.per_second) as f32).collect();
            let s = match picture {
                Picture::Pattern(k) => Some(self.patterns.plane(*k)),
                _ => None,
            };
            match &x {
                Some(x) => add_scene(&mut y.data, x, &c, s),
                None => {
                    let z: f32 = c.iter().zip(&self.white).map(|(c, w)| c * *w as f32).sum();
                    add_uniform(&mut y.data, z, s);
                }
            }
        }
        y.data
            .iter_mut()
            .for_each(|v| *v = v.max(0.0) * self.electrons_per_unit);
        let raw = self.sensor.capture(&y, id)?;
        Ok(raw
            .data
            .iter()
            .map(|&v| v.clamp(0.0, u16::MAX as f32) as u16)
            .collect())
    }
}

/// y += s ⊙ Σ_i c_i x_i (s = 1 without a pattern).
fn add_scene(y: &mut [f32], x: &Cube, c: &[f32], s: Option<&[f32]>) {
    for (p, out) in y.iter_mut().enumerate() {
        let z: f32 = c.iter().enumerate().map(|(i, ci)| ci * x.plane(i)[p]).sum();
        *out += z * s.map_or(1.0, |s| s[p]);
    }
}

/// y += z·s (s = 1 without a pattern).
fn add_uniform(y: &mut [f32], z: f32, s: Option<&[f32]>) {
    match s {
        Some(s) => y.iter_mut().zip(s).for_each(|(o, s)| *o += z * s),
        None => y.iter_mut().for_each(|o| *o += z),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn energies_of_an_aligned_turn_are_one_segment_each() {
        // One 6 µs turn of six equal segments; pattern k shown exactly in segment k.
        let turns: VecDeque<(u64, u64)> = [(0, 6000), (6000, 12000)].into_iter().collect();
        let segments: Vec<(f64, f64)> = (0..6).map(|i| (i as f64 / 6.0, 1.0 / 6.0)).collect();
        let shown: VecDeque<Shown> = (0..12)
            .map(|k| Shown {
                start: k * 1000,
                end: (k + 1) * 1000,
                picture: Picture::Pattern((k % 6) as usize),
            })
            .collect();
        let e = energies(&turns, &segments, &shown, 0, 12000);
        assert_eq!(e.len(), 6);
        for (p, row) in &e {
            let Picture::Pattern(k) = p else {
                panic!("{p:?}")
            };
            for (i, v) in row.iter().enumerate() {
                let expect = if i == *k { 2e-6 } else { 0.0 };
                assert!((v - expect).abs() < 1e-15, "E[{i}][{k}] = {v}");
            }
        }
        // Half the window: half the light; dark pictures carry none.
        let half = energies(&turns, &segments, &shown, 0, 6000);
        assert!((half[0].1[0] - 1e-6).abs() < 1e-15);
        let dark: VecDeque<Shown> = [Shown {
            start: 0,
            end: 6000,
            picture: Picture::Dark,
        }]
        .into_iter()
        .collect();
        assert!(energies(&turns, &segments, &dark, 0, 6000).is_empty());
    }
}
