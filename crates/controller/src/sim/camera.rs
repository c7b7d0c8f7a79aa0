//! The simulated GenICam camera: SFNC features, a trigger divider on Line1 or Line2, triggers
//! refused while exposing or reading out (counted as overlaps), and chunk data — frame id,
//! timestamp and two counters of line edges during the exposure. The exposure's light comes
//! from the pictures the DMD showed and the wheel segments in the beam (`light`), through the
//! twin's EMVA 1288 sensor.

use super::light::energies;
use super::{ns, secs, Bench, Ev, FaultKind};
use crate::devices::{Camera, CameraInfo, ExposureMode, Frame, Target, TriggerMode, TriggerSource};
use crate::error::{Error, Result};
use crate::log::{Event, Kind};
use crate::plan::DeviceLimits;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

const DEVICE: &str = "camera";

/// One exposure in progress.
#[derive(Clone, Copy, Debug)]
struct Exposure {
    start: u64,
    end: u64,
    id: u64,
    /// Its number among the scene's exposures, when the scene is in front of the camera.
    scene: Option<u64>,
}

pub(crate) struct CamSim {
    info: CameraInfo,
    trigger_mode: TriggerMode,
    source: TriggerSource,
    divider: u32,
    exposure_mode: ExposureMode,
    exposure_s: f64,
    frame_rate_hz: f64,
    armed: bool,
    gen: u64,
    /// Edges seen on the trigger source since arming (for the divider).
    edges: u64,
    exposing: Option<Exposure>,
    busy_until: u64,
    last_start: Option<u64>,
    next_id: u64,
    scene_exposures: u64,
    out: VecDeque<Frame>,
    pub(crate) silent: bool,
}

impl CamSim {
    pub(crate) fn new(l: &DeviceLimits) -> CamSim {
        CamSim {
            info: CameraInfo {
                width: l.camera_width,
                height: l.camera_height,
                bits: 12,
                min_exposure_s: l.camera_min_exposure_s,
                max_exposure_s: l.camera_max_exposure_s,
                max_frame_rate_hz: l.camera_max_frame_rate_hz,
                readout_s: l.camera_readout_s,
            },
            trigger_mode: TriggerMode::Off,
            source: TriggerSource::Software,
            divider: 1,
            exposure_mode: ExposureMode::Timed,
            exposure_s: 0.01,
            frame_rate_hz: 10.0,
            armed: false,
            gen: 0,
            edges: 0,
            exposing: None,
            busy_until: 0,
            last_start: None,
            next_id: 0,
            scene_exposures: 0,
            out: VecDeque::new(),
            silent: false,
        }
    }

    /// Start of the exposure in progress.
    pub(crate) fn exposure_start(&self) -> Option<u64> {
        self.exposing.map(|e| e.start)
    }

    /// (start, end, number) of the scene exposure in progress.
    pub(crate) fn scene_exposure(&self) -> Option<(u64, u64, u64)> {
        let e = self.exposing?;
        Some((e.start, e.end, e.scene?))
    }

    /// Shortest time between two exposure starts the camera allows.
    fn min_period_ns(&self) -> u64 {
        ns(1.0
            / self
                .info
                .max_frame_rate_hz
                .min(self.frame_rate_hz.max(f64::MIN_POSITIVE)))
    }
}

impl Bench {
    /// A rising edge on `line`, `width_ns` long: starts an exposure when it is the armed
    /// trigger source, the divider lets it through and the camera is ready.
    pub(super) fn camera_edge(&mut self, line: TriggerSource, width_ns: u64) {
        let c = &mut self.cam;
        if !c.armed || c.silent || c.trigger_mode != TriggerMode::On || c.source != line {
            return;
        }
        c.edges += 1;
        if (c.edges - 1) % c.divider.max(1) as u64 != 0 {
            return;
        }
        let too_soon = c
            .last_start
            .is_some_and(|t| self.now < t + c.min_period_ns() - ns(1e-6));
        if self.now < c.busy_until || too_soon {
            self.log(DEVICE, Kind::Edge, "trigger overlap: ignored (camera busy)");
            return;
        }
        self.start_exposure(width_ns);
    }

