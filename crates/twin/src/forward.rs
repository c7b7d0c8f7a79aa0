//! The forward model as a fixed sequence of typed steps built from the experiment:
//! scene → channels → patterns (ideal, or the optical chain's steps) → exposure (optional
//! timing) → frame → optional sensor. Each step takes its input by type, so no step can run
//! before the one that makes its input; a step the experiment does not ask for is not built.

use crate::device::OpenDevice;
use crate::experiment::Experiment;
use crate::multiplex::{for_device, Multiplexer};
use crate::optics::fourier_filter::FourierFilterConfig;
use crate::optics::imaging;
use crate::optics::imaging::{Chain, Display, ImageSpectrum, IntensitySpectrum};
use crate::optics::psf::LensConfig;
use crate::optics::relay::pair_summer_for;
use crate::pattern_cache::{Entry, PatternCache};
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
use std::sync::Arc;
use std::time::Instant;

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

/// A step's name and what it does with this experiment's values.
pub trait Stage: Send + Sync {
    /// Short name, used in timings and reports.
    fn name(&self) -> &'static str;
    /// One line saying what the stage does with this experiment's values.
    fn describe(&self) -> String;
}

/// A step of the light path: it turns its input into its output, and cannot run without it.
pub trait Step<In, Out>: Stage {
    fn run(&self, input: &In) -> Result<Out>;
}

/// Wall time of one stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTime {
    pub stage: String,
    pub seconds: f64,
}

impl StageTime {
    /// The wall time of `stage` from `start` until now.
    pub fn since(stage: &str, start: Instant) -> StageTime {
        StageTime {
            stage: stage.to_string(),
            seconds: start.elapsed().as_secs_f64(),
        }
    }
}

/// What `load` finds in a cache, else what `make` makes (its own stages added to `times`), then
/// `store`d; the lookup and the write timed as `stage`, after `make`'s.
pub fn kept_or_made<T>(
    times: &mut Vec<StageTime>,
    stage: &str,
    load: impl FnOnce() -> Result<Option<T>>,
    make: impl FnOnce(&mut Vec<StageTime>) -> Result<T>,
    store: impl FnOnce(&T) -> Result<()>,
) -> Result<T> {
    let t = Instant::now();
    let found = load()?;
    let mut seconds = t.elapsed().as_secs_f64();
    let value = match found {
        Some(v) => v,
        None => {
            let v = make(times)?;
            let t = Instant::now();
            store(&v)?;
            seconds += t.elapsed().as_secs_f64();
            v
        }
    };
    let stage = stage.to_string();
    times.push(StageTime { stage, seconds });
    Ok(value)
}

/// x_i: the scene seen through each wheel filter, and white's value in each.
pub struct Channels {
    pub x: Cube,
    pub white: Vec<f64>,
}

/// z_k = Σ_i w_ik x_i: the light that reaches the sample while pattern k is shown, and white's
/// value in each.
pub struct Exposed {
    pub z: Cube,
    pub white: Vec<f64>,
}

/// What the camera sums: the exposed channels and the patterns that modulate them.
pub struct Modulated<'a> {
    pub exposed: &'a Exposed,
    pub patterns: &'a Cube,
}

/// y: the frame, and the value of a white reflector under fully bright patterns.
pub struct Frame {
    pub y: Cube,
    pub full_scale: f32,
}

/// The built steps, in light-path order.
pub struct Pipeline {
    scene: SceneStage,
    wheel: WheelStage,
    patterns: PatternSteps,
    timing: Option<TimingStage>,
    multiplex: MultiplexStage,
    sensor: Option<SensorStage>,
    /// `[compute] device`, opened once: the multiplex and the relay hold its context, and the
    /// run's reconstruction ([`crate::run::run_in`]) uses it too.
    device: OpenDevice,
}

/// How the patterns are made.
enum PatternSteps {
    /// Ideal grey sinusoids: no optical stage asked for.
    Ideal(IdealPatternStage),
    /// The optical chain, one stage per physical step.
    Imaged(OpticalSteps),
}

