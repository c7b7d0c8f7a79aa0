//! The `rehearse` and `acquire` commands: load the experiment, build and check the plan, run it
//! on the simulated (or real) devices while recording, and return the text to print or the
//! one-line error.

use crate::devices::Frame;
use crate::error::{Error, Result};
use crate::plan::{DeviceLimits, HostLimits, Plan};
use crate::real::RealRigArgs;
use crate::reconstruct::{
    self, frame_table, reconstruct_frame, ReconstructedFrame, RecordedFrame, TruthTime,
};
use crate::record::Recorder;
use crate::run::{self, FrameRecord, Outcome, Sink};
use crate::sim::{Fault, Faults, SimRig};
use crate::trigger_chain;
use indicatif::ProgressBar;
use specmux_core::calibration::{Calibration, CalibrationFrames};
use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::device::{DeviceReconstructor, OpenDevice};
use specmux_twin::{Experiment, Rig};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// What `rehearse` and `acquire` are asked to do.
#[derive(Clone, Debug)]
pub struct RunOptions {
    pub experiment: PathBuf,
    pub frames: usize,
    /// Print the plan, its checks and timeline; send nothing.
    pub dry_run: bool,
    /// Faults for the simulated devices, `KIND@EXPOSURE`.
    pub faults: Vec<String>,
    /// The output folder; None for `out/<command>`.
    pub out: Option<PathBuf>,
}

impl RunOptions {
    pub fn new(
        experiment: PathBuf,
        frames: usize,
        dry_run: bool,
        faults: Vec<String>,
        out: Option<PathBuf>,
    ) -> RunOptions {
        RunOptions {
            experiment,
            frames,
            dry_run,
            faults,
            out,
        }
    }

    fn out_or(&self, default: &str) -> PathBuf {
        self.out.clone().unwrap_or_else(|| PathBuf::from(default))
    }
}

/// Append one formatted line.
macro_rules! say {
    ($text:ident, $($t:tt)*) => {{
        use std::fmt::Write;
        let _ = writeln!($text, $($t)*);
    }};
}

/// The plan of an experiment on devices with these limits, with its summary, checks and
/// timeline.
fn plan_for(exp: &Experiment, frames: usize, limits: &DeviceLimits, out: &Path) -> (Plan, String) {
    let plan = Plan::new(exp, frames, limits, &HostLimits::measure(out));
    let text = format!(
        "{}{}{}",
        plan.summary(),
        plan.checks_text(),
        plan.timeline_text()
    );
    (plan, text)
}

/// The verdict of a dry run: nothing is sent to any device.
pub fn dry_run(plan: &Plan, mut text: String) -> String {
    match plan.verify() {
        Ok(()) => say!(
            text,
            "dry run: the plan passes every check; no device was sent a command"
        ),
        Err(e) => say!(text, "dry run: {e}; no device was sent a command"),
    }
    text
}

/// Records the rehearsal and reconstructs each frame as it arrives, with the calibration
/// acquired in the same run.
struct Rehearsal<'a> {
    recorder: Recorder,
    sim: SimRig,
    exp: &'a Experiment,
    rig: Rig,
    /// `[compute] device`, which the frames are reconstructed on.
    device: OpenDevice,
    recon: Option<DeviceReconstructor>,
    rows: Vec<ReconstructedFrame>,
    /// Each frame's cube, when the caller keeps them (Python's `rehearse(cubes=True)`).
    cubes: Option<Vec<Cube>>,
    /// When each frame's truth was in front of the camera, for `truth.json`.
    truths: Vec<TruthTime>,
    bar: ProgressBar,
}

