//! The `rehearse` and `acquire` commands end to end on a small experiment file.

mod common;

use specmux_controller::commands::{acquire, rehearse, RunOptions};
use specmux_controller::ome;
use specmux_controller::real::RealRigArgs;
use std::path::PathBuf;
use tempfile::TempDir;

/// A scratch folder's guard (it removes the folder on drop), an experiment file in it, its out/.
fn setup(name: &str, scene: &str) -> (TempDir, PathBuf, PathBuf) {
    let scratch = common::tmpdir(&format!("cmd-{name}"));
    let dir = scratch.path();
    let file = dir.join("exp.toml");
    let text = format!(
        "[scene]\nsource = \"shaded-objects\"\nsize = [64, 64]\nseed = 11\n{scene}\n[calibration]\nframes = 2\n[rig.timing]\n[rig.sensor]\n"
    );
    std::fs::write(&file, text).unwrap();
    let out = dir.join("out");
    (scratch, file, out)
}

#[test]
fn a_dry_run_prints_plan_checks_and_timeline_and_writes_nothing() {
    let (_scratch, file, out) = setup("dry", "");
    let o = RunOptions::new(file.clone(), 10, true, vec![], Some(out.clone()));
    let text = rehearse(&o, &common::lib()).unwrap();
    for part in [
        "plan for",
        "TriggerDivider=42",
        "checks:",
        "expected timeline",
        "trigger chain",
        "passes every check",
    ] {
        assert!(text.contains(part), "{part}\n{text}");
    }
    assert!(!out.exists());
    // An infeasible plan: the dry run says why, naming the key; the real run refuses in one line.
    let bad = RunOptions::new(file, 0, true, vec![], Some(out.clone()));
    assert!(rehearse(&bad, &common::lib())
        .unwrap()
        .contains("REFUSE --frames = 0"));
    let err = rehearse(
        &RunOptions {
            dry_run: false,
            ..bad
        },
        &common::lib(),
    )
    .unwrap_err();
    assert!(
        err.starts_with("plan refused: `--frames` = 0") && !err.contains('\n'),
        "{err}"
    );
    assert!(!out.exists());
}

/// A fault at an exposure the plan never reaches is refused before anything runs: it would
/// pass unnoticed and the rehearsal would look fault-tolerant.
#[test]
fn a_fault_past_the_plan_is_refused() {
    let (_scratch, file, out) = setup("late-fault", "");
    let faults = vec!["dropped-frame@3".to_string()];
    let o = RunOptions::new(file, 3, false, faults, Some(out.clone()));
    let err = rehearse(&o, &common::lib()).unwrap_err();
    assert!(
        err.contains("`--fault` = dropped-frame@3") && err.contains("exposures 0 to 2"),
        "{err}"
    );
    assert!(!out.exists());
}

#[test]
fn rehearsing_a_moving_scene_reconstructs_every_frame() {
    let (_scratch, file, out) = setup("moving", "velocity_px_per_s = [200, 0]");
    let o = RunOptions::new(
        file,
        3,
        false,
        vec!["dmd-underrun@1".into()],
        Some(out.clone()),
    );
    let text = rehearse(&o, &common::lib()).unwrap();
    assert!(
        text.contains("acquired 3 frames (1 marked)") && text.contains("dmd-underrun"),
        "{text}"
    );
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("rehearsal.json")).unwrap())
            .unwrap();
    assert!(doc["specmux_version"].is_string(), "{doc}");
    let rows = doc["frames"].as_array().unwrap();
    assert_eq!(rows.len(), 3);
    for r in rows {
        assert!(r["psnr_db"].as_f64().unwrap() > 15.0, "{r}");
    }
    let (xml, pages) = ome::read(&out.join("frames.ome.tif")).unwrap();
    assert_eq!(pages.len(), 3);
    assert!(xml.contains("<M K=\"event_log\">events.jsonl</M>"), "{xml}");
}

