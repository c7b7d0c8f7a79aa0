//! Runs an experiment end to end — forward model, reconstruction, error against the truth — and
//! gathers every figure with its wall time into one report.

use crate::captures::{self, CaptureConfig, KeptCaptures, WhiteTarget};
use crate::device::DeviceReconstructor;
use crate::experiment::Experiment;
use crate::forward::{kept_or_made, Pipeline, Simulated, StageTime};
use crate::pattern_cache::PatternCache;
use crate::rig::Rig;
use crate::scene::Materials;
use crate::sensor::Sensor;
use serde::Serialize;
use specmux_core::auto;
use specmux_core::calibration::{self, Calibration, CalibrationFrames, MeasuredCarrier};
use specmux_core::crosstalk::{self, ErrorBudget};
use specmux_core::demux::{Demux, SUPER_GAUSSIAN_ORDER};
use specmux_core::gap::Method;
use specmux_core::metrics::{self, Metrics};
use specmux_core::noise::reads_saturation;
use specmux_core::reconstructor::{Reconstruction, Reconstructor};
use specmux_core::spectral::basis::BasisFit;
use specmux_core::spectral::Library;
use specmux_core::unmix::UnmixStats;
use specmux_core::{Cube, Error, Result};
use std::time::Instant;

/// The rows of [`RunReport::results`], in their order: what each measures, for code that reads
/// one (the printed wording is for people).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Row {
    /// x̂ against the true channels.
    Demultiplexed,
    /// The de-aliased channels (GAP, GAP-TV, the joint method's Fα; x̂ again for Fourier).
    Dealiased,
    /// Each channel through its crop window alone.
    CropBound,
    /// The final cube against the true cube.
    Cube,
    /// The true channels unmixed: the spectral limit.
    SpectralLimit,
}

/// One row of the result table: an estimate against its truth, and what it cost.
#[derive(Clone, Debug, Serialize)]
pub struct ResultRow {
    pub stage: String,
    pub against: String,
    pub psnr_db: f64,
    pub ssim: f64,
    pub nrmse: f64,
    pub sam_deg: Option<f64>,
    pub seconds: f64,
    /// Why these figures are less than they seem (degenerate estimate, undefined SAM).
    pub flags: Vec<String>,
}

/// Demultiplexing of one channel against the best its crop window could do alone.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelRow {
    pub channel: usize,
    pub filter: String,
    pub carrier: [f64; 2],
    /// The demultiplexed channel x̂ against the true channel.
    pub psnr_db: f64,
    pub ssim: f64,
    /// The channel after de-aliasing (GAP, GAP-TV, the joint method's Fα; x̂ for `fourier`),
    /// the one the cube is unmixed from, against the true channel.
    pub final_psnr_db: f64,
    pub bound_psnr_db: f64,
    pub bound_ssim: f64,
    /// |ĝ|/½: the carrier amplitude the demultiplexer divides by, against the ideal pattern's
    /// (1 for ideal sinusoids; measured on the imaged patterns otherwise).
    pub carrier_gain: f64,
}

/// What the frame holds that a figure of merit cannot show: pixels at the ADC's top (the
/// camera's saturation), and non-finite values.
#[derive(Clone, Debug, Serialize)]
pub struct FrameStats {
    pub pixels: usize,
    /// Pixels that read the camera's saturation level, rounded to the DN (raw frames only).
    pub saturated_pixels: usize,
    pub non_finite_pixels: usize,
    /// Mean signal above dark over the noise at that signal (`NoiseModel::mean_snr`); absent
    /// without a camera.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_snr: Option<f64>,
}

