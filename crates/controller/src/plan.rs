//! The acquisition plan: the settings each device will receive, the steps in order, and the
//! checks of those settings against the devices' limits and the host's disk and memory. The
//! plan is built and checked from the experiment and the limits alone, before any device is
//! sent a command; a failed check refuses the plan in one line that names the key and value.

use crate::error::{Error, Result};
use crate::patterns::PictureOptics;
use serde::Serialize;
use specmux_core::Carrier;
use specmux_twin::timing::TimingConfig;
use specmux_twin::Experiment;
use std::path::Path;

/// What the devices can do. The simulated devices take them from the experiment
/// ([`DeviceLimits::of_twin`]); a real rig's come from its devices' data sheets.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceLimits {
    pub dmd_width: usize,
    pub dmd_height: usize,
    /// Shortest binary picture time (AlpDevInquire ALP_MIN_PICTURE_TIME).
    pub dmd_min_picture_s: f64,
    /// Binary pictures the DMD's memory holds.
    pub dmd_max_pictures: usize,
    pub camera_width: usize,
    pub camera_height: usize,
    pub camera_min_exposure_s: f64,
    pub camera_max_exposure_s: f64,
    pub camera_max_frame_rate_hz: f64,
    pub camera_readout_s: f64,
    /// Frame buffers the camera driver is given.
    pub camera_buffers: usize,
    pub wheel_max_hz: f64,
    /// Spin-up acceleration of the wheel (rev/s²), for the expected timeline.
    pub wheel_accel_hz_per_s: f64,
}

/// Binary pictures the simulated DMD holds: 4 GiB of 1024 × 768 bit planes (an assumed
/// memory of the ALP-4 class; a real device reports its own).
const SIM_DMD_PICTURES: usize = 43_690;

/// The GO-5000-class camera's exposure range (its manual: 10 µs to 8 s).
const CAMERA_EXPOSURE_RANGE_S: (f64, f64) = (10e-6, 8.0);

impl DeviceLimits {
    /// The simulated devices of an experiment: the DMD's rate and the camera's frame rate and
    /// read-out from `[rig.timing]` (or its defaults); the camera the scene's size, the DMD the
    /// mirrors of `[rig.dmd]` (without one, a DMD imaged pixel for pixel).
    pub fn of_twin(exp: &Experiment) -> DeviceLimits {
        let t = timing_of(exp);
        let [w, h] = exp.scene.size;
        let (dw, dh) = exp.rig.dmd.as_ref().map_or((w, h), |d| (d.width, d.height));
        DeviceLimits {
            dmd_width: dw,
            dmd_height: dh,
            dmd_min_picture_s: 1.0 / t.dmd.max_rate_hz,
            dmd_max_pictures: SIM_DMD_PICTURES,
            camera_width: w,
            camera_height: h,
            camera_min_exposure_s: CAMERA_EXPOSURE_RANGE_S.0,
            camera_max_exposure_s: CAMERA_EXPOSURE_RANGE_S.1,
            camera_max_frame_rate_hz: t.camera.max_frame_rate_hz,
            camera_readout_s: t.camera.readout_s,
            camera_buffers: 16,
            wheel_max_hz: 2000.0,
            wheel_accel_hz_per_s: 2000.0,
        }
    }
}

/// Room on the host: disk where the recording goes, memory for buffers.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct HostLimits {
    pub disk_free_bytes: u64,
    pub memory_available_bytes: u64,
}

impl HostLimits {
    /// Free space on the file system of `out` (or its nearest existing parent) and the
    /// kernel's MemAvailable; a figure that cannot be read counts as unlimited.
    pub fn measure(out: &Path) -> HostLimits {
        HostLimits {
            disk_free_bytes: disk_free(out).unwrap_or(u64::MAX),
            memory_available_bytes: memory_available().unwrap_or(u64::MAX),
        }
    }
}

fn disk_free(out: &Path) -> Option<u64> {
    let abs = std::path::absolute(out).ok()?;
    let dir = abs.ancestors().find(|p| p.exists())?;
    let c = std::ffi::CString::new(dir.as_os_str().as_encoded_bytes()).ok()?;
    // SAFETY: statvfs writes into the zeroed struct we own; `c` is a valid C string.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut s) } != 0 {
        return None;
    }
    Some(s.f_bavail as u64 * s.f_frsize as u64)
}

