//! Simulated devices on a virtual clock: a deterministic discrete-event simulation of the rig's
//! trigger chain, with no wall-clock sleep. The three devices share one bench (the cables and
//! the clock): the wheel's index pulse reaches the DMD's trigger-in and the camera's Line2, the
//! DMD's synch out reaches the camera's Line1, and an exposure integrates the light of the
//! pictures actually shown through the wheel segments actually in the beam ([`light`]), with the
//! twin's forward model and camera. Time advances only while the controller waits (for lock,
//! for a frame); commands take no virtual time. Every command, edge and fault is logged.

mod camera;
mod dmd;
pub mod faults;
pub mod light;
mod wheel;

pub use faults::{Fault, FaultKind, Faults};

use crate::devices::{Devices, Frame, Operator, Target};
use crate::error::{Error, Result};
use crate::log::{Event, EventLog, Kind};
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::{Experiment, Rig};
use std::cell::RefCell;
use std::collections::BinaryHeap;
use std::rc::Rc;

/// Seconds → virtual nanoseconds.
pub fn ns(s: f64) -> u64 {
    (s * 1e9).round().max(0.0) as u64
}

/// Virtual nanoseconds → seconds.
pub fn secs(t: u64) -> f64 {
    t as f64 * 1e-9
}

/// How long a device that stops answering keeps the controller waiting per command.
pub(crate) const COMMAND_TIMEOUT_S: f64 = 0.5;

/// What happens at a scheduled time. `gen` tags events of a device state that a later command
/// (stop, halt, disarm) cancels.
#[derive(Debug)]
enum Ev {
    Index { gen: u64 },
    DmdSeqStart { gen: u64 },
    SynchOut { gen: u64, width_ns: u64 },
    ExposureEnd { gen: u64 },
    ReadoutEnd { gen: u64, frame: Box<Frame> },
}

/// An event in the queue, ordered by time, then by the order it was scheduled.
#[derive(Debug)]
struct Scheduled {
    t: u64,
    seq: u64,
    ev: Ev,
}

impl PartialEq for Scheduled {
    fn eq(&self, o: &Self) -> bool {
        (self.t, self.seq) == (o.t, o.seq)
    }
}
impl Eq for Scheduled {}
impl PartialOrd for Scheduled {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Scheduled {
    /// Reversed, so that the max-heap pops the earliest event.
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (o.t, o.seq).cmp(&(self.t, self.seq))
    }
}

/// The shared state of the simulated rig: clock, event queue, devices, target, log.
pub struct Bench {
    now: u64,
    queue: BinaryHeap<Scheduled>,
    seq: u64,
    wheel: wheel::WheelSim,
    dmd: dmd::DmdSim,
    cam: camera::CamSim,
    target: Target,
    /// When the scene was placed: its objects move from there.
    scene_since: u64,
    faults: Faults,
    log: EventLog,
    light: light::Light,
    /// The first error raised inside an event (a frame the twin could not make).
    failure: Option<Error>,
}

impl Bench {
    fn schedule(&mut self, t: u64, ev: Ev) {
        self.seq += 1;
        self.queue.push(Scheduled {
            t,
            seq: self.seq,
            ev,
        });
    }

    fn log(&mut self, device: &'static str, kind: Kind, what: impl Into<String>) {
        self.log.push(self.now, device, kind, what);
    }

    /// Process events in time order until `done` holds or the clock reaches `until`; returns
    /// whether `done` holds.
    fn run_until(&mut self, until: u64, done: impl Fn(&Bench) -> bool) -> Result<bool> {
        loop {
            if let Some(e) = self.failure.take() {
                return Err(e);
            }
            if done(self) {
                return Ok(true);
            }
            let next = match self.queue.peek() {
                Some(s) if s.t <= until => self.queue.pop(),
                _ => None,
            };
            match next {
                Some(s) => {
                    self.now = s.t;
                    self.handle(s.ev);
                }
                None => {
                    self.now = self.now.max(until);
                    return Ok(done(self));
                }
            }
        }
    }

