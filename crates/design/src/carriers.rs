//! `specmux design carriers`: lay out J carriers on the exact FFT bins of an N × N frame so the
//! 2J + 1 crop windows fit without overlap and away from the 2ω_i harmonics (and, under the full
//! guard, the ω_i ± ω_j terms); score layouts by the scene spectra leaking into each window
//! (`leak.rs`), search (`optimise.rs`), then simulate the best few against the paper's layout
//! and the diamond rule and keep the one never worse than the paper's on any design scene.
//! Given the user's cubes (`--cube`), the design is made on them alone: scene-adaptive.

use crate::layout::{Guard, Layout};
use crate::leak::{Objective, SceneSpectra};
use crate::scenes::{self, Outcome};
use crate::{optimise, plot};
use nalgebra::DMatrix;
use serde::de::IntoDeserializer;
use serde::{Deserialize, Serialize};
use specmux_core::demux::WindowShape;
use specmux_core::error::check_count;
use specmux_core::spectral::Library;
use specmux_core::unmix::curvature;
use specmux_core::{Error, Result};
use specmux_report::progress;
use specmux_twin::forward::Pipeline;
use specmux_twin::optics::dmd::DmdConfig;
use specmux_twin::optics::fourier_filter::{FourierFilterConfig, Illumination};
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::scene::Materials;
use specmux_twin::{Experiment, Rig};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `specmux design carriers`.
#[derive(clap::Args, Clone, Debug)]
pub struct CarrierArgs {
    /// Side of the (square) frame in pixels: the FFT the carriers sit on.
    #[arg(long, default_value_t = 256)]
    pub size: usize,
    /// Crop fraction(s); several (comma-separated) let the design choose.
    #[arg(long, value_delimiter = ',', default_value = "0.2")]
    pub crop: Vec<f64>,
    /// Window shape(s) tried for the designed layouts: square, circular, super-gaussian.
    #[arg(long, value_delimiter = ',', default_value = "square")]
    pub window: Vec<String>,
    /// Experiment files whose scenes the layout is designed on; default: every file in `--scenes-dir`.
    #[arg(long, num_args = 1..)]
    pub scenes: Vec<PathBuf>,
    /// The folder of experiment files `--scenes` defaults to.
    #[arg(long, default_value = "scenes")]
    pub scenes_dir: PathBuf,
    /// The user's cubes (EXR, or experiment files): design on these alone (scene-adaptive).
    #[arg(long, num_args = 1..)]
    pub cube: Vec<PathBuf>,
    /// Spurious terms kept out of every window.
    #[arg(long, value_enum, default_value = "harmonics")]
    pub guard: Guard,
    /// Relative amplitude of the 2ω harmonic in the predicted leak (0: ideal sinusoids).
    #[arg(long, default_value_t = 0.0)]
    pub harmonic: f64,
    /// Random starts of the search (besides the paper's layout and the diamond).
    #[arg(long, default_value_t = 48)]
    pub restarts: usize,
    /// Designed layouts simulated per crop.
    #[arg(long, default_value_t = 3)]
    pub candidates: usize,
    /// Also simulate the paper's, the diamond and the chosen layout with the coherent 4f model.
    #[arg(long)]
    pub coherent: bool,
    /// Experiment giving the wheel, light, camera QE, η and basis (default: the prototype); its
    /// optics, timing and sensor are not simulated (ideal patterns; the coherent 4f model with
    /// --coherent).
    #[arg(long)]
    pub experiment: Option<PathBuf>,
    /// Seed of the search's random restarts (the same seed, the same layouts).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, default_value = "out/design-carriers")]
    pub out: PathBuf,
}

/// One layout with its crop and window, simulated on the simulation scenes.
#[derive(Clone, Debug, Serialize)]
pub struct Candidate {
    pub label: String,
    pub layout: Layout,
    pub window: WindowShape,
    /// Predicted objective (Σ weighted leak over the design scenes; lower is better).
    pub predicted: f64,
    /// Predicted leak per design scene and channel, dB below peak².
    pub predicted_db: Vec<Vec<f64>>,
    pub ideal: Vec<Outcome>,
    pub coherent: Vec<Outcome>,
}