impl FrameStats {
    /// Count on `frame`; `saturation_dn` is the raw frame's ceiling (None for a linear frame);
    /// `mean_snr` is the frame's, when a camera recorded it.
    pub fn of(frame: &Cube, saturation_dn: Option<f64>, mean_snr: Option<f64>) -> FrameStats {
        FrameStats {
            mean_snr,
            pixels: frame.data.len(),
            saturated_pixels: match saturation_dn {
                Some(s) => frame
                    .data
                    .iter()
                    .filter(|&&v| reads_saturation(v, s))
                    .count(),
                None => 0,
            },
            non_finite_pixels: frame.data.iter().filter(|v| !v.is_finite()).count(),
        }
    }

    /// Warnings when a noticeable share of the frame is saturated (0.1 %) and when its mean
    /// signal is below its noise.
    fn warnings(&self) -> impl Iterator<Item = String> {
        let saturated = (self.saturated_pixels * 1000 > self.pixels).then(|| {
            format!(
                "{} of {} pixels ({:.1} %) are saturated: the reconstruction there is wrong (the joint method with noise_weights = true takes them as lower bounds, the others as readings); lower the light (rig.sensor.electrons_at_full_scale)",
                self.saturated_pixels,
                self.pixels,
                100.0 * self.saturated_pixels as f64 / self.pixels as f64
            )
        });
        let dim = self.mean_snr.and_then(specmux_core::noise::snr_warning);
        saturated.into_iter().chain(dim)
    }
}

/// What the calibration measured, and from what: "captures" (the frames a rig records) or
/// "oracle" (the simulator's exact patterns; figures from it are not a rig's).
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationReport {
    pub source: String,
    pub carriers: Vec<MeasuredCarrier>,
}

impl CalibrationReport {
    fn new(recon: &Reconstructor) -> CalibrationReport {
        CalibrationReport {
            source: recon.calibration.source.clone(),
            carriers: recon.calibration.carriers.clone(),
        }
    }
}

/// How well the spectral basis represents the training and the held-out reflectances.
#[derive(Clone, Debug, Serialize)]
pub struct BasisReport {
    pub vectors: usize,
    pub train: BasisFit,
    pub held_out: BasisFit,
}

/// Version of the JSON reports' layout (docs/report-schema.md): raised when a key is renamed,
/// removed or changes meaning; keys may be added within a version.
pub const SCHEMA_VERSION: u32 = 1;

/// What wrote a JSON report: the layout's version, specmux's version and the spectral library.
#[derive(Clone, Debug, Serialize)]
pub struct Provenance {
    pub schema_version: u32,
    pub specmux_version: String,
    /// The spectral library's folder, or "embedded (specmux X.Y.Z)".
    pub spectra: String,
}

impl Provenance {
    pub fn new(lib: &Library) -> Provenance {
        Provenance {
            schema_version: SCHEMA_VERSION,
            specmux_version: env!("CARGO_PKG_VERSION").to_string(),
            spectra: lib.provenance(),
        }
    }
}

/// Everything an experiment run measured.
#[derive(Clone, Debug, Serialize)]
pub struct RunReport {
    #[serde(flatten)]
    pub provenance: Provenance,
    pub experiment: String,
    pub scene: String,
    pub size: [usize; 2],
    pub bands: usize,
    pub forward_stages: Vec<StageTime>,
    pub results: Vec<ResultRow>,
    pub channels: Vec<ChannelRow>,
    pub basis: BasisReport,
    pub calibration: CalibrationReport,
    pub frame: FrameStats,
    pub unmix: UnmixStats,
    /// The joint reconstruction's objective per iteration, λ, steps and constraint violation.
    pub joint: Option<specmux_core::joint::JointStats>,
    /// What `[reconstruct.gap] method = "auto"` picked, and why.
    pub auto: Option<specmux_core::auto::Choice>,
    /// Where each channel's demultiplexing error comes from (ideal patterns only).
    pub error_budget: Option<Vec<ErrorBudget>>,
    /// What the rig operator should know (timing: exposure not whole turns, rates, spokes).
    pub warnings: Vec<String>,
    /// Building the reconstructor: windows, unmixer, GAP, calibration frames.
    pub setup_seconds: f64,
    /// Per frame: calibration, demultiplexing, crosstalk, de-aliasing and unmixing.
    pub reconstruction_seconds: f64,
    /// Where the frame was reconstructed (`[compute] device`): "CPU, N threads" or "GPU NAME
    /// (…)"; on a GPU device without a kernel for the method or frame, the CPU and why.
    pub reconstruction_device: String,
    pub total_seconds: f64,
}

