//! Running a checked plan on devices: configure, upload, spin up, lock, calibrate, acquire,
//! stop. Every frame is inspected as it arrives — frame id gaps (lost frames), timestamps
//! (late triggers), the chunk counters of index pulses and DMD sequences during the exposure,
//! the wheel's speed and lock — and carries what was found. A frame is labelled with the
//! capture that was running when the camera was armed, and frames stamped before the arming
//! are discarded, so no frame is labelled with a pattern state it was not exposed under.

use crate::devices::{
    BitPlane, Devices, ExposureMode, Frame, ProjectionMode, SeqTiming, SequenceId, Target,
    TriggerMode, TriggerSource,
};
use crate::error::{Error, Result};
use crate::patterns;
use crate::plan::{calibration_captures, Capture, Plan};
use serde::Serialize;
use specmux_core::calibration::CalibrationFrames;
use specmux_core::Cube;

/// Relative wheel-speed error beyond which a frame is flagged (twice the lock tolerance of the
/// simulated wheel's controller).
const SPEED_TOLERANCE: f64 = 2e-4;

/// A frame whose start is this many turns off the expected period is reported.
const LATE_TURNS: f64 = 0.5;

/// What was found wrong with one frame's exposure.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "flag", rename_all = "kebab-case")]
pub enum Flag {
    /// Fewer (or more) index pulses than turns in the exposure: a missed pulse, or a wrong speed.
    IndexPulses { seen: u32, expected: u32 },
    /// Fewer DMD sequences than index pulses: the DMD skipped a turn (underrun).
    DmdSequences { seen: u32, index_pulses: u32 },
    /// The wheel was off its speed or out of lock when the frame arrived.
    WheelSpeed {
        measured_hz: f64,
        target_hz: f64,
        locked: bool,
    },
}

/// One frame as recorded: where it came from and what was found.
#[derive(Clone, Debug, Serialize)]
pub struct FrameRecord {
    pub capture: Capture,
    /// The DMD sequence projecting while it was taken.
    pub sequence: SequenceId,
    pub frame_id: u64,
    pub timestamp_s: f64,
    pub exposure_s: f64,
    pub index_pulses: u32,
    pub dmd_sequences: u32,
    pub wheel_hz: f64,
    pub flags: Vec<Flag>,
}

impl FrameRecord {
    pub fn ok(&self) -> bool {
        self.flags.is_empty()
    }
}

/// Something that went wrong, with the frames it concerns.
#[derive(Clone, Debug, Serialize)]
pub struct Incident {
    /// missed-index, dmd-underrun, wheel-drift, dropped-frame, late-trigger, stale-frame,
    /// not-answering, device-error, interrupted.
    pub kind: &'static str,
    pub frame_ids: Vec<u64>,
    pub message: String,
}

/// What a run produced besides the frames themselves.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Outcome {
    pub calibration: Vec<FrameRecord>,
    pub frames: Vec<FrameRecord>,
    pub incidents: Vec<Incident>,
    /// All planned frames were acquired and the devices stopped cleanly.
    pub completed: bool,
    /// Why the run ended early, when it did.
    pub stopped_because: Option<String>,
}

/// Where frames go as they arrive.
pub trait Sink {
    /// The calibration frames (averaged) and the records of the exposures averaged.
    fn calibrated(&mut self, frames: &CalibrationFrames, records: &[FrameRecord]) -> Result<()>;
    /// One acquisition frame, in order of arrival.
    fn frame(&mut self, record: &FrameRecord, frame: &Frame) -> Result<()>;
    /// Polled between frames: true to stop safely and keep what was acquired (Ctrl-C).
    fn stop_requested(&self) -> bool {
        false
    }
}

/// Check the plan, then run it on `dev`. A refused plan is an error and nothing was sent; a
/// device failure during the run stops the devices in a safe order and is reported in the
/// outcome, with the frames acquired until then already in the sink.
pub fn run(plan: &Plan, dev: &mut Devices, sink: &mut dyn Sink) -> Result<Outcome> {
    plan.verify()?;
    let mut s = Session {
        plan,
        dev,
        out: Outcome::default(),
        last: None,
        seqs: Vec::new(),
        pending: None,
    };
    let result = s.steps(sink);
    let stopped = s.stop_all();
    let mut out = s.out;
    match (result, stopped) {
        (Ok(()), Ok(())) => out.completed = !out.incidents.iter().any(|i| i.kind == "interrupted"),
        (Err(e), _) | (Ok(()), Err(e)) => {
            let id = out
                .frames
                .last()
                .map(|r| vec![r.frame_id])
                .unwrap_or_default();
            let kind = match e {
                Error::Timeout { .. } => "not-answering",
                // Ctrl-C seen inside the sink's own work (a frame's reconstruction): the
                // operator's stop, like the one polled between frames.
                Error::Core(specmux_core::Error::Interrupted(_)) => "interrupted",
                _ => "device-error",
            };
            out.incidents.push(Incident {
                kind,
                frame_ids: id,
                message: e.to_string(),
            });
            if kind != "interrupted" {
                out.stopped_because = Some(e.to_string());
            }
        }
    }
    Ok(out)
}