impl Candidate {
    /// Smallest and mean final-cube PSNR gain over `base` across the simulation scenes.
    pub fn gain_over(&self, base: &Candidate) -> (f64, f64) {
        let g: Vec<f64> = self
            .ideal
            .iter()
            .zip(&base.ideal)
            .map(|(a, b)| a.cube_psnr_db - b.cube_psnr_db)
            .collect();
        let n = g.len().max(1) as f64;
        (
            g.iter().cloned().fold(f64::INFINITY, f64::min),
            g.iter().sum::<f64>() / n,
        )
    }
}

/// The outcome of a design: the design scenes, the candidates (paper's layout first, then the
/// diamond, then the designed ones) and the index of the chosen one.
#[derive(Serialize)]
pub struct CarrierDesign {
    pub design_scenes: Vec<String>,
    pub simulation_scenes: Vec<String>,
    pub candidates: Vec<Candidate>,
    pub chosen: usize,
    pub notes: Vec<String>,
    pub seconds: Vec<(String, f64)>,
    #[serde(skip)]
    pub spectrum: Vec<f64>,
}

/// The design scenes: the user's cubes when given, else the scenes' files; each with the base
/// experiment's wheel, camera and reconstruction.
fn design_scenes(a: &CarrierArgs, base: &Experiment) -> Result<Vec<Experiment>> {
    let mut out = if a.cube.is_empty() {
        scenes::load(&scenes::files(&a.scenes, &a.scenes_dir)?, Some(a.size))?
    } else {
        a.cube
            .iter()
            .map(|p| user_cube(p, base))
            .collect::<Result<Vec<_>>>()?
    };
    for e in &mut out {
        e.rig.wheel = base.rig.wheel.clone();
        e.rig.camera = base.rig.camera.clone();
        e.rig.carriers = Default::default();
        e.reconstruct.eta = base.reconstruct.eta;
        e.reconstruct.basis = base.reconstruct.basis;
    }
    Ok(out)
}

/// A note naming the base experiment's stages the layouts are not simulated with (they are
/// scored with ideal patterns), if it has any.
fn dropped_stages(base: &Experiment) -> Vec<String> {
    let r = &base.rig;
    let stages: Vec<&str> = [
        ("[rig.dmd]", r.dmd.is_some()),
        ("[rig.fourier_filter]", r.fourier_filter.is_some()),
        ("[rig.lens]", r.lens.is_some()),
        ("[rig.timing]", r.timing.is_some()),
        ("[rig.sensor]", r.sensor.is_some()),
    ]
    .into_iter()
    .filter_map(|(name, on)| on.then_some(name))
    .collect();
    if stages.is_empty() {
        return Vec::new();
    }
    vec![format!(
        "{}: {} not simulated: the layouts are scored with ideal patterns (and the coherent 4f model with --coherent)",
        base.file,
        stages.join(", ")
    )]
}

/// An experiment on a user's cube: an experiment file as it is, or an EXR under the base.
fn user_cube(path: &Path, base: &Experiment) -> Result<Experiment> {
    if path.extension().is_some_and(|x| x == "toml") {
        return Ok(scenes::load(&[path.to_path_buf()], None)?.remove(0));
    }
    let (cube, _) = specmux_io::exr::read(path)?;
    let mut e = base.clone();
    let abs = path.canonicalize().map_err(|err| Error::io(path, err))?;
    e.scene.source = format!("exr:{}", abs.display());
    e.scene.size = [cube.width, cube.height];
    e.file = path.display().to_string();
    e.validate()?;
    Ok(e)
}

/// Channel-error weights g_t = ‖column t of B H⁻¹Fᵀ‖²: how much of channel t's error the
/// unmixing carries into the cube.
fn unmix_weights(rig: &Rig, eta: f64) -> Result<Vec<f64>> {
    let f = rig.system_matrix();
    let b = &rig.basis.vectors;
    let h: DMatrix<f64> = f.transpose() * &f + curvature(b, eta / rig.grid.step_nm.powi(4));
    let m = h
        .cholesky()
        .ok_or_else(|| {
            Error::Numerical("the base rig's unmixing Hessian is not positive definite".into())
        })?
        .solve(&f.transpose());
    let p = b * m;
    Ok(p.column_iter().map(|c| c.norm_squared()).collect())
}