    fn start_exposure(&mut self, width_ns: u64) {
        let now = self.now;
        let c = &mut self.cam;
        let length = match c.exposure_mode {
            ExposureMode::Timed => ns(c.exposure_s),
            ExposureMode::TriggerWidth => width_ns,
        };
        let scene = (self.target == Target::Scene).then(|| {
            c.scene_exposures += 1;
            c.scene_exposures - 1
        });
        let id = c.next_id;
        c.next_id += 1;
        c.exposing = Some(Exposure {
            start: now,
            end: now + length,
            id,
            scene,
        });
        c.last_start = Some(now);
        c.busy_until = now + length + ns(c.info.readout_s);
        let gen = c.gen;
        self.log(DEVICE, Kind::Edge, format!("exposure start, frame {id}"));
        if let Some(n) = scene {
            self.wheel_faults_at(n);
            if self.faults.at(FaultKind::CameraStops, n) {
                self.cam.silent = true;
                self.log(DEVICE, Kind::Fault, "stops answering");
            }
        }
        self.schedule(now + length, Ev::ExposureEnd { gen });
    }

    /// The exposure ends: count the line edges it saw, integrate its light, read it out.
    pub(super) fn on_exposure_end(&mut self, gen: u64) {
        let Some(e) = self.cam.exposing.take().filter(|_| gen == self.cam.gen) else {
            return;
        };
        let within = |t: &u64| *t >= e.start && *t < e.end;
        let line1 = self.dmd.synchs.iter().filter(|t| within(t)).count() as u32;
        let line2 = self.wheel.pulses.iter().filter(|t| within(t)).count() as u32;
        let light = energies(
            &self.wheel.turns,
            &self.wheel.segments,
            &self.dmd.shown,
            e.start,
            e.end,
        );
        let scene_t = secs((e.start + (e.end - e.start) / 2).saturating_sub(self.scene_since));
        let data = match self.light.frame(&light, self.target, scene_t, e.id) {
            Ok(d) => d,
            Err(err) => {
                self.failure.get_or_insert(err);
                return;
            }
        };
        self.log(DEVICE, Kind::Edge, format!("exposure end, frame {}", e.id));
        if e.scene
            .is_some_and(|n| self.faults.at(FaultKind::DroppedFrame, n))
            || self.cam.silent
        {
            self.log(
                DEVICE,
                Kind::Fault,
                format!("frame {} lost in transport", e.id),
            );
            return;
        }
        let frame = Frame {
            frame_id: e.id,
            timestamp_ns: e.start,
            exposure_s: secs(e.end - e.start),
            line1_edges: line1,
            line2_edges: line2,
            width: self.cam.info.width,
            height: self.cam.info.height,
            data,
        };
        let t = self.now + ns(self.cam.info.readout_s);
        self.schedule(
            t,
            Ev::ReadoutEnd {
                gen,
                frame: Box::new(frame),
            },
        );
    }

    pub(super) fn on_readout_end(&mut self, gen: u64, frame: Frame) {
        if gen != self.cam.gen {
            return;
        }
        self.log(
            DEVICE,
            Kind::Edge,
            format!("frame {} delivered", frame.frame_id),
        );
        self.cam.out.push_back(frame);
    }
}

/// A handle to the simulated camera.
pub(crate) struct SimCamera(pub(crate) Rc<RefCell<Bench>>);

impl SimCamera {
    /// Log a feature write or command, or time out when the camera has stopped answering.
    fn command(&self, kind: Kind, what: &str) -> Result<std::cell::RefMut<'_, Bench>> {
        let mut b = self.0.borrow_mut();
        if b.cam.silent {
            return Err(b.no_answer(DEVICE, what));
        }
        b.log(DEVICE, kind, what);
        Ok(b)
    }
}