fn memory_available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The experiment's timing, or the prototype's when it has no `[rig.timing]`; the camera's
/// exposure then follows `[rig.sensor]` when that is given.
pub fn timing_of(exp: &Experiment) -> TimingConfig {
    match (&exp.rig.timing, &exp.rig.sensor) {
        (Some(t), _) => t.clone(),
        (None, Some(s)) => {
            let mut t = TimingConfig::default();
            t.camera.exposure_s = s.exposure_s;
            t
        }
        (None, None) => TimingConfig::default(),
    }
}

/// The values the devices will be sent.
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub width: usize,
    pub height: usize,
    pub wheel_hz: f64,
    pub segments: usize,
    /// DMD picture time = one segment's share of a turn.
    pub picture_s: f64,
    pub illuminate_s: f64,
    /// The DMD's trigger-in delay (the experiment's common pattern delay).
    pub trigger_in_delay_s: f64,
    /// The DMD's synch-out delay: the exposure starts this long after the sequence.
    pub synch_delay_s: f64,
    pub exposure_s: f64,
    /// Exposure in wheel turns.
    pub turns_per_exposure: f64,
    /// TriggerDivider: one DMD synch edge (one turn) in this many starts an exposure.
    pub turns_per_frame: u32,
    /// The frame rate the divider gives.
    pub frame_rate_hz: f64,
    pub frames: usize,
    /// Exposures averaged into each calibration frame.
    pub calibration_frames: usize,
    /// Bytes of one raw frame (16-bit pixels).
    pub frame_bytes: u64,
}

/// One calibration capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Capture {
    /// Every mirror off: the camera's offset, dark current and DSNU.
    Dark,
    /// White target, every mirror on: the gain map.
    Flat,
    /// White target, pattern k in its own segment's slot, dark in the others.
    Pattern(usize),
    /// The scene, every pattern in its slot: the acquisition.
    Scene,
}

impl std::fmt::Display for Capture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Capture::Dark => write!(f, "dark"),
            Capture::Flat => write!(f, "flat"),
            Capture::Pattern(k) => write!(f, "pattern {k}"),
            Capture::Scene => write!(f, "scene"),
        }
    }
}

/// One step of the plan, in the order it runs.
#[derive(Clone, Debug, Serialize)]
#[serde(rename_all = "kebab-case", tag = "step")]
pub enum Step {
    /// Camera features, DMD projection mode.
    Configure,
    /// Allocate a sequence and upload its pictures.
    Upload {
        capture: Capture,
        pictures: usize,
    },
    SpinUp {
        rate_hz: f64,
    },
    WaitForLock {
        timeout_s: f64,
    },
    /// Run one capture: start its sequence, arm the camera, take `frames`, disarm, halt.
    Calibrate {
        capture: Capture,
        frames: usize,
    },
    Acquire {
        frames: usize,
    },
    /// Camera, then DMD, then wheel.
    Stop,
}

/// One check of a setting against a limit.
#[derive(Clone, Debug, Serialize)]
pub struct Check {
    pub key: String,
    pub value: String,
    pub ok: bool,
    /// What was compared, with the numbers.
    pub note: String,
}

/// A checked plan.
#[derive(Clone, Debug, Serialize)]
pub struct Plan {
    pub experiment: String,
    pub settings: Settings,
    pub steps: Vec<Step>,
    pub checks: Vec<Check>,
    pub devices: DeviceLimits,
    pub host: HostLimits,
    /// Bytes written to disk: frames, calibration and metadata.
    pub disk_bytes: u64,
    /// Bytes of memory held at once: camera buffers, calibration sums, pictures.
    pub memory_bytes: u64,
    /// The design carriers, in segment order: what the DMD's pictures are made from.
    pub carriers: Vec<Carrier>,
    /// How the camera sees the DMD, which lays the pictures out.
    pub optics: PictureOptics,
}

/// Frames the plan accepts at most (a 24 fps day).
const MAX_FRAMES: usize = 2_000_000;

