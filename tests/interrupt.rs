//! Ctrl-C during `specmux rehearse`, on the built binary: SIGINT after the first frames stops the
//! camera, then the DMD, then the wheel, exits with status 130, and leaves an OME-TIFF whose
//! every page is a complete frame with its own record.

mod common;

use specmux_controller::ome;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn lines(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn ctrl_c_stops_camera_dmd_wheel_and_keeps_a_readable_prefix() {
    let scratch = common::tmpdir("interrupt");
    let out = scratch.path().join("rec");
    let mut child = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .args([
            "rehearse",
            "scenes/moving-spheres.toml",
            "--frames",
            "100",
            "--out",
        ])
        .arg(&out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while lines(&out.join("frames.jsonl")).len() < 2 {
        assert!(start.elapsed() < Duration::from_secs(300), "no frames");
        assert!(child.try_wait().unwrap().is_none(), "ended before Ctrl-C");
        std::thread::sleep(Duration::from_millis(50));
    }
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let done = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&done.stderr);
    assert_eq!(done.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("stopped by the operator"), "{stderr}");

    // Safe order: the camera stops, then the DMD halts, then the wheel stops.
    let events = lines(&out.join("events.jsonl"));
    let last = |device: &str, what: &str| {
        events
            .iter()
            .rposition(|e| e["device"] == device && e["what"] == what)
            .unwrap_or_else(|| panic!("no {device} {what}"))
    };
    let (camera, dmd, wheel) = (
        last("camera", "AcquisitionStop"),
        last("dmd", "AlpProjHalt"),
        last("wheel", "STOP"),
    );
    assert!(camera < dmd && dmd < wheel, "{camera} {dmd} {wheel}");

    // A readable prefix: every page has its record, ids follow, every frame is of the scene's
    // sequence and unflagged; the OME-XML counts exactly these pages.
    let records = lines(&out.join("frames.jsonl"));
    let (xml, pages) = ome::read(&out.join("frames.ome.tif")).unwrap();
    let n = pages.len();
    assert!((2..100).contains(&n), "{n} frames");
    assert_eq!(records.len(), n);
    assert!(xml.contains(&format!("SizeT=\"{n}\"")), "{xml}");
    for (k, (r, p)) in records.iter().zip(&pages).enumerate() {
        assert_eq!(r["capture"], "scene");
        assert_eq!(r["sequence"], records[0]["sequence"]);
        assert_eq!(r["flags"], serde_json::json!([]));
        assert_eq!(
            r["frame_id"].as_u64().unwrap(),
            records[0]["frame_id"].as_u64().unwrap() + k as u64
        );
        assert_eq!((p.width, p.height), (256, 256));
        assert!(p.data.iter().any(|&v| v > 0.0), "an empty page {k}");
    }
    let outcome: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("acquisition.json")).unwrap())
            .unwrap();
    assert_eq!(outcome["frames"].as_array().unwrap().len(), n);
    assert_eq!(outcome["completed"], false);
}