impl Sink for Rehearsal<'_> {
    fn calibrated(&mut self, f: &CalibrationFrames, records: &[FrameRecord]) -> Result<()> {
        self.recorder.calibrated(f, records)?;
        let cal =
            Calibration::from_frames(&self.rig.carriers, f, self.exp.calibration.search_bins)?;
        let recon = Reconstructor::for_device(
            &self.exp.reconstruct,
            &self.rig.design(),
            &cal,
            &self.exp.file,
            self.device.auto_table(),
        )?;
        self.recon = Some(DeviceReconstructor::new(&self.device, recon)?);
        Ok(())
    }

    fn frame(&mut self, r: &FrameRecord, frame: &Frame) -> Result<()> {
        self.recorder.frame(r, frame)?;
        let recon = self
            .recon
            .as_ref()
            .ok_or_else(|| Error::device("controller", "a frame before the calibration"))?;
        let f = RecordedFrame {
            frame_id: r.frame_id,
            timestamp_s: r.timestamp_s,
            flags: r.flags.len(),
            raw: Cube::from_vec(
                frame.width,
                frame.height,
                1,
                frame.data.iter().map(|&v| v as f32).collect(),
            )?,
        };
        let truth = self.sim.truth(frame)?;
        self.truths.push(TruthTime {
            frame_id: r.frame_id,
            scene_t_s: self.sim.scene_time_s(frame),
        });
        let (cube, row) = reconstruct_frame(recon, &f, Some(&truth))?;
        self.rows.push(row);
        if let Some(c) = &mut self.cubes {
            c.push(cube);
        }
        self.bar.inc(1);
        Ok(())
    }

    fn stop_requested(&self) -> bool {
        specmux_core::interrupt::requested()
    }
}

/// Parse `KIND@N` faults (given as `key`: `--fault`, or `faults` in Python) for a plan of
/// `frames` frames; a fault at an exposure the plan never reaches is refused (it would pass
/// unnoticed).
pub fn faults(specs: &[String], frames: usize, key: &str) -> Result<Faults> {
    let faults: Vec<Fault> = specs
        .iter()
        .map(|s| Fault::parse(s, key))
        .collect::<Result<_>>()?;
    if let Some((spec, f)) = specs
        .iter()
        .zip(&faults)
        .find(|(_, f)| frames > 0 && f.exposure >= frames as u64)
    {
        return Err(Error::refused(
            key,
            spec,
            format!(
                "exposure {} is past the plan's {frames} frames (scene exposures 0 to {}, counted from the first scene frame, not by frame id)",
                f.exposure,
                frames.saturating_sub(1)
            ),
        ));
    }
    Ok(Faults(faults))
}

/// `specmux rehearse`: the plan, its checks and timeline; then (unless a dry run) calibration
/// and acquisition on the simulated rig, every frame reconstructed with the acquired
/// calibration and compared with the truth.
pub fn rehearse(o: &RunOptions, lib: &Library) -> std::result::Result<String, String> {
    rehearse_in(o, &o.out_or("out/rehearse"), lib).map_err(|e| e.to_string())
}

fn rehearse_in(o: &RunOptions, out: &Path, lib: &Library) -> Result<String> {
    let exp = experiment_of(o, out)?;
    let faults = faults(&o.faults, o.frames, "--fault")?;
    let (plan, text) = rehearsal_plan(&exp, o.frames, out);
    if o.dry_run {
        return Ok(dry_run(&plan, text));
    }
    let r = rehearsal(&exp, &plan, faults, out, false, lib)?;
    // A rehearsal stopped by a fault reports it below; one stopped by Ctrl-C is an error (exit
    // status 130), its files written.
    if !r.outcome.completed && r.outcome.stopped_because.is_none() {
        return Err(stopped_early("rehearse", &r.outcome, out));
    }
    let mut text = text + &r.text();
    say!(text, "wrote {}", out.display());
    Ok(text)
}

/// The experiment of a run: a file or a built-in scene's name, as every command takes them; a
/// file inside the recording's folder `out` is refused (a simulated run replaces the folder).
fn experiment_of(o: &RunOptions, out: &Path) -> Result<Experiment> {
    specmux_io::output_set::inputs_outside(out, &[&o.experiment])?;
    Ok(specmux_report::commands::experiment_for(
        &o.experiment.to_string_lossy(),
        None,
    )?)
}

/// The plan of a rehearsal of `frames` frames recorded into `out`, on the twin's devices, with
/// the text `rehearse` prints of it: summary, checks, expected timeline.
pub fn rehearsal_plan(exp: &Experiment, frames: usize, out: &Path) -> (Plan, String) {
    plan_for(exp, frames, &DeviceLimits::of_twin(exp), out)
}