fn refuse(msg: String) -> Error {
    Error::device(DEVICE, msg)
}

impl Camera for SimCamera {
    fn inquire(&mut self) -> Result<CameraInfo> {
        Ok(self.command(Kind::Inquiry, "feature ranges?")?.cam.info)
    }

    fn set_trigger_mode(&mut self, mode: TriggerMode) -> Result<()> {
        self.command(Kind::Command, &format!("TriggerMode={mode:?}"))?
            .cam
            .trigger_mode = mode;
        Ok(())
    }

    fn set_trigger_source(&mut self, source: TriggerSource) -> Result<()> {
        self.command(Kind::Command, &format!("TriggerSource={source:?}"))?
            .cam
            .source = source;
        Ok(())
    }

    fn set_trigger_divider(&mut self, n: u32) -> Result<()> {
        let mut b = self.command(Kind::Command, &format!("TriggerDivider={n}"))?;
        if n == 0 {
            return Err(refuse("TriggerDivider=0: must be ≥ 1".into()));
        }
        b.cam.divider = n;
        Ok(())
    }

    fn set_exposure_mode(&mut self, mode: ExposureMode) -> Result<()> {
        self.command(Kind::Command, &format!("ExposureMode={mode:?}"))?
            .cam
            .exposure_mode = mode;
        Ok(())
    }

    fn set_exposure_time_s(&mut self, s: f64) -> Result<()> {
        let mut b = self.command(Kind::Command, &format!("ExposureTime={}", s * 1e6))?;
        let i = b.cam.info;
        if !(s >= i.min_exposure_s && s <= i.max_exposure_s) {
            return Err(refuse(format!(
                "ExposureTime={} µs outside [{}, {}] µs",
                s * 1e6,
                i.min_exposure_s * 1e6,
                i.max_exposure_s * 1e6
            )));
        }
        b.cam.exposure_s = s;
        Ok(())
    }

    fn set_acquisition_frame_rate_hz(&mut self, hz: f64) -> Result<()> {
        let mut b = self.command(Kind::Command, &format!("AcquisitionFrameRate={hz}"))?;
        let max = b.cam.info.max_frame_rate_hz;
        if !(hz > 0.0 && hz <= max * (1.0 + 1e-9)) {
            return Err(refuse(format!(
                "AcquisitionFrameRate={hz} outside (0, {max}] Hz"
            )));
        }
        b.cam.frame_rate_hz = hz;
        Ok(())
    }

    fn arm(&mut self) -> Result<u64> {
        let mut b = self.command(Kind::Command, "AcquisitionStart")?;
        let c = &mut b.cam;
        c.armed = true;
        c.edges = 0;
        Ok(b.now)
    }

    fn disarm(&mut self) -> Result<()> {
        let mut b = self.command(Kind::Command, "AcquisitionStop")?;
        let now = b.now;
        let c = &mut b.cam;
        c.armed = false;
        c.gen += 1;
        c.exposing = None;
        c.busy_until = now;
        let flushed = c.out.len();
        c.out.clear();
        if flushed > 0 {
            b.log(
                DEVICE,
                Kind::Edge,
                format!("{flushed} undelivered frames discarded"),
            );
        }
        Ok(())
    }

    fn next_frame(&mut self, timeout_s: f64) -> Result<Frame> {
        let mut b = self.0.borrow_mut();
        let until = b.now + ns(timeout_s);
        b.run_until(until, |b| !b.cam.out.is_empty())?;
        match b.cam.out.pop_front() {
            Some(f) => Ok(f),
            None => Err(Error::Timeout {
                device: DEVICE.into(),
                what: "the next frame".into(),
                after_s: timeout_s,
            }),
        }
    }

    fn events(&self) -> Vec<Event> {
        self.0.borrow().events_of(DEVICE)
    }
}
