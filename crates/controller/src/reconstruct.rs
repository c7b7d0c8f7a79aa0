//! Reconstructing recorded frames with the calibration acquired in the same recording: each
//! frame as it arrives during a rehearsal, and a whole recording folder afterwards
//! (`specmux reconstruct DIR`). The error against the truth is reported only where the
//! recording holds one: a rehearsal's `truth.json` names, per frame, the time of the
//! experiment's scene that was in front of the camera (the twin rebuilds it; storing the cubes
//! would take 8 MB a frame at 256 × 256 × 31 bands).

use crate::error::{Error, Result};
use crate::ome;
use crate::record;
use serde::{Deserialize, Serialize};
use specmux_core::calibration::Calibration;
use specmux_core::metrics;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_io::exr;
use specmux_io::output_set::OutputSet;
use specmux_twin::device::DeviceReconstructor;
use specmux_twin::scene::{build_at, Materials};
use specmux_twin::{Experiment, Rig};
use std::path::{Path, PathBuf};

/// One reconstructed frame: its time, flags, reconstruction time and, with a truth, its error.
#[derive(Clone, Debug, Serialize)]
pub struct ReconstructedFrame {
    pub frame_id: u64,
    pub timestamp_s: f64,
    pub flags: usize,
    pub psnr_db: Option<f64>,
    pub ssim: Option<f64>,
    pub sam_deg: Option<f64>,
    pub reconstruction_s: f64,
    /// The frame's mean signal over its noise (`Reconstructor::frame_snr`); None without a
    /// camera noise model or a dark frame.
    pub mean_snr: Option<f64>,
}

/// A recorded frame: id, time, number of flags, raw DN.
pub struct RecordedFrame {
    pub frame_id: u64,
    pub timestamp_s: f64,
    pub flags: usize,
    pub raw: Cube,
}

/// Reconstruct one frame, timed, and compare it with `truth` when there is one.
pub fn reconstruct_frame(
    recon: &DeviceReconstructor,
    f: &RecordedFrame,
    truth: Option<&Cube>,
) -> Result<(Cube, ReconstructedFrame)> {
    let mean_snr = recon.reconstructor().frame_snr(&f.raw)?;
    let run = recon.run(&f.raw, false)?;
    let (cube, reconstruction_s) = (run.cube, run.seconds);
    let m = truth.map(|t| metrics::compare(t, &cube)).transpose()?;
    let row = ReconstructedFrame {
        frame_id: f.frame_id,
        timestamp_s: f.timestamp_s,
        flags: f.flags,
        psnr_db: m.as_ref().map(|m| m.psnr_db),
        ssim: m.as_ref().map(|m| m.ssim),
        sam_deg: m.and_then(|m| m.sam_deg),
        reconstruction_s,
        mean_snr,
    };
    Ok((cube, row))
}

/// When a frame's truth was in front of the camera: the experiment's scene at `scene_t_s`
/// (seconds since it was placed, at the frame's mid-exposure).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TruthTime {
    pub frame_id: u64,
    pub scene_t_s: f64,
}

const TRUTH_FILE: &str = "truth.json";

/// Write a rehearsal's `truth.json`.
pub fn write_truth_times(dir: &Path, times: &[TruthTime]) -> Result<()> {
    Ok(specmux_io::json::write_json(&dir.join(TRUTH_FILE), &times)?)
}

/// The truths of a recording, by frame id: none without `truth.json` (a real acquisition).
struct Truths {
    times: Vec<TruthTime>,
    materials: Materials,
}

impl Truths {
    fn read(dir: &Path, lib: &Library) -> Result<Option<Truths>> {
        let path = dir.join(TRUTH_FILE);
        if !path.exists() {
            return Ok(None);
        }
        Ok(Some(Truths {
            times: read_json(&path)?,
            materials: Materials::load(lib)?,
        }))
    }

    /// The scene of frame `id`; None where the rehearsal recorded no time for it.
    fn of(&self, exp: &Experiment, id: u64) -> Result<Option<Cube>> {
        let Some(t) = self.times.iter().find(|t| t.frame_id == id) else {
            return Ok(None);
        };
        let scene = build_at(&exp.scene, &exp.file, &self.materials, t.scene_t_s)?;
        Ok(Some(scene.cube))
    }
}

/// The band names of an experiment's cubes.
pub fn band_names(exp: &Experiment) -> Result<Vec<String>> {
    let grid = exp.scene.grid(&exp.file)?;
    Ok(grid.wavelengths().into_iter().map(exr::band_name).collect())
}