struct Session<'a> {
    plan: &'a Plan,
    dev: &'a mut Devices,
    out: Outcome,
    /// (frame id, timestamp ns) of the previous frame of the current capture.
    last: Option<(u64, u64)>,
    /// The sequences allocated, freed at the end.
    seqs: Vec<SequenceId>,
    /// A device failure found while inspecting a frame: raised once the frame is kept.
    pending: Option<Error>,
}

impl Session<'_> {
    fn steps(&mut self, sink: &mut dyn Sink) -> Result<()> {
        let seqs = self.configure()?;
        let s = &self.plan.settings;
        self.dev.wheel.set_speed_hz(s.wheel_hz)?;
        self.dev.wheel.start()?;
        self.dev.wheel.wait_for_lock(lock_timeout(self.plan))?;
        let seq_of = |c: Capture| {
            seqs.iter()
                .find(|(k, _)| *k == c)
                .map(|(_, id)| *id)
                .unwrap_or(0)
        };
        let cal = self.calibrate(&seq_of)?;
        sink.calibrated(&cal, &self.out.calibration)?;
        self.dev.operator.place(Target::Scene)?;
        self.acquire(seq_of(Capture::Scene), sink)
    }

    /// Camera features, DMD mode, and one uploaded, timed sequence per capture.
    fn configure(&mut self) -> Result<Vec<(Capture, SequenceId)>> {
        let s = &self.plan.settings;
        let cam = &mut self.dev.camera;
        cam.set_trigger_mode(TriggerMode::On)?;
        cam.set_trigger_source(TriggerSource::Line1)?;
        cam.set_trigger_divider(s.turns_per_frame)?;
        cam.set_exposure_mode(ExposureMode::Timed)?;
        cam.set_exposure_time_s(s.exposure_s)?;
        cam.set_acquisition_frame_rate_hz(s.frame_rate_hz)?;
        self.dev.dmd.set_projection_mode(ProjectionMode::Slave)?;
        let timing = SeqTiming {
            illuminate_s: s.illuminate_s,
            picture_s: s.picture_s,
            synch_delay_s: s.synch_delay_s,
            synch_pulse_width_s: s.picture_s / 2.0,
            trigger_in_delay_s: s.trigger_in_delay_s,
        };
        let optics = &self.plan.optics;
        let pics = patterns::carrier_pictures(&self.plan.carriers, optics, s.width, s.height)?;
        let (dw, dh) = (optics.dmd.width, optics.dmd.height);
        let mut seqs = Vec::new();
        for capture in calibration_captures(s.segments)
            .into_iter()
            .chain([Capture::Scene])
        {
            let pictures = sequence_pictures(capture, &pics, dw, dh);
            let id = self.dev.dmd.seq_alloc(1, pictures.len())?;
            self.dev.dmd.seq_put(id, 0, &pictures)?;
            self.dev.dmd.seq_timing(id, &timing)?;
            seqs.push((capture, id));
            self.seqs.push(id);
        }
        Ok(seqs)
    }

    /// Dark, flat and pattern captures, each the mean of its clean exposures.
    fn calibrate(&mut self, seq_of: &dyn Fn(Capture) -> SequenceId) -> Result<CalibrationFrames> {
        let s = &self.plan.settings;
        let (w, h, n) = (s.width, s.height, s.calibration_frames);
        let mut patterns = Cube::zeros(w, h, s.segments);
        let (mut dark, mut flat) = (None, None);
        for capture in calibration_captures(s.segments) {
            if capture == Capture::Flat {
                self.dev.operator.place(Target::White)?;
            }
            let mean = self.mean_of(capture, seq_of(capture), n)?;
            match capture {
                Capture::Dark => dark = Some(mean),
                Capture::Flat => flat = Some(mean),
                Capture::Pattern(k) => patterns.plane_mut(k).copy_from_slice(&mean.data),
                Capture::Scene => {}
            }
        }
        Ok(CalibrationFrames {
            dark,
            flat,
            patterns,
            patterns_linear: false,
            frames_averaged: n,
            source: "captures".into(),
        })
    }

    /// The mean of `n` clean exposures of one capture; flagged ones are discarded and retaken
    /// (at most `n` times).
    fn mean_of(&mut self, capture: Capture, seq: SequenceId, n: usize) -> Result<Cube> {
        let s = &self.plan.settings;
        let mut sum = vec![0f64; s.width * s.height];
        let armed = self.begin(seq)?;
        let (mut good, mut bad) = (0, 0);
        while good < n {
            let (rec, frame) = self.next(capture, seq, armed)?;
            if let Some(e) = self.pending.take() {
                return Err(e);
            }
            if !rec.ok() {
                bad += 1;
                self.incident(
                    "discarded",
                    vec![rec.frame_id],
                    format!(
                        "calibration {capture}: frame {} discarded ({:?})",
                        rec.frame_id, rec.flags
                    ),
                );
                if bad > n {
                    return Err(Error::device("controller", format!("calibration {capture}: {bad} faulty frames; the rig is not stable enough to calibrate")));
                }
                continue;
            }
            sum.iter_mut()
                .zip(&frame.data)
                .for_each(|(a, &v)| *a += v as f64);
            self.out.calibration.push(rec);
            good += 1;
        }
        self.end()?;
        let data = sum.into_iter().map(|v| (v / n as f64) as f32).collect();
        Ok(Cube::from_vec(s.width, s.height, 1, data)?)
    }

    /// The scene's frames, each handed to the sink as it arrives.
    fn acquire(&mut self, seq: SequenceId, sink: &mut dyn Sink) -> Result<()> {
        let armed = self.begin(seq)?;
        for _ in 0..self.plan.settings.frames {
            if sink.stop_requested() {
                let n = self.out.frames.len();
                self.incident(
                    "interrupted",
                    vec![],
                    format!("stopped by the operator after {n} frames"),
                );
                break;
            }
            let (rec, frame) = self.next(Capture::Scene, seq, armed)?;
            // The frame was acquired even if the sink's own work on it stops (Ctrl-C): keep it.
            let handled = sink.frame(&rec, &frame);
            self.out.frames.push(rec);
            handled?;
            if let Some(e) = self.pending.take() {
                return Err(e);
            }
        }
        self.end()
    }

    /// Start projecting `seq`, then arm the camera; returns the camera's clock at arming.
    fn begin(&mut self, seq: SequenceId) -> Result<u64> {
        self.dev.dmd.proj_start_cont(seq)?;
        self.last = None;
        self.dev.camera.arm()
    }

    /// Disarm the camera, then halt the DMD.
    fn end(&mut self) -> Result<()> {
        self.dev.camera.disarm()?;
        self.dev.dmd.proj_halt()
    }

    fn incident(&mut self, kind: &'static str, frame_ids: Vec<u64>, message: String) {
        self.out.incidents.push(Incident {
            kind,
            frame_ids,
            message,
        });
    }

    /// Camera, then DMD, then wheel — each tried even when an earlier one fails; then the
    /// sequences are freed. The first failure is returned.
    fn stop_all(&mut self) -> Result<()> {
        let mut results = vec![
            self.dev.camera.disarm(),
            self.dev.dmd.proj_halt(),
            self.dev.wheel.stop(),
        ];
        for id in std::mem::take(&mut self.seqs) {
            results.push(self.dev.dmd.seq_free(id));
        }
        results.into_iter().collect::<Result<Vec<()>>>().map(|_| ())
    }
}

