//! The controller on the simulated rig: a clean run, the plan's refusals, the order of
//! operations, the recording and its prefix, and the reconstruction with the acquired
//! calibration.

mod common;

use common::*;
use specmux_controller::log::Kind;
use specmux_controller::plan::{DeviceLimits, HostLimits, Plan};
use specmux_controller::record::{read_calibration, Recorder};
use specmux_controller::run::{run, FrameRecord, Sink};
use specmux_controller::{ome, Error};
use specmux_core::calibration::Calibration;
use specmux_core::metrics;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::Cube;
use specmux_twin::optics::dither::DitherMethod;
use specmux_twin::optics::dmd::DmdConfig;

#[test]
fn a_clean_run_labels_every_frame_and_reconstructs_like_the_twin() {
    let exp = experiment("");
    let (sim, rig) = rig(&exp, &[]);
    let mut dev = sim.devices();
    let mut keep = Keep::default();
    let out = run(&plan(&exp, 4), &mut dev, &mut keep).unwrap();
    assert!(
        out.completed && out.incidents.is_empty(),
        "{:?}",
        out.incidents
    );
    assert_eq!(keep.frames.len(), 4);
    // 8 captures × 4 clean exposures, each 40 index pulses and 40 DMD sequences.
    assert_eq!(out.calibration.len(), 8 * 4);
    for (r, _) in &keep.frames {
        assert_eq!(
            (r.index_pulses, r.dmd_sequences, r.flags.len()),
            (40, 40, 0),
            "{r:?}"
        );
    }
    let ids: Vec<u64> = keep.frames.iter().map(|(r, _)| r.frame_id).collect();
    assert!(ids.windows(2).all(|w| w[1] == w[0] + 1), "{ids:?}");
    let mut all: Vec<FrameRecord> = out.calibration.clone();
    all.extend(out.frames.iter().cloned());
    assert_labels_match_the_dmd(&sim.events(), &all);
    // Frames 42 turns apart (24 fps asked, 1000 rev/s): 23.81 fps.
    let dt = keep.frames[1].0.timestamp_s - keep.frames[0].0.timestamp_s;
    assert!((dt - 0.042).abs() < 1e-9, "{dt}");

    // The core reconstructs from the acquired calibration; the error is the twin's own run's.
    let cal = Calibration::from_frames(
        &rig.carriers,
        keep.calibration.as_ref().unwrap(),
        exp.calibration.search_bins,
    )
    .unwrap();
    let recon = Reconstructor::new(&exp.reconstruct, &rig.design(), &cal, &exp.file).unwrap();
    let (_, f) = &keep.frames[0];
    let raw = Cube::from_vec(64, 64, 1, f.data.iter().map(|&v| v as f32).collect()).unwrap();
    let cube = recon.run(&raw, None).unwrap().cube;
    let ours = metrics::compare(&sim.truth(f).unwrap(), &cube)
        .unwrap()
        .psnr_db;
    let (twin, _) = specmux_twin::run::run(&exp, &lib()).unwrap();
    let theirs = twin.row(specmux_twin::run::Row::Cube).psnr_db;
    assert!(
        (ours - theirs).abs() < 1.0,
        "rehearsal {ours:.2} dB, twin {theirs:.2} dB"
    );
}

/// A DMD larger than the camera's field (80 × 72 mirrors, one a pixel, for 64 × 64 pixels): a DMD
/// takes whole pictures, so the controller uploads 80 × 72 ones, which the simulated DMD (which
/// refuses any other size) takes, and the captures measure every carrier.
#[test]
fn the_pictures_cover_the_whole_dmd() {
    let mut exp = experiment("");
    exp.rig.dmd = Some(DmdConfig {
        width: 80,
        height: 72,
        dither: DitherMethod::Threshold,
        ..DmdConfig::default()
    });
    let p = plan(&exp, 2);
    assert_eq!((p.optics.dmd.width, p.optics.dmd.height), (80, 72));
    let (sim, rig) = rig(&exp, &[]);
    let mut keep = Keep::default();
    let out = run(&p, &mut sim.devices(), &mut keep).unwrap();
    assert!(
        out.completed && keep.frames.len() == 2,
        "{:?}",
        out.incidents
    );
    let cal = Calibration::from_frames(
        &rig.carriers,
        keep.calibration.as_ref().unwrap(),
        exp.calibration.search_bins,
    )
    .unwrap();
    assert_eq!(cal.warning(), None);
}

#[test]
fn infeasible_plans_are_refused_before_any_device_command() {
    let exp = experiment("");
    let slow_dmd = DeviceLimits {
        dmd_min_picture_s: 200e-6,
        ..DeviceLimits::of_twin(&exp)
    };
    let narrow_dmd = DeviceLimits {
        dmd_width: 60,
        ..DeviceLimits::of_twin(&exp)
    };
    let small_disk = HostLimits {
        disk_free_bytes: 1 << 20,
        memory_available_bytes: u64::MAX,
    };
    let mut partial = experiment("");
    partial.rig.timing.as_mut().unwrap().camera.exposure_s = 0.0405;
    partial.rig.sensor.as_mut().unwrap().exposure_s = 0.0405;
    let cases = [
        (
            Plan::new(&exp, 4, &slow_dmd, &roomy()),
            "`rig.timing.wheel.rate_hz` = 1000",
            "minimum picture time is 200.000 µs",
        ),
        (
            Plan::new(&partial, 4, &DeviceLimits::of_twin(&partial), &roomy()),
            "`rig.timing.camera.exposure_s` = 0.0405",
            "40.500000 wheel turns",
        ),
        (
            Plan::new(&exp, 100, &DeviceLimits::of_twin(&exp), &small_disk),
            "`--frames` = 100",
            "MB are free",
        ),
        (plan(&exp, 0), "`--frames` = 0", "1 to"),
        (
            Plan::new(&exp, 4, &narrow_dmd, &roomy()),
            "`scene.size` = [64, 64]",
            "the camera sees 64.0 × 64.0 mirrors (1.0000 pixels per mirror); the DMD has 60 × 64",
        ),
    ];
    for (p, key, why) in cases {
        let (sim, _) = rig(&exp, &[]);
        let mut dev = sim.devices();
        let err = run(&p, &mut dev, &mut Keep::default()).unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, Error::Refused { .. }) && msg.contains(key) && msg.contains(why),
            "{msg}"
        );
        assert!(!msg.contains('\n'), "{msg}");
        assert!(sim.events().is_empty(), "{msg}: {:?}", sim.events().first());
        assert!(p.checks_text().contains("REFUSE"));
    }
}