/// A warning line naming the frames whose mean signal is under their noise (empty if none).
fn dim_frames_warning(rows: &[ReconstructedFrame]) -> String {
    let dim: Vec<&ReconstructedFrame> = rows
        .iter()
        .filter(|r| r.mean_snr.is_some_and(|s| s < 1.0))
        .collect();
    let worst = dim.iter().filter_map(|r| r.mean_snr).reduce(f64::min);
    match worst.and_then(specmux_core::noise::snr_warning) {
        Some(w) => {
            let ids: Vec<String> = dim.iter().map(|r| r.frame_id.to_string()).collect();
            format!(
                "warning: frames {} under their noise; the dimmest: {w}\n",
                ids.join(", ")
            )
        }
        None => String::new(),
    }
}

/// The table of per-frame results (the SNR column: `Reconstructor::frame_snr`), a warning for
/// frames under their noise, and a summary line of the clean frames. "-" marks a figure the
/// frame has nothing for (no truth, no noise model); "undefined" a SAM with a truth but no
/// non-zero spectrum to measure. `place`: where the frames were reconstructed.
pub fn frame_table(rows: &[ReconstructedFrame], place: &str) -> String {
    let absent = || "-".to_string();
    let mut t = format!(
        "{:>6} {:>10} {:>6} {:>9} {:>7} {:>9} {:>9} {:>7}\n",
        "frame", "t (s)", "flags", "PSNR dB", "SSIM", "SAM °", "recon s", "SNR"
    );
    for r in rows {
        // PSNR is defined whenever there is a truth.
        let error =
            |v: Option<f64>, p: usize| r.psnr_db.map_or_else(absent, |_| metrics::show(v, p));
        t += &format!(
            "{:>6} {:>10.6} {:>6} {:>9} {:>7} {:>9} {:>9.4} {:>7}\n",
            r.frame_id,
            r.timestamp_s,
            r.flags,
            error(r.psnr_db, 2),
            error(r.ssim, 4),
            error(r.sam_deg, 2),
            r.reconstruction_s,
            r.mean_snr.map_or_else(absent, |v| format!("{v:.1}"))
        );
    }
    t += &dim_frames_warning(rows);
    let clean: Vec<&ReconstructedFrame> = rows.iter().filter(|r| r.flags == 0).collect();
    if clean.is_empty() {
        return t;
    }
    let mean = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let psnr: Vec<f64> = clean.iter().filter_map(|r| r.psnr_db).collect();
    let time = mean(clean.iter().map(|r| r.reconstruction_s).collect()).unwrap_or(0.0);
    t += &format!("clean frames {}: ", clean.len());
    if psnr.is_empty() {
        t += "no truth in this recording; ";
    } else {
        let (lo, hi) = psnr
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        t += &format!(
            "cube PSNR mean {} dB (min {lo:.2}, max {hi:.2}), SSIM {}, SAM {}°; ",
            metrics::show(mean(psnr.clone()), 2),
            metrics::show(mean(clean.iter().filter_map(|r| r.ssim).collect()), 4),
            metrics::show(mean(clean.iter().filter_map(|r| r.sam_deg).collect()), 2),
        );
    }
    t += &format!("reconstruction {time:.4} s/frame ({place})\n");
    t
}

/// `specmux reconstruct DIR` for a recording folder: every frame reconstructed with the
/// calibration acquired in that recording; cubes and `reconstruct.json` written to `out`.
pub fn reconstruct_recording(
    dir: &Path,
    out: &Path,
    lib: &Library,
) -> std::result::Result<String, String> {
    reconstruct_in(dir, out, lib).map_err(|e| e.to_string())
}

fn reconstruct_in(dir: &Path, out: &Path, lib: &Library) -> Result<String> {
    let exp = recorded_experiment(dir)?;
    let rig = Rig::build(&exp, lib, &Materials::load(lib)?)?;
    let frames_cal = record::read_calibration(dir)?;
    let cal = Calibration::from_frames(&rig.carriers, &frames_cal, exp.calibration.search_bins)?;
    let device = exp.open_device()?;
    let table = device.auto_table();
    let recon = Reconstructor::for_device(&exp.reconstruct, &rig.design(), &cal, &exp.file, table)?;
    let recon = DeviceReconstructor::new(&device, recon)?;
    let frames = recorded_frames(dir)?;
    let truths = Truths::read(dir, lib)?;
    let names = band_names(&exp)?;
    let files = OutputSet::begin(out)?;
    let mut rows = Vec::new();
    for f in &frames {
        let truth = match &truths {
            Some(t) => t.of(&exp, f.frame_id)?,
            None => None,
        };
        let (cube, row) = reconstruct_frame(&recon, f, truth.as_ref())?;
        exr::write(
            &files.path(&format!("cube-{:06}.exr", f.frame_id)),
            &cube,
            &names,
        )?;
        rows.push(row);
    }
    specmux_report::commands::write_report(&files.path("reconstruct.json"), lib, "frames", &rows)?;
    let mut text = format!(
        "{}: {} frames reconstructed with its own calibration ({})\n",
        dir.display(),
        rows.len(),
        dir.join("calibration.ome.tif").display()
    );
    text += &frame_table(&rows, recon.describe());
    if let Some(w) = cal.warning() {
        text += &format!("warning: {w}\n");
    }
    for note in files.commit()? {
        text += &format!("{note}\n");
    }
    text += &format!("wrote {}\n", out.display());
    Ok(text)
}

