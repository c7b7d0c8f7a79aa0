//! One function per CLI command: run the library, write the files, return the text to print.

use crate::plot::Colorimetry;
use specmux_core::reconstructor::{ComputeDevice, Reconstructor};
use specmux_core::spectral::{Grid, Library};
use specmux_core::unmix::UnmixStats;
use specmux_core::{Cube, Error, Result};
use specmux_io::exr as exr_io;
use specmux_io::output_set::OutputSet;
use specmux_twin::experiment::Experiment;
use specmux_twin::run::{self, RunData, RunReport};
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

/// The experiment a `--scene` names: a built-in scene or a TOML file.
pub fn experiment_for(scene: &str, size: Option<usize>) -> Result<Experiment> {
    let mut exp = if scene.ends_with(".toml") {
        Experiment::load(Path::new(scene))?
    } else {
        let mut e = Experiment::prototype();
        e.scene.source = scene.to_string();
        e
    };
    if let Some(n) = size {
        exp.scene.size = [n, n];
    }
    exp.validate()?;
    Ok(exp)
}

fn load(path: &Path) -> Result<Experiment> {
    Experiment::load(path)
}

/// One frame's cube and unmixing counters on the device `[compute] device` names, with a line
/// of stage times. The GPU (feature `gpu`) runs the `fourier` chain: demultiplex, crosstalk
/// mix, unmix; GAP is not on the GPU yet, so `gpu` with GAP is an error and `auto` with GAP, or
/// without an adapter, stays on the CPU and says so in one line.
fn reconstruct_on_device(
    exp: &Experiment,
    recon: &Reconstructor,
    frame: &Cube,
) -> Result<(Cube, UnmixStats, String)> {
    let fourier = recon.gap.is_none();
    match (exp.compute.device, fourier) {
        (ComputeDevice::Cpu, _) => {}
        (ComputeDevice::Gpu, false) => {
            return Err(Error::config(
                &exp.file,
                "compute.device",
                "gpu",
                "GAP and GAP-TV are not on the GPU yet: set [reconstruct.gap] method = \"fourier\" or device = \"cpu\"",
            ))
        }
        (ComputeDevice::Auto, false) => {
            eprintln!("compute device auto: GAP is not on the GPU yet; reconstructing on the CPU")
        }
        (_, true) => {
            if let Some(done) = gpu::reconstruct(exp, recon, frame)? {
                return Ok(done);
            }
        }
    }
    let r = recon.run(frame, None)?;
    let [t_demux, t_gap, t_unmix] = r.seconds;
    let times =
        format!("CPU: demultiplex {t_demux:.4} s, de-alias {t_gap:.4} s, unmix {t_unmix:.4} s");
    Ok((r.cube, r.unmix, times))
}

/// The GPU's `fourier` chain (specmux-gpu), or None where `auto` found no adapter.
#[cfg(feature = "gpu")]
mod gpu {
    use super::*;

    pub fn reconstruct(
        exp: &Experiment,
        recon: &Reconstructor,
        frame: &Cube,
    ) -> Result<Option<(Cube, UnmixStats, String)>> {
        let err = |e: specmux_gpu::GpuError| Error::Numerical(e.to_string());
        let Some(ctx) = specmux_gpu::backend::open(exp.compute.device).map_err(err)? else {
            return Ok(None);
        };
        let t = std::time::Instant::now();
        let g = specmux_gpu::GpuReconstructor::new(&ctx, recon).map_err(err)?;
        let t_setup = t.elapsed().as_secs_f64();
        let mut cube = g.output_cube();
        let t = std::time::Instant::now();
        let stats = g.run_into(&ctx, frame, &mut cube).map_err(err)?;
        let times = format!(
            "GPU {}: setup {t_setup:.4} s, demultiplex + unmix {:.4} s (first frame)",
            ctx.adapter_name(),
            t.elapsed().as_secs_f64()
        );
        Ok(Some((cube, stats, times)))
    }
}

/// Without the `gpu` feature: `gpu` is an error, `auto` stays on the CPU and says so.
#[cfg(not(feature = "gpu"))]
mod gpu {
    use super::*;

    pub fn reconstruct(
        exp: &Experiment,
        _: &Reconstructor,
        _: &Cube,
    ) -> Result<Option<(Cube, UnmixStats, String)>> {
        if exp.compute.device == ComputeDevice::Gpu {
            return Err(Error::config(
                &exp.file,
                "compute.device",
                "gpu",
                "this specmux was built without the GPU backend: cargo build --release --features gpu",
            ));
        }
        eprintln!("compute device auto: built without the gpu feature; reconstructing on the CPU");
        Ok(None)
    }
}

fn band_names(grid: &Grid) -> Vec<String> {
    grid.wavelengths()
        .into_iter()
        .map(exr_io::band_name)
        .collect()
}

