//! The device traits, one per role, named as their users know them: a colour-wheel motor
//! controller, a ViALUX ALP-4-style DMD and a GenICam camera (SFNC feature names). The
//! controller drives simulated devices (`sim`) and real ones through these same traits, so an
//! acquisition is rehearsed on the twin before the hardware is powered.

use crate::error::Result;
use crate::log::Event;
use serde::Serialize;

/// What a wheel's motor controller reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WheelStatus {
    pub spinning: bool,
    /// The speed it was asked to hold (rev/s).
    pub target_hz: f64,
    /// The speed measured from the last index period (rev/s); 0 when stopped.
    pub measured_hz: f64,
    /// Phase lock: the measured speed has held the target within the lock tolerance.
    pub locked: bool,
    /// Index pulses counted since power-up.
    pub index_pulses: u64,
}

/// A spinning colour wheel with an index sensor (one pulse per turn, as segment 0 enters the
/// beam) whose output starts the DMD's sequence.
pub trait ColorWheel {
    /// Set the speed to hold (rev/s); takes effect at `start` or at once when spinning.
    fn set_speed_hz(&mut self, rev_per_s: f64) -> Result<()>;
    /// Spin up towards the set speed.
    fn start(&mut self) -> Result<()>;
    /// Spin down (the index pulses stop).
    fn stop(&mut self) -> Result<()>;
    fn status(&mut self) -> Result<WheelStatus>;
    /// Wait until the wheel reports phase lock; a timeout error otherwise.
    fn wait_for_lock(&mut self, timeout_s: f64) -> Result<WheelStatus>;
    /// Every command, edge and fault so far.
    fn events(&self) -> Vec<Event>;
}

/// How the DMD starts its sequence (ALP_PROJ_MODE and ALP_PROJ_STEP).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ProjectionMode {
    /// Free-running: the sequence repeats on the DMD's own clock (ALP_MASTER).
    Master,
    /// Each edge on trigger-in runs the sequence once (ALP_SLAVE).
    Slave,
    /// Each edge on trigger-in shows the next picture (ALP_PROJ_STEP).
    Step,
}

/// The timing of a sequence (AlpSeqTiming), in seconds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SeqTiming {
    /// How long each picture is lit (≤ `picture_s`; the rest of the picture is dark).
    pub illuminate_s: f64,
    /// Time from one picture to the next.
    pub picture_s: f64,
    /// Delay of the synch output after the sequence starts.
    pub synch_delay_s: f64,
    pub synch_pulse_width_s: f64,
    /// Delay from the trigger-in edge to the sequence start (slave mode).
    pub trigger_in_delay_s: f64,
}

/// What the DMD says about itself (AlpDevInquire).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct DmdInfo {
    pub width: usize,
    pub height: usize,
    /// The shortest picture time of a binary (1 bit-plane) sequence.
    pub min_picture_time_s: f64,
    /// Binary pictures its memory holds.
    pub max_pictures: usize,
}

/// Counters of the projection (AlpProjInquireEx, ALP_PROJ_PROGRESS).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct DmdStatus {
    pub projecting: bool,
    /// Edges received on trigger-in.
    pub triggers: u64,
    /// Sequences started (each emits one synch-out edge).
    pub sequences_started: u64,
}

/// A handle to an allocated sequence.
pub type SequenceId = u32;

/// One binary picture, one bit per mirror, row-major, packed most significant bit first
/// (ALP_DATA_BINARY_TOPDOWN).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BitPlane {
    pub width: usize,
    pub height: usize,
    pub bits: Vec<u8>,
}

impl BitPlane {
    /// A picture with every mirror `on` (bright) or off (dark).
    pub fn uniform(width: usize, height: usize, on: bool) -> BitPlane {
        let mut p = BitPlane {
            width,
            height,
            bits: vec![0; (width * height).div_ceil(8)],
        };
        if on {
            for i in 0..width * height {
                p.set(i);
            }
        }
        p
    }

    /// Turn mirror `i` (row-major index) on.
    pub fn set(&mut self, i: usize) {
        self.bits[i / 8] |= 0x80 >> (i % 8);
    }

    pub fn get(&self, i: usize) -> bool {
        self.bits[i / 8] & (0x80 >> (i % 8)) != 0
    }
}

