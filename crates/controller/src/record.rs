//! The recording of an acquisition, written as it happens into one folder:
//!
//! - `frames.ome.tif` — the raw frames (uint16 DN), one page each, appended as they arrive; its
//!   OME-XML counts the pages written so far, and at the end also holds each plane's time and
//!   exposure and the settings;
//! - `frames.jsonl` — one line per frame (id, timestamp, counters, flags), appended and flushed
//!   with each frame, so an interrupted run keeps every frame's record;
//! - `calibration.ome.tif` — the dark, flat and pattern captures (float32 means) the
//!   reconstruction of these frames must use;
//! - `plan.json` and `experiment.json` (the experiment as run, so the recording is reconstructed
//!   with the rig it was taken on) at the start; `events.jsonl` (every device's log) and `acquisition.json` (the
//!   outcome and its incidents) at the end.
//!
//! A recording goes into a new or empty folder. A simulated one (`rehearse`, `acquire --backend
//! sim`) carries a marker ([`SIMULATED`]) and may be replaced by the next simulated run; a real
//! one is never replaced.

use crate::devices::Frame;
use crate::error::{Error, Result};
use crate::log::Event;
use crate::ome::{self, OmeImage, Sample, TiffWriter};
use crate::plan::Plan;
use crate::run::{FrameRecord, Outcome, Sink};
use specmux_core::calibration::CalibrationFrames;
use specmux_core::Cube;
use specmux_io::output_set;
use specmux_twin::Experiment;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The file that marks a recording as simulated, which the next simulated run may replace.
pub const SIMULATED: &str = ".specmux-simulated-recording";