/// The arrays of a run, for writing files.
pub struct RunData {
    pub truth: Cube,
    pub channels: Cube,
    pub frame: Cube,
    pub xhat: Cube,
    pub cube: Cube,
}

fn row(stage: &str, against: &str, m: &Metrics, seconds: f64) -> ResultRow {
    ResultRow {
        stage: stage.into(),
        against: against.into(),
        psnr_db: m.psnr_db,
        ssim: m.ssim,
        nrmse: m.nrmse,
        sam_deg: m.sam_deg,
        seconds,
        flags: m.flags.clone(),
    }
}

/// The reconstructor the core builds for this rig from its design and the calibration frames
/// the twin captures (or the oracle, when `[calibration] source = "oracle"`), kept in `cache`.
pub fn reconstructor(
    exp: &Experiment,
    rig: &Rig,
    sim: &Simulated,
    cache: Option<&PatternCache>,
) -> Result<Reconstructor> {
    reconstructor_for(exp, rig, sim, cache, auto::CPU)
}

/// [`reconstructor`] whose `method = "auto"` picks from `table` (the device's,
/// [`OpenDevice::auto_table`]).
pub fn reconstructor_for(
    exp: &Experiment,
    rig: &Rig,
    sim: &Simulated,
    cache: Option<&PatternCache>,
    table: auto::Table<'_>,
) -> Result<Reconstructor> {
    let cal = calibration(exp, rig, sim, cache)?;
    Reconstructor::for_device(&exp.reconstruct, &rig.design(), &cal, &exp.file, table)
}

/// The calibration frames the twin captures for this rig (`[calibration]`), read from `cache`
/// when an earlier run left them there; the stages that ran are added to `times`
/// ([`kept_calibration_frames`]).
pub fn calibration_frames(
    exp: &Experiment,
    rig: &Rig,
    sim: &Simulated,
    cache: Option<&PatternCache>,
    times: &mut Vec<StageTime>,
) -> Result<CalibrationFrames> {
    let sensor = match &exp.rig.sensor {
        Some(c) => Some(Sensor::new(c, rig.width, rig.height)?),
        None => None,
    };
    let target = WhiteTarget {
        patterns: &sim.patterns,
        exposed_white: &sim.exposed_white,
        full_scale: sim.full_scale,
    };
    kept_calibration_frames(&exp.calibration, &target, sensor.as_ref(), cache, times)
}

/// The calibration frames as `captures::calibration_frames` makes them, read from `cache` when
/// an earlier run captured them on the same rig and camera (captures with a camera only: the
/// rest cost milliseconds). Adds the captures' time to `times` as `calibration-captures` when they
/// run, and the cache's lookup and write as `calibration-cache`.
pub fn kept_calibration_frames(
    cfg: &CaptureConfig,
    target: &WhiteTarget,
    sensor: Option<&Sensor>,
    cache: Option<&PatternCache>,
    times: &mut Vec<StageTime>,
) -> Result<CalibrationFrames> {
    let capture = |times: &mut Vec<StageTime>| {
        let t = Instant::now();
        let frames = captures::calibration_frames(cfg, target, sensor)?;
        times.push(StageTime::since("calibration-captures", t));
        Ok(frames)
    };
    let kept = cache.zip(sensor);
    let Some(kept) = kept.and_then(|(c, cam)| KeptCaptures::new(c, cfg, target, cam)) else {
        return capture(times);
    };
    let load = || kept.load();
    kept_or_made(times, "calibration-cache", load, capture, |f| kept.store(f))
}