    fn handle(&mut self, ev: Ev) {
        match ev {
            Ev::Index { gen } => self.on_index(gen),
            Ev::DmdSeqStart { gen } => self.on_seq_start(gen),
            Ev::SynchOut { gen, width_ns } => self.on_synch_out(gen, width_ns),
            Ev::ExposureEnd { gen } => self.on_exposure_end(gen),
            Ev::ReadoutEnd { gen, frame } => self.on_readout_end(gen, *frame),
        }
    }

    /// Wait `COMMAND_TIMEOUT_S` and fail: a device that stopped answering.
    fn no_answer(&mut self, device: &str, what: &str) -> Error {
        let until = self.now + ns(COMMAND_TIMEOUT_S);
        if let Err(e) = self.run_until(until, |_| false) {
            return e;
        }
        Error::Timeout {
            device: device.into(),
            what: what.into(),
            after_s: COMMAND_TIMEOUT_S,
        }
    }

    /// Events of one device.
    fn events_of(&self, device: &str) -> Vec<Event> {
        self.log
            .entries()
            .iter()
            .filter(|e| e.device == device)
            .cloned()
            .collect()
    }
}

/// The simulated rig: its bench, shared by the device handles it gives out.
#[derive(Clone)]
pub struct SimRig {
    bench: Rc<RefCell<Bench>>,
}

/// The operator of the simulated rig places targets instantly.
struct SimOperator(Rc<RefCell<Bench>>);

impl Operator for SimOperator {
    fn place(&mut self, target: Target) -> Result<()> {
        let mut b = self.0.borrow_mut();
        b.target = target;
        if target == Target::Scene {
            b.scene_since = b.now;
        }
        b.log("operator", Kind::Command, format!("place {target:?}"));
        Ok(())
    }
}

impl SimRig {
    /// The simulated rig of an experiment with the given faults; also the resolved rig (the
    /// design the reconstruction needs).
    pub fn new(exp: &Experiment, lib: &Library, faults: Faults) -> Result<(SimRig, Rig)> {
        let (light, rig) = light::Light::new(exp, lib)?;
        let timing = crate::plan::timing_of(exp);
        let limits = crate::plan::DeviceLimits::of_twin(exp);
        let bench = Bench {
            now: 0,
            queue: BinaryHeap::new(),
            seq: 0,
            wheel: wheel::WheelSim::new(&timing, &limits),
            dmd: dmd::DmdSim::new(&limits, light.picture_table()),
            cam: camera::CamSim::new(&limits),
            target: Target::White,
            scene_since: 0,
            faults,
            log: EventLog::default(),
            light,
            failure: None,
        };
        let rig_sim = SimRig {
            bench: Rc::new(RefCell::new(bench)),
        };
        Ok((rig_sim, rig))
    }

    /// Handles to the three devices and the operator.
    pub fn devices(&self) -> Devices {
        Devices {
            wheel: Box::new(wheel::SimWheel(self.bench.clone())),
            dmd: Box::new(dmd::SimDmd(self.bench.clone())),
            camera: Box::new(camera::SimCamera(self.bench.clone())),
            operator: Box::new(SimOperator(self.bench.clone())),
        }
    }

    /// The true cube in front of the camera during `frame` (the scene at the exposure's
    /// mid-time), for the rehearsal's error figures.
    pub fn truth(&self, frame: &Frame) -> Result<Cube> {
        self.bench.borrow().light.truth_at(self.scene_time_s(frame))
    }

    /// The scene's time at `frame`'s mid-exposure (seconds since the scene was placed): the
    /// twin's scene at that time is the frame's truth (`scene::build_at`).
    pub fn scene_time_s(&self, frame: &Frame) -> f64 {
        let b = self.bench.borrow();
        let mid = frame.timestamp_ns + ns(frame.exposure_s / 2.0);
        secs(mid.saturating_sub(b.scene_since))
    }

    /// Every event of every device, in order.
    pub fn events(&self) -> Vec<Event> {
        self.bench.borrow().log.entries().to_vec()
    }

    /// `[compute] device`, as the twin opened it (a clone shares its context): the
    /// rehearsal reconstructs its frames there.
    pub fn device(&self) -> specmux_twin::device::OpenDevice {
        self.bench.borrow().light.device().clone()
    }

    /// The virtual clock, seconds.
    pub fn now_s(&self) -> f64 {
        secs(self.bench.borrow().now)
    }
}