/// The experiment a recording was taken with (`experiment.json`); its file name from the plan,
/// so that paths in it resolve as they did for the run.
fn recorded_experiment(dir: &Path) -> Result<Experiment> {
    let mut exp: Experiment = read_json(&dir.join("experiment.json"))?;
    let plan: serde_json::Value = read_json(&dir.join("plan.json"))?;
    exp.file = plan["experiment"].as_str().unwrap_or_default().to_string();
    exp.validate()?;
    Ok(exp)
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    serde_json::from_str(&text).map_err(|e| Error::io(path, std::io::Error::other(e)))
}

/// The frames of `frames.ome.tif` with their records (`frames.jsonl`, one line per frame);
/// an interrupted recording gives its complete prefix.
fn recorded_frames(dir: &Path) -> Result<Vec<RecordedFrame>> {
    let (_, pages) = ome::read(&dir.join("frames.ome.tif"))?;
    let jpath: PathBuf = dir.join("frames.jsonl");
    let text = std::fs::read_to_string(&jpath).map_err(|e| Error::io(&jpath, e))?;
    let bad = |n: usize, why: String| {
        Error::device("recording", format!("{} line {n}: {why}", jpath.display()))
    };
    text.lines()
        .zip(pages)
        .enumerate()
        .map(|(n, (line, page))| {
            let v: serde_json::Value =
                serde_json::from_str(line).map_err(|e| bad(n + 1, e.to_string()))?;
            let field = |k: &str| v.get(k).ok_or_else(|| bad(n + 1, format!("no `{k}`")));
            Ok(RecordedFrame {
                frame_id: field("frame_id")?
                    .as_u64()
                    .ok_or_else(|| bad(n + 1, "`frame_id` is not a count".into()))?,
                timestamp_s: field("timestamp_s")?
                    .as_f64()
                    .ok_or_else(|| bad(n + 1, "`timestamp_s` is not a number".into()))?,
                flags: field("flags")?.as_array().map_or(0, Vec::len),
                raw: Cube::from_vec(page.width, page.height, 1, page.data)?,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(frame_id: u64, mean_snr: Option<f64>) -> ReconstructedFrame {
        ReconstructedFrame {
            frame_id,
            timestamp_s: 0.0,
            flags: 0,
            psnr_db: None,
            ssim: None,
            sam_deg: None,
            reconstruction_s: 0.1,
            mean_snr,
        }
    }

    /// The table shows each frame's SNR and names the frames under their noise (0.3 and 0.8),
    /// not the bright one (5) nor the one without a noise model.
    #[test]
    fn frames_under_their_noise_are_named_below_the_table() {
        let rows = [
            row(1, Some(0.8)),
            row(2, Some(5.0)),
            row(3, None),
            row(4, Some(0.3)),
        ];
        let t = frame_table(&rows, "CPU");
        assert!(t.lines().next().unwrap().ends_with("SNR"), "{t}");
        let warning: Vec<&str> = t.lines().filter(|l| l.starts_with("warning:")).collect();
        assert_eq!(warning.len(), 1, "{t}");
        assert!(
            warning[0].starts_with("warning: frames 1, 4 under their noise; the dimmest:")
                && warning[0].contains("0.30 times its noise"),
            "{t}"
        );
        assert!(!frame_table(&rows[1..3], "CPU").contains("warning"));
    }

    /// Without a truth or a noise model the figures are "-"; with a truth a SAM over zero
    /// spectra alone is "undefined".
    #[test]
    fn absent_figures_are_dashes_and_an_undefined_angle_says_so() {
        let cells = |r: &ReconstructedFrame| -> Vec<String> {
            let t = frame_table(std::slice::from_ref(r), "CPU");
            t.lines()
                .nth(1)
                .unwrap()
                .split_whitespace()
                .map(String::from)
                .collect()
        };
        assert_eq!(cells(&row(1, None))[3..], ["-", "-", "-", "0.1000", "-"]);
        let judged = ReconstructedFrame {
            psnr_db: Some(21.5),
            ssim: Some(0.5),
            ..row(2, Some(3.0))
        };
        assert_eq!(
            cells(&judged)[3..],
            ["21.50", "0.5000", "undefined", "0.1000", "3.0"]
        );
    }
}
