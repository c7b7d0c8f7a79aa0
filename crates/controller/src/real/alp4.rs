//! A ViALUX ALP-4 DMD through the vendor's library, loaded at run time (dlopen), so the build
//! needs no SDK and a machine without the library refuses cleanly, naming the path and the
//! reason. The call flow is the vendor's: AlpDevAlloc → AlpSeqAlloc → AlpSeqControl (packed
//! binary data) → AlpSeqPut → AlpSeqTiming → AlpProjControl → AlpProjStartCont → AlpProjHalt
//! → AlpSeqFree → AlpDevFree. Constants are those of the vendor's alp.h (as its Python, C# and
//! MATLAB wrappers repeat them); times go to the library in µs.

use crate::devices::{BitPlane, Dmd, DmdInfo, DmdStatus, ProjectionMode, SeqTiming, SequenceId};
use crate::error::{Error, Result};
use crate::log::{Event, EventLog, Kind};
use libc::{c_long, c_ulong, c_void};
use std::ffi::{CStr, CString};
use std::path::Path;
use std::time::Instant;

const DEVICE: &str = "dmd";
const ALP_DEFAULT: c_long = 0;
const ALP_OK: c_long = 0;
const ALP_AVAIL_MEMORY: c_long = 2003;
const ALP_DEV_DISPLAY_HEIGHT: c_long = 2057;
const ALP_DEV_DISPLAY_WIDTH: c_long = 2058;
const ALP_DATA_FORMAT: c_long = 2110;
const ALP_DATA_BINARY_TOPDOWN: c_long = 2;
const ALP_MIN_PICTURE_TIME: c_long = 2211;
const ALP_PROJ_MODE: c_long = 2300;
const ALP_MASTER: c_long = 2301;
const ALP_SLAVE: c_long = 2302;
const ALP_PROJ_STEP: c_long = 2329;
const ALP_EDGE_RISING: c_long = 2009;
const ALP_PROJ_STATE: c_long = 2400;
const ALP_PROJ_ACTIVE: c_long = 1200;

type Id = c_ulong;

type DevAlloc = unsafe extern "C" fn(c_long, c_long, *mut Id) -> c_long;
type DevInquire = unsafe extern "C" fn(Id, c_long, *mut c_long) -> c_long;
type DevOnly = unsafe extern "C" fn(Id) -> c_long;
type SeqAlloc = unsafe extern "C" fn(Id, c_long, c_long, *mut Id) -> c_long;
type SeqControl = unsafe extern "C" fn(Id, Id, c_long, c_long) -> c_long;
type SeqInquire = unsafe extern "C" fn(Id, Id, c_long, *mut c_long) -> c_long;
type SeqPut = unsafe extern "C" fn(Id, Id, c_long, c_long, *const c_void) -> c_long;
type SeqTime = unsafe extern "C" fn(Id, Id, c_long, c_long, c_long, c_long, c_long) -> c_long;
type DevSeq = unsafe extern "C" fn(Id, Id) -> c_long;
type ProjControl = unsafe extern "C" fn(Id, c_long, c_long) -> c_long;

/// The library's entry points.
struct Api {
    dev_alloc: DevAlloc,
    dev_inquire: DevInquire,
    dev_free: DevOnly,
    seq_alloc: SeqAlloc,
    seq_control: SeqControl,
    seq_inquire: SeqInquire,
    seq_put: SeqPut,
    seq_timing: SeqTime,
    seq_free: DevSeq,
    proj_control: ProjControl,
    proj_inquire: DevInquire,
    proj_start_cont: DevSeq,
    proj_halt: DevOnly,
}

fn dl_error() -> String {
    // SAFETY: dlerror returns a thread-local C string or null.
    unsafe {
        let e = libc::dlerror();
        if e.is_null() {
            "unknown error".into()
        } else {
            CStr::from_ptr(e).to_string_lossy().into_owned()
        }
    }
}