/// Twice the expected spin-up at the wheel's acceleration, plus a second.
fn lock_timeout(plan: &Plan) -> f64 {
    2.0 * plan.settings.wheel_hz / plan.devices.wheel_accel_hz_per_s.max(f64::MIN_POSITIVE) + 1.0
}

/// The pictures of one capture's sequence, one per wheel segment.
fn sequence_pictures(capture: Capture, pics: &[BitPlane], w: usize, h: usize) -> Vec<BitPlane> {
    let dark = BitPlane::uniform(w, h, false);
    match capture {
        Capture::Dark => vec![dark; pics.len()],
        Capture::Flat => vec![BitPlane::uniform(w, h, true); pics.len()],
        Capture::Pattern(k) => (0..pics.len())
            .map(|j| {
                if j == k {
                    pics[j].clone()
                } else {
                    dark.clone()
                }
            })
            .collect(),
        Capture::Scene => pics.to_vec(),
    }
}

impl Session<'_> {
    /// The next frame of `capture`: stale frames (stamped before `armed`) are discarded, lost
    /// frame ids and late starts reported, and the frame's own exposure inspected.
    fn next(
        &mut self,
        capture: Capture,
        seq: SequenceId,
        armed: u64,
    ) -> Result<(FrameRecord, Frame)> {
        let timeout = 2.0 * self.plan.frame_period_s() + self.plan.settings.exposure_s + 0.1;
        loop {
            let frame = self.dev.camera.next_frame(timeout)?;
            if frame.timestamp_ns < armed {
                self.incident(
                    "stale-frame",
                    vec![frame.frame_id],
                    format!(
                        "frame {} was exposed before the camera was armed for {capture}: discarded",
                        frame.frame_id
                    ),
                );
                continue;
            }
            self.check_sequence(&frame);
            let (measured_hz, locked) = match self.dev.wheel.status() {
                Ok(w) => (w.measured_hz, w.locked),
                Err(e) => {
                    self.pending.get_or_insert(e);
                    (f64::NAN, false)
                }
            };
            match self.dev.dmd.status() {
                Ok(d) if !d.projecting => {
                    let e = Error::device("dmd", format!("stopped projecting during {capture}"));
                    self.pending.get_or_insert(e);
                }
                Err(e) => {
                    self.pending.get_or_insert(e);
                }
                Ok(_) => {}
            }
            let flags = self.inspect(&frame, measured_hz, locked);
            let rec = FrameRecord {
                capture,
                sequence: seq,
                frame_id: frame.frame_id,
                timestamp_s: frame.timestamp_ns as f64 * 1e-9,
                exposure_s: frame.exposure_s,
                index_pulses: frame.line2_edges,
                dmd_sequences: frame.line1_edges,
                wheel_hz: measured_hz,
                flags,
            };
            self.diagnose(&rec);
            return Ok((rec, frame));
        }
    }

    /// Frame ids must follow each other, one frame period apart.
    fn check_sequence(&mut self, f: &Frame) {
        if let Some((id, ts)) = self.last {
            if f.frame_id > id + 1 {
                let lost: Vec<u64> = (id + 1..f.frame_id).collect();
                self.incident(
                    "dropped-frame",
                    lost.clone(),
                    format!("frame ids {lost:?} never arrived (lost in transport)"),
                );
            }
            let s = &self.plan.settings;
            let periods = f.frame_id.saturating_sub(id).max(1) as f64;
            let turns = (f.timestamp_ns.saturating_sub(ts)) as f64 * 1e-9 * s.wheel_hz;
            let off = turns - periods * s.turns_per_frame as f64;
            if off.abs() > LATE_TURNS {
                self.incident("late-trigger", vec![f.frame_id], format!("frame {} started {off:+.2} turns off its period (a trigger edge missing or the wheel off speed)", f.frame_id));
            }
        }
        self.last = Some((f.frame_id, f.timestamp_ns));
    }

    /// What the chunk counters and the wheel's status say about this exposure.
    fn inspect(&self, f: &Frame, measured_hz: f64, locked: bool) -> Vec<Flag> {
        let s = &self.plan.settings;
        let expected = s.turns_per_exposure.round() as u32;
        let mut flags = Vec::new();
        if f.line2_edges != expected {
            flags.push(Flag::IndexPulses {
                seen: f.line2_edges,
                expected,
            });
        }
        if f.line1_edges < f.line2_edges {
            flags.push(Flag::DmdSequences {
                seen: f.line1_edges,
                index_pulses: f.line2_edges,
            });
        }
        let err = (measured_hz - s.wheel_hz).abs() / s.wheel_hz;
        // A NaN speed (the wheel did not answer) counts as off speed.
        if err.is_nan() || err > SPEED_TOLERANCE || !locked {
            flags.push(Flag::WheelSpeed {
                measured_hz,
                target_hz: s.wheel_hz,
                locked,
            });
        }
        flags
    }

    /// Name the fault behind a frame's flags: a wrong speed explains a wrong pulse count;
    /// a missing pulse at the right speed is a missed index; fewer sequences is an underrun.
    fn diagnose(&mut self, r: &FrameRecord) {
        let speed = r.flags.iter().any(|f| matches!(f, Flag::WheelSpeed { .. }));
        for flag in &r.flags {
            let (kind, why) = match flag {
                Flag::WheelSpeed {
                    measured_hz,
                    locked,
                    ..
                } => (
                    "wheel-drift",
                    format!(
                        "wheel at {measured_hz:.3} rev/s (target {}), lock {locked}",
                        self.plan.settings.wheel_hz
                    ),
                ),
                Flag::IndexPulses { seen, expected } if !speed => (
                    "missed-index",
                    format!("{seen} index pulses in an exposure of {expected} turns"),
                ),
                Flag::DmdSequences { seen, index_pulses } => (
                    "dmd-underrun",
                    format!("{seen} DMD sequences for {index_pulses} index pulses"),
                ),
                Flag::IndexPulses { .. } => continue,
            };
            self.incident(
                kind,
                vec![r.frame_id],
                format!(
                    "{} frame {}: {why}; the frame is marked",
                    r.capture, r.frame_id
                ),
            );
        }
    }
}
