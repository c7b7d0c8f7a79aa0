//! The simulated colour wheel: a motor that ramps to its set speed, an index sensor that fires
//! once per turn (to the DMD's trigger-in and the camera's Line2), and a phase-lock indicator
//! computed from the measured index period, as a motor controller reports it.

use super::{ns, secs, Bench, Ev, FaultKind};
use crate::devices::{ColorWheel, TriggerSource, WheelStatus};
use crate::error::{Error, Result};
use crate::log::{Event, Kind};
use crate::plan::DeviceLimits;
use specmux_twin::timing::TimingConfig;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

const DEVICE: &str = "wheel";

/// Relative speed error within which the wheel counts as locked.
pub(crate) const LOCK_TOLERANCE: f64 = 1e-4;

/// Turns the speed must stay within tolerance before the lock indicator comes on.
const LOCK_TURNS: u32 = 8;

/// Speed from which the motor starts ramping, as a fraction of the set speed.
const START_FRACTION: f64 = 0.05;

pub(crate) struct WheelSim {
    target_hz: f64,
    max_hz: f64,
    accel: f64,
    /// The wheel's true speed during the current turn.
    rate_hz: f64,
    spinning: bool,
    gen: u64,
    /// Counted index pulses (a missed one is not counted).
    count: u64,
    /// Times of recent counted pulses.
    pub(crate) pulses: VecDeque<u64>,
    /// Recent turns (start at the index angle, end), missed pulses included.
    pub(crate) turns: VecDeque<(u64, u64)>,
    /// Start of each segment after the index angle and its length, as fractions of a turn.
    pub(crate) segments: Vec<(f64, f64)>,
    measured_hz: f64,
    stable_turns: u32,
    /// Start of a speed drift (virtual ns), once the fault is active.
    drift_from: Option<u64>,
    pub(crate) silent: bool,
}

impl WheelSim {
    pub(crate) fn new(t: &TimingConfig, limits: &DeviceLimits) -> WheelSim {
        let offset = t.wheel.index_offset_deg;
        let mut theta = 0.0;
        let segments = t
            .wheel
            .segments_deg
            .iter()
            .map(|&d| {
                let start = ((theta - offset) / 360.0f64).rem_euclid(1.0);
                theta += d;
                (start, d / 360.0)
            })
            .collect();
        WheelSim {
            target_hz: 0.0,
            max_hz: limits.wheel_max_hz,
            accel: limits.wheel_accel_hz_per_s,
            rate_hz: 0.0,
            spinning: false,
            gen: 0,
            count: 0,
            pulses: VecDeque::new(),
            turns: VecDeque::new(),
            segments,
            measured_hz: 0.0,
            stable_turns: 0,
            drift_from: None,
            silent: false,
        }
    }

    fn locked(&self) -> bool {
        self.spinning && self.stable_turns >= LOCK_TURNS
    }

    fn status(&self) -> WheelStatus {
        WheelStatus {
            spinning: self.spinning,
            target_hz: self.target_hz,
            measured_hz: self.measured_hz,
            locked: self.locked(),
            index_pulses: self.count,
        }
    }

    /// The true speed of the next turn: ramping towards the target, or drifting.
    fn next_rate(&self, now: u64, period_s: f64) -> f64 {
        if let Some(t0) = self.drift_from {
            return self.target_hz * (1.0 + super::faults::DRIFT_PER_S * secs(now - t0));
        }
        let step = self.accel * period_s;
        if self.rate_hz < self.target_hz {
            (self.rate_hz + step).min(self.target_hz)
        } else {
            (self.rate_hz - step).max(self.target_hz)
        }
    }
}

impl Bench {
    /// The wheel reaches its index angle: record the turn, fire (or miss) the pulse, update the
    /// measured speed and the lock, and schedule the next turn.
    pub(super) fn on_index(&mut self, gen: u64) {
        if gen != self.wheel.gen || !self.wheel.spinning {
            return;
        }
        let now = self.now;
        let period_s = 1.0 / self.wheel.rate_hz;
        let end = now + ns(period_s);
        let mid = self.mid_exposure(now);
        self.wheel.turns.push_back((now, end));
        if mid.is_some_and(|n| self.faults.at(FaultKind::MissedIndex, n)) {
            self.log(DEVICE, Kind::Fault, "index pulse missed by the sensor");
        } else {
            self.count_pulse(now);
            self.dmd_trigger_in(mid);
            self.camera_edge(TriggerSource::Line2, ns(1e-6));
        }
        let rate = self.wheel.next_rate(now, period_s);
        self.wheel.rate_hz = rate;
        self.prune(now);
        self.schedule(end, Ev::Index { gen });
    }

