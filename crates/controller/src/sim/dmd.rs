//! The simulated DMD, after the ALP-4 call flow: sequences are allocated, filled with binary
//! pictures and timed; in slave mode each trigger-in edge runs the sequence once (a trigger
//! during a running sequence is ignored), in master mode the sequence repeats on its own clock,
//! in step mode each edge shows the next picture. Each sequence start emits a synch-out edge.
//! The twin images only the pictures it knows: each design pattern, all dark, all bright.

use super::{ns, Bench, Ev, FaultKind};
use crate::devices::{
    BitPlane, Dmd, DmdInfo, DmdStatus, ProjectionMode, SeqTiming, SequenceId, TriggerSource,
};
use crate::error::{Error, Result};
use crate::log::{Event, Kind};
use crate::plan::DeviceLimits;
use std::cell::RefCell;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::rc::Rc;

const DEVICE: &str = "dmd";

/// What a binary picture images to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Picture {
    /// Design pattern k: the twin's s̃_k.
    Pattern(usize),
    /// Every mirror off.
    Dark,
    /// Every mirror on: a uniform 1.
    Bright,
}

/// One picture on the mirrors from `start` to `end` (virtual ns).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Shown {
    pub start: u64,
    pub end: u64,
    pub picture: Picture,
}

struct Sequence {
    pictures: Vec<Option<Picture>>,
    timing: Option<SeqTiming>,
}

pub(crate) struct DmdSim {
    info: DmdInfo,
    table: HashMap<BitPlane, Picture>,
    seqs: BTreeMap<SequenceId, Sequence>,
    next_id: SequenceId,
    mode: ProjectionMode,
    running: Option<SequenceId>,
    gen: u64,
    busy_until: u64,
    step: usize,
    status: DmdStatus,
    /// Recent pictures shown, and synch-out edges.
    pub(crate) shown: VecDeque<Shown>,
    pub(crate) synchs: VecDeque<u64>,
}

impl DmdSim {
    pub(crate) fn new(limits: &DeviceLimits, table: HashMap<BitPlane, Picture>) -> DmdSim {
        DmdSim {
            info: DmdInfo {
                width: limits.dmd_width,
                height: limits.dmd_height,
                min_picture_time_s: limits.dmd_min_picture_s,
                max_pictures: limits.dmd_max_pictures,
            },
            table,
            seqs: BTreeMap::new(),
            next_id: 1,
            mode: ProjectionMode::Master,
            running: None,
            gen: 0,
            busy_until: 0,
            step: 0,
            status: DmdStatus::default(),
            shown: VecDeque::new(),
            synchs: VecDeque::new(),
        }
    }

    fn allocated(&self) -> usize {
        self.seqs.values().map(|s| s.pictures.len()).sum()
    }

    /// The running sequence's pictures and timing.
    fn current(&self) -> Option<(Vec<Picture>, SeqTiming)> {
        let s = self.seqs.get(&self.running?)?;
        let pics = s
            .pictures
            .iter()
            .map(|p| p.unwrap_or(Picture::Dark))
            .collect();
        Some((pics, s.timing?))
    }
}

impl Bench {
    /// An edge on trigger-in (the wheel's index pulse). `mid` is the scene exposure whose middle
    /// this turn reaches, where an underrun fault strikes.
    pub(super) fn dmd_trigger_in(&mut self, mid: Option<u64>) {
        if self.dmd.running.is_none() || self.dmd.mode == ProjectionMode::Master {
            return;
        }
        self.dmd.status.triggers += 1;
        let Some((pics, timing)) = self.dmd.current() else {
            return;
        };
        if mid.is_some_and(|n| self.faults.at(FaultKind::DmdUnderrun, n)) {
            self.log(
                DEVICE,
                Kind::Fault,
                "underrun: the sequence did not start on this trigger",
            );
            return;
        }
        let start = self.now + ns(timing.trigger_in_delay_s);
        if self.dmd.mode == ProjectionMode::Step {
            let k = self.dmd.step % pics.len().max(1);
            self.dmd.step += 1;
            self.show(start, &pics[k..=k], &timing);
            return;
        }
        // A sequence as long as the turn ends when the next trigger comes (ns rounding aside).
        if self.now + ns(timing.picture_s) / 100 < self.dmd.busy_until {
            self.log(
                DEVICE,
                Kind::Edge,
                "trigger ignored: the sequence is still running",
            );
            return;
        }
        self.dmd.busy_until = start + ns(timing.picture_s) * pics.len() as u64;
        let gen = self.dmd.gen;
        self.schedule(start, Ev::DmdSeqStart { gen });
    }