/// The optical chain's stages: what the modulator shows, the relay, the lens (optional), the
/// sensor pixels; with a pattern cache, its lookup first.
struct OpticalSteps {
    cache: Option<PatternCacheStage>,
    modulator: ModulatorStage,
    relay: RelayStage,
    lens: Option<LensStage>,
    sampling: PixelSamplingStage,
}

/// Runs `step` on `input`, appending its wall time to `times`; stops first on Ctrl-C.
fn timed<In, Out>(times: &mut Vec<StageTime>, step: &dyn Step<In, Out>, input: &In) -> Result<Out> {
    specmux_core::interrupt::check(&format!("the {} stage", step.name()))?;
    let t = Instant::now();
    let out = step.run(input)?;
    times.push(StageTime::since(step.name(), t));
    Ok(out)
}

impl Pipeline {
    /// The stages this experiment needs, in light-path order.
    pub fn build(exp: &Experiment, rig: &Rig, materials: &Materials) -> Result<Pipeline> {
        let device = exp.open_device()?;
        let w = &rig.projection.w;
        let rows: Vec<Vec<f64>> = w.row_iter().map(|r| r.iter().cloned().collect()).collect();
        let patterns = if exp.rig.has_optics() {
            let chain = rig.chain(exp)?.with_pair_summer(pair_summer_for(&device));
            PatternSteps::Imaged(OpticalSteps::new(Arc::new(chain)))
        } else {
            PatternSteps::Ideal(IdealPatternStage {
                carriers: rig.imaged_carriers.clone(),
                width: rig.width,
                height: rig.height,
            })
        };
        Ok(Pipeline {
            scene: SceneStage {
                cfg: exp.scene.clone(),
                file: exp.file.clone(),
                materials: materials.clone(),
            },
            wheel: WheelStage {
                w: rows,
                names: rig.wheel.filters.iter().map(|f| f.name.clone()).collect(),
            },
            patterns,
            timing: exp.rig.timing.as_ref().map(timing_stage).transpose()?,
            multiplex: MultiplexStage {
                device: for_device(&device, (rig.width, rig.height, rig.imaged_carriers.len()))
                    .map_err(|e| exp.on_device(e))?,
                timed: exp.rig.timing.is_some(),
            },
            sensor: match &exp.rig.sensor {
                Some(c) => Some(SensorStage {
                    cfg: c.clone(),
                    sensor: Sensor::new(c, rig.width, rig.height)?,
                }),
                None => None,
            },
            device,
        })
    }

    /// The device `[compute] device` named, as opened for this pipeline.
    pub fn device(&self) -> &OpenDevice {
        &self.device
    }

    /// The pipeline with its imaged patterns kept in `cache` (None, as built: none; the command
    /// line passes `PatternCache::from_env()`); ideal patterns are not cached (they cost
    /// milliseconds).
    pub fn with_pattern_cache(mut self, cache: Option<PatternCache>) -> Pipeline {
        if let PatternSteps::Imaged(o) = &mut self.patterns {
            o.keep_in(cache);
        }
        self
    }

    /// The stages that will run, in order.
    pub fn stages(&self) -> Vec<&dyn Stage> {
        let mut out: Vec<&dyn Stage> = vec![&self.scene, &self.wheel];
        match &self.patterns {
            PatternSteps::Ideal(s) => out.push(s),
            PatternSteps::Imaged(o) => {
                if let Some(c) = &o.cache {
                    out.push(c);
                }
                out.push(&o.modulator);
                out.push(&o.relay);
                if let Some(l) = &o.lens {
                    out.push(l);
                }
                out.push(&o.sampling);
            }
        }
        if let Some(t) = &self.timing {
            out.push(t);
        }
        out.push(&self.multiplex);
        if let Some(s) = &self.sensor {
            out.push(s);
        }
        out
    }

    /// One line per stage: what will run.
    pub fn explain(&self) -> String {
        self.stages()
            .iter()
            .enumerate()
            .map(|(k, s)| format!("{:>2}. {:<20} {}\n", k + 1, s.name(), s.describe()))
            .collect()
    }