/// A ViALUX ALP-4-style DMD: allocate a sequence, upload binary pictures, set its timing and
/// the projection mode, start, halt. Its synch output starts the camera's exposure.
pub trait Dmd {
    /// AlpDevInquire: size, minimum picture time, memory.
    fn inquire(&mut self) -> Result<DmdInfo>;
    /// AlpSeqAlloc: room for `pictures` pictures of `bit_planes` bit planes.
    fn seq_alloc(&mut self, bit_planes: u32, pictures: usize) -> Result<SequenceId>;
    /// AlpSeqPut: upload pictures from index `first`.
    fn seq_put(&mut self, seq: SequenceId, first: usize, pictures: &[BitPlane]) -> Result<()>;
    /// AlpSeqTiming; refused below the minimum picture time.
    fn seq_timing(&mut self, seq: SequenceId, timing: &SeqTiming) -> Result<()>;
    /// AlpProjControl(ALP_PROJ_MODE / ALP_PROJ_STEP).
    fn set_projection_mode(&mut self, mode: ProjectionMode) -> Result<()>;
    /// AlpProjStartCont: project `seq` until halted (waiting for triggers in slave/step mode).
    fn proj_start_cont(&mut self, seq: SequenceId) -> Result<()>;
    /// AlpProjHalt: stop projecting; the mirrors go dark.
    fn proj_halt(&mut self) -> Result<()>;
    /// AlpSeqFree.
    fn seq_free(&mut self, seq: SequenceId) -> Result<()>;
    fn status(&mut self) -> Result<DmdStatus>;
    fn events(&self) -> Vec<Event>;
}

/// GenICam TriggerMode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum TriggerMode {
    Off,
    On,
}

/// GenICam TriggerSource: Line1 is wired to the DMD's synch out, Line2 to the wheel's index.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum TriggerSource {
    Line1,
    Line2,
    Software,
}

/// GenICam ExposureMode.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum ExposureMode {
    /// ExposureTime sets the length.
    Timed,
    /// The trigger pulse's width sets the length.
    TriggerWidth,
}

/// What the camera says about itself (feature ranges).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CameraInfo {
    pub width: usize,
    pub height: usize,
    /// Bits per pixel delivered (Mono12 in 16-bit words: 12).
    pub bits: u32,
    pub min_exposure_s: f64,
    pub max_exposure_s: f64,
    pub max_frame_rate_hz: f64,
    /// Sensor read-out after each exposure.
    pub readout_s: f64,
}

/// One frame with its chunk data (SFNC ChunkFrameID, ChunkTimestamp, ChunkExposureTime,
/// ChunkCounterValue of two counters reset at ExposureStart).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// ChunkFrameID (BlockID): counts every exposure, so a gap is a lost frame.
    pub frame_id: u64,
    /// ChunkTimestamp: exposure start on the camera's clock, ns.
    pub timestamp_ns: u64,
    pub exposure_s: f64,
    /// Counter0: Line1 (DMD synch out) rising edges during the exposure.
    pub line1_edges: u32,
    /// Counter1: Line2 (wheel index) rising edges during the exposure.
    pub line2_edges: u32,
    pub width: usize,
    pub height: usize,
    /// Raw DN, row-major.
    pub data: Vec<u16>,
}

/// A GenICam camera, configured through SFNC features and triggered by a hardware line.
pub trait Camera {
    fn inquire(&mut self) -> Result<CameraInfo>;
    fn set_trigger_mode(&mut self, mode: TriggerMode) -> Result<()>;
    fn set_trigger_source(&mut self, source: TriggerSource) -> Result<()>;
    /// TriggerDivider: accept one trigger edge in `n`.
    fn set_trigger_divider(&mut self, n: u32) -> Result<()>;
    fn set_exposure_mode(&mut self, mode: ExposureMode) -> Result<()>;
    /// ExposureTime (the feature is in µs; the argument in seconds).
    fn set_exposure_time_s(&mut self, s: f64) -> Result<()>;
    /// AcquisitionFrameRate: the free-running rate, and the highest rate triggers may reach.
    fn set_acquisition_frame_rate_hz(&mut self, hz: f64) -> Result<()>;
    /// AcquisitionStart; returns the camera clock at that moment (TimestampLatchValue, ns):
    /// frames stamped earlier belong to an earlier acquisition.
    fn arm(&mut self) -> Result<u64>;
    /// AcquisitionStop; frames not yet delivered are discarded.
    fn disarm(&mut self) -> Result<()>;
    /// The next frame, or a timeout error after `timeout_s`.
    fn next_frame(&mut self, timeout_s: f64) -> Result<Frame>;
    fn events(&self) -> Vec<Event>;
}

/// What sits in front of the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Target {
    /// The scene to be imaged.
    Scene,
    /// A uniform white reflector (flat and pattern captures).
    White,
}

/// Whoever changes what sits in front of the camera: a person at the rig, or a motorised stage.
pub trait Operator {
    fn place(&mut self, target: Target) -> Result<()>;
}

/// The three devices and the operator of one rig.
pub struct Devices {
    pub wheel: Box<dyn ColorWheel>,
    pub dmd: Box<dyn Dmd>,
    pub camera: Box<dyn Camera>,
    pub operator: Box<dyn Operator>,
}

impl Devices {
    /// Every device's log merged in time order (stable for equal times: wheel, DMD, camera).
    pub fn events(&self) -> Vec<Event> {
        let mut all = self.wheel.events();
        all.extend(self.dmd.events());
        all.extend(self.camera.events());
        all.sort_by_key(|e| e.t_ns);
        all
    }
}
