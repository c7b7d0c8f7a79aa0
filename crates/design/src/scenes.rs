//! The scenes a design is scored on, and one simulated run of a candidate design on a scene.
//!
//! A design is judged on scenes, not on experiments: every `*.toml` in the scenes folder
//! contributes its `[scene]` and `[reconstruct]`, with the rig reduced to the wheel, the camera
//! and the carriers (ideal patterns, no timing, no sensor) unless the caller asks for more, and
//! scenes repeated across files (the studies reuse dead-leaves) counted once.

use serde::Serialize;
use specmux_core::spectral::Library;
use specmux_core::{Error, Result};
use specmux_twin::run::{self, Row};
use specmux_twin::Experiment;
use std::path::{Path, PathBuf};

/// A procedural source is generated at any size; files (`exr:`, `mitsuba:`) have their own.
pub fn is_procedural(exp: &Experiment) -> bool {
    !exp.scene.source.contains(':')
}

/// The experiment files to use: `paths` as given, or every `*.toml` of `dir` (sorted).
pub fn files(paths: &[PathBuf], dir: &Path) -> Result<Vec<PathBuf>> {
    if !paths.is_empty() {
        return Ok(paths.to_vec());
    }
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| {
            let why = format!("cannot read this folder of experiment files ({e}): run from the repository root, or pass --scenes-dir DIR or --scenes FILE…");
            Error::config("--scenes-dir", "scenes-dir", dir.display(), &why)
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    out.sort();
    Ok(out)
}

/// A scene file's error after `--size n` replaced its size: the file alone would be blamed for
/// what the option did.
fn resized_error(err: Error, resized: Option<usize>) -> Error {
    match (resized, err) {
        (
            Some(n),
            Error::Config {
                file,
                key,
                value,
                reason,
            },
        ) => Error::Config {
            file: format!("--size {n} on {file}"),
            key,
            value,
            reason,
        },
        (_, err) => err,
    }
}

/// The distinct scenes of `files`, each an experiment with an ideal rig; procedural scenes at
/// `size × size` when given.
pub fn load(files: &[PathBuf], size: Option<usize>) -> Result<Vec<Experiment>> {
    let mut out: Vec<Experiment> = Vec::new();
    for f in files {
        let mut e = Experiment::load(f)?;
        e.rig.dmd = None;
        e.rig.fourier_filter = None;
        e.rig.lens = None;
        e.rig.timing = None;
        e.rig.sensor = None;
        e.reconstruct.crosstalk_weights = None;
        let resized = size.filter(|_| is_procedural(&e));
        if let Some(n) = resized {
            e.scene.size = [n, n];
        }
        let key = |x: &Experiment| format!("{:?} {}", x.scene.source, x.scene.seed);
        if out.iter().all(|o| key(o) != key(&e)) {
            e.validate().map_err(|err| resized_error(err, resized))?;
            out.push(e);
        }
    }
    if out.is_empty() {
        return Err(Error::config(
            "--scenes",
            "scenes",
            "none",
            "no experiment file to take scenes from",
        ));
    }
    Ok(out)
}

/// A short label of a scene for tables: a procedural scene's source, else the file stem.
pub fn label(exp: &Experiment) -> String {
    if is_procedural(exp) {
        return exp.scene.source.clone();
    }
    Path::new(&exp.file)
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_else(|| exp.scene.source.clone())
}

/// The final cube's error of one run, the per-channel demultiplexing PSNR and the simulated
/// crosstalk per channel (the total leak of the error budget, dB; ideal patterns only).
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    pub scene: String,
    pub cube_psnr_db: f64,
    pub cube_sam_deg: f64,
    pub channel_psnr_db: Vec<f64>,
    pub leak_db: Option<Vec<f64>>,
    pub seconds: f64,
}

/// Simulate and reconstruct `exp` (checked first) and collect its [`Outcome`].
pub fn simulate(exp: &Experiment, lib: &Library) -> Result<Outcome> {
    exp.validate()?;
    let (rep, _) = run::run(exp, lib)?;
    let cube = rep.row(Row::Cube);
    let leak_db = rep.error_budget.as_ref().map(|b| {
        b.iter()
            .map(|e| {
                // Total leak: the parts' MSEs add (their cross terms are not in the budget).
                let parts = std::iter::once(e.dc_db).chain(e.carrier_db.iter().cloned());
                -10.0 * parts.map(|db| 10f64.powf(-db / 10.0)).sum::<f64>().log10()
            })
            .collect()
    });
    Ok(Outcome {
        scene: label(exp),
        cube_psnr_db: cube.psnr_db,
        // A candidate whose cube has no spectral angle anywhere (all zero) cannot be ranked.
        cube_sam_deg: cube.sam_deg.ok_or_else(|| {
            Error::Numerical(format!(
                "{}: the reconstructed cube has no defined spectral angle ({})",
                label(exp),
                cube.flags.join("; ")
            ))
        })?,
        channel_psnr_db: rep.channels.iter().map(|c| c.psnr_db).collect(),
        leak_db,
        seconds: rep.total_seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A missing default folder (a run outside the repository) names the option and the folder.
    #[test]
    fn a_missing_scenes_folder_names_the_option() {
        let e = files(&[], Path::new("no-such-scenes-dir"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--scenes-dir")
                && e.contains("no-such-scenes-dir")
                && e.contains("--scenes FILE"),
            "{e}"
        );
        let given = [PathBuf::from("a.toml")];
        assert_eq!(
            files(&given, Path::new("no-such-scenes-dir")).unwrap(),
            given
        );
    }
}
