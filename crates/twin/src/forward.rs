//! The forward model as a list of stages built from the experiment: each stage the experiment
//! asks for is built and run in light-path order; a stage it does not ask for does not exist.

use crate::experiment::Experiment;
use crate::multiplex::multiplex;
use crate::optics::imaging;
use crate::optics::imaging::OpticsConfig;
use crate::optics::light::PatternLight;
use crate::rig::Rig;
use crate::scene;
use crate::scene::Materials;
use crate::scene::Scene;
use crate::scene::{Quantity, SceneConfig};
use crate::sensor::Sensor;
use crate::sensor::SensorConfig;
use crate::timing;
use crate::timing::TimingConfig;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::Carrier;
use specmux_core::Cube;
use std::time::Instant;

/// What flows between stages.
#[derive(Default)]
pub struct State {
    pub scene: Option<Scene>,
    /// x_i: the scene seen through each wheel filter.
    pub channels: Option<Cube>,
    /// White's value in each channel x_i (a white reflector, or the brightest band's scale).
    pub white: Vec<f64>,
    /// z_k = Σ_i w_ik x_i: the light that reaches the sample while pattern k is shown, when the
    /// timing is modelled (None: z = x).
    pub exposed: Option<Cube>,
    /// White's value in each z_k.
    pub exposed_white: Vec<f64>,
    /// s̃_k: the modulation patterns as they reach the sample.
    pub patterns: Option<Cube>,
    /// y: the frame.
    pub frame: Option<Cube>,
    /// The frame value of a white reflector under fully bright patterns (for the sensor's scale).
    pub full_scale: f32,
    /// True once the sensor has turned the frame into raw DN.
    pub raw: bool,
}

/// What a run of the forward model produced: every product a later step may need.
pub struct Simulated {
    pub scene: Scene,
    /// x_i: the scene seen through each wheel filter.
    pub channels: Cube,
    /// z_k = Σ_i w_ik x_i (= x without a timing stage).
    pub exposed: Cube,
    /// z_k of a white reflector: what the white calibration target gives in each slot.
    pub exposed_white: Vec<f64>,
    /// s̃_k: the patterns as they reach the sample.
    pub patterns: Cube,
    /// y: the frame (raw DN when `raw`).
    pub frame: Cube,
    /// The frame value of a white reflector under fully bright patterns.
    pub full_scale: f32,
    pub raw: bool,
}

impl State {
    /// The products of a finished run; names the first one no stage produced.
    fn finish(self) -> Result<Simulated> {
        let need = |what: &str| missing(what, "the end of the pipeline");
        let channels = self.channels.ok_or_else(|| need("channels x_i"))?;
        let (exposed, exposed_white) = match self.exposed {
            Some(z) => (z, self.exposed_white),
            None => (channels.clone(), self.white),
        };
        Ok(Simulated {
            scene: self.scene.ok_or_else(|| need("a scene"))?,
            channels,
            exposed,
            exposed_white,
            patterns: self.patterns.ok_or_else(|| need("patterns s̃_k"))?,
            frame: self.frame.ok_or_else(|| need("a frame"))?,
            full_scale: self.full_scale,
            raw: self.raw,
        })
    }
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
    cfg: SceneConfig,
    file: String,
    materials: Materials,
}

impl Stage for SceneStage {
    fn name(&self) -> &'static str {
        "scene"
    }
    fn describe(&self) -> String {
        let s = &self.cfg;
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
        st.scene = Some(scene::build(&self.cfg, &self.file, &self.materials)?);
        Ok(())
    }
}

/// x_i = ∫ T_i L QE r dλ, exactly for a piecewise-linear cube.
struct WheelStage {
    w: Vec<Vec<f64>>,
    names: Vec<String>,
}

impl WheelStage {
    /// White's value in each channel: the row sums of the projection.
    fn white(&self) -> Vec<f64> {
        self.w.iter().map(|r| r.iter().sum()).collect()
    }
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
        st.white = self.white();
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
        st.patterns = Some(Carrier::ideal_patterns(
            &self.carriers,
            self.width,
            self.height,
        ));
        Ok(())
    }
}

/// s̃_i as the rig images them: DMD dithering, 4f Fourier pinhole filter, lens and pixel
/// integration, only those the experiment asks for (optics/imaging.rs).
struct ImagedPatternStage {
    optics: OpticsConfig,
    carriers: Vec<Carrier>,
    lights: Vec<PatternLight>,
    width: usize,
    height: usize,
}

impl Stage for ImagedPatternStage {
    fn name(&self) -> &'static str {
        "imaged-patterns"
    }
    fn describe(&self) -> String {
        imaging::stage_names(&self.optics, self.width, self.height).join("\n                    ")
    }
    fn run(&self, st: &mut State) -> Result<()> {
        st.patterns = Some(imaging::imaged_patterns(
            &self.optics,
            &self.carriers,
            &self.lights,
            self.width,
            self.height,
        )?);
        Ok(())
    }
}

/// z_k = Σ_i w_ik x_i: the timing of wheel, DMD and exposure mixes the channels that each
/// pattern sees (timing/).
struct TimingStage {
    w: Vec<Vec<f64>>,
    warnings: Vec<String>,
}

