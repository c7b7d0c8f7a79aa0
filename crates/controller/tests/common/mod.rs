//! Shared set-up of the controller's tests: a small experiment, a sink that keeps everything,
//! and checks on the event log.

#![allow(dead_code)]

use specmux_controller::devices::Frame;
use specmux_controller::log::{Event, Kind};
use specmux_controller::plan::{DeviceLimits, HostLimits, Plan};
use specmux_controller::run::{FrameRecord, Sink};
use specmux_controller::sim::{Fault, FaultKind, Faults, SimRig};
use specmux_controller::Result;
use specmux_core::calibration::CalibrationFrames;
use specmux_core::spectral::Library;
use specmux_twin::{Experiment, Rig};
use tempfile::TempDir;

/// A fresh scratch folder `specmux-{tag}-*`, removed when the returned guard drops.
pub fn tmpdir(tag: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("specmux-{tag}-"))
        .tempdir()
        .unwrap()
}

/// The shaded objects at 64 × 64 with the prototype's timing and camera, 4 exposures per
/// calibration frame; `scene` adds keys to `[scene]`.
pub fn experiment(scene: &str) -> Experiment {
    let text = format!(
        "[scene]\nsource = \"shaded-objects\"\nsize = [64, 64]\nseed = 11\n{scene}\n\
         [calibration]\nframes = 4\n[rig.timing]\n[rig.sensor]\n"
    );
    Experiment::from_toml(&text, "test.toml").unwrap()
}

pub fn lib() -> Library {
    Library::default_root()
}

/// Plenty of disk and memory.
pub fn roomy() -> HostLimits {
    HostLimits {
        disk_free_bytes: u64::MAX,
        memory_available_bytes: u64::MAX,
    }
}

pub fn plan(exp: &Experiment, frames: usize) -> Plan {
    Plan::new(exp, frames, &DeviceLimits::of_twin(exp), &roomy())
}

pub fn rig(exp: &Experiment, faults: &[(FaultKind, u64)]) -> (SimRig, Rig) {
    let f = faults
        .iter()
        .map(|&(kind, exposure)| Fault { kind, exposure })
        .collect();
    SimRig::new(exp, &lib(), Faults(f)).unwrap()
}

/// Keeps every frame and the calibration; asks to stop after `stop_after` frames.
#[derive(Default)]
pub struct Keep {
    pub calibration: Option<CalibrationFrames>,
    pub frames: Vec<(FrameRecord, Frame)>,
    pub stop_after: Option<usize>,
}

impl Sink for Keep {
    fn calibrated(&mut self, f: &CalibrationFrames, _: &[FrameRecord]) -> Result<()> {
        self.calibration = Some(f.clone());
        Ok(())
    }
    fn frame(&mut self, r: &FrameRecord, f: &Frame) -> Result<()> {
        self.frames.push((r.clone(), f.clone()));
        Ok(())
    }
    fn stop_requested(&self) -> bool {
        self.stop_after.is_some_and(|n| self.frames.len() >= n)
    }
}

/// Every frame's label must match what the DMD projected during its exposure: the sequence
/// started at least once inside the exposure, and no other sequence did.
pub fn assert_labels_match_the_dmd(events: &[Event], records: &[FrameRecord]) {
    for r in records {
        let start = (r.timestamp_s * 1e9).round() as u64;
        let end = start + (r.exposure_s * 1e9).round() as u64;
        let starts: Vec<&str> = events
            .iter()
            .filter(|e| {
                e.device == "dmd" && e.kind == Kind::Edge && e.t_ns >= start && e.t_ns < end
            })
            .filter_map(|e| e.what.strip_prefix("sequence "))
            .map(|w| w.split(' ').next().unwrap_or(""))
            .collect();
        let mine = r.sequence.to_string();
        assert!(!starts.is_empty(), "frame {} saw no sequence", r.frame_id);
        assert!(
            starts.iter().all(|s| *s == mine),
            "frame {} labelled {} saw {starts:?}",
            r.frame_id,
            r.capture
        );
    }
}

/// Position of the first event of `device` whose text starts with `what`.
pub fn position(events: &[Event], device: &str, what: &str) -> Option<usize> {
    events
        .iter()
        .position(|e| e.device == device && e.what.starts_with(what))
}

/// Position of the last such event.
pub fn last_position(events: &[Event], device: &str, what: &str) -> Option<usize> {
    events
        .iter()
        .rposition(|e| e.device == device && e.what.starts_with(what))
}