pub fn demo(scene: &str, size: Option<usize>, out: &Path, lib: &Library) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, size)?;
    let (rep, data) = run::run(&exp, lib)?;
    say!(text, "{}", rep.table());
    let files = OutputSet::begin(out)?;
    write_run_files(&exp, &rep, &data, &files, lib)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

fn write_run_files(
    exp: &Experiment,
    rep: &RunReport,
    d: &RunData,
    files: &OutputSet,
    lib: &Library,
) -> Result<()> {
    let grid = exp.scene.grid(&exp.file)?;
    exr_io::write(&files.path("frame.exr"), &d.frame, &["Y".to_string()])?;
    specmux_io::png::plane_png(&files.path("frame.png"), &d.frame, 0)?;
    exr_io::write(&files.path("cube.exr"), &d.cube, &band_names(&grid))?;
    let ch: Vec<String> = (0..d.xhat.planes).map(|i| format!("x{i}")).collect();
    exr_io::write(&files.path("channels.exr"), &d.xhat, &ch)?;
    let light = match exp.scene.quantity {
        specmux_twin::scene::Quantity::Reflectance => Some(lib.curve(&exp.scene.illuminant)?),
        specmux_twin::scene::Quantity::Radiance => None,
    };
    let col = Colorimetry::new(lib, &grid, light.as_ref())?;
    let exposure = if light.is_some() {
        1.0
    } else {
        1.0 / f64::from(d.truth.max().max(f32::MIN_POSITIVE))
    };
    for (name, cube) in [("truth_rgb.png", &d.truth), ("cube_rgb.png", &d.cube)] {
        specmux_io::png::write_png(
            &files.path(name),
            image::DynamicImage::ImageRgb8(col.preview(cube, exposure)?),
        )?;
    }
    crate::plot::spectra_plot(&files.path("spectra.png"), &grid, &d.truth, &d.cube)?;
    specmux_io::json::write_json(&files.path("report.json"), rep)
}