/// What a rehearsal did: each frame's error and time (and cube when kept), the outcome, the
/// devices' event log, and its virtual and wall time.
pub struct Rehearsed {
    pub rows: Vec<ReconstructedFrame>,
    /// Each frame's cube in the order of `rows`; empty unless asked for.
    pub cubes: Vec<Cube>,
    pub outcome: Outcome,
    pub events: Vec<crate::log::Event>,
    pub virtual_s: f64,
    pub wall_s: f64,
    /// What the acquired calibration warns of (carriers that do not stand out of their captures).
    pub warning: Option<String>,
    /// Where the frames were reconstructed ("CPU, 2 threads", "GPU NAME (…)").
    pub reconstructed_on: String,
}

impl Rehearsed {
    /// The per-frame table, the calibration's warning and the outcome, as `rehearse` prints
    /// them after the plan.
    pub fn text(&self) -> String {
        let warning = (self.warning.iter()).map(|w| format!("warning: {w}\n"));
        frame_table(&self.rows, &self.reconstructed_on)
            + &warning.collect::<String>()
            + &outcome_text(&self.outcome, Some(self.virtual_s), self.wall_s)
    }
}

/// Run `plan` (checked first) on the simulated rig with `faults`, recording into `out` and
/// reconstructing every frame with the calibration acquired in the same run; `keep_cubes` keeps
/// each frame's cube in memory.
pub fn rehearsal(
    exp: &Experiment,
    plan: &Plan,
    faults: Faults,
    out: &Path,
    keep_cubes: bool,
    lib: &Library,
) -> Result<Rehearsed> {
    plan.verify()?;
    let wall = Instant::now();
    let (sim, rig) = SimRig::new(exp, lib, faults)?;
    let mut dev = sim.devices();
    let recorder = Recorder::create(out, plan, exp, true)?;
    let mut sink = Rehearsal {
        recorder,
        sim: sim.clone(),
        exp,
        rig,
        device: sim.device(),
        recon: None,
        rows: Vec::new(),
        cubes: keep_cubes.then(Vec::new),
        truths: Vec::new(),
        bar: frame_bar(plan.settings.frames),
    };
    let outcome = run::run(plan, &mut dev, &mut sink)?;
    let events = sim.events();
    sink.recorder.finish(&outcome, &events)?;
    sink.bar.finish_and_clear();
    trigger_chain::write(&out.join("trigger-chain.png"), &events)?;
    specmux_report::commands::write_report(&out.join("rehearsal.json"), lib, "frames", &sink.rows)?;
    reconstruct::write_truth_times(out, &sink.truths)?;
    Ok(Rehearsed {
        rows: sink.rows,
        cubes: sink.cubes.unwrap_or_default(),
        outcome,
        events,
        virtual_s: sim.now_s(),
        wall_s: wall.elapsed().as_secs_f64(),
        warning: (sink.recon.as_ref()).and_then(|r| r.reconstructor().calibration.warning()),
        reconstructed_on: match &sink.recon {
            Some(r) => r.describe().to_string(),
            None => sink.device.describe(),
        },
    })
}

/// The one-line error of a run that stopped early, after its files are written.
fn stopped_early(command: &str, outcome: &Outcome, out: &Path) -> Error {
    let why = outcome
        .stopped_because
        .clone()
        .unwrap_or_else(|| "stopped by the operator".into());
    let n = outcome.frames.len();
    Error::device(
        command,
        format!("{why}; {n} frames kept in {}", out.display()),
    )
}

/// What a run did; `virtual_s` is the simulated rig's clock (None on the real rig).
fn outcome_text(o: &Outcome, virtual_s: Option<f64>, wall_s: f64) -> String {
    let mut t = String::new();
    let flagged = o.frames.iter().filter(|r| !r.ok()).count();
    say!(
        t,
        "acquired {} frames ({flagged} marked), calibration from {} exposures; {} incident{}",
        o.frames.len(),
        o.calibration.len(),
        o.incidents.len(),
        if o.incidents.len() == 1 { "" } else { "s" }
    );
    for i in &o.incidents {
        say!(t, "  {}: {}", i.kind, i.message);
    }
    match &o.stopped_because {
        Some(why) => say!(t, "stopped early: {why}; the frames acquired are kept"),
        None if !o.completed => say!(
            t,
            "stopped early by the operator; the frames acquired are kept"
        ),
        None => say!(t, "completed; devices stopped camera → DMD → wheel"),
    }
    match virtual_s {
        Some(v) => say!(t, "virtual time {v:.3} s, wall time {wall_s:.2} s"),
        None => say!(t, "wall time {wall_s:.2} s"),
    }
    t
}