    /// Run every stage in order, timing each.
    pub fn run(&self) -> Result<(Simulated, Vec<StageTime>)> {
        self.run_stages().map_err(|e| e.in_file(&self.scene.file))
    }

    /// [`Pipeline::run`], its optics' refusals not yet named by the experiment's file.
    fn run_stages(&self) -> Result<(Simulated, Vec<StageTime>)> {
        let mut times = Vec::new();
        let scene = timed(&mut times, &self.scene, &())?;
        let channels = timed(&mut times, &self.wheel, &scene)?;
        let patterns = self.patterns.run(&mut times)?;
        let exposed = match &self.timing {
            Some(t) => timed(&mut times, t, &channels)?,
            None => Exposed {
                z: channels.x.clone(),
                white: channels.white.clone(),
            },
        };
        let modulated = Modulated {
            exposed: &exposed,
            patterns: &patterns,
        };
        let frame = timed(&mut times, &self.multiplex, &modulated)?;
        self.scene.check_light(&frame.y)?;
        let full_scale = frame.full_scale;
        let (frame, raw) = match &self.sensor {
            Some(s) => (timed(&mut times, s, &frame)?, true),
            None => (frame.y, false),
        };
        let sim = Simulated {
            scene,
            channels: channels.x,
            exposed: exposed.z,
            exposed_white: exposed.white,
            patterns,
            frame,
            full_scale,
            raw,
        };
        Ok((sim, times))
    }
}

impl PatternSteps {
    /// s̃_k: the ideal patterns, or the optical chain's stages one after the other.
    fn run(&self, times: &mut Vec<StageTime>) -> Result<Cube> {
        match self {
            PatternSteps::Ideal(s) => timed(times, s, &()),
            PatternSteps::Imaged(o) => match &o.cache {
                Some(c) => c.run(times, |times| o.run(times)),
                None => o.run(times),
            },
        }
    }
}

impl OpticalSteps {
    /// Keep the patterns in `cache` (None: no cache), looked up under the chain's key.
    fn keep_in(&mut self, cache: Option<PatternCache>) {
        self.cache = cache.map(|cache| PatternCacheStage {
            cache,
            key: self.sampling.chain.cache_key(),
        });
    }

    /// s̃_k through every optical stage.
    fn run(&self, times: &mut Vec<StageTime>) -> Result<Cube> {
        let displays = timed(times, &self.modulator, &())?;
        let spectra = timed(times, &self.relay, &displays)?;
        match &self.lens {
            Some(l) => {
                let images = timed(times, l, &spectra)?;
                timed(times, &self.sampling, &images)
            }
            None => timed(times, &self.sampling, &spectra),
        }
    }
}

/// The pattern cache's lookup: s̃_k read from its file when the chain's key is there, else made
/// by the optical stages and kept (pattern_cache.rs).
struct PatternCacheStage {
    cache: PatternCache,
    /// The chain's `cache_key`, made once.
    key: String,
}

impl Stage for PatternCacheStage {
    fn name(&self) -> &'static str {
        "pattern-cache"
    }
    fn describe(&self) -> String {
        let place = self.cache.place(Entry::Patterns, &self.key);
        match self.cache.holds(Entry::Patterns, &self.key) {
            true => format!(
                "s̃_k read from {} (an earlier run of this chain left it there; the optical stages below do not run unless it holds another chain)",
                place.display()
            ),
            false => format!(
                "no s̃_k in {} yet: the optical stages below run and s̃_k is kept there",
                place.display()
            ),
        }
    }
}

impl PatternCacheStage {
    /// The cached patterns, or those `image` makes, then kept; the lookup and the write are
    /// timed as this stage.
    fn run(
        &self,
        times: &mut Vec<StageTime>,
        image: impl FnOnce(&mut Vec<StageTime>) -> Result<Cube>,
    ) -> Result<Cube> {
        kept_or_made(
            times,
            self.name(),
            || self.cache.load(Entry::Patterns, &self.key),
            image,
            |p| self.cache.store(Entry::Patterns, &self.key, p),
        )
    }
}