/// Resolve every entry point of the library at `path`.
fn load(path: &Path) -> Result<Api> {
    let refuse =
        |why: String| Error::device(DEVICE, format!("ALP-4 library {}: {why}", path.display()));
    let c = CString::new(path.as_os_str().as_encoded_bytes())
        .map_err(|_| refuse("a NUL in the path".into()))?;
    // SAFETY: dlopen with a valid C string; the handle is kept for the process's life.
    let h = unsafe { libc::dlopen(c.as_ptr(), libc::RTLD_NOW | libc::RTLD_LOCAL) };
    if h.is_null() {
        return Err(refuse(format!(
            "cannot be loaded ({}); install the vendor's ALP-4 library or pass its path",
            dl_error()
        )));
    }
    macro_rules! sym {
        ($name:literal as $ty:ty) => {{
            // SAFETY: the name is NUL-terminated; the symbol is cast to the ALP signature of alp.h.
            let p = unsafe { libc::dlsym(h, concat!($name, "\0").as_ptr().cast()) };
            if p.is_null() {
                return Err(refuse(format!("has no {} (not an ALP-4 library?)", $name)));
            }
            unsafe { std::mem::transmute::<*mut c_void, $ty>(p) }
        }};
    }
    Ok(Api {
        dev_alloc: sym!("AlpDevAlloc" as DevAlloc),
        dev_inquire: sym!("AlpDevInquire" as DevInquire),
        dev_free: sym!("AlpDevFree" as DevOnly),
        seq_alloc: sym!("AlpSeqAlloc" as SeqAlloc),
        seq_control: sym!("AlpSeqControl" as SeqControl),
        seq_inquire: sym!("AlpSeqInquire" as SeqInquire),
        seq_put: sym!("AlpSeqPut" as SeqPut),
        seq_timing: sym!("AlpSeqTiming" as SeqTime),
        seq_free: sym!("AlpSeqFree" as DevSeq),
        proj_control: sym!("AlpProjControl" as ProjControl),
        proj_inquire: sym!("AlpProjInquire" as DevInquire),
        proj_start_cont: sym!("AlpProjStartCont" as DevSeq),
        proj_halt: sym!("AlpProjHalt" as DevOnly),
    })
}

/// An allocated ALP-4 device.
pub struct AlpDmd {
    api: Api,
    dev: Id,
    width: usize,
    height: usize,
    log: EventLog,
    t0: Instant,
}

impl AlpDmd {
    /// Load the library at `lib` and allocate the first device (AlpDevAlloc(ALP_DEFAULT)).
    pub fn open(lib: &Path) -> Result<AlpDmd> {
        let api = load(lib)?;
        let mut dev: Id = 0;
        // SAFETY: the out-pointer is a local the call fills.
        let rc = unsafe { (api.dev_alloc)(ALP_DEFAULT, ALP_DEFAULT, &mut dev) };
        let mut d = AlpDmd {
            api,
            dev,
            width: 0,
            height: 0,
            log: EventLog::default(),
            t0: Instant::now(),
        };
        d.check("AlpDevAlloc", rc)?;
        d.width = d.dev_inquire(ALP_DEV_DISPLAY_WIDTH)? as usize;
        d.height = d.dev_inquire(ALP_DEV_DISPLAY_HEIGHT)? as usize;
        Ok(d)
    }

    fn note(&mut self, kind: Kind, what: String) {
        self.log
            .push(self.t0.elapsed().as_nanos() as u64, DEVICE, kind, what);
    }

    fn check(&mut self, call: &str, rc: c_long) -> Result<()> {
        if rc == ALP_OK {
            return Ok(());
        }
        Err(Error::device(
            DEVICE,
            format!("{call} returned {rc} ({})", alp_error(rc)),
        ))
    }

    fn dev_inquire(&mut self, what: c_long) -> Result<c_long> {
        let mut v: c_long = 0;
        // SAFETY: out-pointer to a local.
        let rc = unsafe { (self.api.dev_inquire)(self.dev, what, &mut v) };
        self.check("AlpDevInquire", rc).map(|_| v)
    }