/// The frames the rig's calibration captures (None for `[calibration] source = "oracle"`, which
/// captures nothing), with their stages added to `times`; kept in `cache`.
pub fn captured_calibration(
    exp: &Experiment,
    rig: &Rig,
    sim: &Simulated,
    cache: Option<&PatternCache>,
    times: &mut Vec<StageTime>,
) -> Result<Option<CalibrationFrames>> {
    if exp.calibration.source != captures::CalibrationSource::Captures {
        return Ok(None);
    }
    calibration_frames(exp, rig, sim, cache, times).map(Some)
}

/// The core's calibration from the frames the twin captures for this rig, kept in `cache`.
pub fn calibration(
    exp: &Experiment,
    rig: &Rig,
    sim: &Simulated,
    cache: Option<&PatternCache>,
) -> Result<Calibration> {
    let frames = calibration_frames(exp, rig, sim, cache, &mut Vec::new())?;
    // A camera whose flat does not rise above its dark, a pattern with no carrier: name the
    // section that made the frames so.
    let key = if exp.rig.sensor.is_some() {
        "rig.sensor"
    } else {
        "rig"
    };
    Calibration::from_frames(&rig.carriers, &frames, exp.calibration.search_bins)
        .map_err(|e| e.within(&exp.file, key, "the calibration frames it gives"))
}

/// Simulate the experiment's frame, reconstruct it and compare every stage with the truth; the
/// patterns and captures kept in `$SPECMUX_PATTERN_CACHE`.
pub fn run(exp: &Experiment, lib: &Library) -> Result<(RunReport, RunData)> {
    run_in(exp, lib, PatternCache::from_env()?.as_ref())
}

/// [`run`] with the patterns and captures kept in `cache` (None: none) instead.
pub fn run_in(
    exp: &Experiment,
    lib: &Library,
    cache: Option<&PatternCache>,
) -> Result<(RunReport, RunData)> {
    let t_all = Instant::now();
    let materials = Materials::load(lib)?;
    let rig = Rig::build(exp, lib, &materials)?;
    let pipeline = Pipeline::build(exp, &rig, &materials)?.with_pattern_cache(cache.cloned());
    let (sim, forward_stages) = pipeline.run()?;
    if let Some(why) = sim.frame.frame_problem("") {
        let reason = format!("the camera's frame of this scene is out of range: {why}");
        return Err(Error::config(
            &exp.file,
            "scene.source",
            &exp.scene.source,
            &reason,
        ));
    }
    let t = Instant::now();
    let device = pipeline.device();
    let recon = reconstructor_for(exp, &rig, &sim, cache, device.auto_table())?;
    let on_device = DeviceReconstructor::new(device, recon)?;
    let t_setup = t.elapsed().as_secs_f64();
    let out = on_device.stages(&sim.frame, Some(&sim.exposed))?;
    let reconstruction_device = on_device.describe().to_string();
    let recon = on_device.reconstructor();
    let (results, channel_metrics) = result_rows(exp, recon, &sim, &out)?;
    let saturation = match &exp.rig.sensor {
        Some(c) => Some(Sensor::new(c, rig.width, rig.height)?.saturation_dn()),
        None => None,
    };
    let snr = recon.frame_snr(&sim.frame)?;
    let frame = FrameStats::of(&sim.frame, saturation, snr);
    let error_budget = error_budget(exp, &rig, &sim.channels)?;
    let basis = BasisReport {
        vectors: rig.basis.len(),
        train: rig.basis.fit(&materials.train)?,
        held_out: rig.basis.fit(&materials.held_out)?,
    };
    let [t_demux, t_gap, t_unmix] = out.seconds;
    let report = RunReport {
        provenance: Provenance::new(lib),
        warnings: warnings(&rig, recon, &frame, out.joint.as_ref(), &results),
        frame,
        results,
        experiment: exp.file.clone(),
        scene: sim.scene.name.clone(),
        size: [sim.frame.width, sim.frame.height],
        bands: sim.scene.grid.count,
        forward_stages,
        channels: channel_rows(&rig, recon, &channel_metrics),
        calibration: CalibrationReport::new(recon),
        basis,
        unmix: out.unmix,
        joint: out.joint.clone(),
        auto: recon.auto.clone(),
        error_budget,
        setup_seconds: t_setup,
        reconstruction_seconds: t_demux + t_gap + t_unmix,
        reconstruction_device,
        total_seconds: t_all.elapsed().as_secs_f64(),
    };
    let data = RunData {
        truth: sim.scene.cube,
        channels: sim.channels,
        frame: sim.frame,
        xhat: out.xhat,
        cube: out.cube,
    };
    Ok((report, data))
}

