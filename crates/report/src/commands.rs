//! One function per CLI command: run the library, write the files, return the text to print.

use specmux_core::calibration::{Calibration, CalibrationFrames};
use specmux_core::error::check_count;
use specmux_core::reconstructor::{ComputeDevice, Reconstructor};
use specmux_core::spectral::{Grid, Library};
use specmux_core::unmix::UnmixStats;
use specmux_core::{Cube, Error, Result};
use specmux_io::exr as exr_io;
use specmux_io::output_set::OutputSet;
use specmux_twin::device::{DeviceReconstructor, FrameRun, OpenDevice};
use specmux_twin::experiment::Experiment;
use specmux_twin::pattern_cache::PatternCache;
use specmux_twin::rig::Rig;
use specmux_twin::run::{self, RunData, RunReport};
use specmux_twin::scene::Materials;
use std::path::Path;

/// Append one formatted line to the command's output.
macro_rules! say {
    ($text:ident, $($t:tt)*) => {{
        use std::fmt::Write;
        let _ = writeln!($text, $($t)*);
    }};
}

/// Commit the command's output set and say where it went (and what leftovers it removed).
fn finish(files: OutputSet, out: &Path, text: &mut String) -> Result<()> {
    for note in files.commit()? {
        say!(text, "{note}");
    }
    say!(text, "wrote {}", out.display());
    Ok(())
}

/// The scenes every command accepts by name, as the prototype rig imaging them.
pub const BUILT_IN_SCENES: [&str; 3] = ["dead-leaves", "shaded-objects", "bars"];

/// The experiment a command names: a built-in scene or an experiment file; `size` (`--size`)
/// overrides a procedural scene's square frame size.
pub fn experiment_for(scene: &str, size: Option<usize>) -> Result<Experiment> {
    let mut exp = if BUILT_IN_SCENES.contains(&scene) {
        let mut e = Experiment::prototype();
        e.scene.source = scene.to_string();
        e
    } else if scene.ends_with(".toml") || Path::new(scene).is_file() {
        Experiment::load(Path::new(scene))?
    } else {
        return Err(Error::config(
            scene,
            "experiment",
            format!("\"{scene}\""),
            "is neither a built-in scene (dead-leaves, shaded-objects, bars) nor an experiment file",
        ));
    };
    if let Some(n) = size {
        resize(&mut exp, n)?;
    }
    exp.validate()?;
    Ok(exp)
}

/// `--size n` on a procedural scene; refused for a cube read from a file, and, with `method =
/// "gap"`, for a side that its wavelet cannot split, with the nearest sides that it can (the
/// other methods take any side).
fn resize(exp: &mut Experiment, n: usize) -> Result<()> {
    let refuse = |why: &str| Err(Error::config("--size", "size", n, why));
    let source = &exp.scene.source;
    if source.contains(':') {
        return refuse(&format!("{source} takes its size from the file"));
    }
    let sides = specmux_twin::scene::config::SIDE_PX;
    check_count("--size", "size", n, sides, "pixels (as scene.size)")?;
    exp.scene.size = [n, n];
    let gap = &exp.reconstruct.gap;
    if gap.method != specmux_core::gap::Method::Gap {
        return Ok(());
    }
    let fits = |m: usize| gap.wavelet_for(m, m, "").is_ok();
    if fits(n) {
        return Ok(());
    }
    let near: Vec<String> = [
        (16..n).rev().find(|&m| fits(m)),
        (n + 1..=8192).find(|&m| fits(m)),
    ]
    .into_iter()
    .flatten()
    .map(|m| m.to_string())
    .collect();
    refuse(&format!(
        "GAP's wavelet (reconstruct.gap.levels = {}) splits only sides divisible by {}: try --size {}, or an experiment file with fewer levels or another [reconstruct.gap] method",
        gap.levels,
        1usize << gap.levels,
        near.join(" or ")
    ))
}