/// Measure every design scene's channel spectra on the N-bin grid; the weights of the base rig.
fn measure(
    scenes: &[Experiment],
    base: &Experiment,
    n: usize,
    lib: &Library,
) -> Result<(Vec<SceneSpectra>, Vec<f64>)> {
    let materials = Materials::load(lib)?;
    let bar = progress::bar("measuring scene spectra");
    bar.set_length(scenes.len() as u64);
    let mut out = Vec::new();
    let cache = PatternCache::from_env()?;
    for e in scenes {
        let rig = Rig::build(e, lib, &materials)?;
        let (sim, _) = Pipeline::build(e, &rig, &materials)?
            .with_pattern_cache(cache.clone())
            .run()?;
        out.push(SceneSpectra::measure(&scenes::label(e), &sim.channels, n)?);
        progress::step(&bar, "measuring scene spectra")?;
    }
    bar.finish_and_clear();
    let rig = Rig::build(base, lib, &materials)?;
    Ok((out, unmix_weights(&rig, base.reconstruct.eta)?))
}

fn parse_window(s: &str) -> Result<WindowShape> {
    WindowShape::deserialize(s.into_deserializer()).map_err(|e: serde::de::value::Error| {
        Error::config("--window", "window", s, &e.to_string())
    })
}

/// The first value of `v` that an earlier one equals.
fn first_repeat<T: PartialEq>(v: &[T]) -> Option<&T> {
    (v.iter().enumerate()).find_map(|(i, x)| v[..i].contains(x).then_some(x))
}

/// Check the arguments; the error names the option and the value.
fn check_args(a: &CarrierArgs) -> Result<()> {
    check_count("--size", "size", a.size, 16..=4096, "pixels")?;
    if let Some(c) = a.crop.iter().find(|c| !(**c > 0.0 && **c <= 0.5)) {
        return Err(Error::config("--crop", "crop", c, "must be in (0, 0.5]"));
    }
    // A value listed twice would be searched and listed twice.
    if let Some(c) = first_repeat(&a.crop) {
        return Err(Error::config("--crop", "crop", c, "is listed twice"));
    }
    if let Some(w) = first_repeat(&a.window) {
        return Err(Error::config("--window", "window", w, "is listed twice"));
    }
    if !(a.harmonic.is_finite() && (0.0..=1.0).contains(&a.harmonic)) {
        return Err(Error::config(
            "--harmonic",
            "harmonic",
            a.harmonic,
            "must be in [0, 1]",
        ));
    }
    let per_crop = "designed layouts per crop";
    check_count(
        "--candidates",
        "candidates",
        a.candidates,
        1..=100,
        per_crop,
    )
}

/// Predicted scores of a layout as a candidate (simulations filled in later).
fn candidate(label: String, layout: Layout, window: WindowShape, obj: &Objective) -> Candidate {
    Candidate {
        label,
        predicted: obj.cost(&layout),
        predicted_db: obj.leak_db(&layout),
        layout,
        window,
        ideal: Vec::new(),
        coherent: Vec::new(),
    }
}

/// The paper's layout (its own crop 0.25), the diamond and the designed layouts of every crop.
fn candidates(
    a: &CarrierArgs,
    j: usize,
    obj: &Objective,
    notes: &mut Vec<String>,
) -> Result<Vec<Candidate>> {
    let n = a.size;
    let square = WindowShape::Square;
    let mut paper = Layout::paper_default(n, 0.25);
    paper.bins.truncate(j);
    let mut out = vec![candidate(
        "paper default (crop 0.25)".into(),
        paper,
        square,
        obj,
    )];
    let windows = a
        .window
        .iter()
        .map(|w| parse_window(w))
        .collect::<Result<Vec<_>>>()?;
    let bar = progress::bar("searching layouts");
    for &crop in &a.crop {
        let mut starts = Vec::new();
        let mut p = Layout::paper_default(n, crop);
        p.bins.truncate(j);
        starts.push(p);
        match Layout::diamond(n, crop, j) {
            Ok((d, note)) => {
                notes.extend(note);
                let label = format!("diamond (crop {crop})");
                out.push(candidate(label, d.clone(), square, obj));
                starts.push(d);
            }
            Err(why) => notes.push(format!("no diamond baseline: {why}")),
        }
        let step = (starts[0].window / 12).max(1);
        let found = optimise::search(&starts, a.restarts, step, obj, a.guard, a.seed, &bar);
        for (k, (_, l)) in found.into_iter().take(a.candidates).enumerate() {
            for &w in &windows {
                let label = format!("designed #{} (crop {crop}, {w})", k + 1);
                out.push(candidate(label, l.clone(), w, obj));
            }
        }
    }
    bar.finish_and_clear();
    if !out.iter().any(|c| c.label.starts_with("designed")) {
        return Err(Error::config(
            "--guard",
            "guard",
            format!("{:?}", a.guard),
            "no feasible layout was found at any crop; relax the guard or reduce the crop",
        ));
    }
    Ok(out)
}