/// A classic TIFF addresses 4 GiB; the recorder does not write BigTIFF.
const TIFF_LIMIT_BYTES: u64 = u32::MAX as u64;

/// Metadata written beside the frames, per frame (OME-XML plane, JSON record, event log).
const METADATA_BYTES_PER_FRAME: u64 = 4096;

/// Relative tolerance of "a whole number of turns".
const WHOLE_TURNS_TOLERANCE: f64 = 1e-6;

impl Plan {
    /// The plan of a calibration and an acquisition of `frames` frames, with every check
    /// evaluated (nothing is refused here: see [`Plan::verify`]).
    pub fn new(exp: &Experiment, frames: usize, dev: &DeviceLimits, host: &HostLimits) -> Plan {
        let settings = settings(exp, frames);
        let n = settings.segments;
        let mut steps = vec![Step::Configure];
        let captures = calibration_captures(n);
        for &capture in captures.iter().chain([Capture::Scene].iter()) {
            steps.push(Step::Upload {
                capture,
                pictures: n,
            });
        }
        steps.push(Step::SpinUp {
            rate_hz: settings.wheel_hz,
        });
        steps.push(Step::WaitForLock {
            timeout_s: lock_timeout_s(&settings, dev),
        });
        for capture in captures {
            steps.push(Step::Calibrate {
                capture,
                frames: settings.calibration_frames,
            });
        }
        steps.push(Step::Acquire { frames });
        steps.push(Step::Stop);
        let pictures = (n + 3) * n;
        let pixels = (settings.width * settings.height) as u64;
        let mirrors = (dev.dmd_width * dev.dmd_height) as u64;
        let disk_bytes = frames as u64 * (settings.frame_bytes + METADATA_BYTES_PER_FRAME)
            + (n as u64 + 2) * pixels * 4
            + (1 << 20);
        let memory_bytes = dev.camera_buffers as u64 * settings.frame_bytes
            + pixels * 8 * 2
            + pictures as u64 * mirrors.div_ceil(8);
        let mut plan = Plan {
            experiment: exp.file.clone(),
            settings,
            steps,
            checks: Vec::new(),
            devices: dev.clone(),
            host: *host,
            disk_bytes,
            memory_bytes,
            carriers: exp.carriers().map(|(c, _)| c).unwrap_or_default(),
            optics: PictureOptics::of(exp, dev.dmd_width, dev.dmd_height),
        };
        plan.checks = checks(exp, &plan);
        plan
    }

    /// Refuse the plan at its first failed check, naming the key and value.
    pub fn verify(&self) -> Result<()> {
        match self.checks.iter().find(|c| !c.ok) {
            Some(c) => Err(Error::refused(&c.key, &c.value, &c.note)),
            None => Ok(()),
        }
    }

    /// Seconds of one frame period (the divider's turns at the nominal speed).
    pub fn frame_period_s(&self) -> f64 {
        self.settings.turns_per_frame as f64 / self.settings.wheel_hz
    }
}

/// Dark, flat, then one capture per pattern: what the core's calibration needs.
pub fn calibration_captures(patterns: usize) -> Vec<Capture> {
    let mut c = vec![Capture::Dark, Capture::Flat];
    c.extend((0..patterns).map(Capture::Pattern));
    c
}

/// The spin-up time at the wheel's acceleration, doubled, plus a second.
fn lock_timeout_s(s: &Settings, dev: &DeviceLimits) -> f64 {
    2.0 * s.wheel_hz / dev.wheel_accel_hz_per_s.max(f64::MIN_POSITIVE) + 1.0
}

fn settings(exp: &Experiment, frames: usize) -> Settings {
    let t = timing_of(exp);
    let n = t.segment_count();
    let turn = t.period_s();
    let picture_s = turn / n as f64;
    let delay = t.delay_s(0);
    let turns_per_frame = (t.wheel.rate_hz / t.camera.frame_rate_hz - 1e-9)
        .ceil()
        .max(1.0);
    let [w, h] = exp.scene.size;
    Settings {
        width: w,
        height: h,
        wheel_hz: t.wheel.rate_hz,
        segments: n,
        picture_s,
        illuminate_s: picture_s - t.dmd.dark_time_s,
        trigger_in_delay_s: delay,
        synch_delay_s: t.camera.start_s - delay,
        exposure_s: t.camera.exposure_s,
        turns_per_exposure: t.camera.exposure_s * t.wheel.rate_hz,
        turns_per_frame: turns_per_frame.min(u32::MAX as f64) as u32,
        frame_rate_hz: t.wheel.rate_hz / turns_per_frame,
        frames,
        calibration_frames: exp.calibration.frames,
        frame_bytes: (w * h * 2) as u64,
    }
}