impl Stage for TimingStage {
    fn name(&self) -> &'static str {
        "exposure-timing"
    }
    fn describe(&self) -> String {
        let off: f64 = (0..self.w.len())
            .flat_map(|i| (0..self.w.len()).map(move |k| (i, k)))
            .filter(|(i, k)| i != k)
            .map(|(i, k)| self.w[i][k].abs())
            .fold(0.0, f64::max);
        let mut s = format!(
            "z_k = Σ_i w_ik x_i, diagonal {:.4}–{:.4}, largest off-diagonal {:.4}",
            (0..self.w.len())
                .map(|i| self.w[i][i])
                .fold(f64::INFINITY, f64::min),
            (0..self.w.len()).map(|i| self.w[i][i]).fold(0.0, f64::max),
            off
        );
        for w in &self.warnings {
            s += &format!("\n                    warning: {w}");
        }
        s
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let x = st
            .channels
            .as_ref()
            .ok_or_else(|| missing("channels x_i", self.name()))?;
        // mix() takes rows = outputs: z_k = Σ_i (wᵀ)_ki x_i.
        let wt: Vec<Vec<f64>> = (0..self.w[0].len())
            .map(|k| self.w.iter().map(|row| row[k]).collect())
            .collect();
        st.exposed_white = wt
            .iter()
            .map(|r| r.iter().zip(&st.white).map(|(a, b)| a * b).sum())
            .collect();
        st.exposed = Some(x.mix(&wt)?);
        Ok(())
    }
}

/// y = Σ_k z_k ⊙ s̃_k: the monochrome camera sums the modulated images.
struct MultiplexStage;

impl Stage for MultiplexStage {
    fn name(&self) -> &'static str {
        "multiplex"
    }
    fn describe(&self) -> String {
        "y = Σ_k z_k ⊙ s̃_k (z = x without timing; noiseless, unquantised)".into()
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let (x, white) = match &st.exposed {
            Some(z) => (z, &st.exposed_white),
            None => (
                st.channels
                    .as_ref()
                    .ok_or_else(|| missing("channels x_i", self.name()))?,
                &st.white,
            ),
        };
        let s = st
            .patterns
            .as_ref()
            .ok_or_else(|| missing("patterns s_i", self.name()))?;
        let y = multiplex(x, s)?;
        st.full_scale = full_scale(white, s);
        st.frame = Some(y);
        Ok(())
    }
}

/// The frame value of a white reflector where every pattern is at its brightest:
/// Σ_k white_k · max s̃_k. The sensor's "electrons at full scale" refers to it.
pub fn full_scale(white: &[f64], patterns: &Cube) -> f32 {
    white
        .iter()
        .enumerate()
        .map(|(k, w)| *w as f32 * patterns.plane(k).iter().cloned().fold(0.0f32, f32::max))
        .sum()
}

/// The camera: electrons = frame × electrons_at_full_scale / full scale, then the EMVA 1288
/// chain to raw DN (sensor/).
struct SensorStage {
    cfg: SensorConfig,
    sensor: Sensor,
}

impl Stage for SensorStage {
    fn name(&self) -> &'static str {
        "sensor"
    }
    fn describe(&self) -> String {
        let c = &self.cfg;
        format!(
            "EMVA 1288: {} e⁻ at full scale, full well {} e⁻, read noise {:.2} e⁻, dark {:.2} e⁻, \
             PRNU {} %, DSNU {} e⁻, K {} DN/e⁻, offset {} DN, {} bit, seed {}",
            c.electrons_at_full_scale,
            c.full_well_e,
            c.read_noise_e,
            c.dark_electrons(),
            100.0 * c.prnu_fraction,
            c.dsnu_e,
            c.gain_dn_per_e,
            c.black_offset_dn,
            c.bits,
            c.seed
        )
    }
    fn run(&self, st: &mut State) -> Result<()> {
        let y = st
            .frame
            .as_ref()
            .ok_or_else(|| missing("a frame", self.name()))?;
        let e = self.sensor.electrons_from_relative(y, st.full_scale)?;
        st.frame = Some(self.sensor.capture(&e, 0)?);
        st.raw = true;
        Ok(())
    }
}

fn timing_stage(cfg: &TimingConfig) -> Result<TimingStage> {
    let tw = timing::weights(cfg)?;
    Ok(TimingStage {
        w: tw.w,
        warnings: tw.warnings,
    })
}

impl Pipeline {
    /// The stages this experiment needs, in light-path order.
    pub fn build(exp: &Experiment, rig: &Rig, materials: &Materials) -> Result<Pipeline> {
        let w = &rig.projection.w;
        let rows: Vec<Vec<f64>> = w.row_iter().map(|r| r.iter().cloned().collect()).collect();
        let mut stages: Vec<Box<dyn Stage>> = vec![
            Box::new(SceneStage {
                cfg: exp.scene.clone(),
                file: exp.file.clone(),
                materials: materials.clone(),
            }),
            Box::new(WheelStage {
                w: rows,
                names: rig.wheel.filters.iter().map(|f| f.name.clone()).collect(),
            }),
        ];
        stages.push(if exp.rig.has_optics() {
            let optics = exp.rig.optics();
            Box::new(ImagedPatternStage {
                lights: rig.pattern_lights(exp)?,
                optics,
                carriers: rig.imaged_carriers.clone(),
                width: rig.width,
                height: rig.height,
            })
        } else {
            Box::new(IdealPatternStage {
                carriers: rig.imaged_carriers.clone(),
                width: rig.width,
                height: rig.height,
            })
        });
        if let Some(t) = &exp.rig.timing {
            stages.push(Box::new(timing_stage(t)?));
        }
        stages.push(Box::new(MultiplexStage));
        if let Some(c) = &exp.rig.sensor {
            stages.push(Box::new(SensorStage {
                cfg: c.clone(),
                sensor: Sensor::new(c, rig.width, rig.height)?,
            }));
        }
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
    pub fn run(&self) -> Result<(Simulated, Vec<StageTime>)> {
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
        Ok((st.finish()?, times))
    }
}