/// The rig's warnings, its calibration's, the frame's, the joint run's, then every result row's
/// flags, named by its stage.
fn warnings(
    rig: &Rig,
    recon: &Reconstructor,
    frame: &FrameStats,
    joint: Option<&specmux_core::joint::JointStats>,
    results: &[ResultRow],
) -> Vec<String> {
    let flagged = results.iter().flat_map(|r| {
        r.flags
            .iter()
            .map(move |f| format!("{} against {}: {f}", r.stage, r.against))
    });
    rig.warnings
        .iter()
        .cloned()
        .chain(recon.calibration.notes())
        .chain(frame.warnings())
        .chain(joint.and_then(|j| j.warning()))
        .chain(flagged)
        .collect()
}

/// The result table: demultiplexed and de-aliased channels, the crop bound, the cube and the
/// spectral limit, each against its truth; also the metrics of x̂, the de-aliased channels and the
/// crop bound, for the channel table.
fn result_rows(
    exp: &Experiment,
    recon: &Reconstructor,
    sim: &Simulated,
    out: &Reconstruction,
) -> Result<(Vec<ResultRow>, [Metrics; 3])> {
    let [t_demux, t_gap, t_unmix] = out.seconds;
    let t = Instant::now();
    let bound = recon.demux.crop_bound(&sim.channels);
    let t_bound = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (ideal_cube, _) = recon.unmix(&sim.channels)?;
    let t_ideal = t.elapsed().as_secs_f64();
    let truth = &sim.scene.cube;
    let m_x = metrics::compare(&sim.channels, &out.xhat)?;
    let m_gap = metrics::compare(&sim.channels, &out.xgap)?;
    let m_bound = metrics::compare(&sim.channels, &bound)?;
    let gap = match (&out.joint, &recon.auto) {
        (Some(j), None) => format!("joint ({} it)", j.iterations),
        (Some(j), Some(_)) => format!("auto: joint ({} it)", j.iterations),
        (None, Some(a)) => format!("auto: {} ({} it)", a.method, out.gap.iterations),
        // Fourier has no iterations to count.
        (None, None) if exp.reconstruct.gap.method == Method::Fourier => "fourier".to_string(),
        (None, None) => format!("{} ({} it)", exp.reconstruct.gap.method, out.gap.iterations),
    };
    // In the order of `Row`.
    let rows = vec![
        row("demultiplex", "x (true channels)", &m_x, t_demux),
        row(&gap, "x (true channels)", &m_gap, t_gap),
        row(
            "crop bound",
            "x (window on each channel alone)",
            &m_bound,
            t_bound,
        ),
        row(
            "unmix",
            "r (true cube)",
            &metrics::compare(truth, &out.cube)?,
            t_unmix,
        ),
        row(
            "unmix of true x",
            "r (spectral limit)",
            &metrics::compare(truth, &ideal_cube)?,
            t_ideal,
        ),
    ];
    Ok((rows, [m_x, m_gap, m_bound]))
}