fn check(key: &str, value: impl std::fmt::Display, ok: bool, note: String) -> Check {
    Check {
        key: key.into(),
        value: value.to_string(),
        ok,
        note,
    }
}

/// The camera's field on the DMD (its pixels over the lens's pixels per mirror) within the mirrors.
fn field_check(p: &Plan) -> Check {
    let (s, d) = (&p.settings, &p.devices);
    let per_mirror = p.optics.pixels_per_mirror();
    let (fw, fh) = (s.width as f64 / per_mirror, s.height as f64 / per_mirror);
    check(
        "scene.size",
        format!("[{}, {}]", s.width, s.height),
        fw <= d.dmd_width as f64 + 1e-9 && fh <= d.dmd_height as f64 + 1e-9,
        format!(
            "the camera sees {fw:.1} × {fh:.1} mirrors ({per_mirror:.4} pixels per mirror); the DMD has {} × {}",
            d.dmd_width, d.dmd_height
        ),
    )
}

/// Every check, in the order a person would fix them: the DMD, the camera, the wheel, the host.
fn checks(exp: &Experiment, plan: &Plan) -> Vec<Check> {
    let mut c = dmd_checks(exp, plan);
    c.extend(camera_checks(plan));
    c.extend(host_checks(plan));
    c
}

fn dmd_checks(exp: &Experiment, p: &Plan) -> Vec<Check> {
    let (s, d) = (&p.settings, &p.devices);
    let t = timing_of(exp);
    let seg = &t.wheel.segments_deg;
    let equal = seg.iter().all(|&v| (v - seg[0]).abs() < 1e-9);
    let same_delay = (0..s.segments).all(|k| (t.delay_s(k) - s.trigger_in_delay_s).abs() < 1e-12);
    let pictures = (s.segments + 3) * s.segments;
    vec![
        check(
            "rig.timing.wheel.segments_deg",
            format!("{seg:?}"),
            equal,
            "a DMD sequence shows every picture for one picture time: the segments must be equal"
                .into(),
        ),
        check(
            "rig.timing.dmd.delays_s",
            format!("{:?}", t.dmd.delays_s),
            same_delay,
            "one trigger-in delay per sequence: every pattern's delay must be the same".into(),
        ),
        check(
            "rig.wheel.filters",
            exp.rig.wheel.filters.len(),
            exp.rig.wheel.filters.len() == s.segments,
            format!(
                "one pattern per wheel segment: {} filters, {} segments",
                exp.rig.wheel.filters.len(),
                s.segments
            ),
        ),
        check(
            "rig.timing.wheel.rate_hz",
            s.wheel_hz,
            s.illuminate_s >= d.dmd_min_picture_s * (1.0 - 1e-9),
            format!(
                "each pattern is shown {:.3} µs; the DMD's minimum picture time is {:.3} µs",
                s.illuminate_s * 1e6,
                d.dmd_min_picture_s * 1e6
            ),
        ),
        field_check(p),
        check(
            "rig.wheel.filters",
            s.segments,
            pictures <= d.dmd_max_pictures,
            format!(
                "{pictures} pictures (calibration and acquisition sequences); the DMD holds {}",
                d.dmd_max_pictures
            ),
        ),
        check(
            "rig.timing.camera.start_s",
            t.camera.start_s,
            s.synch_delay_s >= 0.0,
            format!(
                "the exposure starts from the DMD's synch out, so not before the DMD's delay {} s",
                s.trigger_in_delay_s
            ),
        ),
    ]
}