    fn count_pulse(&mut self, now: u64) {
        let w = &mut self.wheel;
        if let Some(&last) = w.pulses.back() {
            w.measured_hz = 1e9 / (now - last).max(1) as f64;
        }
        let err = (w.measured_hz - w.target_hz).abs() / w.target_hz.max(f64::MIN_POSITIVE);
        w.stable_turns = if err <= LOCK_TOLERANCE {
            w.stable_turns.saturating_add(1)
        } else {
            0
        };
        w.count += 1;
        w.pulses.push_back(now);
        let n = w.count;
        self.log(DEVICE, Kind::Edge, format!("index pulse {n}"));
    }

    /// The scene exposure whose middle this turn's index angle is the first to reach, if any:
    /// where the missed-index and DMD-underrun faults strike.
    fn mid_exposure(&self, now: u64) -> Option<u64> {
        let (start, end, n) = self.cam.scene_exposure()?;
        let mid = start + (end - start) / 2;
        let prev = self.wheel.turns.back()?.0;
        (prev < mid && now >= mid).then_some(n)
    }

    /// Forget turns and pulses no exposure can still need.
    fn prune(&mut self, now: u64) {
        let keep_from = self
            .cam
            .exposure_start()
            .unwrap_or(now)
            .saturating_sub(ns(0.1));
        let w = &mut self.wheel;
        while w.turns.front().is_some_and(|t| t.1 < keep_from) {
            w.turns.pop_front();
        }
        while w.pulses.len() > 1 && w.pulses.front().is_some_and(|&p| p < keep_from) {
            w.pulses.pop_front();
        }
    }

    /// Start a lasting wheel fault due at scene exposure `n`.
    pub(super) fn wheel_faults_at(&mut self, n: u64) {
        if self.faults.at(FaultKind::WheelDrift, n) && self.wheel.drift_from.is_none() {
            self.wheel.drift_from = Some(self.now);
            self.log(DEVICE, Kind::Fault, "speed starts drifting (1 %/s)");
        }
        if self.faults.at(FaultKind::WheelStops, n) && !self.wheel.silent {
            self.wheel.silent = true;
            self.log(DEVICE, Kind::Fault, "controller stops answering");
        }
    }
}

/// A handle to the simulated wheel.
pub(crate) struct SimWheel(pub(crate) Rc<RefCell<Bench>>);

impl SimWheel {
    /// Log a command, or time out when the controller has stopped answering.
    fn command(&self, kind: Kind, what: &str) -> Result<std::cell::RefMut<'_, Bench>> {
        let mut b = self.0.borrow_mut();
        if b.wheel.silent {
            return Err(b.no_answer(DEVICE, what));
        }
        b.log(DEVICE, kind, what);
        Ok(b)
    }
}

impl ColorWheel for SimWheel {
    fn set_speed_hz(&mut self, rev_per_s: f64) -> Result<()> {
        let mut b = self.command(Kind::Command, &format!("SPEED {rev_per_s}"))?;
        if !(rev_per_s.is_finite() && rev_per_s > 0.0 && rev_per_s <= b.wheel.max_hz) {
            return Err(Error::device(
                DEVICE,
                format!("speed {rev_per_s} rev/s outside (0, {}]", b.wheel.max_hz),
            ));
        }
        b.wheel.target_hz = rev_per_s;
        Ok(())
    }

    fn start(&mut self) -> Result<()> {
        let mut b = self.command(Kind::Command, "START")?;
        if b.wheel.target_hz <= 0.0 {
            return Err(Error::device(DEVICE, "START before SPEED: no speed set"));
        }
        if !b.wheel.spinning {
            let w = &mut b.wheel;
            w.spinning = true;
            w.gen += 1;
            w.rate_hz = START_FRACTION * w.target_hz;
            w.stable_turns = 0;
            let (gen, first) = (w.gen, ns(1.0 / w.rate_hz));
            let t = b.now + first;
            b.schedule(t, Ev::Index { gen });
        }
        Ok(())
    }

    fn stop(&mut self) -> Result<()> {
        let mut b = self.command(Kind::Command, "STOP")?;
        let w = &mut b.wheel;
        w.spinning = false;
        w.gen += 1;
        w.rate_hz = 0.0;
        w.measured_hz = 0.0;
        w.stable_turns = 0;
        Ok(())
    }

    fn status(&mut self) -> Result<WheelStatus> {
        let b = self.command(Kind::Inquiry, "STATUS?")?;
        Ok(b.wheel.status())
    }

    fn wait_for_lock(&mut self, timeout_s: f64) -> Result<WheelStatus> {
        let mut b = self.command(Kind::Inquiry, "wait for LOCK")?;
        let until = b.now + ns(timeout_s);
        if b.run_until(until, |b| b.wheel.locked())? {
            return Ok(b.wheel.status());
        }
        Err(Error::Timeout {
            device: DEVICE.into(),
            what: format!("phase lock at {} rev/s", b.wheel.target_hz),
            after_s: timeout_s,
        })
    }

    fn events(&self) -> Vec<Event> {
        self.0.borrow().events_of(DEVICE)
    }
}