/// Per channel: the demultiplexed, the de-aliased and the crop bound's metrics (`m`, in that
/// order) and the carrier's gain.
fn channel_rows(rig: &Rig, recon: &Reconstructor, m: &[Metrics; 3]) -> Vec<ChannelRow> {
    let [m_x, m_gap, m_bound] = m;
    (0..rig.carriers.len())
        .map(|i| ChannelRow {
            channel: i,
            filter: rig.wheel.filters[i].name.clone(),
            carrier: [rig.carriers[i].fx, rig.carriers[i].fy],
            psnr_db: m_x.psnr_per_plane[i],
            ssim: m_x.ssim_per_plane[i],
            final_psnr_db: m_gap.psnr_per_plane[i],
            bound_psnr_db: m_bound.psnr_per_plane[i],
            bound_ssim: m_bound.ssim_per_plane[i],
            carrier_gain: carrier_gain(&recon.calibration.carriers[i]),
        })
        .collect()
}

/// |ĝ|/½ of a calibrated pattern relative to its own mean: 1 for an ideal sinusoid 1 + cos.
fn carrier_gain(m: &MeasuredCarrier) -> f64 {
    m.amplitude().norm() / m.white_level / 0.5
}

/// The leaks of the ideal sinusoids into each channel's window; None with simulated optics or
/// timing, where it would describe another frame than the one reconstructed.
fn error_budget(exp: &Experiment, rig: &Rig, channels: &Cube) -> Result<Option<Vec<ErrorBudget>>> {
    if exp.rig.has_optics() || exp.rig.timing.is_some() {
        return Ok(None);
    }
    let r = &exp.reconstruct;
    let ideal = Demux::new(rig.width, rig.height, &rig.carriers, r.crop)
        .with_window(r.window, SUPER_GAUSSIAN_ORDER)?;
    Ok(Some(crosstalk::budget(&ideal, channels, &rig.carriers)?))
}

impl RunReport {
    /// One row of the result table, by what it measures.
    pub fn row(&self, which: Row) -> &ResultRow {
        &self.results[which as usize]
    }

    /// The result table as fixed-width text.
    pub fn table(&self) -> String {
        // An oracle's figures say so before any of them (and not again among the warnings).
        let oracle = self.calibration.source == calibration::ORACLE;
        let mut s = match oracle {
            true => format!("{}\n", calibration::ORACLE_LABEL),
            false => String::new(),
        };
        s += &format!(
            "{:<20} {:<34} {:>9} {:>7} {:>8} {:>8} {:>10}\n",
            "stage", "against", "PSNR dB", "SSIM", "NRMSE", "SAM °", "seconds"
        );
        for r in &self.results {
            s += &format!(
                "{:<20} {:<34} {:>9.2} {:>7.4} {:>8.4} {:>9} {:>10.4}\n",
                r.stage,
                r.against,
                r.psnr_db,
                r.ssim,
                r.nrmse,
                metrics::show(r.sam_deg, 2),
                r.seconds
            );
        }
        s += &format!(
            "\n{:<8} {:<16} {:>12} {:>10} {:>8} {:>9} {:>10} {:>8} {:>7}\n",
            "channel",
            "filter",
            "carrier",
            "PSNR dB",
            "SSIM",
            "final dB",
            "bound dB",
            "bound",
            "gain"
        );
        for c in &self.channels {
            s += &format!(
                "{:<8} {:<16} {:>12} {:>10.2} {:>8.4} {:>9.2} {:>10.2} {:>8.4} {:>7.3}\n",
                c.channel,
                c.filter,
                format!("({},{})", c.carrier[0], c.carrier[1]),
                c.psnr_db,
                c.ssim,
                c.final_psnr_db,
                c.bound_psnr_db,
                c.bound_ssim,
                c.carrier_gain
            );
        }
        if let Some(b) = &self.error_budget {
            s += "\nerror budget of demultiplexing, dB (higher = smaller leak): DC term, then each carrier term (own = mirror)\n";
            for e in b {
                let parts: Vec<String> = e.carrier_db.iter().map(|v| format!("{v:6.1}")).collect();
                s += &format!(
                    "ch{} DC {:6.1} | {} | worst: {}\n",
                    e.channel,
                    e.dc_db,
                    parts.join(" "),
                    e.worst
                );
            }
        }
        for w in self
            .warnings
            .iter()
            .filter(|w| *w != calibration::ORACLE_LABEL)
        {
            s += &format!("\nwarning: {w}");
        }
        s += "\nforward stages: ";
        s += &self
            .forward_stages
            .iter()
            .map(|t| format!("{} {:.3}s", t.stage, t.seconds))
            .collect::<Vec<_>>()
            .join(", ");
        s += &format!(
            "\nbasis J={}: held-out RMSE {:.4} (train {:.4}), energy {:.5}\n",
            self.basis.vectors,
            self.basis.held_out.rmse,
            self.basis.train.rmse,
            self.basis.held_out.energy_captured,
        );
        // The joint method fits α from the frame: no per-pixel unmixing ran to count.
        if self.unmix.pixels > 0 {
            s += &format!(
                "unmix: {} of {} pixels hit the non-negativity bound\n",
                self.unmix.bound_pixels, self.unmix.pixels
            );
        }
        s += &format!(
            "reconstructor set-up {:.4}s, reconstruction {:.4}s ({}), total {:.2}s\n",
            self.setup_seconds,
            self.reconstruction_seconds,
            self.reconstruction_device,
            self.total_seconds
        );
        if let Some(a) = &self.auto {
            s += &format!("auto: {}\n", a.reason);
        }
        if let Some(j) = &self.joint {
            s += &joint_summary(j);
        }
        s
    }
}