pub fn bench(
    scene: &str,
    out: &Path,
    repeats: usize,
    size: Option<usize>,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, size)?;
    let sim = crate::bench::simulate(&exp, lib)?;
    let threads = rayon::current_num_threads();
    say!(
        text,
        "{}: {}×{}, {repeats} timed runs per setting, {threads} threads",
        exp.file,
        sim.frame.width,
        sim.frame.height
    );
    let rows = crate::bench::work_precision(&sim, &crate::bench::default_grid(), repeats)?;
    let md = crate::bench::work_precision_markdown(&rows);
    say!(text, "{md}");
    let files = OutputSet::begin(out)?;
    specmux_io::atomic::write_bytes(&files.path("bench.md"), md.as_bytes())?;
    specmux_io::json::write_json(&files.path("bench.json"), &rows)?;
    crate::bench::work_precision_plot(
        &files.path("pareto.png"),
        &format!(
            "{} {}×{}: error against run time ({threads} threads)",
            scene, sim.frame.width, sim.frame.height
        ),
        &rows,
        sim.frame.pixels(),
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
    specmux_io::json::write_json(&files.path("sweep.json"), &rows)?;
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
    specmux_io::json::write_json(&files.path("sweep.json"), &rows)?;
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
        )?;
        let md = pr::study_table(&rows);
        say!(
            text,
            "{md}\n{} runs in {:.1} s",
            rows.len(),
            t.elapsed().as_secs_f64()
        );
        let files = OutputSet::begin(out)?;
        specmux_io::atomic::write_bytes(&files.path("study.md"), md.as_bytes())?;
        specmux_io::json::write_json(&files.path("study.json"), &rows)?;
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
    )?;
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
    pr::write_pattern_pngs(&set, files.dir())?;
    specmux_io::json::write_json(&files.path("patterns.json"), &rep)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn timing(scene: &str, out: &Path) -> Result<String> {
    let mut text = String::new();
    let exp = experiment_for(scene, None)?;
    let cfg = exp.rig.timing.clone().ok_or_else(|| {
        Error::config(
            &exp.file,
            "rig.timing",
            "absent",
            "the experiment has no [rig.timing] section to report on",
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
    crate::timeline::timeline_png(&cfg, &files.path("timeline.png"))?;
    specmux_io::json::write_json(&files.path("timing.json"), &tw)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn ptc(scene: Option<&str>, size: usize, out: &Path) -> Result<String> {
    let mut text = String::new();
    let cfg = match scene {
        Some(s) => experiment_for(s, None)?.rig.sensor.unwrap_or_default(),
        None => specmux_twin::sensor::SensorConfig::default(),
    };
    let sensor = specmux_twin::sensor::Sensor::new(&cfg, size, size)?;
    let r = specmux_twin::sensor::photon_transfer(
        &sensor,
        &specmux_twin::sensor::default_levels(cfg.full_well_e),
    )?;
    say!(
        text,
        "{:<22} {:>12} {:>12}",
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
        ("full well (e⁻)", r.full_well_e, cfg.full_well_e),
        (
            "PRNU (%)",
            100.0 * r.prnu_fraction,
            100.0 * cfg.prnu_fraction,
        ),
        ("DSNU (e⁻)", r.dsnu_e, cfg.dsnu_e),
    ] {
        say!(text, "{name:<22} {m:>12.4} {g:>12.4}");
    }
    say!(
        text,
        "K standard error {:.2e} DN/e⁻ over {} pixels",
        r.k_stderr_dn_per_e,
        r.pixels
    );
    let files = OutputSet::begin(out)?;
    crate::ptc::plot_ptc(&r, &files.path("ptc.png"))?;
    specmux_io::json::write_json(&files.path("ptc.json"), &r)?;
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn simulate(path: &Path, explain: bool, out: &Path, lib: &Library) -> Result<String> {
    let mut text = String::new();
    let exp = load(path)?;
    let materials = specmux_twin::scene::Materials::load(lib)?;
    let rig = specmux_twin::rig::Rig::build(&exp, lib, &materials)?;
    let pipeline = specmux_twin::forward::Pipeline::build(&exp, &rig, &materials)?;
    say!(text, "{}", pipeline.explain());
    if explain {
        return Ok(text);
    }
    let (sim, times) = pipeline.run()?;
    let files = OutputSet::begin(out)?;
    exr_io::write(&files.path("frame.exr"), &sim.frame, &["Y".to_string()])?;
    specmux_io::png::plane_png(&files.path("frame.png"), &sim.frame, 0)?;
    let scene = &sim.scene;
    exr_io::write(
        &files.path("truth.exr"),
        &scene.cube,
        &band_names(&scene.grid),
    )?;
    specmux_io::json::write_json(&files.path("simulate.json"), &times)?;
    for t in &times {
        say!(text, "{:<15} {:>8.4} s", t.stage, t.seconds);
    }
    finish(files, out, &mut text)?;
    Ok(text)
}

pub fn reconstruct(
    frame_path: &Path,
    exp: Option<&Path>,
    truth: Option<&Path>,
    out: &Path,
    lib: &Library,
) -> Result<String> {
    let mut text = String::new();
    let mut exp = match exp {
        Some(p) => load(p)?,
        None => Experiment::prototype(),
    };
    let frame = read_frame(frame_path)?;
    exp.scene.size = [frame.width, frame.height];
    exp.validate()?;
    let grid = exp.scene.grid(&exp.file)?;
    // Every input is read and checked before any work and any output.
    let truth = truth
        .map(|p| read_truth(p, &frame, grid.count).map(|c| (p, c)))
        .transpose()?;
    let materials = specmux_twin::scene::Materials::load(lib)?;
    let rig = specmux_twin::rig::Rig::build(&exp, lib, &materials)?;
    // The calibration frames of this rig, as the twin captures them.
    let (sim, _) = specmux_twin::forward::Pipeline::build(&exp, &rig, &materials)?.run()?;
    let recon = run::reconstructor(&exp, &rig, &sim)?;
    let (cube, stats, times) = reconstruct_on_device(&exp, &recon, &frame)?;
    say!(
        text,
        "{times} ({} pixels bound by r ≥ 0)",
        stats.constrained_pixels
    );
    let files = OutputSet::begin(out)?;
    exr_io::write(&files.path("cube.exr"), &cube, &band_names(&grid))?;
    if let Some((tp, tc)) = truth {
        let m = specmux_core::metrics::compare(&tc, &cube)?;
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
        specmux_io::json::write_json(&files.path("metrics.json"), &m)?;
    }
    finish(files, out, &mut text)?;
    Ok(text)
}

/// A camera frame: one channel of an EXR file.
fn read_frame(path: &Path) -> Result<specmux_core::Cube> {
    let (frame, _) = exr_io::read(path)?;
    let bad = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    if frame.planes != 1 {
        return Err(bad(format!(
            "a frame has one channel, this file has {}",
            frame.planes
        )));
    }
    if let Some(p) = frame.data.iter().position(|v| !v.is_finite()) {
        let (x, y) = (p % frame.width, p / frame.width);
        return Err(bad(format!(
            "pixel ({x}, {y}) is {}: a frame must be finite",
            frame.data[p]
        )));
    }
    Ok(frame)
}

/// A truth cube that matches the frame's size and the experiment's band count.
fn read_truth(path: &Path, frame: &specmux_core::Cube, bands: usize) -> Result<specmux_core::Cube> {
    let (cube, _) = exr_io::read(path)?;
    if (cube.width, cube.height, cube.planes) != (frame.width, frame.height, bands) {
        return Err(Error::Exr {
            path: path.to_path_buf(),
            msg: format!(
                "a {}×{}×{} truth for a {}×{} frame and {bands} bands (scene.wavelengths_nm)",
                cube.width, cube.height, cube.planes, frame.width, frame.height
            ),
        });
    }
    Ok(cube)
}