fn camera_checks(p: &Plan) -> Vec<Check> {
    let (s, d) = (&p.settings, &p.devices);
    let turns = s.turns_per_exposure;
    let whole = (turns - turns.round()).abs() <= WHOLE_TURNS_TOLERANCE * turns.max(1.0)
        && turns.round() >= 1.0;
    let busy = s.exposure_s + d.camera_readout_s;
    vec![
        check("rig.timing.camera.exposure_s", s.exposure_s, whole,
            format!("{turns:.6} wheel turns at {} rev/s: every channel gets equal light only over whole turns (use a multiple of {} s)",
                s.wheel_hz, 1.0 / s.wheel_hz)),
        check("rig.timing.camera.exposure_s", s.exposure_s,
            s.exposure_s >= d.camera_min_exposure_s && s.exposure_s <= d.camera_max_exposure_s,
            format!("the camera exposes {} s to {} s", d.camera_min_exposure_s, d.camera_max_exposure_s)),
        check("rig.timing.camera.frame_rate_hz", s.frame_rate_hz, s.frame_rate_hz <= d.camera_max_frame_rate_hz * (1.0 + 1e-9),
            format!("one frame every {} turns is {:.3} fps; the camera's maximum is {} fps",
                s.turns_per_frame, s.frame_rate_hz, d.camera_max_frame_rate_hz)),
        check("rig.timing.camera.exposure_s", s.exposure_s, busy <= s.turns_per_frame as f64 / s.wheel_hz * (1.0 + 1e-9),
            format!("exposure + read-out = {busy} s must fit one frame period of {} turns ({} s)",
                s.turns_per_frame, s.turns_per_frame as f64 / s.wheel_hz)),
        check("scene.size", format!("[{}, {}]", s.width, s.height), s.width <= d.camera_width && s.height <= d.camera_height,
            format!("the camera has {} × {} pixels", d.camera_width, d.camera_height)),
        check("rig.timing.wheel.rate_hz", s.wheel_hz, s.wheel_hz <= d.wheel_max_hz,
            format!("the wheel's motor reaches {} rev/s", d.wheel_max_hz)),
    ]
}

fn host_checks(p: &Plan) -> Vec<Check> {
    let (s, h) = (&p.settings, &p.host);
    let tiff = s.frames as u64 * s.frame_bytes;
    let mb = |b: u64| b as f64 / 1e6;
    vec![
        check(
            "--frames",
            s.frames,
            (1..=MAX_FRAMES).contains(&s.frames),
            format!("1 to {MAX_FRAMES} frames"),
        ),
        check(
            "--frames",
            s.frames,
            tiff <= TIFF_LIMIT_BYTES,
            format!(
                "{:.1} MB of frames; one classic TIFF holds at most 4 GiB",
                mb(tiff)
            ),
        ),
        check(
            "--frames",
            s.frames,
            p.disk_bytes <= h.disk_free_bytes,
            format!(
                "the recording needs {:.1} MB on disk, {:.1} MB are free",
                mb(p.disk_bytes),
                mb(h.disk_free_bytes)
            ),
        ),
        check(
            "scene.size",
            format!("[{}, {}]", s.width, s.height),
            p.memory_bytes <= h.memory_available_bytes,
            format!(
                "buffers need {:.1} MB of memory, {:.1} MB are available",
                mb(p.memory_bytes),
                mb(h.memory_available_bytes)
            ),
        ),
    ]
}

/// One phase of the expected timeline: the longest it takes (a capture's first trigger may come
/// up to one frame period after arming).
#[derive(Clone, Debug, Serialize)]
pub struct Phase {
    pub what: String,
    pub start_s: f64,
    pub seconds: f64,
}

impl Plan {
    /// The settings and steps, one line each.
    pub fn summary(&self) -> String {
        let s = &self.settings;
        let mut t = format!(
            "plan for {}: {} × {} px, {} segments\n  wheel {} rev/s; DMD slave on the index pulse, {} pictures of {:.3} µs (lit {:.3} µs), \
             trigger-in delay {} s, synch delay {} s\n  camera TriggerMode=On TriggerSource=Line1 TriggerDivider={} ExposureMode=Timed \
             ExposureTime={} µs ({} turns), {:.3} fps\n  calibration: dark, flat, {} patterns × {} exposures; acquisition: {} frames\n",
            self.experiment, s.width, s.height, s.segments, s.wheel_hz, s.segments, s.picture_s * 1e6,
            s.illuminate_s * 1e6, s.trigger_in_delay_s, s.synch_delay_s, s.turns_per_frame,
            s.exposure_s * 1e6, s.turns_per_exposure, s.frame_rate_hz, s.segments,
            s.calibration_frames, s.frames
        );
        for (i, step) in self.steps.iter().enumerate() {
            t += &format!("  {:>2}. {}\n", i + 1, step_text(step));
        }
        t
    }