/// The joint method's run in two lines: iterations, λ, objective and violation; then its
/// prior, weights, residual and λ rule (`demo`'s table and `reconstruct`).
pub fn joint_summary(j: &specmux_core::joint::JointStats) -> String {
    let relaxed = j
        .relaxation
        .map(|g| format!(", relaxation γ = {g}"))
        .unwrap_or_default();
    format!(
        "joint: {} iterations{relaxed}, λ = {:.3e}, objective {:.4e} → {:.4e}, constraint violation {:.1e} of the peak (clipped)\n",
        j.iterations,
        j.lambda,
        j.objective.first().copied().unwrap_or(f64::NAN),
        j.objective.last().copied().unwrap_or(f64::NAN),
        j.violation
    ) + &joint_noise_line(j)
}

/// The joint method's prior, data weights, weighted residual and λ rule in one line.
fn joint_noise_line(j: &specmux_core::joint::JointStats) -> String {
    let weights = if j.noise_weights {
        "noise weights ω = 1/var(y), Σωr²/N"
    } else {
        "uniform weights, Σr²/N (frame units²)"
    };
    let mut s = format!(
        "joint prior {} (spectral: {}): {weights} = {:.3}",
        j.prior, j.spectral_prior, j.residual_ratio
    );
    if j.reweight_rounds > 0 {
        let n = j.reweight_rounds;
        let times = if n == 1 { "once" } else { "times" };
        let n = if n == 1 {
            String::new()
        } else {
            format!("{n} ")
        };
        s += &format!("; TV weights refreshed {n}{times} (reweighted TV)");
    }
    if j.saturated_pixels > 0 {
        s += &format!(
            "; {} saturated pixels fitted one-sided (aᵀα ≥ y costs nothing)",
            j.saturated_pixels
        );
    }
    if let Some(d) = &j.discrepancy {
        s += &format!(
            "; λ by the discrepancy principle: {:.3e} after {} trials ({})",
            d.lambda,
            d.trials.len(),
            if d.reached {
                "Σωr²/N within 10 % of 1"
            } else {
                "not reached: closest trial taken"
            }
        );
    }
    if let (Some(first), Some(last)) = (j.fixed_point.first(), j.fixed_point.last()) {
        s += &format!("; ADMM fixed-point residual {first:.3e} → {last:.3e}");
    }
    s + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;
    use specmux_core::noise::NoiseModel;

    /// A frame whose mean signal is under its noise is named in the warnings (SNR 0.4), one
    /// above it is not (SNR 3), nor one without a camera.
    #[test]
    fn a_frame_below_its_noise_is_a_warning() {
        let frame = Cube::zeros(4, 1, 1);
        let said = |snr| {
            FrameStats::of(&frame, None, snr)
                .warnings()
                .collect::<Vec<_>>()
        };
        let dim = said(Some(0.4));
        assert!(
            dim.len() == 1 && dim[0].contains("0.40 times its noise"),
            "{dim:?}"
        );
        assert!(said(Some(3.0)).is_empty() && said(None).is_empty());
    }

    /// The frame statistics count the pixels the noise weights flag: level 3882 DN, raw (3882,
    /// 3881.6, 3881.4, 4095) → the first, second (rounds to 3882) and last read it.
    #[test]
    fn the_saturated_count_agrees_with_the_noise_weights() {
        let raw = Cube::from_vec(4, 1, 1, vec![3882.0, 3881.6, 3881.4, 4095.0]).unwrap();
        let model = NoiseModel {
            gain_dn_per_e: 0.5,
            dark_noise_dn: 2.0,
            saturation_dn: Some(3882.0),
        };
        let flagged = model.weights(&raw, &raw, None).unwrap().saturated;
        let stats = FrameStats::of(&raw, model.saturation_dn, None);
        assert_eq!(stats.saturated_pixels, 3);
        assert_eq!(flagged.iter().filter(|&&s| s).count(), 3);
        assert_eq!(FrameStats::of(&raw, None, None).saturated_pixels, 0);
    }
}