/// Make `dir` the empty folder of a new recording: refused where it holds files, unless they are
/// a simulated recording and this one is simulated too (then they are removed first).
fn empty_folder(dir: &Path, simulated: bool) -> Result<()> {
    let names = output_set::entries(dir);
    let replaceable = simulated && names.iter().any(|n| n == SIMULATED);
    if replaceable {
        std::fs::remove_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    } else if !names.is_empty() {
        let what = match simulated {
            true => "files that are not a simulated recording",
            false => "files, and a real acquisition replaces none",
        };
        let why = format!("a recording needs a new or empty folder; this one holds {what}: {}; pass another --out", output_set::listed(&names));
        return Err(Error::io(dir, std::io::Error::other(why)));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    if simulated {
        let marker = dir.join(SIMULATED);
        let note = "a simulated recording of specmux: the next simulated run with this --out replaces it\n";
        std::fs::write(&marker, note).map_err(|e| Error::io(&marker, e))?;
    }
    Ok(())
}

/// Room kept for the frames file's OME-XML while frames arrive.
const XML_RESERVE: usize = 16 << 10;

/// Writes an acquisition's files as it runs.
pub struct Recorder {
    dir: PathBuf,
    frames: TiffWriter,
    jsonl: File,
    settings: Vec<(String, String)>,
    planes: Vec<(f64, f64)>,
    first_ns: Option<f64>,
    width: usize,
    height: usize,
}

fn json_err(path: &Path, e: serde_json::Error) -> Error {
    Error::io(path, std::io::Error::other(e))
}

impl Recorder {
    /// Create the folder (new or empty; a `simulated` run may replace a simulated recording)
    /// and its files; write the plan and the experiment.
    pub fn create(dir: &Path, plan: &Plan, exp: &Experiment, simulated: bool) -> Result<Recorder> {
        empty_folder(dir, simulated)?;
        specmux_io::json::write_json(&dir.join("plan.json"), plan)?;
        specmux_io::json::write_json(&dir.join("experiment.json"), exp)?;
        let s = &plan.settings;
        let path = dir.join("frames.ome.tif");
        let frames = TiffWriter::create(&path, s.width, s.height, Sample::U16, XML_RESERVE)?;
        let jpath = dir.join("frames.jsonl");
        let jsonl = File::create(&jpath).map_err(|e| Error::io(&jpath, e))?;
        let settings = vec![
            ("experiment".into(), plan.experiment.clone()),
            ("wheel_rev_per_s".into(), s.wheel_hz.to_string()),
            ("dmd_picture_s".into(), s.picture_s.to_string()),
            ("exposure_s".into(), s.exposure_s.to_string()),
            (
                "turns_per_exposure".into(),
                s.turns_per_exposure.to_string(),
            ),
            (
                "trigger".into(),
                format!(
                    "wheel index → DMD slave → synch out → camera Line1, TriggerDivider={}",
                    s.turns_per_frame
                ),
            ),
            ("frame_rate_hz".into(), s.frame_rate_hz.to_string()),
            ("calibration".into(), "calibration.ome.tif".into()),
            ("frame_records".into(), "frames.jsonl".into()),
            ("event_log".into(), "events.jsonl".into()),
        ];
        Ok(Recorder {
            dir: dir.to_path_buf(),
            frames,
            jsonl,
            settings,
            planes: Vec::new(),
            first_ns: None,
            width: s.width,
            height: s.height,
        })
    }

    fn xml(&self, with_planes: bool) -> String {
        let channels = ["raw DN".to_string()];
        ome::ome_xml(&OmeImage {
            name: "acquisition",
            width: self.width,
            height: self.height,
            sample: Sample::U16,
            channels: &channels,
            size_t: self.frames.pages(),
            planes: if with_planes { &self.planes } else { &[] },
            annotations: &self.settings,
        })
    }

    /// The full OME-XML, the event log and the outcome; the files are synced to disk.
    pub fn finish(&mut self, outcome: &Outcome, events: &[Event]) -> Result<()> {
        let x = self.xml(true);
        self.frames.set_description(&x)?;
        self.frames.sync()?;
        let path = self.dir.join("events.jsonl");
        let mut text = String::new();
        for e in events {
            text += &serde_json::to_string(e).map_err(|e| json_err(&path, e))?;
            text.push('\n');
        }
        specmux_io::atomic::write_bytes(&path, text.as_bytes())?;
        specmux_io::json::write_json(&self.dir.join("acquisition.json"), outcome)?;
        Ok(())
    }
}

impl Sink for Recorder {
    fn calibrated(&mut self, f: &CalibrationFrames, records: &[FrameRecord]) -> Result<()> {
        write_calibration(&self.dir, f)?;
        Ok(specmux_io::json::write_json(
            &self.dir.join("calibration.json"),
            &records,
        )?)
    }

    fn frame(&mut self, r: &FrameRecord, frame: &Frame) -> Result<()> {
        let bytes: Vec<u8> = frame.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.frames.append(&bytes)?;
        let t0 = *self.first_ns.get_or_insert(r.timestamp_s);
        self.planes.push((r.timestamp_s - t0, r.exposure_s));
        let x = self.xml(false);
        self.frames.set_description(&x)?;
        let jpath = self.dir.join("frames.jsonl");
        let line = serde_json::to_string(r).map_err(|e| json_err(&jpath, e))?;
        writeln!(self.jsonl, "{line}").map_err(|e| Error::io(&jpath, e))
    }
}

/// The calibration captures as one float32 OME-TIFF: dark, flat, then each pattern.
pub fn write_calibration(dir: &Path, f: &CalibrationFrames) -> Result<()> {
    let p = &f.patterns;
    let (Some(dark), Some(flat)) = (&f.dark, &f.flat) else {
        return Err(Error::device(
            "recorder",
            "calibration without dark and flat frames",
        ));
    };
    let path = dir.join("calibration.ome.tif");
    let tmp = dir.join(".calibration.ome.tif.tmp");
    let mut w = TiffWriter::create(&tmp, p.width, p.height, Sample::F32, 4096)?;
    let mut names = vec!["dark".to_string(), "flat".to_string()];
    names.extend((0..p.planes).map(|k| format!("pattern {k}")));
    let ann = vec![
        ("frames_averaged".to_string(), f.frames_averaged.to_string()),
        ("source".to_string(), f.source.clone()),
        (
            "units".to_string(),
            "raw DN, mean of the exposures".to_string(),
        ),
    ];
    w.set_description(&ome::ome_xml(&OmeImage {
        name: "calibration",
        width: p.width,
        height: p.height,
        sample: Sample::F32,
        channels: &names,
        size_t: 1,
        planes: &[],
        annotations: &ann,
    }))?;
    for plane in [dark.plane(0), flat.plane(0)]
        .into_iter()
        .chain((0..p.planes).map(|k| p.plane(k)))
    {
        w.append(
            &plane
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect::<Vec<u8>>(),
        )?;
    }
    w.sync()?;
    std::fs::rename(&tmp, &path).map_err(|e| Error::io(&path, e))
}

/// Read `calibration.ome.tif` back into the frames the core's calibration takes.
pub fn read_calibration(dir: &Path) -> Result<CalibrationFrames> {
    let path = dir.join("calibration.ome.tif");
    let (xml, pages) = ome::read(&path)?;
    if pages.len() < 3 {
        return Err(Error::device(
            "recorder",
            format!(
                "{}: {} planes; dark, flat and at least one pattern expected",
                path.display(),
                pages.len()
            ),
        ));
    }
    let (w, h) = (pages[0].width, pages[0].height);
    let cube = |k: usize| Cube::from_vec(w, h, 1, pages[k].data.clone());
    let mut patterns = Cube::zeros(w, h, pages.len() - 2);
    for (k, p) in pages[2..].iter().enumerate() {
        patterns.plane_mut(k).copy_from_slice(&p.data);
    }
    let averaged = xml
        .split("<M K=\"frames_averaged\">")
        .nth(1)
        .and_then(|r| r.split('<').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    Ok(CalibrationFrames {
        dark: Some(cube(0)?),
        flat: Some(cube(1)?),
        patterns,
        patterns_linear: false,
        frames_averaged: averaged,
        source: "captures".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_simulated_recording_is_replaced_and_only_by_a_simulated_run() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join("rec");
        empty_folder(&dir, true).unwrap();
        std::fs::write(dir.join("frames.ome.tif"), "old").unwrap();
        // A real run never replaces a recording, even a simulated one.
        let e = empty_folder(&dir, false).unwrap_err().to_string();
        assert!(e.contains("a real acquisition replaces none"), "{e}");
        assert!(dir.join("frames.ome.tif").exists());
        // A simulated run replaces a simulated recording whole.
        empty_folder(&dir, true).unwrap();
        assert!(!dir.join("frames.ome.tif").exists() && dir.join(SIMULATED).exists());
        // A real recording (no marker) is replaced by no run.
        let real = scratch.path().join("real");
        empty_folder(&real, false).unwrap();
        std::fs::write(real.join("frames.ome.tif"), "raw").unwrap();
        let e = empty_folder(&real, true).unwrap_err().to_string();
        assert!(
            e.contains("not a simulated recording") && e.contains("frames.ome.tif"),
            "{e}"
        );
        assert!(!real.join(SIMULATED).exists());
    }
}