/// One frame's reconstruction on `device` (the GPU's whole chain, every method with a kernel),
/// and a line of its stage times and where it ran.
fn reconstruct_on_device(
    device: &OpenDevice,
    recon: Reconstructor,
    frame: &Cube,
) -> Result<(FrameRun, String)> {
    let t = std::time::Instant::now();
    let on_device = DeviceReconstructor::new(device, recon)?;
    let t_setup = t.elapsed().as_secs_f64();
    let run = on_device.run(frame, false)?;
    let place = on_device.describe();
    let times = match on_device.device() {
        "gpu" => {
            let iterations = run
                .joint
                .as_ref()
                .map_or(run.gap.iterations, |j| j.iterations);
            format!(
                "demultiplex + de-alias ({iterations} iterations) + unmix {:.4} s, the first frame after a setup of {t_setup:.4} s ({place})",
                run.seconds
            )
        }
        _ => {
            let [t_demux, t_gap, t_unmix] = run.stage_seconds;
            format!(
                "demultiplex {t_demux:.4} s, de-alias {t_gap:.4} s, unmix {t_unmix:.4} s ({place})"
            )
        }
    };
    Ok((run, times))
}

fn band_names(grid: &Grid) -> Vec<String> {
    grid.wavelengths()
        .into_iter()
        .map(exr_io::band_name)
        .collect()
}

/// Write `cube` as `<stem>.exr` with channels `names`, and as `<stem>.npy` when `npy`.
fn write_cube(
    files: &OutputSet,
    stem: &str,
    cube: &Cube,
    names: &[String],
    npy: bool,
) -> Result<()> {
    exr_io::write(&files.path(&format!("{stem}.exr")), cube, names)?;
    if npy {
        specmux_io::npy::write(&files.path(&format!("{stem}.npy")), cube)?;
    }
    Ok(())
}

/// `demo`: run an experiment end to end and write its files (`npy`: .npy beside every EXR).
pub fn demo(
    scene: &str,
    size: Option<usize>,
    out: &Path,
    npy: bool,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, size)?;
    let (rep, data) = run::run(&exp, lib)?;
    say!(text, "{}", rep.table());
    let t = std::time::Instant::now();
    let files = OutputSet::begin(out)?;
    write_run_files(&exp, &rep, &data, &files, npy, lib)?;
    // After the report: its own writing is not in it.
    say!(
        text,
        "files (EXR, figures, report) written in {:.2}s",
        t.elapsed().as_secs_f64()
    );
    finish(files, out, &mut text)?;
    Ok(text)
}

fn write_run_files(
    exp: &Experiment,
    rep: &RunReport,
    d: &RunData,
    files: &OutputSet,
    npy: bool,
    lib: &Library,
) -> Result<()> {
    let grid = exp.scene.grid(&exp.file)?;
    let bands = band_names(&grid);
    // The cube and the truth (most of the bytes) beside the rest: an EXR is written on one thread.
    let cubes = || -> Result<()> {
        let (cube, truth) = rayon::join(
            || write_cube(files, "cube", &d.cube, &bands, npy),
            || write_cube(files, "truth", &d.truth, &bands, npy),
        );
        cube.and(truth)
    };
    let (cube, rest) = rayon::join(cubes, || -> Result<()> {
        write_cube(files, "frame", &d.frame, &["Y".to_string()], npy)?;
        specmux_io::png::plane_png(&files.path("frame.png"), &d.frame, 0)?;
        let ch: Vec<String> = (0..d.xhat.planes).map(|i| format!("x{i}")).collect();
        write_cube(files, "channels", &d.xhat, &ch, npy)?;
        crate::panel::write_figures(exp, lib, Some(&d.truth), &d.cube, files)?;
        specmux_io::json::write_json(&files.path("report.json"), rep)
    });
    cube.and(rest)
}