/// Builds the scene cube.
struct SceneStage {
    cfg: SceneConfig,
    file: String,
    materials: Materials,
}

impl SceneStage {
    /// The light the scene sends to the camera, refused by `scene.source` where it overflows f32
    /// (a scene's values near f32's largest); the sensor and the reconstruction need it finite.
    fn check_light(&self, light: &Cube) -> Result<()> {
        match light.data.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(p) => {
                let (_, x, y) = light.place(p);
                Err(Error::config(
                    &self.file,
                    "scene.source",
                    &self.cfg.source,
                    &format!("the light on the camera overflows f32 at pixel ({x}, {y}): scale the scene's values down"),
                ))
            }
        }
    }
}

impl Stage for SceneStage {
    fn name(&self) -> &'static str {
        "scene"
    }
    fn describe(&self) -> String {
        let s = &self.cfg;
        // A seed draws a procedural scene; a file's cube has none.
        let seed = match s.source.contains(':') {
            true => String::new(),
            false => format!(", seed {}", s.seed),
        };
        format!(
            "{} {}×{}, {} on {}–{} nm / {} nm{seed}",
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
        )
    }
}

impl Step<(), Scene> for SceneStage {
    fn run(&self, _: &()) -> Result<Scene> {
        scene::build(&self.cfg, &self.file, &self.materials)
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
}

impl Step<Scene, Channels> for WheelStage {
    fn run(&self, scene: &Scene) -> Result<Channels> {
        Ok(Channels {
            x: scene.cube.mix(&self.w)?,
            // White's value in each channel: the row sums of the projection.
            white: self.w.iter().map(|r| r.iter().sum()).collect(),
        })
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
}

impl Step<(), Cube> for IdealPatternStage {
    fn run(&self, _: &()) -> Result<Cube> {
        Ok(Carrier::ideal_patterns(
            &self.carriers,
            self.width,
            self.height,
        ))
    }
}

impl OpticalSteps {
    /// One stage per physical step of `chain`'s optics; the lens only with `[rig.lens]`; no
    /// pattern cache yet (`OpticalSteps::keep_in` adds one).
    fn new(chain: Arc<Chain>) -> OpticalSteps {
        let cfg = chain.config();
        OpticalSteps {
            cache: None,
            modulator: ModulatorStage {
                chain: chain.clone(),
            },
            relay: RelayStage {
                filter: cfg.fourier_filter.clone(),
                chain: chain.clone(),
            },
            lens: cfg.lens.clone().map(|lens| LensStage {
                lens,
                chain: chain.clone(),
            }),
            sampling: PixelSamplingStage { chain },
        }
    }
}

/// What the modulator shows for each pattern: the DMD's dither of the grey target s_i/2, or
/// the target itself on an ideal grey modulator (optics/imaging.rs, optics/dither.rs).
struct ModulatorStage {
    chain: Arc<Chain>,
}

impl Stage for ModulatorStage {
    fn name(&self) -> &'static str {
        match self.chain.config().dmd {
            Some(_) => "dmd-dither",
            None => "grey-modulator",
        }
    }
    fn describe(&self) -> String {
        match &self.chain.config().dmd {
            Some(d) => format!("s_i/2 on {}", imaging::describe_dmd(d)),
            None => format!(
                "s_i/2 shown as is: {}",
                imaging::describe_grey_modulator(self.chain.modulator())
            ),
        }
    }
}

impl Step<(), Vec<Display>> for ModulatorStage {
    fn run(&self, _: &()) -> Result<Vec<Display>> {
        self.chain.dither()
    }
}

/// The 4f relay: the intensity spectrum past the Fourier mask (its moment spectra over the
/// light), or without a filter the modulator's whole spectrum (optics/relay.rs).
struct RelayStage {
    filter: Option<FourierFilterConfig>,
    chain: Arc<Chain>,
}

impl Stage for RelayStage {
    fn name(&self) -> &'static str {
        match self.filter {
            Some(_) => "relay-fourier-filter",
            None => "modulator-spectrum",
        }
    }
    fn describe(&self) -> String {
        match &self.filter {
            Some(f) => format!(
                "{}; {}",
                imaging::describe_filter(f, self.chain.modulator()),
                self.chain.describe_pairs()
            ),
            None => "no Fourier filter: the modulator's whole band-limited spectrum".into(),
        }
    }
}