    /// The sequence starts: its pictures go on the mirrors one picture time apart.
    pub(super) fn on_seq_start(&mut self, gen: u64) {
        if gen != self.dmd.gen {
            return;
        }
        let Some((pics, timing)) = self.dmd.current() else {
            return;
        };
        self.show(self.now, &pics, &timing);
        if self.dmd.mode == ProjectionMode::Master {
            let next = self.now + ns(timing.picture_s) * pics.len() as u64;
            self.schedule(next, Ev::DmdSeqStart { gen });
        }
    }

    /// Show `pics` from `start`, count a sequence start and schedule its synch-out edge.
    fn show(&mut self, start: u64, pics: &[Picture], t: &SeqTiming) {
        let (pic, lit) = (ns(t.picture_s), ns(t.illuminate_s));
        for (k, &picture) in pics.iter().enumerate() {
            let s = start + pic * k as u64;
            self.dmd.shown.push_back(Shown {
                start: s,
                end: s + lit,
                picture,
            });
        }
        self.dmd.status.sequences_started += 1;
        let n = self.dmd.status.sequences_started;
        let id = self.dmd.running.unwrap_or(0);
        self.log(DEVICE, Kind::Edge, format!("sequence {id} start {n}"));
        let gen = self.dmd.gen;
        let width_ns = ns(t.synch_pulse_width_s);
        self.schedule(start + ns(t.synch_delay_s), Ev::SynchOut { gen, width_ns });
        let keep_from = self
            .cam
            .exposure_start()
            .unwrap_or(self.now)
            .saturating_sub(ns(0.1));
        while self.dmd.shown.front().is_some_and(|s| s.end < keep_from) {
            self.dmd.shown.pop_front();
        }
        while self.dmd.synchs.front().is_some_and(|&s| s < keep_from) {
            self.dmd.synchs.pop_front();
        }
    }

    pub(super) fn on_synch_out(&mut self, gen: u64, width_ns: u64) {
        if gen != self.dmd.gen {
            return;
        }
        self.dmd.synchs.push_back(self.now);
        self.log(DEVICE, Kind::Edge, "synch out");
        self.camera_edge(TriggerSource::Line1, width_ns);
    }
}

/// A handle to the simulated DMD.
pub(crate) struct SimDmd(pub(crate) Rc<RefCell<Bench>>);

impl SimDmd {
    fn command(&self, kind: Kind, what: String) -> std::cell::RefMut<'_, Bench> {
        let mut b = self.0.borrow_mut();
        b.log(DEVICE, kind, what);
        b
    }
}

fn refuse(msg: impl Into<String>) -> Error {
    Error::device(DEVICE, msg)
}

impl Dmd for SimDmd {
    fn inquire(&mut self) -> Result<DmdInfo> {
        Ok(self.command(Kind::Inquiry, "AlpDevInquire".into()).dmd.info)
    }

    fn seq_alloc(&mut self, bit_planes: u32, pictures: usize) -> Result<SequenceId> {
        let mut b = self.command(
            Kind::Command,
            format!("AlpSeqAlloc bitplanes={bit_planes} pictures={pictures}"),
        );
        let d = &mut b.dmd;
        if bit_planes != 1 {
            return Err(refuse(format!("AlpSeqAlloc: {bit_planes} bit planes; the simulated DMD shows binary sequences only")));
        }
        if pictures == 0 || d.allocated() + pictures > d.info.max_pictures {
            return Err(refuse(format!(
                "AlpSeqAlloc: {pictures} pictures do not fit ({} of {} in use)",
                d.allocated(),
                d.info.max_pictures
            )));
        }
        let id = d.next_id;
        d.next_id += 1;
        d.seqs.insert(
            id,
            Sequence {
                pictures: vec![None; pictures],
                timing: None,
            },
        );
        Ok(id)
    }

    fn seq_put(&mut self, seq: SequenceId, first: usize, pictures: &[BitPlane]) -> Result<()> {
        let mut b = self.command(
            Kind::Command,
            format!("AlpSeqPut {seq} first={first} n={}", pictures.len()),
        );
        let d = &mut b.dmd;
        let (w, h) = (d.info.width, d.info.height);
        let kinds = pictures
            .iter()
            .enumerate()
            .map(|(i, p)| match d.table.get(p) {
                Some(k) if (p.width, p.height) == (w, h) => Ok(Some(*k)),
                _ => Err(refuse(format!("AlpSeqPut {seq}: picture {} is not a design pattern, dark or bright picture of {w} × {h}; the twin cannot image it", first + i))),
            })
            .collect::<Result<Vec<_>>>()?;
        let s = d
            .seqs
            .get_mut(&seq)
            .ok_or_else(|| refuse(format!("AlpSeqPut: no sequence {seq}")))?;
        if first + kinds.len() > s.pictures.len() {
            return Err(refuse(format!(
                "AlpSeqPut {seq}: pictures {first}..{} beyond the {} allocated",
                first + kinds.len(),
                s.pictures.len()
            )));
        }
        s.pictures[first..first + kinds.len()].copy_from_slice(&kinds);
        Ok(())
    }