    /// Every check with its verdict.
    pub fn checks_text(&self) -> String {
        let mut t = String::from("checks:\n");
        for c in &self.checks {
            let mark = if c.ok { "ok    " } else { "REFUSE" };
            t += &format!("  {mark} {} = {}: {}\n", c.key, c.value, c.note);
        }
        t
    }

    /// When each phase is expected to start and how long it lasts, and the trigger chain of
    /// one frame.
    pub fn timeline(&self) -> Vec<Phase> {
        let s = &self.settings;
        let frame = self.frame_period_s();
        let mut phases = Vec::new();
        let mut t = 0.0;
        let mut add = |what: String, seconds: f64| {
            phases.push(Phase {
                what,
                start_s: t,
                seconds,
            });
            t += seconds;
        };
        add("configure and upload".into(), 0.0);
        add(
            "spin up and lock".into(),
            s.wheel_hz / self.devices.wheel_accel_hz_per_s,
        );
        for c in calibration_captures(s.segments) {
            // The first trigger comes up to one frame period after arming.
            add(
                format!("calibrate {c}"),
                (s.calibration_frames + 1) as f64 * frame,
            );
        }
        add(
            format!("acquire {} frames", s.frames),
            (s.frames + 1) as f64 * frame,
        );
        add("stop".into(), 0.0);
        phases
    }

    /// The timeline and the trigger chain as text.
    pub fn timeline_text(&self) -> String {
        let s = &self.settings;
        let mut t = String::from(
            "expected timeline (virtual seconds; each capture allows one frame period for its first trigger, so a run ends up to that much sooner):\n",
        );
        let phases = self.timeline();
        for p in &phases {
            t += &format!(
                "  {:>9.3} s  {:<28} {:>8.3} s\n",
                p.start_s, p.what, p.seconds
            );
        }
        let end = phases.last().map_or(0.0, |p| p.start_s + p.seconds);
        t += &format!("  {end:>9.3} s  end\n");
        let start = s.trigger_in_delay_s + s.synch_delay_s;
        t += &format!(
            "trigger chain of one frame (from the wheel's index pulse):\n  0 µs index pulse → DMD trigger-in\n  {:.3} µs DMD sequence starts (pattern k at +k·{:.3} µs)\n  \
             {:.3} µs DMD synch out → camera Line1 (one edge in {}) → exposure starts\n  {:.3} µs exposure ends ({} turns)\n  \
             {:.3} µs frame read out; next exposure {:.3} µs after this one\n",
            s.trigger_in_delay_s * 1e6, s.picture_s * 1e6, start * 1e6, s.turns_per_frame,
            (start + s.exposure_s) * 1e6, s.turns_per_exposure,
            (start + s.exposure_s + self.devices.camera_readout_s) * 1e6, self.frame_period_s() * 1e6
        );
        t
    }
}

fn step_text(step: &Step) -> String {
    match step {
        Step::Configure => "configure: camera features, DMD projection mode slave".into(),
        Step::Upload { capture, pictures } => {
            format!("upload the {capture} sequence ({pictures} binary pictures)")
        }
        Step::SpinUp { rate_hz } => format!("spin the wheel up to {rate_hz} rev/s"),
        Step::WaitForLock { timeout_s } => {
            format!("wait for phase lock (at most {timeout_s:.2} s)")
        }
        Step::Calibrate { capture, frames } => {
            format!("calibrate: {capture}, mean of {frames} exposures")
        }
        Step::Acquire { frames } => format!("acquire {frames} frames of the scene"),
        Step::Stop => "stop: camera, then DMD, then wheel".into(),
    }
}