/// `device`: `--device` (None: the experiment's `[compute] device`).
pub fn bench(
    scene: &str,
    out: &Path,
    repeats: usize,
    size: Option<usize>,
    device: Option<ComputeDevice>,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, size)?;
    let sim = crate::bench::simulate(&exp, lib)?;
    let device = match device {
        Some(d) => OpenDevice::open(d).map_err(|e| e.in_file("--device"))?,
        // The one the forward model opened (`auto` says once where it stays).
        None => sim.device.clone(),
    };
    say!(
        text,
        "{}: {}×{}, {repeats} timed run{} per setting, on {}",
        exp.file,
        sim.frame.width,
        sim.frame.height,
        if repeats == 1 { "" } else { "s" },
        device.describe()
    );
    if let Some(why) = crate::bench::gap_left_out(&sim) {
        say!(text, "{why}");
    }
    let rows = crate::bench::work_precision_on(
        &device,
        &sim,
        &crate::bench::grid_for(&sim, &device),
        repeats,
    )?;
    let mut md = crate::bench::work_precision_markdown(&rows);
    // The setting the plot rings, in words.
    let pick = crate::bench::auto_pick(&rows, sim.frame.pixels());
    if let Some(a) = &pick {
        md += &format!("\n`method = \"auto\"` from these rows: {}\n", a.reason);
    }
    if sim.calibration.is_oracle() {
        say!(text, "{}", specmux_core::calibration::ORACLE_LABEL);
    }
    say!(text, "{md}");
    let files = OutputSet::begin(out)?;
    specmux_io::atomic::write_bytes(&files.path("bench.md"), md.as_bytes())?;
    write_report(&files.path("bench.json"), lib, "rows", &rows)?;
    let oracle = match sim.calibration.is_oracle() {
        true => ", ORACLE calibration",
        false => "",
    };
    crate::bench::work_precision_plot(
        &files.path("pareto.png"),
        &format!(
            "{} {}×{}: error against run time, {}{oracle}",
            scene,
            sim.frame.width,
            sim.frame.height,
            device.short()
        ),
        &rows,
        sim.frame.pixels(),
        pick.as_ref(),
    )?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn sweep_crop(
    scenes: &[String],
    out: &Path,
    size: Option<usize>,
    no_gap: bool,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let mut rows = Vec::new();
    for scene in scenes {
        let exp = experiment_for(scene, size)?;
        let sim = crate::bench::simulate(&exp, lib)?;
        let cfg = specmux_core::gap::GapConfig {
            method: specmux_core::gap::Method::Gap,
            ..exp.reconstruct.gap.clone()
        };
        let (w, h) = (sim.frame.width, sim.frame.height);
        if !no_gap && cfg.wavelet_for(w, h, "").is_err() {
            return Err(Error::config(
                &exp.file,
                "reconstruct.gap.levels",
                cfg.levels,
                &format!("GAP's wavelet cannot split a {w}×{h} frame: --no-gap sweeps the Fourier estimate alone"),
            ));
        }
        let name = Path::new(scene)
            .file_stem()
            .map_or(scene.clone(), |s| s.to_string_lossy().into_owned());
        let r = crate::bench::sweep_crop(
            &sim,
            &name,
            &crate::bench::paper_crops(),
            (!no_gap).then_some(&cfg),
        )?;
        rows.extend(r);
    }
    let md = crate::bench::sweep_markdown(&rows);
    say!(text, "{md}");
    for (scene, crop, psnr) in crate::bench::sweep_peaks(&rows) {
        say!(
            text,
            "{scene}: Fourier PSNR peaks at crop {crop:.3} ({psnr:.2} dB)"
        );
    }
    let files = OutputSet::begin(out)?;
    specmux_io::atomic::write_bytes(&files.path("sweep.md"), md.as_bytes())?;
    write_report(&files.path("sweep.json"), lib, "rows", &rows)?;
    crate::bench::sweep_plot(&files.path("sweep_crop.png"), &rows)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn sweep(
    scene: &str,
    vary: &[String],
    out: &Path,
    size: Option<usize>,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, size)?;
    let vary = vary
        .iter()
        .map(|v| crate::sweep::Vary::parse(v))
        .collect::<Result<Vec<_>>>()?;
    let rows = crate::sweep::sweep(&exp, &vary, lib)?;
    let md = crate::sweep::markdown(&vary, &rows);
    say!(
        text,
        "{}: {}×{}\n{md}",
        exp.file,
        exp.scene.size[0],
        exp.scene.size[1]
    );
    let files = OutputSet::begin(out)?;
    specmux_io::atomic::write_bytes(&files.path("sweep.md"), md.as_bytes())?;
    write_report(&files.path("sweep.json"), lib, "rows", &rows)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn patterns(
    scene: &str,
    out: &Path,
    size: Option<usize>,
    study: Option<&[f64]>,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    use crate::patterns as pr;
    let exp = experiment_for(scene, size)?;
    let materials = specmux_twin::scene::Materials::load(lib)?;
    let rig = specmux_twin::rig::Rig::build(&exp, lib, &materials)?;
    let optics = exp.rig.optics();
    let lights = rig.pattern_lights(&exp)?;
    if let Some(radii) = study {
        let t = std::time::Instant::now();
        let rows = pr::dither_study(
            &optics,
            &rig.carriers,
            &lights,
            rig.width,
            rig.height,
            exp.reconstruct.crop,
            radii,
        )
        .map_err(|e| e.in_file(&exp.file))?;
        let md = pr::study_table(&rows);
        say!(
            text,
            "{md}\n{} runs in {:.1} s",
            rows.len(),
            t.elapsed().as_secs_f64()
        );
        let files = OutputSet::begin(out)?;
        specmux_io::atomic::write_bytes(&files.path("study.md"), md.as_bytes())?;
        write_report(&files.path("study.json"), lib, "rows", &rows)?;
        finish(files, out, &mut text)?;
        return Ok(text);
    }
    let (rep, set) = pr::pattern_report(
        &optics,
        &rig.carriers,
        &lights,
        rig.width,
        rig.height,
        exp.reconstruct.crop,
    )
    .map_err(|e| e.in_file(&exp.file))?;
    for s in &rep.stages {
        say!(text, "{s}");
    }
    say!(
        text,
        "\n{:<3} {:>14} {:>10} {:>10} {:>7} {:>9} {:>10} {:>10} {:>10}",
        "ch",
        "carrier",
        "rms err",
        "residual",
        "gain",
        "phase °",
        "2ω",
        "worst x",
        "through"
    );
    for (i, c) in rep.channels.iter().enumerate() {
        let worst = c
            .crosstalk
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .map(|(_, v)| *v)
            .fold(0.0, f64::max);
        say!(
            text,
            "{:<3} {:>14} {:>10.4} {:>10.4} {:>7.3} {:>9.2} {:>10.2e} {:>10.2e} {:>10.4}",
            i,
            format!("({},{})", c.fx, c.fy),
            c.rel_rms_error,
            c.residual_error,
            c.gain,
            c.gain_phase_rad.to_degrees(),
            c.harmonic_2w,
            worst,
            c.throughput
        );
    }
    say!(
        text,
        "\ncrosstalk (energy in window j / own window), rows = channel i:"
    );
    for c in &rep.channels {
        let row: Vec<String> = c.crosstalk.iter().map(|v| format!("{v:9.2e}")).collect();
        say!(text, "{}", row.join(" "));
    }
    let files = OutputSet::begin(out)?;
    pr::write_pattern_pngs(&set, &rig.carriers, files.dir())?;
    write_report(&files.path("patterns.json"), lib, "patterns", &rep)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn timing(scene: &str, out: &Path, lib: &Library) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, None)?;
    let cfg = exp.rig.timing.clone().ok_or_else(|| {
        Error::config(
            &exp.file,
            "rig.timing",
            "absent",
            "the experiment has no [rig.timing] section to report on (scenes/study-timing.toml and scenes/full-rig.toml have one)",
        )
    })?;
    let tw = specmux_twin::timing::weights(&cfg)?;
    say!(
        text,
        "exposure {} s = {:.4} wheel turns; spot on a spoke {:.2} % of the time",
        cfg.camera.exposure_s,
        tw.turns_per_exposure,
        100.0 * tw.spoke_fraction
    );
    say!(text, "weights w_ik (rows: filter i, columns: pattern k):");
    for row in &tw.w {
        let r: Vec<String> = row.iter().map(|v| format!("{v:8.5}")).collect();
        say!(text, "{}", r.join(" "));
    }
    for w in &tw.warnings {
        say!(text, "warning: {w}");
    }
    if tw.warnings.is_empty() {
        say!(
            text,
            "no warnings: whole turns, aligned, within the DMD's and the camera's rates"
        );
    }
    let files = OutputSet::begin(out)?;
    let chips = filter_chips(&exp, lib)?;
    crate::timeline::timeline_png(&cfg, &chips, &files.path("timeline.png"))?;
    write_report(&files.path("timing.json"), lib, "timing", &tw)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

/// `specmux ptc`: the EMVA 1288 photon-transfer measurement of the experiment's camera; with
/// `emva`, its raw frames too, as the EMVA 1288 reference code reads them (`emva1288/`).
pub fn ptc(
    scene: Option<&str>,
    size: usize,
    emva: bool,
    out: &Path,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let sides = specmux_twin::scene::config::SIDE_PX;
    check_count(
        "--size",
        "size",
        size,
        sides,
        "pixels (the side of the test frames)",
    )?;
    let cfg = match scene {
        Some(s) => experiment_for(s, None)?.rig.sensor.unwrap_or_default(),
        None => specmux_twin::sensor::SensorConfig::default(),
    };
    let sensor = specmux_twin::sensor::Sensor::new(&cfg, size, size)?;
    let levels = specmux_twin::sensor::default_levels(cfg.full_well_e);
    let r = specmux_twin::sensor::photon_transfer(&sensor, &levels)?;
    say!(
        text,
        "{:<26} {:>12} {:>12}",
        "EMVA 1288",
        "measured",
        "given"
    );
    for (name, m, g) in [
        ("K (DN/e⁻)", r.k_dn_per_e, cfg.gain_dn_per_e),
        (
            "dark noise (e⁻)",
            r.read_noise_e,
            (cfg.read_noise_e.powi(2) + cfg.dark_electrons()).sqrt(),
        ),
        // EMVA 1288's saturation capacity μ_e.sat, beside the model's full well (the clip level
        // sits above it: docs/sensor.md).
        ("μ_e.sat / full well (e⁻)", r.full_well_e, cfg.full_well_e),
        (
            "PRNU (%)",
            100.0 * r.prnu_fraction,
            100.0 * cfg.prnu_fraction,
        ),
        ("DSNU (e⁻)", r.dsnu_e, cfg.dsnu_e),
    ] {
        say!(text, "{name:<26} {m:>12.4} {g:>12.4}");
    }
    say!(
        text,
        "K standard error {:.2e} DN/e⁻ over {} pixels",
        r.k_stderr_dn_per_e,
        r.pixels
    );
    let files = OutputSet::begin(out)?;
    crate::ptc::plot_ptc(&r, &files.path("ptc.png"))?;
    let mut report = serde_json::json!(run::Provenance::new(lib));
    report["camera"] = serde_json::json!(cfg);
    report["dark_electrons_per_exposure"] = serde_json::json!(sensor.dark_electrons());
    report["measured"] = serde_json::json!(r);
    specmux_io::json::write_json(&files.path("ptc.json"), &report)?;
    if emva {
        let frames = specmux_twin::sensor::ptc_frames(&sensor, &levels, &r)?;
        crate::ptc::write_emva_dataset(&files.path("emva1288"), &frames, cfg.bits)?;
    }
    finish(files, out, &mut text)?;
    Ok(text)
}

/// `simulate`: the frame the camera would record, the true cube, and the calibration frames
/// the rig would capture (`calibration/`, the folder `reconstruct --calibration` reads).
pub fn simulate(
    scene: &str,
    explain: bool,
    out: &Path,
    npy: bool,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, None)?;
    let materials = specmux_twin::scene::Materials::load(lib)?;
    let rig = specmux_twin::rig::Rig::build(&exp, lib, &materials)?;
    let cache = PatternCache::from_env()?;
    let pipeline = specmux_twin::forward::Pipeline::build(&exp, &rig, &materials)?
        .with_pattern_cache(cache.clone());
    let stages = pipeline.explain();
    say!(text, "{stages}");
    // A stage's own warning is in its line already.
    for w in rig.warnings.iter().filter(|w| !stages.contains(w.as_str())) {
        say!(text, "warning: {w}");
    }
    if explain {
        return Ok(text);
    }
    let (sim, mut times) = pipeline.run()?;
    let frames = run::captured_calibration(&exp, &rig, &sim, cache.as_ref(), &mut times)?;
    let t = std::time::Instant::now();
    let files = OutputSet::begin(out)?;
    let scene = &sim.scene;
    // The true cube (most of the bytes) beside the rest: an EXR is written on one thread.
    let (truth, rest) = rayon::join(
        || write_cube(&files, "truth", &scene.cube, &band_names(&scene.grid), npy),
        || -> Result<()> {
            write_cube(&files, "frame", &sim.frame, &["Y".to_string()], npy)?;
            specmux_io::png::plane_png(&files.path("frame.png"), &sim.frame, 0)?;
            if let Some(frames) = &frames {
                let dir = files.path("calibration");
                std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
                specmux_io::frame::write_calibration(&dir, frames, npy)?;
            }
            Ok(())
        },
    );
    truth.and(rest)?;
    times.push(specmux_twin::forward::StageTime::since("write-files", t));
    write_report(&files.path("simulate.json"), lib, "stages", &times)?;
    for t in &times {
        say!(text, "{:<20} {:>8.4} s", t.stage, t.seconds);
    }
    let total: f64 = times.iter().map(|t| t.seconds).sum();
    say!(text, "{:<20} {:>8.4} s", "total", total);
    finish(files, out, &mut text)?;
    Ok(text)
}