    fn seq_timing(&mut self, seq: SequenceId, t: &SeqTiming) -> Result<()> {
        let mut b = self.command(Kind::Command, format!("AlpSeqTiming {seq} illuminate={}µs picture={}µs synch_delay={}µs trigger_in_delay={}µs",
            t.illuminate_s * 1e6, t.picture_s * 1e6, t.synch_delay_s * 1e6, t.trigger_in_delay_s * 1e6));
        let d = &mut b.dmd;
        let min = d.info.min_picture_time_s;
        let finite = [
            t.illuminate_s,
            t.picture_s,
            t.synch_delay_s,
            t.synch_pulse_width_s,
            t.trigger_in_delay_s,
        ]
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0);
        if !finite || t.illuminate_s > t.picture_s || t.illuminate_s < min * (1.0 - 1e-9) {
            return Err(refuse(format!("AlpSeqTiming {seq}: ALP_PARM_INVALID (illuminate {} µs, picture {} µs, minimum picture time {} µs)",
                t.illuminate_s * 1e6, t.picture_s * 1e6, min * 1e6)));
        }
        let s = d
            .seqs
            .get_mut(&seq)
            .ok_or_else(|| refuse(format!("AlpSeqTiming: no sequence {seq}")))?;
        s.timing = Some(*t);
        Ok(())
    }

    fn set_projection_mode(&mut self, mode: ProjectionMode) -> Result<()> {
        let mut b = self.command(Kind::Command, format!("AlpProjControl mode={mode:?}"));
        if b.dmd.running.is_some() {
            return Err(refuse(
                "AlpProjControl: halt the projection before changing its mode",
            ));
        }
        b.dmd.mode = mode;
        Ok(())
    }

    fn proj_start_cont(&mut self, seq: SequenceId) -> Result<()> {
        let mut b = self.command(Kind::Command, format!("AlpProjStartCont {seq}"));
        let ready = b
            .dmd
            .seqs
            .get(&seq)
            .map(|s| s.timing.is_some() && s.pictures.iter().all(Option::is_some));
        match ready {
            None => return Err(refuse(format!("AlpProjStartCont: no sequence {seq}"))),
            Some(false) => {
                return Err(refuse(format!(
                    "AlpProjStartCont {seq}: pictures or timing not set"
                )))
            }
            Some(true) => {}
        }
        if b.dmd.running.is_some() {
            return Err(refuse("AlpProjStartCont: already projecting; halt first"));
        }
        b.dmd.running = Some(seq);
        b.dmd.status.projecting = true;
        b.dmd.busy_until = b.now;
        b.dmd.step = 0;
        if b.dmd.mode == ProjectionMode::Master {
            let (t, gen) = (b.now, b.dmd.gen);
            b.schedule(t, Ev::DmdSeqStart { gen });
        }
        Ok(())
    }

    fn proj_halt(&mut self) -> Result<()> {
        let mut b = self.command(Kind::Command, "AlpProjHalt".into());
        let now = b.now;
        let d = &mut b.dmd;
        d.running = None;
        d.status.projecting = false;
        d.gen += 1;
        d.shown.retain(|s| s.start < now);
        d.shown.iter_mut().for_each(|s| s.end = s.end.min(now));
        Ok(())
    }

    fn seq_free(&mut self, seq: SequenceId) -> Result<()> {
        let mut b = self.command(Kind::Command, format!("AlpSeqFree {seq}"));
        if b.dmd.running == Some(seq) {
            return Err(refuse(format!(
                "AlpSeqFree {seq}: the sequence is projecting; halt first"
            )));
        }
        b.dmd
            .seqs
            .remove(&seq)
            .map(|_| ())
            .ok_or_else(|| refuse(format!("AlpSeqFree: no sequence {seq}")))
    }

    fn status(&mut self) -> Result<DmdStatus> {
        Ok(self
            .command(Kind::Inquiry, "AlpProjInquireEx PROGRESS".into())
            .dmd
            .status)
    }

    fn events(&self) -> Vec<Event> {
        self.0.borrow().events_of(DEVICE)
    }
}