/// A progress bar of `frames` frames on stderr, drawn only when stderr is a terminal (stdout
/// stays the report).
fn frame_bar(frames: usize) -> ProgressBar {
    let bar = specmux_report::progress::bar("frames (Ctrl-C stops safely)");
    bar.set_length(frames as u64);
    bar
}

/// A recorder that also shows progress and honours Ctrl-C.
struct Acquisition {
    recorder: Recorder,
    bar: ProgressBar,
}

impl Sink for Acquisition {
    fn calibrated(&mut self, f: &CalibrationFrames, r: &[FrameRecord]) -> Result<()> {
        self.recorder.calibrated(f, r)
    }

    fn frame(&mut self, r: &FrameRecord, frame: &Frame) -> Result<()> {
        self.recorder.frame(r, frame)?;
        self.bar.inc(1);
        Ok(())
    }

    fn stop_requested(&self) -> bool {
        specmux_core::interrupt::requested()
    }
}

/// `specmux acquire`: the same plan on the simulated devices (`sim`) or the real ones
/// (`real`, opened from `real`), writing the same files. An acquisition that stops early is an
/// error, after its files are written.
pub fn acquire(
    backend: &str,
    o: &RunOptions,
    real: &RealRigArgs,
    lib: &Library,
) -> std::result::Result<String, String> {
    acquire_in(backend, o, real, &o.out_or("out/acquire"), lib).map_err(|e| e.to_string())
}

fn acquire_in(
    backend: &str,
    o: &RunOptions,
    real: &RealRigArgs,
    out: &Path,
    lib: &Library,
) -> Result<String> {
    let (exp, frames, dry) = (experiment_of(o, out)?, o.frames, o.dry_run);
    let faults = faults(&o.faults, o.frames, "--fault")?;
    // The real rig is opened (inquiries only) even for a dry run: the plan needs its limits.
    let (real_devices, limits) = match backend {
        "sim" => (None, DeviceLimits::of_twin(&exp)),
        "real" if !faults.0.is_empty() => {
            return Err(Error::refused(
                "--fault",
                &o.faults[0],
                "faults are injected in the simulated rig only",
            ))
        }
        "real" => {
            let (d, l) = crate::real::open_rig(real, &exp)?;
            (Some(d), l)
        }
        other => return Err(Error::refused("--backend", other, "`sim` or `real`")),
    };
    let (plan, text) = plan_for(&exp, frames, &limits, out);
    if dry {
        return Ok(dry_run(&plan, text));
    }
    plan.verify()?;
    let wall = Instant::now();
    let (mut dev, sim) = match real_devices {
        Some(d) => (d, None),
        None => {
            let (sim, _) = SimRig::new(&exp, lib, faults)?;
            (sim.devices(), Some(sim))
        }
    };
    let mut sink = Acquisition {
        recorder: Recorder::create(out, &plan, &exp, sim.is_some())?,
        bar: frame_bar(frames),
    };
    let outcome = run::run(&plan, &mut dev, &mut sink)?;
    let events = sim.as_ref().map_or_else(|| dev.events(), |s| s.events());
    sink.recorder.finish(&outcome, &events)?;
    sink.bar.finish_and_clear();
    trigger_chain::write(&out.join("trigger-chain.png"), &events)?;
    if !outcome.completed {
        return Err(stopped_early("acquire", &outcome, out));
    }
    let mut text = text;
    text += &outcome_text(
        &outcome,
        sim.map(|s| s.now_s()),
        wall.elapsed().as_secs_f64(),
    );
    say!(text, "wrote {}", out.display());
    Ok(text)
}

/// The plan of `rehearse` and `acquire`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
    pub experiment: PathBuf,
    /// Frames to acquire after the calibration captures.
    #[arg(long, default_value_t = 100)]
    pub frames: usize,
    /// Print the plan, its checks and the expected timeline; send nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Inject a fault in the simulated rig, KIND@EXPOSURE, e.g. dropped-frame@5; EXPOSURE counts
    /// the scene's exposures from 0 (frame ids count the calibration's exposures too).
    #[arg(long)]
    pub fault: Vec<String>,
    /// Output folder (default out/rehearse or out/acquire).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

impl From<RunArgs> for RunOptions {
    fn from(a: RunArgs) -> Self {
        Self::new(a.experiment, a.frames, a.dry_run, a.fault, a.out)
    }
}