/// The experiment of a candidate on a scene (ideal patterns, or the coherent 4f model).
fn experiment_for(scene: &Experiment, c: &Candidate, coherent: bool) -> Experiment {
    let mut e = scene.clone();
    e.rig.carriers.frequencies = Some(c.layout.carriers().iter().map(|k| [k.fx, k.fy]).collect());
    e.reconstruct.crop = c.layout.crop();
    e.reconstruct.window = c.window;
    if coherent {
        let [w, h] = e.scene.size;
        e.rig.dmd = Some(DmdConfig {
            width: w,
            height: h,
            ..Default::default()
        });
        e.rig.fourier_filter = Some(FourierFilterConfig {
            illumination: Illumination::Coherent,
            ..Default::default()
        });
    }
    e
}

/// Simulate the candidates `which` on the simulation scenes (ideal, or coherent).
fn simulate(
    cands: &mut [Candidate],
    which: &[usize],
    sims: &[Experiment],
    coherent: bool,
    lib: &Library,
) -> Result<()> {
    let bar = progress::bar(if coherent {
        "simulating (coherent 4f)"
    } else {
        "simulating (ideal)"
    });
    bar.set_length((which.len() * sims.len()) as u64);
    for &i in which {
        let mut out = Vec::new();
        for s in sims {
            out.push(scenes::simulate(
                &experiment_for(s, &cands[i], coherent),
                lib,
            )?);
            progress::step(&bar, "simulating carrier layouts")?;
        }
        if coherent {
            cands[i].coherent = out;
        } else {
            cands[i].ideal = out;
        }
    }
    bar.finish_and_clear();
    Ok(())
}

/// The designed candidate with the largest smallest gain over the paper's layout (then the
/// largest mean gain); the paper's layout itself when none gains on every scene.
fn choose(cands: &[Candidate]) -> usize {
    let key = |i: usize| cands[i].gain_over(&cands[0]);
    (0..cands.len())
        .filter(|&i| i == 0 || cands[i].label.starts_with("designed"))
        .max_by(|&a, &b| {
            let (ka, kb) = (key(a), key(b));
            ka.0.total_cmp(&kb.0)
                .then(ka.1.total_cmp(&kb.1))
                .then(b.cmp(&a))
        })
        .unwrap_or(0)
}

/// Design the layout (no files written).
pub fn design(a: &CarrierArgs, lib: &Library) -> Result<CarrierDesign> {
    let t0 = Instant::now();
    let base = crate::filters::base_experiment(a.experiment.as_deref())?;
    // One carrier per wheel filter.
    let j = base.rig.wheel.filters.len();
    check_args(a)?;
    let scenes = design_scenes(a, &base)?;
    let (spectra, weights) = measure(&scenes, &base, a.size, lib)?;
    let t_measure = t0.elapsed().as_secs_f64();
    let obj = Objective {
        scenes: &spectra,
        weights,
        a2: a.harmonic * a.harmonic,
    };
    let mut notes = dropped_stages(&base);
    let t = Instant::now();
    let mut cands = candidates(a, j, &obj, &mut notes)?;
    let t_search = t.elapsed().as_secs_f64();
    let sims: Vec<Experiment> = scenes
        .iter()
        .filter(|e| e.scene.size == [a.size, a.size])
        .cloned()
        .collect();
    if sims.is_empty() {
        return Err(Error::config("--size", "size", a.size, "no design scene has this size, so no layout can be simulated; give --size the cubes' size"));
    }
    for e in scenes.iter().filter(|e| e.scene.size != [a.size, a.size]) {
        notes.push(format!(
            "{} ({}×{}) scores the prediction only: the layout is on a {}-point grid",
            scenes::label(e),
            e.scene.size[0],
            e.scene.size[1],
            a.size
        ));
    }
    let t = Instant::now();
    let all: Vec<usize> = (0..cands.len()).collect();
    simulate(&mut cands, &all, &sims, false, lib)?;
    let chosen = choose(&cands);
    let t_sim = t.elapsed().as_secs_f64();
    let t = Instant::now();
    if a.coherent {
        let mut which = vec![0, chosen];
        which.extend(cands.iter().position(|c| c.label.starts_with("diamond")));
        which.sort_unstable();
        which.dedup();
        simulate(&mut cands, &which, &sims, true, lib)?;
    }
    let t_coh = t.elapsed().as_secs_f64();
    let n2 = (a.size * a.size) as f64;
    let spectrum = (0..a.size * a.size)
        .map(|k| spectra.iter().map(|s| s.mean_power[k]).sum::<f64>() / n2)
        .collect();
    Ok(CarrierDesign {
        design_scenes: spectra.iter().map(|s| s.name.clone()).collect(),
        simulation_scenes: sims.iter().map(scenes::label).collect(),
        candidates: cands,
        chosen,
        notes,
        seconds: [
            ("measure", t_measure),
            ("search", t_search),
            ("simulate", t_sim),
            ("coherent", t_coh),
            ("total", t0.elapsed().as_secs_f64()),
        ]
        .map(|(k, v)| (k.to_string(), v))
        .to_vec(),
        spectrum,
    })
}