impl Step<Vec<Display>, Vec<IntensitySpectrum>> for RelayStage {
    fn run(&self, displays: &Vec<Display>) -> Result<Vec<IntensitySpectrum>> {
        match &self.filter {
            Some(f) => self.chain.relay_filtered(f, displays),
            None => Ok(self.chain.relay_open(displays)),
        }
    }
}

/// The projection lens and the pixel box applied to the relay's intensity (optics/psf.rs).
struct LensStage {
    lens: LensConfig,
    chain: Arc<Chain>,
}

impl Stage for LensStage {
    fn name(&self) -> &'static str {
        "lens"
    }
    fn describe(&self) -> String {
        imaging::describe_lens(&self.lens, self.chain.modulator())
    }
}

impl Step<Vec<IntensitySpectrum>, Vec<ImageSpectrum>> for LensStage {
    fn run(&self, spectra: &Vec<IntensitySpectrum>) -> Result<Vec<ImageSpectrum>> {
        Ok(self.chain.lens(Some(&self.lens), spectra))
    }
}

/// s̃_k at the sensor pixels: inverse FFT, Keys cubic resampling and normalisation by the mean.
/// Without a lens stage it takes the relay's intensity as the image, unblurred.
struct PixelSamplingStage {
    chain: Arc<Chain>,
}

impl Stage for PixelSamplingStage {
    fn name(&self) -> &'static str {
        "pixel-sampling"
    }
    fn describe(&self) -> String {
        let (w, h) = self.chain.sensor_size();
        let unblurred = match self.chain.config().lens {
            Some(_) => "",
            None => " (no lens: the relay's image unblurred, one pixel per mirror)",
        };
        format!(
            "inverse FFT, Keys cubic resampling onto {w}×{h} sensor pixels, s̃ normalised to the ideal pattern's mean{unblurred}"
        )
    }
}

impl Step<Vec<ImageSpectrum>, Cube> for PixelSamplingStage {
    fn run(&self, images: &Vec<ImageSpectrum>) -> Result<Cube> {
        self.chain.pixel_sampling(images)
    }
}

impl Step<Vec<IntensitySpectrum>, Cube> for PixelSamplingStage {
    fn run(&self, spectra: &Vec<IntensitySpectrum>) -> Result<Cube> {
        self.chain.pixel_sampling(&self.chain.lens(None, spectra))
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
            s += &format!("\n                         warning: {w}");
        }
        s
    }
}

impl Step<Channels, Exposed> for TimingStage {
    fn run(&self, x: &Channels) -> Result<Exposed> {
        // mix() takes rows = outputs: z_k = Σ_i (wᵀ)_ki x_i.
        let wt: Vec<Vec<f64>> = (0..self.w[0].len())
            .map(|k| self.w.iter().map(|row| row[k]).collect())
            .collect();
        Ok(Exposed {
            white: wt
                .iter()
                .map(|r| r.iter().zip(&x.white).map(|(a, b)| a * b).sum())
                .collect(),
            z: x.x.mix(&wt)?,
        })
    }
}

/// y = Σ_k z_k ⊙ s̃_k: the monochrome camera sums the modulated images, on the device
/// `[compute] device` names.
struct MultiplexStage {
    device: Box<dyn Multiplexer>,
    /// Whether z is the timing stage's exposed channels (else the wheel's x).
    timed: bool,
}

impl Stage for MultiplexStage {
    fn name(&self) -> &'static str {
        "multiplex"
    }
    fn describe(&self) -> String {
        let z = match self.timed {
            true => "z the exposed channels",
            false => "z = x, no [rig.timing]",
        };
        let device = self.device.device().to_uppercase();
        format!("y = Σ_k z_k ⊙ s̃_k ({z}), noiseless and unquantised, on the {device}")
    }
}

