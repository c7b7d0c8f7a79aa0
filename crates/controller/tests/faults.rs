//! One test per fault the simulated devices inject: the controller detects it, reports it,
//! marks the frames it touched, loses no frame it received and labels none with a pattern
//! state it was not exposed under.

mod common;

use common::*;
use specmux_controller::run::{run, Flag, Outcome};
use specmux_controller::sim::FaultKind;

/// Run 6 frames with one fault at scene exposure 2.
fn with_fault(kind: FaultKind) -> (Outcome, Keep, Vec<specmux_controller::log::Event>) {
    let exp = experiment("");
    let (sim, _) = rig(&exp, &[(kind, 2)]);
    let mut dev = sim.devices();
    let mut keep = Keep::default();
    let out = run(&plan(&exp, 6), &mut dev, &mut keep).unwrap();
    // Whatever happened, every frame the sink got is in the outcome, in order, correctly labelled.
    let ids: Vec<u64> = keep.frames.iter().map(|(r, _)| r.frame_id).collect();
    assert_eq!(
        ids,
        out.frames.iter().map(|r| r.frame_id).collect::<Vec<_>>()
    );
    assert_labels_match_the_dmd(&sim.events(), &out.frames);
    assert_labels_match_the_dmd(&sim.events(), &out.calibration);
    (out, keep, sim.events())
}

fn kinds(o: &Outcome) -> Vec<&str> {
    o.incidents.iter().map(|i| i.kind).collect()
}

fn faulted(events: &[specmux_controller::log::Event], device: &str) -> usize {
    events
        .iter()
        .filter(|e| e.device == device && e.kind == specmux_controller::log::Kind::Fault)
        .count()
}

#[test]
fn a_missed_index_pulse_is_found_by_the_pulse_counter() {
    let (out, keep, ev) = with_fault(FaultKind::MissedIndex);
    assert_eq!(faulted(&ev, "wheel"), 1);
    assert!(out.completed, "{:?}", out.incidents);
    assert_eq!(keep.frames.len(), 6);
    let third = &out.frames[2];
    assert_eq!(
        third.flags,
        vec![Flag::IndexPulses {
            seen: 39,
            expected: 40
        }],
        "{third:?}"
    );
    assert!(
        out.frames.iter().enumerate().all(|(i, r)| i == 2 || r.ok()),
        "{:?}",
        out.frames
    );
    let missed = out
        .incidents
        .iter()
        .find(|i| i.kind == "missed-index")
        .expect("reported");
    assert_eq!(missed.frame_ids, vec![third.frame_id]);
    // The next trigger comes one turn late (the divider counted one edge fewer): reported.
    assert!(kinds(&out).contains(&"late-trigger"), "{:?}", kinds(&out));
}

#[test]
fn a_dropped_frame_is_found_by_its_frame_id() {
    let (out, keep, ev) = with_fault(FaultKind::DroppedFrame);
    assert_eq!(faulted(&ev, "camera"), 1);
    assert!(out.completed);
    // Six frames still acquired; the lost id is named and no received frame is marked.
    assert_eq!(keep.frames.len(), 6);
    assert!(out.frames.iter().all(|r| r.ok()));
    let lost = out
        .incidents
        .iter()
        .find(|i| i.kind == "dropped-frame")
        .expect("reported");
    assert_eq!(lost.frame_ids, vec![out.frames[1].frame_id + 1]);
    assert_eq!(out.frames[2].frame_id, out.frames[1].frame_id + 2);
}

#[test]
fn a_dmd_underrun_is_found_by_the_sequence_counter() {
    let (out, _, ev) = with_fault(FaultKind::DmdUnderrun);
    assert_eq!(faulted(&ev, "dmd"), 1);
    assert!(out.completed);
    assert_eq!(
        out.frames[2].flags,
        vec![Flag::DmdSequences {
            seen: 39,
            index_pulses: 40
        }]
    );
    assert!(out.frames.iter().enumerate().all(|(i, r)| i == 2 || r.ok()));
    let under = out
        .incidents
        .iter()
        .find(|i| i.kind == "dmd-underrun")
        .expect("reported");
    assert_eq!(under.frame_ids, vec![out.frames[2].frame_id]);
}

#[test]
fn wheel_drift_marks_every_frame_from_its_start() {
    let (out, _, ev) = with_fault(FaultKind::WheelDrift);
    assert_eq!(faulted(&ev, "wheel"), 1);
    assert!(out.frames[..2].iter().all(|r| r.ok()));
    for r in &out.frames[2..] {
        assert!(
            r.flags.iter().any(|f| matches!(f, Flag::WheelSpeed { .. })),
            "{r:?}"
        );
        assert!(r.wheel_hz > 1000.0, "{r:?}");
    }
    assert!(kinds(&out).iter().filter(|k| **k == "wheel-drift").count() >= 4);
    assert!(
        !kinds(&out).contains(&"missed-index"),
        "a wrong speed is not a missed pulse"
    );
}

#[test]
fn a_camera_that_stops_answering_ends_the_run_with_its_frames_kept() {
    let (out, keep, ev) = with_fault(FaultKind::CameraStops);
    assert!(!out.completed);
    assert_eq!(keep.frames.len(), 2, "exposures 0 and 1 arrived");
    let why = out.stopped_because.as_deref().unwrap();
    assert!(
        why.starts_with("camera: no answer to") && !why.contains('\n'),
        "{why}"
    );
    assert_eq!(out.incidents.last().unwrap().kind, "not-answering");
    // The DMD and the wheel are still stopped, in that order, after the camera fails to.
    let (d, w) = (
        last_position(&ev, "dmd", "AlpProjHalt").unwrap(),
        last_position(&ev, "wheel", "STOP").unwrap(),
    );
    assert!(d < w);
}

#[test]
fn a_wheel_controller_that_stops_answering_keeps_the_frame_in_hand() {
    let (out, keep, ev) = with_fault(FaultKind::WheelStops);
    assert!(!out.completed);
    // Exposure 2's frame arrived before the status query timed out: it is kept, and marked.
    assert_eq!(keep.frames.len(), 3);
    assert!(!out.frames[2].ok());
    assert!(out
        .stopped_because
        .as_deref()
        .unwrap()
        .starts_with("wheel: no answer to STATUS?"));
    // The camera and the DMD were stopped although the wheel answers nothing.
    assert!(
        last_position(&ev, "camera", "AcquisitionStop") < last_position(&ev, "dmd", "AlpProjHalt")
    );
}