#[test]
fn acquire_writes_the_files_and_refuses_an_unbuilt_backend() {
    let (_scratch, file, out) = setup("acquire", "");
    let o = RunOptions::new(file, 2, false, vec![], Some(out.clone()));
    let none = RealRigArgs::default();
    let text = acquire("sim", &o, &none, &common::lib()).unwrap();
    assert!(text.contains("completed"), "{text}");
    for f in [
        "plan.json",
        "frames.ome.tif",
        "frames.jsonl",
        "calibration.ome.tif",
        "calibration.json",
        "events.jsonl",
        "acquisition.json",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    // The real rig without its devices: one line naming each one missing, never a panic.
    let err = acquire("real", &o, &none, &common::lib()).unwrap_err();
    assert!(err.starts_with("plan refused: `--backend` = real"), "{err}");
    for device in ["wheel: ", "DMD: ", "camera: "] {
        assert!(err.contains(device) && !err.contains('\n'), "{err}");
    }
    let err = acquire("laser", &o, &none, &common::lib()).unwrap_err();
    assert!(
        err.starts_with("plan refused: `--backend` = laser"),
        "{err}"
    );
    let err = acquire(
        "sim",
        &RunOptions {
            faults: vec!["camera-stops@1".into()],
            ..o
        },
        &none,
        &common::lib(),
    )
    .unwrap_err();
    assert!(
        err.contains("no answer") && err.contains("1 frames kept"),
        "{err}"
    );
}

#[test]
fn only_the_shaded_objects_can_move_and_at_a_finite_speed() {
    use specmux_twin::Experiment;
    let err = Experiment::from_toml("[scene]\nvelocity_px_per_s = [1, 0]\n", "t.toml").unwrap_err();
    assert!(
        err.to_string()
            .contains("`scene.velocity_px_per_s` = [1, 0]"),
        "{err}"
    );
    let err = Experiment::from_toml(
        "[scene]\nsource = \"shaded-objects\"\nvelocity_px_per_s = [1e9, 0]\n",
        "t.toml",
    )
    .unwrap_err();
    assert!(err.to_string().contains("at most 1e6 px/s"), "{err}");
    assert!(Experiment::from_toml(
        "[scene]\nsource = \"shaded-objects\"\nvelocity_px_per_s = [3, -1]\n",
        "t.toml"
    )
    .unwrap()
    .scene
    .moves());
}

#[test]
fn a_rehearsal_folder_reconstructs_to_the_errors_the_rehearsal_reported() {
    use specmux_controller::reconstruct::reconstruct_recording;
    let (_scratch, file, rec) = setup("replay", "velocity_px_per_s = [200, 0]");
    let o = RunOptions::new(file, 3, false, vec![], Some(rec.clone()));
    rehearse(&o, &common::lib()).unwrap();
    let out = rec.with_file_name("replay-out");
    let text = reconstruct_recording(&rec, &out, &common::lib()).unwrap();
    assert!(text.contains("3 frames reconstructed"), "{text}");
    // The frame rows of a report (beside its version and provenance).
    let read = |p: PathBuf| -> Vec<serde_json::Value> {
        let doc: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
        doc["frames"].as_array().unwrap().clone()
    };
    let (rehearsed, replayed) = (
        read(rec.join("rehearsal.json")),
        read(out.join("reconstruct.json")),
    );
    assert_eq!(replayed.len(), 3);
    for (a, b) in rehearsed.iter().zip(&replayed) {
        assert_eq!(a["frame_id"], b["frame_id"]);
        // The same frames, calibration and rig: the same cube, to the last bit.
        for k in ["psnr_db", "ssim", "sam_deg"] {
            assert_eq!(a[k], b[k], "{k}: {a} vs {b}");
        }
        assert!(b["psnr_db"].as_f64().unwrap() > 15.0, "{b}");
        let id = b["frame_id"].as_u64().unwrap();
        let (cube, names) = specmux_io::exr::read(&out.join(format!("cube-{id:06}.exr"))).unwrap();
        assert_eq!(
            (cube.width, cube.height, cube.planes),
            (64, 64, names.len())
        );
    }
    // Without the truths (an acquisition), frames are reconstructed and no error is claimed.
    std::fs::remove_file(rec.join("truth.json")).unwrap();
    let text = reconstruct_recording(&rec, &out, &common::lib()).unwrap();
    assert!(text.contains("no truth in this recording"), "{text}");
    assert!(read(out.join("reconstruct.json"))
        .iter()
        .all(|r| r["psnr_db"].is_null()));
}