/// What `reconstruct` reports beside the cube (reconstruct.json; docs/report-schema.md).
#[derive(serde::Serialize)]
struct ReconstructReport {
    #[serde(flatten)]
    provenance: run::Provenance,
    frame: String,
    experiment: String,
    /// Where the calibration came from: the twin's simulation of the experiment's rig, or the
    /// measured frames of `--calibration`.
    calibration: ReconstructCalibration,
    unmix: UnmixStats,
    /// The joint method's run, as in report.json (null for the other methods).
    joint: Option<specmux_core::joint::JointStats>,
    metrics: Option<specmux_core::metrics::Metrics>,
    /// What `method = "auto"` picked, from the table of the device that ran it (null for the
    /// other methods).
    auto: Option<specmux_core::auto::Choice>,
    /// The frame's mean signal over its noise, when the design has the camera's noise model and
    /// the calibration a dark frame (null otherwise).
    mean_snr: Option<f64>,
    /// For the operator: a frame under its noise.
    warnings: Vec<String>,
}

#[derive(serde::Serialize)]
struct ReconstructCalibration {
    source: String,
    carriers: Vec<specmux_core::calibration::MeasuredCarrier>,
}

/// `reconstruct`: a cube from a camera frame (EXR, or a 16-bit PNG of raw DN) with the rig of
/// `experiment` (a file or a built-in scene name; required), calibrated from the measured
/// frames in `calibration` or, without them, from the twin's simulated captures of that rig.
pub fn reconstruct(
    frame_path: &Path,
    experiment: Option<&str>,
    calibration: Option<&Path>,
    truth: Option<&Path>,
    out: &Path,
    npy: bool,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let frame_name = frame_path.display().to_string();
    let Some(experiment) = experiment else {
        return Err(Error::config(&frame_name, "--experiment", "absent", "a frame is decoded with the rig that recorded it: pass --experiment EXP.toml (the experiment that made the frame) or a built-in scene name such as dead-leaves (the prototype rig)"));
    };
    let exp = experiment_for(experiment, None)?;
    let frame = specmux_io::frame::read(frame_path)?;
    let raw_dn = specmux_io::frame::is_raw_dn(frame_path)
        .then(|| format!("{frame_name} is a 16-bit PNG of raw DN"));
    let resized = size_note(&exp, &frame);
    let exp = frame_experiment(&exp, &frame, raw_dn.as_deref())?;
    let grid = exp.scene.grid(&exp.file)?;
    // Every input is read and checked before any work and any output.
    let truth = truth
        .map(|p| read_truth(p, &frame, grid.count).map(|c| (p, c)))
        .transpose()?;
    let materials = Materials::load(lib)?;
    let rig = Rig::build(&exp, lib, &materials)?;
    let (w, h, n) = (frame.width, frame.height, rig.carriers.len());
    let frames = calibration
        .map(|dir| specmux_io::frame::read_calibration(dir, n, w, h))
        .transpose()?;
    let place = calibration.map(|dir| dir.display().to_string());
    let measured = frames
        .as_ref()
        .zip(place.as_deref())
        .map(|(frames, place)| Measured {
            frames,
            place,
            key: "--calibration",
        });
    let cache = PatternCache::from_env()?;
    let cal = frame_calibration(&exp, &rig, &materials, measured, cache.as_ref())?;
    say!(text, "calibration: {}", cal.source);
    let device = exp.open_device()?;
    let design = rig.design();
    let table = device.auto_table();
    let recon = Reconstructor::for_device(&exp.reconstruct, &design, &cal, &exp.file, table)?;
    if let Some(choice) = &recon.auto {
        say!(text, "auto: {}", choice.reason);
    }
    let mean_snr = recon.frame_snr(&frame)?;
    let mut warnings: Vec<String> = resized
        .into_iter()
        .chain(recon.warnings(mean_snr))
        .collect();
    for w in &warnings {
        say!(text, "warning: {w}");
    }
    let auto = recon.auto.clone();
    let (run, times) = reconstruct_on_device(&device, recon, &frame)?;
    let (cube, stats) = (run.cube, run.unmix);
    // The joint method fits α from the frame: no per-pixel unmixing ran to count.
    match stats.pixels {
        0 => say!(text, "{times}"),
        _ => say!(
            text,
            "{times} ({} pixels bound by r ≥ 0)",
            stats.bound_pixels
        ),
    }
    if let Some(j) = &run.joint {
        text += &run::joint_summary(j);
        if let Some(w) = j.warning() {
            say!(text, "warning: {w}");
            warnings.push(w);
        }
    }
    let files = OutputSet::begin(out)?;
    write_cube(&files, "cube", &cube, &band_names(&grid), npy)?;
    let metrics = match &truth {
        Some((tp, tc)) => {
            let m = specmux_core::metrics::compare(tc, &cube)?;
            say!(
                text,
                "against {}: PSNR {:.2} dB, SSIM {:.4}, NRMSE {:.4}, SAM {}°",
                tp.display(),
                m.psnr_db,
                m.ssim,
                m.nrmse,
                specmux_core::metrics::show(m.sam_deg, 2)
            );
            for f in &m.flags {
                say!(text, "warning: {f}");
            }
            Some(m)
        }
        None => None,
    };
    let report = ReconstructReport {
        provenance: run::Provenance::new(lib),
        frame: frame_name,
        experiment: exp.file.clone(),
        calibration: ReconstructCalibration {
            source: cal.source.clone(),
            carriers: cal.carriers.clone(),
        },
        unmix: stats,
        joint: run.joint,
        metrics,
        auto,
        mean_snr,
        warnings,
    };
    specmux_io::json::write_json(&files.path("reconstruct.json"), &report)?;
    crate::panel::write_figures(&exp, lib, truth.as_ref().map(|t| &t.1), &cube, &files)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

/// The experiment a frame is decoded with: the rig of `exp` at the frame's size. `raw_dn` says
/// what makes the frame raw DN (a 16-bit PNG or TIFF, an integer array): such a frame needs the
/// experiment's camera (`[rig.sensor]`) to turn DN into light.
pub fn frame_experiment(
    exp: &Experiment,
    frame: &Cube,
    raw_dn: Option<&str>,
) -> Result<Experiment> {
    if let (Some(what), None) = (raw_dn, &exp.rig.sensor) {
        let why =
            format!("{what}: the experiment needs its camera ([rig.sensor]) to turn DN into light");
        return Err(Error::config(&exp.file, "rig.sensor", "absent", &why));
    }
    let mut exp = exp.clone();
    exp.scene.size = [frame.width, frame.height];
    exp.validate()?;
    Ok(exp)
}

/// A note when the experiment wrote a `scene.size` the frame does not have: the frame's size is
/// the one reconstructed ([`frame_experiment`]), which the user may not expect.
pub fn size_note(exp: &Experiment, frame: &Cube) -> Option<String> {
    let [w, h] = exp.scene.size;
    (exp.wrote("scene.size") && [w, h] != [frame.width, frame.height]).then(|| {
        format!(
            "{}: scene.size = [{w}, {h}], but the frame is {}×{}: the frame's size is used",
            exp.file, frame.width, frame.height
        )
    })
}

/// Calibration frames a user measured, with where they came from (`place`: a folder) and the
/// option or key that gave them, for error messages.
pub struct Measured<'a> {
    pub frames: &'a CalibrationFrames,
    pub place: &'a str,
    pub key: &'a str,
}

