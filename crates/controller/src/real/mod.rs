//! Real device backends, each behind a cargo feature so the default build needs no vendor SDK:
//! `serial-wheel` (a colour-wheel motor controller on a serial line), `alp4` (a ViALUX
//! ALP-4 DMD, its library loaded at run time) and `aravis` (a GenICam camera through
//! libaravis-0.8). [`open_rig`] builds the rig `specmux acquire --backend real` drives.

#[cfg(feature = "alp4")]
pub mod alp4;
#[cfg(feature = "aravis")]
pub mod aravis_camera;
#[cfg(feature = "serial-wheel")]
pub mod serial_wheel;

use crate::devices::{Camera, ColorWheel, Devices, Dmd, Operator, Target};
use crate::error::{Error, Result};
use crate::plan::DeviceLimits;
use specmux_twin::Experiment;
use std::io::BufRead;
use std::path::PathBuf;

/// Where the real devices are (`specmux acquire --backend real`).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct RealRigArgs {
    /// The GenICam camera's Aravis id (e.g. `Basler-21234567`) or IP address; needs the
    /// `aravis` feature.
    #[arg(long)]
    pub camera: Option<String>,
    /// The wheel controller's serial port (e.g. /dev/ttyUSB0); needs the `serial-wheel` feature.
    #[arg(long)]
    pub wheel_port: Option<PathBuf>,
    /// The ViALUX ALP-4 library (e.g. /opt/alp/alp4395.so); needs the `alp4` feature.
    #[arg(long)]
    pub alp_lib: Option<PathBuf>,
}

/// A device, or why this build or these arguments cannot give it.
type Opened<T> = std::result::Result<T, String>;

/// Open the real wheel, DMD and camera, with a person at the rig as the operator, and their
/// limits (the DMD's and camera's as they report them; the wheel's from the experiment). What
/// is missing is refused in one line naming every device that could not be opened.
pub fn open_rig(a: &RealRigArgs, exp: &Experiment) -> Result<(Devices, DeviceLimits)> {
    let (wheel, dmd, camera) = (open_wheel(a), open_dmd(a), open_camera(a));
    let (mut wheel, mut dmd, mut camera) = match (wheel, dmd, camera) {
        (Ok(w), Ok(d), Ok(c)) => (w, d, c),
        (w, d, c) => {
            let missing: Vec<String> = [w.err(), d.err(), c.err()].into_iter().flatten().collect();
            return Err(Error::refused("--backend", "real", missing.join("; ")));
        }
    };
    let mut limits = DeviceLimits::of_twin(exp);
    let d = dmd.inquire()?;
    let c = camera.inquire()?;
    (limits.dmd_width, limits.dmd_height) = (d.width, d.height);
    limits.dmd_min_picture_s = d.min_picture_time_s;
    limits.dmd_max_pictures = d.max_pictures;
    (limits.camera_width, limits.camera_height) = (c.width, c.height);
    (limits.camera_min_exposure_s, limits.camera_max_exposure_s) =
        (c.min_exposure_s, c.max_exposure_s);
    limits.camera_max_frame_rate_hz = c.max_frame_rate_hz;
    limits.camera_readout_s = c.readout_s;
    wheel.status()?;
    let devices = Devices {
        wheel,
        dmd,
        camera,
        operator: Box::new(PersonAtTheRig),
    };
    Ok((devices, limits))
}

#[cfg(feature = "serial-wheel")]
fn open_wheel(a: &RealRigArgs) -> Opened<Box<dyn ColorWheel>> {
    let path = a
        .wheel_port
        .as_ref()
        .ok_or("wheel: --wheel-port is not given")?;
    let w = serial_wheel::SerialWheel::open(path).map_err(|e| e.to_string())?;
    Ok(Box::new(w))
}

#[cfg(not(feature = "serial-wheel"))]
fn open_wheel(_: &RealRigArgs) -> Opened<Box<dyn ColorWheel>> {
    Err("wheel: this binary was built without the `serial-wheel` feature".into())
}

#[cfg(feature = "alp4")]
fn open_dmd(a: &RealRigArgs) -> Opened<Box<dyn Dmd>> {
    let lib = a.alp_lib.as_ref().ok_or("DMD: --alp-lib is not given")?;
    let d = alp4::AlpDmd::open(lib).map_err(|e| e.to_string())?;
    Ok(Box::new(d))
}

#[cfg(not(feature = "alp4"))]
fn open_dmd(_: &RealRigArgs) -> Opened<Box<dyn Dmd>> {
    Err("DMD: this binary was built without the `alp4` feature".into())
}

#[cfg(feature = "aravis")]
fn open_camera(a: &RealRigArgs) -> Opened<Box<dyn Camera>> {
    let name = a.camera.as_deref().ok_or("camera: --camera is not given")?;
    let c = aravis_camera::AravisCamera::open(name).map_err(|e| e.to_string())?;
    if !c.has_counters() {
        return Err(format!("camera: `{name}` sends no ChunkCounterValue; enable its chunk data and two counters on Line1/Line2 (docs/controller.md)"));
    }
    Ok(Box::new(c))
}

#[cfg(not(feature = "aravis"))]
fn open_camera(_: &RealRigArgs) -> Opened<Box<dyn Camera>> {
    Err("camera: this binary was built without the `aravis` feature".into())
}

/// A person at the rig: asked on the terminal to place each target, and answers with Enter.
struct PersonAtTheRig;

impl Operator for PersonAtTheRig {
    fn place(&mut self, target: Target) -> Result<()> {
        let what = match target {
            Target::Scene => "the scene",
            Target::White => "the white reflector",
        };
        eprintln!("place {what} in front of the camera, then press Enter");
        let mut line = String::new();
        match std::io::stdin().lock().read_line(&mut line) {
            Ok(n) if n > 0 => Ok(()),
            _ => Err(Error::device(
                "operator",
                format!("no answer on stdin while waiting for {what}"),
            )),
        }
    }
}