    fn us(s: f64) -> c_long {
        (s * 1e6).round() as c_long
    }
}

/// The meaning of an ALP return code (alp.h).
fn alp_error(rc: c_long) -> &'static str {
    match rc {
        1001 => "ALP_NOT_ONLINE: device not found or not ready",
        1002 => "ALP_NOT_IDLE",
        1003 => "ALP_NOT_AVAILABLE: invalid device id",
        1004 => "ALP_NOT_READY: already allocated",
        1005 => "ALP_PARM_INVALID",
        1006 => "ALP_ADDR_INVALID",
        1007 => "ALP_MEMORY_FULL",
        1008 => "ALP_SEQ_IN_USE",
        _ => "see alp.h",
    }
}

impl Dmd for AlpDmd {
    fn inquire(&mut self) -> Result<DmdInfo> {
        self.note(Kind::Inquiry, "AlpDevInquire".into());
        let memory = self.dev_inquire(ALP_AVAIL_MEMORY)?;
        // The minimum picture time is a property of a binary sequence: ask a one-picture one.
        let seq = self.seq_alloc(1, 1)?;
        let mut min_us: c_long = 0;
        // SAFETY: out-pointer to a local.
        let rc = unsafe {
            (self.api.seq_inquire)(self.dev, seq as Id, ALP_MIN_PICTURE_TIME, &mut min_us)
        };
        let freed = self.seq_free(seq);
        self.check("AlpSeqInquire", rc)?;
        freed?;
        Ok(DmdInfo {
            width: self.width,
            height: self.height,
            min_picture_time_s: min_us as f64 * 1e-6,
            max_pictures: memory.max(0) as usize,
        })
    }

    fn seq_alloc(&mut self, bit_planes: u32, pictures: usize) -> Result<SequenceId> {
        self.note(
            Kind::Command,
            format!("AlpSeqAlloc bitplanes={bit_planes} pictures={pictures}"),
        );
        let mut id: Id = 0;
        // SAFETY: out-pointer to a local.
        let rc = unsafe {
            (self.api.seq_alloc)(self.dev, bit_planes as c_long, pictures as c_long, &mut id)
        };
        self.check("AlpSeqAlloc", rc)?;
        // SAFETY: plain call on the sequence just allocated.
        let rc = unsafe {
            (self.api.seq_control)(self.dev, id, ALP_DATA_FORMAT, ALP_DATA_BINARY_TOPDOWN)
        };
        self.check("AlpSeqControl ALP_DATA_FORMAT", rc)?;
        Ok(id as SequenceId)
    }

    fn seq_put(&mut self, seq: SequenceId, first: usize, pictures: &[BitPlane]) -> Result<()> {
        self.note(
            Kind::Command,
            format!("AlpSeqPut {seq} first={first} n={}", pictures.len()),
        );
        if let Some(p) = pictures
            .iter()
            .find(|p| (p.width, p.height) != (self.width, self.height))
        {
            return Err(Error::device(DEVICE, format!("AlpSeqPut {seq}: a {} × {} picture for a {} × {} DMD; pad the patterns to the DMD", p.width, p.height, self.width, self.height)));
        }
        let data: Vec<u8> = pictures
            .iter()
            .flat_map(|p| p.bits.iter().copied())
            .collect();
        // SAFETY: `data` holds `pictures.len()` packed pictures of the DMD's size and outlives the call.
        let rc = unsafe {
            (self.api.seq_put)(
                self.dev,
                seq as Id,
                first as c_long,
                pictures.len() as c_long,
                data.as_ptr().cast(),
            )
        };
        self.check("AlpSeqPut", rc)
    }