#[test]
fn devices_are_driven_in_order_and_stopped_camera_dmd_wheel() {
    let exp = experiment("");
    let (sim, _) = rig(&exp, &[]);
    let mut dev = sim.devices();
    run(&plan(&exp, 2), &mut dev, &mut Keep::default()).unwrap();
    let ev = sim.events();
    let at = |d: &str, w: &str| position(&ev, d, w).unwrap_or_else(|| panic!("no {d} {w}"));
    let last = |d: &str, w: &str| last_position(&ev, d, w).unwrap();
    // Configure and upload before the wheel turns; lock before the first projection.
    assert!(at("camera", "TriggerMode=On") < at("wheel", "START"));
    assert!(last("dmd", "AlpSeqTiming") < at("wheel", "START"));
    assert!(at("wheel", "wait for LOCK") < at("dmd", "AlpProjStartCont"));
    assert!(at("dmd", "AlpProjStartCont") < at("camera", "AcquisitionStart"));
    // The white target is placed before the flat, the scene before the acquisition.
    assert!(at("operator", "place White") < at("dmd", "AlpProjStartCont 2"));
    assert!(at("operator", "place Scene") < last("camera", "AcquisitionStart"));
    // Safe stop: camera, DMD, wheel; then the sequences are freed.
    let (c, d, w) = (
        last("camera", "AcquisitionStop"),
        last("dmd", "AlpProjHalt"),
        last("wheel", "STOP"),
    );
    assert!(c < d && d < w && w < at("dmd", "AlpSeqFree"), "{c} {d} {w}");
    // No command at all before the first configuration command.
    assert_eq!(ev.iter().position(|e| e.kind == Kind::Command), Some(0));
}

#[test]
fn the_recording_reads_back_and_an_interrupted_one_keeps_its_prefix() {
    let exp = experiment("");
    let scratch = tmpdir("rec");
    let dir = scratch.path().join("rec");
    let (sim, _) = rig(&exp, &[]);
    let mut dev = sim.devices();
    let p = plan(&exp, 5);
    struct Both(Recorder, Keep);
    impl Sink for Both {
        fn calibrated(
            &mut self,
            f: &specmux_core::calibration::CalibrationFrames,
            r: &[FrameRecord],
        ) -> specmux_controller::Result<()> {
            self.0.calibrated(f, r)?;
            self.1.calibrated(f, r)
        }
        fn frame(
            &mut self,
            r: &FrameRecord,
            f: &specmux_controller::devices::Frame,
        ) -> specmux_controller::Result<()> {
            self.0.frame(r, f)?;
            self.1.frame(r, f)
        }
        fn stop_requested(&self) -> bool {
            self.1.stop_requested()
        }
    }
    let mut both = Both(
        Recorder::create(&dir, &p, &exp, true).unwrap(),
        Keep {
            stop_after: Some(3),
            ..Keep::default()
        },
    );
    let out = run(&p, &mut dev, &mut both).unwrap();
    // Ctrl-C after 3 frames: stopped safely, 3 frames kept.
    assert!(!out.completed && out.incidents.iter().any(|i| i.kind == "interrupted"));
    assert_eq!(out.frames.len(), 3);
    // Before finishing, the file is already a valid OME-TIFF of the 3 frames.
    let (xml, pages) = ome::read(&dir.join("frames.ome.tif")).unwrap();
    assert_eq!(pages.len(), 3);
    assert!(
        xml.contains("SizeT=\"3\"") && xml.contains("PlaneCount=\"3\""),
        "{xml}"
    );
    for ((_, f), page) in both.1.frames.iter().zip(&pages) {
        assert!(f.data.iter().zip(&page.data).all(|(&a, &b)| a as f32 == b));
    }
    both.0.finish(&out, &sim.events()).unwrap();
    let (xml, _) = ome::read(&dir.join("frames.ome.tif")).unwrap();
    assert_eq!(xml.matches("<Plane ").count(), 3);
    assert!(xml.contains("DeltaT=\"0.042000000\""), "{xml}");
    let lines = std::fs::read_to_string(dir.join("frames.jsonl")).unwrap();
    assert_eq!(lines.lines().count(), 3);
    assert!(std::fs::read_to_string(dir.join("events.jsonl"))
        .unwrap()
        .contains("AlpProjHalt"));
    // The calibration reads back bit for bit.
    let cal = read_calibration(&dir).unwrap();
    let kept = both.1.calibration.as_ref().unwrap();
    assert_eq!(cal.patterns, kept.patterns);
    assert_eq!((cal.dark, cal.frames_averaged), (kept.dark.clone(), 4));
}