#[cfg(all(test, feature = "gpu"))]
mod gpu_tests {
    use super::*;
    use crate::forward::gpu_tests::context;

    /// The report of a 64² dead-leaves run with `method` and `[compute] device`.
    fn report(method: &str, prior: &str, device: &str) -> RunReport {
        let toml = format!(
            "[scene]\nsize = [64, 64]\n[reconstruct.gap]\nmethod = \"{method}\"\n\
             [reconstruct.joint]\niterations = 10\nprior = \"{prior}\"\n\
             [compute]\ndevice = \"{device}\"\n"
        );
        let exp = Experiment::from_toml(&toml, "t.toml").unwrap();
        run_in(&exp, &Library::default_root(), None).unwrap().0
    }

    /// `[compute] device = "gpu"` reconstructs the run's frame on the GPU, every stage's row
    /// within 0.01 dB of the CPU's (the GPU chain's bound, issue 17), and says where; the
    /// plug-and-play prior, which has no GPU kernel, runs on the CPU and says that.
    #[test]
    fn a_run_reconstructs_on_the_device_its_experiment_names() {
        if context().is_none() {
            return;
        }
        for method in ["fourier", "gap", "gap-tv", "joint"] {
            let cpu = report(method, "tv", "cpu");
            let gpu = report(method, "tv", "gpu");
            assert!(cpu.reconstruction_device.starts_with("CPU"));
            assert!(
                gpu.reconstruction_device.starts_with("GPU"),
                "{method}: {}",
                gpu.reconstruction_device
            );
            for row in [Row::Demultiplexed, Row::Dealiased, Row::Cube] {
                let (c, g) = (cpu.row(row).psnr_db, gpu.row(row).psnr_db);
                eprintln!("{method} {row:?}: CPU {c:.4} dB, GPU {g:.4} dB");
                assert!((c - g).abs() < 0.01, "{method} {row:?}: {c} against {g}");
            }
        }
        let pnp = report("joint", "pnp", "gpu");
        assert!(
            pnp.reconstruction_device.starts_with("CPU")
                && pnp.reconstruction_device.contains("no kernel for this")
                && pnp
                    .reconstruction_device
                    .contains("reconstruct.joint.prior"),
            "{}",
            pnp.reconstruction_device
        );
    }
}