/// Design, print the tables, write the figures, the rig section and a runnable experiment.
pub fn run(a: &CarrierArgs, lib: &Library) -> Result<String> {
    let d = design(a, lib)?;
    let mut t = layout_table(&d);
    t += &crosstalk_table(&d);
    t += &write_outputs(a, &d, lib)?;
    let times: Vec<String> = d
        .seconds
        .iter()
        .map(|(k, v)| format!("{k} {v:.2} s"))
        .collect();
    t += &format!(
        "time: {} (search: heuristic coordinate descent, {} random starts)\n",
        times.join(", "),
        a.restarts
    );
    Ok(t)
}

/// Every candidate: predicted objective, final-cube PSNR / SAM per scene, gain over the paper's.
fn layout_table(d: &CarrierDesign) -> String {
    let mut t = format!(
        "design scenes: {}\nsimulated on: {}\n",
        d.design_scenes.join(", "),
        d.simulation_scenes.join(", ")
    );
    for n in &d.notes {
        t += &format!("note: {n}\n");
    }
    t += &format!("\n{:<38} {:>10}", "layout (ideal patterns)", "predicted");
    for s in &d.simulation_scenes {
        t += &format!(" {:>16}", s);
    }
    t += &format!(" {:>9} {:>9}\n", "min gain", "mean gain");
    for (i, c) in d.candidates.iter().enumerate() {
        let mark = if i == d.chosen { "*" } else { " " };
        t += &format!("{mark}{:<37} {:>10.3e}", c.label, c.predicted);
        for o in &c.ideal {
            t += &format!(" {:>7.2} / {:>6.2}", o.cube_psnr_db, o.cube_sam_deg);
        }
        let (lo, mean) = c.gain_over(&d.candidates[0]);
        t += &format!(" {lo:>+9.2} {mean:>+9.2}\n");
    }
    let c = &d.candidates[d.chosen];
    t += &format!("(final cube PSNR dB / SAM °; gains in dB over the paper's layout)\nchosen: {} bins {:?} on {}², crop {}\n", c.label, c.layout.bins, c.layout.size, c.layout.crop());
    let coh: Vec<&Candidate> = d
        .candidates
        .iter()
        .filter(|c| !c.coherent.is_empty())
        .collect();
    if !coh.is_empty() {
        t += "\ncoherent 4f patterns (DMD Floyd–Steinberg + Fourier filter), final cube PSNR dB / SAM °:\n";
        for c in coh {
            t += &format!("{:<38}", c.label);
            for o in &c.coherent {
                t += &format!(
                    " {}: {:.2} / {:.2};",
                    o.scene, o.cube_psnr_db, o.cube_sam_deg
                );
            }
            t += "\n";
        }
    }
    t
}