/// The calibration a frame is reconstructed with: the core's `Calibration::from_frames` on the
/// `measured` frames, or without them the twin's simulated captures of the experiment's rig
/// (patterns and captures kept in `cache`), its source saying so.
pub fn frame_calibration(
    exp: &Experiment,
    rig: &Rig,
    materials: &Materials,
    measured: Option<Measured>,
    cache: Option<&PatternCache>,
) -> Result<Calibration> {
    if let Some(m) = measured {
        return Calibration::from_frames(&rig.carriers, m.frames, exp.calibration.search_bins)
            .map_err(|e| e.within(m.place, m.key, "its frames"));
    }
    let pipeline = specmux_twin::forward::Pipeline::build(exp, rig, materials)?;
    let (sim, _) = pipeline.with_pattern_cache(cache.cloned()).run()?;
    let mut cal = run::calibration(exp, rig, &sim, cache)?;
    cal.source = format!(
        "the twin's simulated {} of the experiment's rig (no --calibration)",
        cal.source
    );
    Ok(cal)
}

/// A truth cube that matches the frame's size and the experiment's band count.
fn read_truth(path: &Path, frame: &specmux_core::Cube, bands: usize) -> Result<specmux_core::Cube> {
    let (cube, _) = exr_io::read(path)?;
    if (cube.width, cube.height, cube.planes) != (frame.width, frame.height, bands) {
        return Err(Error::Exr {
            path: path.to_path_buf(),
            msg: format!(
                "a truth {} for a frame {} wide × {} high and {bands} bands (scene.wavelengths_nm)",
                cube.size_text(),
                frame.width,
                frame.height
            ),
        });
    }
    Ok(cube)
}

/// The colour of each wheel filter (its transmittance seen under the scene's illuminant, at full
/// brightness): the timing figures draw segment i in it.
pub fn filter_chips(exp: &Experiment, lib: &Library) -> Result<Vec<[u8; 3]>> {
    let grid = exp.scene.grid(&exp.file)?;
    let light = exp.curve(lib, &exp.scene.illuminant)?;
    let col = crate::plot::Colorimetry::new(lib, &grid, Some(&light))?;
    exp.rig
        .wheel
        .filters
        .iter()
        .map(|name| Ok(col.chip(&exp.curve(lib, name)?.sample(&grid))))
        .collect()
}

/// Write a command's JSON file with the version and library provenance every report carries
/// (docs/report-schema.md): the keys of `run::Provenance`, then `key` holding `body`.
pub fn write_report(
    path: &Path,
    lib: &Library,
    key: &str,
    body: &impl serde::Serialize,
) -> Result<()> {
    let mut doc = serde_json::json!(run::Provenance::new(lib));
    doc[key] = serde_json::json!(body);
    specmux_io::json::write_json(path, &doc)
}
