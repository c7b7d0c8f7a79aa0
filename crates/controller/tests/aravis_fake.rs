//! The Aravis camera backend against Aravis's simulated GigE Vision camera on loopback
//! (`arv-fake-gv-camera-0.8`, Debian package aravis-tools; `.ci/aravis-check.sh` installs it):
//! configured through GenICam features, software-triggered, its frames received over UDP.
#![cfg(feature = "aravis")]

use specmux_controller::devices::{Camera, ExposureMode, TriggerMode, TriggerSource};
use specmux_controller::real::aravis_camera::AravisCamera;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The fake camera as a child process, killed when dropped.
struct FakeCamera {
    child: Child,
    id: String,
}

impl FakeCamera {
    fn start() -> FakeCamera {
        let serial = format!("specmux{}", std::process::id());
        let child = Command::new("arv-fake-gv-camera-0.8")
            .args(["-i", "127.0.0.1", "-s", &serial])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("arv-fake-gv-camera-0.8 (apt-get install aravis-tools)");
        FakeCamera {
            child,
            id: format!("Aravis-Fake-{serial}"),
        }
    }

    /// Open it once it answers (it needs a moment to bind its sockets).
    fn open(&self) -> AravisCamera {
        let start = Instant::now();
        loop {
            match AravisCamera::open(&self.id) {
                Ok(c) => return c,
                Err(e) if start.elapsed() > Duration::from_secs(10) => {
                    panic!("{} never answered: {e}", self.id)
                }
                Err(_) => std::thread::sleep(Duration::from_millis(200)),
            }
        }
    }
}

impl Drop for FakeCamera {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn configured_by_genicam_features_triggered_and_streamed_over_loopback() {
    let fake = FakeCamera::start();
    let mut cam = fake.open();
    let (w, h, exposure_s) = (128, 96, 2e-3);
    cam.set_format("Mono16", w, h).unwrap();
    cam.set_trigger_mode(TriggerMode::On).unwrap();
    cam.set_trigger_source(TriggerSource::Software).unwrap();
    cam.set_trigger_divider(1).unwrap();
    cam.set_exposure_mode(ExposureMode::Timed).unwrap();
    cam.set_exposure_time_s(exposure_s).unwrap();
    let info = cam.inquire().unwrap();
    assert_eq!((info.width, info.height, info.bits), (w, h, 16));
    assert!(info.min_exposure_s <= exposure_s && exposure_s <= info.max_exposure_s);

    cam.arm().unwrap();
    let n = 8;
    let mut frames = Vec::new();
    for _ in 0..n {
        cam.software_trigger().unwrap();
        frames.push(cam.next_frame(3.0).unwrap());
    }
    cam.disarm().unwrap();

    for f in &frames {
        assert_eq!((f.width, f.height, f.data.len()), (w, h, w * h));
        assert_eq!(f.exposure_s, exposure_s);
        // The fake camera draws a gradient: a constant frame would mean the bytes were lost.
        assert!(f.data.iter().any(|&v| v != f.data[0]), "a flat frame");
    }
    for pair in frames.windows(2) {
        assert_eq!(pair[1].frame_id, pair[0].frame_id + 1, "a lost frame id");
        assert!(pair[1].timestamp_ns > pair[0].timestamp_ns);
    }
    eprintln!(
        "{n} frames {w}x{h}: ids {:?}, timestamps {:?} ns",
        frames.iter().map(|f| f.frame_id).collect::<Vec<_>>(),
        frames.iter().map(|f| f.timestamp_ns).collect::<Vec<_>>()
    );
    let log: Vec<String> = cam.events().iter().map(|e| e.what.clone()).collect();
    for cmd in [
        "TriggerMode=On",
        "TriggerSource=Software",
        "ExposureTimeAbs=2000",
        "AcquisitionStart",
        "TriggerSoftware",
        "AcquisitionStop",
    ] {
        assert!(log.iter().any(|w| w == cmd), "{cmd} not in {log:?}");
    }
}

#[test]
fn a_camera_that_is_not_there_is_one_clear_error() {
    let e = AravisCamera::open("Aravis-Fake-nobody-here").err().unwrap();
    assert!(
        e.to_string()
            .starts_with("camera: no GenICam camera `Aravis-Fake-nobody-here`"),
        "{e}"
    );
}