    fn seq_timing(&mut self, seq: SequenceId, t: &SeqTiming) -> Result<()> {
        self.note(
            Kind::Command,
            format!(
                "AlpSeqTiming {seq} illuminate={}µs picture={}µs",
                t.illuminate_s * 1e6,
                t.picture_s * 1e6
            ),
        );
        let us = Self::us;
        // SAFETY: plain values.
        let rc = unsafe {
            (self.api.seq_timing)(
                self.dev,
                seq as Id,
                us(t.illuminate_s),
                us(t.picture_s),
                us(t.synch_delay_s),
                us(t.synch_pulse_width_s),
                us(t.trigger_in_delay_s),
            )
        };
        self.check("AlpSeqTiming", rc)
    }

    fn set_projection_mode(&mut self, mode: ProjectionMode) -> Result<()> {
        self.note(Kind::Command, format!("AlpProjControl mode={mode:?}"));
        let (ty, value) = match mode {
            ProjectionMode::Master => (ALP_PROJ_MODE, ALP_MASTER),
            ProjectionMode::Slave => (ALP_PROJ_MODE, ALP_SLAVE),
            ProjectionMode::Step => (ALP_PROJ_STEP, ALP_EDGE_RISING),
        };
        // SAFETY: plain values.
        let rc = unsafe { (self.api.proj_control)(self.dev, ty, value) };
        self.check("AlpProjControl", rc)
    }

    fn proj_start_cont(&mut self, seq: SequenceId) -> Result<()> {
        self.note(Kind::Command, format!("AlpProjStartCont {seq}"));
        // SAFETY: plain values.
        let rc = unsafe { (self.api.proj_start_cont)(self.dev, seq as Id) };
        self.check("AlpProjStartCont", rc)
    }

    fn proj_halt(&mut self) -> Result<()> {
        self.note(Kind::Command, "AlpProjHalt".into());
        // SAFETY: plain value.
        let rc = unsafe { (self.api.proj_halt)(self.dev) };
        self.check("AlpProjHalt", rc)
    }

    fn seq_free(&mut self, seq: SequenceId) -> Result<()> {
        self.note(Kind::Command, format!("AlpSeqFree {seq}"));
        // SAFETY: plain values.
        let rc = unsafe { (self.api.seq_free)(self.dev, seq as Id) };
        self.check("AlpSeqFree", rc)
    }

    /// The projection state; the trigger and sequence counters are not read from the device
    /// (the camera's chunk counters carry them on a real rig).
    fn status(&mut self) -> Result<DmdStatus> {
        self.note(Kind::Inquiry, "AlpProjInquire ALP_PROJ_STATE".into());
        let mut v: c_long = 0;
        // SAFETY: out-pointer to a local.
        let rc = unsafe { (self.api.proj_inquire)(self.dev, ALP_PROJ_STATE, &mut v) };
        self.check("AlpProjInquire", rc)?;
        Ok(DmdStatus {
            projecting: v == ALP_PROJ_ACTIVE,
            ..DmdStatus::default()
        })
    }

    fn events(&self) -> Vec<Event> {
        self.log.entries().to_vec()
    }
}

impl Drop for AlpDmd {
    /// Halt and free the device, whatever happened before.
    fn drop(&mut self) {
        // SAFETY: the device id came from AlpDevAlloc.
        unsafe {
            (self.api.proj_halt)(self.dev);
            (self.api.dev_free)(self.dev);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_absent_or_foreign_library_is_refused_in_one_line() {
        let Err(e) = AlpDmd::open(Path::new("/nonexistent/libalp4395.so")) else {
            panic!("loaded")
        };
        let msg = e.to_string();
        assert!(
            msg.starts_with("dmd: ALP-4 library /nonexistent/libalp4395.so: cannot be loaded"),
            "{msg}"
        );
        assert!(!msg.contains('\n'));
        // A real shared library without the ALP entry points.
        let Err(e) = AlpDmd::open(Path::new("libc.so.6")) else {
            panic!("libc is not an ALP")
        };
        assert!(e.to_string().contains("has no AlpDevAlloc"), "{e}");
    }
}