/// Predicted against simulated crosstalk per channel (total leak, dB below peak²) on each
/// simulation scene, for the paper's layout, the diamond and the chosen one.
fn crosstalk_table(d: &CarrierDesign) -> String {
    let mut which = vec![0];
    which.extend(
        d.candidates
            .iter()
            .position(|c| c.label.starts_with("diamond")),
    );
    if d.chosen != 0 {
        which.push(d.chosen);
    }
    let mut t = String::from(
        "\ncrosstalk per channel, dB below peak² (higher = less leak), predicted / simulated:\n",
    );
    for (k, scene) in d.simulation_scenes.iter().enumerate() {
        let Some(p) = d.design_scenes.iter().position(|s| s == scene) else {
            continue;
        };
        t += &format!("{scene}:\n{:<8}", "channel");
        for &i in &which {
            t += &format!(" {:>30}", d.candidates[i].label);
        }
        t += "\n";
        for ch in 0..d.candidates[0].layout.bins.len() {
            t += &format!("{ch:<8}");
            for &i in &which {
                let c = &d.candidates[i];
                let sim = c.ideal[k].leak_db.as_ref().map_or(f64::NAN, |v| v[ch]);
                t += &format!(
                    " {:>30}",
                    format!("{:.1} / {:.1}", c.predicted_db[p][ch], sim)
                );
            }
            t += "\n";
        }
    }
    t
}

/// The Fourier-plane PNGs, `carriers.toml`, `experiment.toml` and `report.json`.
fn write_outputs(a: &CarrierArgs, d: &CarrierDesign, lib: &Library) -> Result<String> {
    let mut t = String::from("\n");
    let c = &d.candidates[d.chosen];
    let shape = serde_json::to_value(c.window)
        .ok()
        .and_then(|v| v.as_str().map(String::from))
        .unwrap_or_default();
    let section = format!(
        "# specmux design carriers: {} on the scenes {}\n{}",
        c.label,
        d.design_scenes.join(", "),
        c.layout.toml(&shape)
    );
    specmux_io::atomic::write_bytes(&a.out.join("carriers.toml"), section.as_bytes())?;
    let base = crate::filters::base_experiment(a.experiment.as_deref())?;
    let sim = design_scenes(a, &base)?
        .into_iter()
        .find(|e| e.scene.size == [a.size, a.size]);
    if let Some(s) = sim.filter(scenes::is_procedural) {
        let e = experiment_for(&s, c, false);
        let text = toml::to_string(&e.to_table()?).map_err(|err| Error::Toml {
            file: "experiment.toml".into(),
            msg: err.to_string(),
        })?;
        let path = a.out.join("experiment.toml");
        Experiment::from_toml(&text, &path.display().to_string())?;
        specmux_io::atomic::write_bytes(&path, text.as_bytes())?;
        t += &format!(
            "wrote {} (runs as it is: specmux demo --scene {})\n",
            path.display(),
            path.display()
        );
    }
    let mut which = vec![0, d.chosen];
    which.extend(
        d.candidates
            .iter()
            .position(|c| c.label.starts_with("diamond")),
    );
    which.dedup();
    for i in which {
        let c = &d.candidates[i];
        let name = c.label.split(' ').next().unwrap_or("layout");
        let path = a.out.join(format!("fourier_{name}.png"));
        let title = format!(
            "{} on {}²: windows, harmonics, scene spectrum",
            c.label, a.size
        );
        plot::fourier_plane(&path, &title, &c.layout, &d.spectrum)?;
        t += &format!("wrote {}\n", path.display());
    }
    specmux_report::commands::write_report(&a.out.join("report.json"), lib, "design", d)?;
    t += &format!(
        "wrote {} and {}\n",
        a.out.join("carriers.toml").display(),
        a.out.join("report.json").display()
    );
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The prototype has no stage to drop; an experiment with timing and a camera is told that
    /// both are left out, by name.
    #[test]
    fn the_stages_a_design_leaves_out_are_named() {
        assert!(dropped_stages(&Experiment::prototype()).is_empty());
        let text = "[scene]\nsize = [64, 64]\n[rig.timing]\n[rig.sensor]\n";
        let e = Experiment::from_toml(text, "e.toml").unwrap();
        let [note] = &dropped_stages(&e)[..] else {
            panic!("one note expected")
        };
        assert!(
            note.starts_with("e.toml: [rig.timing], [rig.sensor] not simulated"),
            "{note}"
        );
    }
}
