//! The forward model as a list of stages built from the experiment: each stage the experiment
//! asks for is built and run in light-path order; a stage it does not ask for does not exist.

use crate::error::{Error, Result};
use crate::optics::Carrier;
use crate::rig::Rig;
use crate::scene::{self, Cube, Experiment, Materials, Quantity, Scene};
use rayon::prelude::*;
use std::time::Instant;

/// What flows between stages.
#[derive(Default)]
pub struct State {
    pub scene: Option<Scene>,
    /// x_i: the scene seen through each wheel filter.
    pub channels: Option<Cube>,
    /// s̃_k: the modulation patterns as they reach the sample.
    pub patterns: Option<Cube>,
    /// y: the frame.
    pub frame: Option<Cube>,
    /// The frame value of a white reflector under fully bright patterns (for the sensor's scale).
    pub full_scale: f32,
}

/// One step of the light path.
pub trait Stage: Send + Sync {
    /// Short name, used in timings and reports.
    fn name(&self) -> &'static str;
    /// One line saying what the stage does with this experiment's values.
    fn describe(&self) -> String;
    fn run(&self, state: &mut State) -> Result<()>;
}

/// Wall time of one stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

/// The built list of stages.
pub struct Pipeline {
    pub stages: Vec<Box<dyn Stage>>,
}

fn missing(what: &str, stage: &str) -> Error {
    Error::Numerical(format!(
        "stage `{stage}` needs {what}, which no earlier stage produced"
    ))
}

/// Builds the scene cube.
struct SceneStage {
    exp: Experiment,
    materials: Materials,
}

impl Stage for SceneStage {
    fn name(&self) -> &'static str {
        "scene"
    }
    fn describe(&self) -> String {
        let s = &self.exp.scene;
        format!(
            "{} {}×{}, {} on {}–{} nm / {} nm, seed {}",
            s.source,
            s.size[0],
            s.size[1],
            match s.quantity {
                Quantity::Reflectance => format!("reflectance under {}", s.illuminant),
                Quantity::Radiance => "radiance".into(),
            },
            s.wavelengths_nm[0],
            s.wavelengths_nm[1],
            s.wavelengths_nm[2],
            s.seed
        )
    }
    fn run(&self, st: &mut State) -> Result<()> {
        st.scene = Some(scene::build(&self.exp, &self.materials)?);
        Ok(())
    }
}

/// x_i = ∫ T_i L QE r dλ, exactly for a piecewise-linear cube.
struct WheelStage {
    w: Vec<Vec<f64>>,
    names: Vec<String>,
}

impl Stage for WheelStage {
    fn name(&self) -> &'static str {
        "colour-wheel"
    }
    fn describe(&self) -> String {
        format!(
            "x_i = ∫ T_i·L·QE·r dλ for filters {}",
            self.names.join(", ")
        )
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let scene = st
            .scene
            .as_ref()
            .ok_or_else(|| missing("a scene", self.name()))?;
        st.channels = Some(scene.cube.mix(&self.w)?);
        Ok(())
    }
}

/// Ideal grey sinusoids s_i = 1 + cos(2π ω_i·p + φ_i): no DMD, no dithering, no 4f stage.
struct IdealPatternStage {
    carriers: Vec<Carrier>,
    width: usize,
    height: usize,
}

impl Stage for IdealPatternStage {
    fn name(&self) -> &'static str {
        "ideal-patterns"
    }
    fn describe(&self) -> String {
        let f: Vec<String> = self
            .carriers
            .iter()
            .map(|c| format!("({}, {})", c.fx, c.fy))
            .collect();
        format!(
            "s_i = 1 + cos(2π ω_i·p + φ_i), ω = {} cycles/px",
            f.join(" ")
        )
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let mut p = Cube::zeros(self.width, self.height, self.carriers.len());
        p.planes_mut()
            .collect::<Vec<_>>()
            .into_par_iter()
            .zip(&self.carriers)
            .for_each(|(plane, c)| {
                plane.copy_from_slice(&c.ideal_pattern(self.width, self.height))
            });
        st.patterns = Some(p);
        Ok(())
    }
}

/// y = Σ_i x_i ⊙ s_i: the monochrome camera sums the modulated images.
struct MultiplexStage {
    white: Vec<f64>,
}

impl Stage for MultiplexStage {
    fn name(&self) -> &'static str {
        "multiplex"
    }
    fn describe(&self) -> String {
        "y = Σ_i x_i ⊙ s_i (noiseless, unquantised)".into()
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let x = st
            .channels
            .as_ref()
            .ok_or_else(|| missing("channels x_i", self.name()))?;
        let s = st
            .patterns
            .as_ref()
            .ok_or_else(|| missing("patterns s_i", self.name()))?;
        x.check_same_shape(s, "channels against patterns")?;
        let mut y = Cube::zeros(x.width, x.height, 1);
        let n = x.pixels();
        y.data
            .par_chunks_mut(4096)
            .enumerate()
            .for_each(|(c, out)| {
                let off = c * 4096;
                for k in 0..x.planes {
                    let (xs, ss) = (
                        &x.plane(k)[off..off + out.len()],
                        &s.plane(k)[off..off + out.len()],
                    );
                    for ((o, a), b) in out.iter_mut().zip(xs).zip(ss) {
                        *o += a * b;
                    }
                }
            });
        debug_assert_eq!(y.data.len(), n);
        let peak = (0..s.planes).map(|k| s.plane(k).iter().cloned().fold(0.0f32, f32::max));
        st.full_scale = self
            .white
            .iter()
            .zip(peak)
            .map(|(w, p)| *w as f32 * p)
            .sum();
        st.frame = Some(y);
        Ok(())
    }
}

impl Pipeline {
    /// The stages this experiment needs, in light-path order.
    pub fn build(exp: &Experiment, rig: &Rig, materials: &Materials) -> Result<Pipeline> {
        let w = &rig.projection.w;
        let rows: Vec<Vec<f64>> = w.row_iter().map(|r| r.iter().cloned().collect()).collect();
        let stages: Vec<Box<dyn Stage>> = vec![
            Box::new(SceneStage {
                exp: exp.clone(),
                materials: materials.clone(),
            }),
            Box::new(WheelStage {
                w: rows.clone(),
                names: rig.wheel.filters.iter().map(|f| f.name.clone()).collect(),
            }),
            Box::new(IdealPatternStage {
                carriers: rig.carriers.clone(),
                width: rig.width,
                height: rig.height,
            }),
            Box::new(MultiplexStage {
                white: rows.iter().map(|r| r.iter().sum()).collect(),
            }),
        ];
        Ok(Pipeline { stages })
    }

    /// One line per stage: what will run.
    pub fn explain(&self) -> String {
        self.stages
            .iter()
            .enumerate()
            .map(|(k, s)| format!("{:>2}. {:<15} {}\n", k + 1, s.name(), s.describe()))
            .collect()
    }

    /// Run every stage in order, timing each.
    pub fn run(&self) -> Result<(State, Vec<StageTime>)> {
        let mut st = State::default();
        let mut times = Vec::new();
        for s in &self.stages {
            let t = Instant::now();
            s.run(&mut st)?;
            times.push(StageTime {
                stage: s.name().to_string(),
                seconds: t.elapsed().as_secs_f64(),
            });
        }
        Ok((st, times))
    }
}