impl<'a> Step<Modulated<'a>, Frame> for MultiplexStage {
    fn run(&self, m: &Modulated<'a>) -> Result<Frame> {
        Ok(Frame {
            y: self.device.multiplex(&m.exposed.z, m.patterns)?,
            full_scale: full_scale(&m.exposed.white, m.patterns),
        })
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
}

impl Step<Frame, Cube> for SensorStage {
    fn run(&self, f: &Frame) -> Result<Cube> {
        let e = self.sensor.electrons_from_relative(&f.y, f.full_scale)?;
        self.sensor.capture(&e, 0)
    }
}

/// The exposure-timing stage: the weights w_ik and the timing model's warnings.
fn timing_stage(cfg: &TimingConfig) -> Result<TimingStage> {
    let tw = timing::weights(cfg)?;
    Ok(TimingStage {
        w: tw.w,
        warnings: tw.warnings,
    })
}

/// The forward model on a device, for the GPU tests of its stages.
#[cfg(all(test, feature = "gpu"))]
pub(crate) mod gpu_tests {
    use super::Pipeline;
    use crate::experiment::Experiment;
    use crate::rig::Rig;
    use crate::scene::Materials;
    use specmux_core::Cube;

    /// A GPU context, or None (said in one line) when no adapter opens; any other failure to
    /// open one fails the test.
    pub fn context() -> Option<specmux_gpu::GpuContext> {
        match specmux_gpu::GpuContext::new() {
            Ok(ctx) => Some(ctx),
            Err(specmux_gpu::GpuError::NoAdapter(e)) => {
                eprintln!("no GPU adapter found ({e}): GPU test skipped");
                None
            }
            Err(e) => panic!("a GPU adapter exists but could not be opened: {e}"),
        }
    }

    /// The frame and the stages' lines of a 48 × 40 scene through `rig` (TOML sections) with
    /// `[compute] device`; None (said in one line) when no GPU adapter opens.
    pub fn run(rig: &str, device: &str) -> Option<(Cube, String)> {
        context()?;
        let toml = format!("[scene]\nsize = [48, 40]\n{rig}[compute]\ndevice = \"{device}\"\n");
        let exp = Experiment::from_toml(&toml, "t.toml").unwrap();
        let lib = specmux_core::spectral::Library::default_root();
        let materials = Materials::load(&lib).unwrap();
        let rig = Rig::build(&exp, &lib, &materials).unwrap();
        let p = Pipeline::build(&exp, &rig, &materials).unwrap();
        Some((p.run().unwrap().0.frame, p.explain()))
    }

    /// `[compute] device = "gpu"` sums the relay's pairs on the GPU (the stage says so: this rig's
    /// relays pass fewer bins than slicing starts at) and
    /// gives the CPU's frame within 1e-5 NRMSE: the pair sums' bound, which the lens and the
    /// resampling (linear, norm ≤ 1 per pattern) do not amplify. DMD 64 × 48, line light: the
    /// wheel's bands pass 7–19 thousand bins a pattern, whose sums took lavapipe 12 minutes
    /// (the CPU a few seconds; docs/gpu.md); `imaging`'s relay test sums band light on the GPU.
    #[test]
    fn the_forward_model_with_gpu_pair_sums_gives_the_cpus_frame() {
        let rig = "[rig.dmd]\nwidth = 64\nheight = 48\n[rig.fourier_filter]\nlight = \"line\"\n\
                   [rig.lens]\n";
        let Some((cpu, explain)) = run(rig, "cpu") else {
            return;
        };
        assert!(explain.contains("pair sums on the CPU"), "{explain}");
        let (gpu, explain) = run(rig, "gpu").unwrap();
        assert!(explain.contains("pair sums on the GPU"), "{explain}");
        let e = specmux_core::metrics::compare(&cpu, &gpu).unwrap().nrmse;
        eprintln!("forward model frame, GPU pair sums and multiplex against CPU: NRMSE {e:.2e}");
        assert!(e < 1e-5, "{e:.2e}");
    }
}
