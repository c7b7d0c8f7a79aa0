//! The `specmux` command line: parses, calls the library, prints. Errors are one line.

use clap::{Parser, Subcommand};
use specmux::report::{self, Colorimetry};
use specmux::run::{self, RunData, RunReport};
use specmux::scene::{exr_io, Experiment};
use specmux::spectral::{Grid, Library};
use specmux::{Error, Result};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "specmux",
    version,
    about = "Digital twin of a Fourier-spectral-multiplexing snapshot hyperspectral camera"
)]
struct Cli {
    /// Folder of spectral CSV curves (default: $SPECMUX_SPECTRA or the source tree's spectra/).
    #[arg(long, global = true)]
    spectra: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run an experiment end to end (default: the 2019 prototype on the dead-leaves scene),
    /// print the error of every stage against the truth and its run time, write the files.
    Demo {
        /// A built-in scene (dead-leaves, shaded-objects) or an experiment file.
        #[arg(long, default_value = "dead-leaves")]
        scene: String,
        /// Override the frame size (square), e.g. 256 for a quick look.
        #[arg(long)]
        size: Option<usize>,
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
    },
    /// Simulate the frame the camera would record for an experiment.
    Simulate {
        experiment: PathBuf,
        /// Print the stages that would run, and run nothing.
        #[arg(long)]
        explain: bool,
        #[arg(long, default_value = "out/simulate")]
        out: PathBuf,
    },
    /// Work–precision study: simulate the frame once, reconstruct it with Fourier, GAP and GAP-TV
    /// over a grid of iterations, crops and window shapes; table (stdout, JSON, Markdown) and a
    /// plot of final-cube PSNR against median run time with the Pareto front.
    Bench {
        /// A built-in scene (dead-leaves, shaded-objects) or an experiment file.
        experiment: String,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Timed runs per setting; the median is reported.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Override the frame size (square).
        #[arg(long)]
        size: Option<usize>,
    },
    /// The paper's crop-size figure: mean channel PSNR/RMSE/SSIM of the demultiplexed channels
    /// for crops 0.05–0.4 with the carrier layout held fixed (windows above 0.25 overlap).
    SweepCrop {
        /// Built-in scenes or experiment files, one curve each.
        #[arg(required = true)]
        experiments: Vec<String>,
        #[arg(long, default_value = "out/sweep-crop")]
        out: PathBuf,
        /// Override the frame size (square).
        #[arg(long)]
        size: Option<usize>,
        /// Leave out the GAP curve (the experiment's [reconstruct.gap], method gap).
        #[arg(long)]
        no_gap: bool,
    },
    /// Run an experiment over a grid of values of its keys and tabulate the error of each run
    /// against the truth, e.g. `--vary rig.sensor.electrons_at_full_scale=10;100;1000`.
    Sweep {
        /// A built-in scene (dead-leaves, shaded-objects) or an experiment file.
        experiment: String,
        /// KEY=V1;V2;… (TOML values; a bare word is a string). Repeat for a Cartesian grid.
        #[arg(long, required = true)]
        vary: Vec<String>,
        #[arg(long, default_value = "out/sweep")]
        out: PathBuf,
        /// Override the frame size (square).
        #[arg(long)]
        size: Option<usize>,
    },
    /// Pattern report: for each channel the error of the imaged pattern s̃ against the ideal
    /// sinusoid, its carrier gain, the 2ω and cross-window energies, the pinhole throughput,
    /// and PNGs of the binary and imaged patterns and their spectra.
    Patterns {
        experiment: String,
        #[arg(long, default_value = "out/patterns")]
        out: PathBuf,
        #[arg(long)]
        size: Option<usize>,
        /// Dithering study instead: every dither × illumination at these pinhole radii (µm,
        /// comma-separated), the experiment's other optics kept (study.md, study.json).
        #[arg(long, value_delimiter = ',')]
        study: Option<Vec<f64>>,
    },
    /// Timing report: the weight matrix w_ik of one exposure, the operator's warnings and a
    /// timeline PNG (wheel segment, pattern shown, exposure window).
    Timing {
        experiment: String,
        #[arg(long, default_value = "out/timing")]
        out: PathBuf,
    },
    /// EMVA 1288 photon-transfer measurement of the experiment's camera ([rig.sensor], else the
    /// default): K, read noise, full well, PRNU, DSNU, and the photon-transfer curve as a PNG.
    Ptc {
        /// An experiment file (default: the prototype's camera).
        experiment: Option<String>,
        /// Side of the square test frames.
        #[arg(long, default_value_t = 256)]
        size: usize,
        #[arg(long, default_value = "out/ptc")]
        out: PathBuf,
    },
    /// Reconstruct a cube from a frame (EXR, one channel) with an experiment's rig.
    Reconstruct {
        frame: PathBuf,
        #[arg(long)]
        experiment: Option<PathBuf>,
        /// A truth cube (EXR) to report the error against.
        #[arg(long)]
        truth: Option<PathBuf>,
        #[arg(long, default_value = "out/reconstruct")]
        out: PathBuf,
    },
}

/// Print a line to stdout; a closed pipe (`specmux demo | head`) ends the program quietly.
macro_rules! say {
    ($($t:tt)*) => { emit(&format!($($t)*)) };
}

fn emit(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if writeln!(out, "{}", text.trim_end_matches('\n')).is_err() {
        std::process::exit(0);
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let lib = cli
        .spectra
        .clone()
        .map(Library::new)
        .unwrap_or_else(Library::default_root);
    match dispatch(cli.command, &lib) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("specmux: {e}");
            ExitCode::FAILURE
        }
    }
}

fn dispatch(cmd: Command, lib: &Library) -> Result<()> {
    match cmd {
        Command::Demo { scene, size, out } => demo(&scene, size, &out, lib),
        Command::Simulate {
            experiment,
            explain,
            out,
        } => simulate(&experiment, explain, &out, lib),
        Command::Bench {
            experiment,
            out,
            repeats,
            size,
        } => bench(&experiment, &out, repeats, size, lib),
        Command::SweepCrop {
            experiments,
            out,
            size,
            no_gap,
        } => sweep_crop(&experiments, &out, size, no_gap, lib),
        Command::Sweep {
            experiment,
            vary,
            out,
            size,
        } => sweep(&experiment, &vary, &out, size, lib),
        Command::Patterns {
            experiment,
            out,
            size,
            study,
        } => patterns(&experiment, &out, size, study.as_deref(), lib),
        Command::Timing { experiment, out } => timing(&experiment, &out),
        Command::Ptc {
            experiment,
            size,
            out,
        } => ptc(experiment.as_deref(), size, &out),
        Command::Reconstruct {
            frame,
            experiment,
            truth,
            out,
        } => reconstruct(&frame, experiment.as_deref(), truth.as_deref(), &out, lib),
    }
}

/// The experiment a `--scene` names: a built-in scene or a TOML file.
fn experiment_for(scene: &str, size: Option<usize>) -> Result<Experiment> {
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

fn band_names(grid: &Grid) -> Vec<String> {
    grid.wavelengths()
        .into_iter()
        .map(exr_io::band_name)
        .collect()
}

fn demo(scene: &str, size: Option<usize>, out: &Path, lib: &Library) -> Result<()> {
    let exp = experiment_for(scene, size)?;
    let (rep, data) = run::run(&exp, lib)?;
    say!("{}", rep.table());
    write_run_files(&exp, &rep, &data, out, lib)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn write_run_files(
    exp: &Experiment,
    rep: &RunReport,
    d: &RunData,
    out: &Path,
    lib: &Library,
) -> Result<()> {
    let grid = specmux::scene::grid_of(exp)?;
    exr_io::write(&out.join("frame.exr"), &d.frame, &["Y".to_string()])?;
    report::plane_png(&out.join("frame.png"), &d.frame, 0)?;
    exr_io::write(&out.join("cube.exr"), &d.cube, &band_names(&grid))?;
    let ch: Vec<String> = (0..d.xhat.planes).map(|i| format!("x{i}")).collect();
    exr_io::write(&out.join("channels.exr"), &d.xhat, &ch)?;
    let light = match exp.scene.quantity {
        specmux::scene::Quantity::Reflectance => Some(lib.curve(&exp.scene.illuminant)?),
        specmux::scene::Quantity::Radiance => None,
    };
    let col = Colorimetry::new(lib, &grid, light.as_ref())?;
    let exposure = if light.is_some() {
        1.0
    } else {
        1.0 / f64::from(d.truth.max().max(f32::MIN_POSITIVE))
    };
    for (name, cube) in [("truth_rgb.png", &d.truth), ("cube_rgb.png", &d.cube)] {
        report::write_png(
            &out.join(name),
            image::DynamicImage::ImageRgb8(col.preview(cube, exposure)?),
        )?;
    }
    report::spectra_plot(&out.join("spectra.png"), &grid, &d.truth, &d.cube)?;
    report::write_json(&out.join("report.json"), rep)
}

fn bench(
    scene: &str,
    out: &Path,
    repeats: usize,
    size: Option<usize>,
    lib: &Library,
) -> Result<()> {
    let exp = experiment_for(scene, size)?;
    let sim = specmux::bench::simulate(&exp, lib)?;
    let threads = rayon::current_num_threads();
    say!(
        "{}: {}×{}, {repeats} timed runs per setting, {threads} threads",
        exp.file,
        sim.frame.width,
        sim.frame.height
    );
    let rows = specmux::bench::work_precision(&sim, &specmux::bench::default_grid(), repeats)?;
    let md = specmux::bench::work_precision_markdown(&rows);
    say!("{md}");
    specmux::atomic::write_bytes(&out.join("bench.md"), md.as_bytes())?;
    report::write_json(&out.join("bench.json"), &rows)?;
    specmux::bench::work_precision_plot(
        &out.join("pareto.png"),
        &format!(
            "{} {}×{}: error against run time ({threads} threads)",
            scene, sim.frame.width, sim.frame.height
        ),
        &rows,
    )?;
    say!("wrote {}", out.display());
    Ok(())
}

fn sweep_crop(
    scenes: &[String],
    out: &Path,
    size: Option<usize>,
    no_gap: bool,
    lib: &Library,
) -> Result<()> {
    let mut rows = Vec::new();
    for scene in scenes {
        let exp = experiment_for(scene, size)?;
        let sim = specmux::bench::simulate(&exp, lib)?;
        let cfg = specmux::recon::gap::GapConfig {
            method: specmux::recon::gap::Method::Gap,
            ..exp.reconstruct.gap.clone()
        };
        let name = Path::new(scene)
            .file_stem()
            .map_or(scene.clone(), |s| s.to_string_lossy().into_owned());
        let r = specmux::bench::sweep_crop(
            &sim,
            &name,
            &specmux::bench::paper_crops(),
            (!no_gap).then_some(&cfg),
        )?;
        rows.extend(r);
    }
    let md = specmux::bench::sweep_markdown(&rows);
    say!("{md}");
    for (scene, crop, psnr) in specmux::bench::sweep_peaks(&rows) {
        say!("{scene}: Fourier PSNR peaks at crop {crop:.3} ({psnr:.2} dB)");
    }
    specmux::atomic::write_bytes(&out.join("sweep.md"), md.as_bytes())?;
    report::write_json(&out.join("sweep.json"), &rows)?;
    specmux::bench::sweep_plot(&out.join("sweep_crop.png"), &rows)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn sweep(
    scene: &str,
    vary: &[String],
    out: &Path,
    size: Option<usize>,
    lib: &Library,
) -> Result<()> {
    let exp = experiment_for(scene, size)?;
    let vary = vary
        .iter()
        .map(|v| specmux::sweep::Vary::parse(v))
        .collect::<Result<Vec<_>>>()?;
    let rows = specmux::sweep::sweep(&exp, &vary, lib)?;
    let md = specmux::sweep::markdown(&vary, &rows);
    say!(
        "{}: {}×{}\n{md}",
        exp.file,
        exp.scene.size[0],
        exp.scene.size[1]
    );
    specmux::atomic::write_bytes(&out.join("sweep.md"), md.as_bytes())?;
    report::write_json(&out.join("sweep.json"), &rows)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn patterns(
    scene: &str,
    out: &Path,
    size: Option<usize>,
    study: Option<&[f64]>,
    lib: &Library,
) -> Result<()> {
    use specmux::optics::pattern_report as pr;
    let exp = experiment_for(scene, size)?;
    let materials = specmux::scene::Materials::load(lib)?;
    let rig = specmux::rig::Rig::build(&exp, lib, &materials)?;
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
            "{md}\n{} runs in {:.1} s",
            rows.len(),
            t.elapsed().as_secs_f64()
        );
        specmux::atomic::write_bytes(&out.join("study.md"), md.as_bytes())?;
        report::write_json(&out.join("study.json"), &rows)?;
        say!("wrote {}", out.display());
        return Ok(());
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
        say!("{s}");
    }
    say!(
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
    say!("\ncrosstalk (energy in window j / own window), rows = channel i:");
    for c in &rep.channels {
        let row: Vec<String> = c.crosstalk.iter().map(|v| format!("{v:9.2e}")).collect();
        say!("{}", row.join(" "));
    }
    pr::write_pattern_pngs(&set, out)?;
    report::write_json(&out.join("patterns.json"), &rep)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn timing(scene: &str, out: &Path) -> Result<()> {
    let exp = experiment_for(scene, None)?;
    let cfg = exp.rig.timing.clone().ok_or_else(|| {
        Error::config(
            &exp.file,
            "rig.timing",
            "absent",
            "the experiment has no [rig.timing] section to report on",
        )
    })?;
    let tw = specmux::timing::weights(&cfg)?;
    say!(
        "exposure {} s = {:.4} wheel turns; spot on a spoke {:.2} % of the time",
        cfg.camera.exposure_s,
        tw.turns_per_exposure,
        100.0 * tw.spoke_fraction
    );
    say!("weights w_ik (rows: filter i, columns: pattern k):");
    for row in &tw.w {
        let r: Vec<String> = row.iter().map(|v| format!("{v:8.5}")).collect();
        say!("{}", r.join(" "));
    }
    for w in &tw.warnings {
        say!("warning: {w}");
    }
    if tw.warnings.is_empty() {
        say!("no warnings: whole turns, aligned, within the DMD's and the camera's rates");
    }
    specmux::timing::timeline_png(&cfg, &out.join("timeline.png"))?;
    report::write_json(&out.join("timing.json"), &tw)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn ptc(scene: Option<&str>, size: usize, out: &Path) -> Result<()> {
    let cfg = match scene {
        Some(s) => experiment_for(s, None)?.rig.sensor.unwrap_or_default(),
        None => specmux::sensor::SensorConfig::default(),
    };
    let sensor = specmux::sensor::Sensor::new(&cfg, size, size)?;
    let r = specmux::sensor::photon_transfer(
        &sensor,
        &specmux::sensor::default_levels(cfg.full_well_e),
    )?;
    say!("{:<22} {:>12} {:>12}", "EMVA 1288", "measured", "given");
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
        say!("{name:<22} {m:>12.4} {g:>12.4}");
    }
    say!(
        "K standard error {:.2e} DN/e⁻ over {} pixels",
        r.k_stderr_dn_per_e,
        r.pixels
    );
    specmux::sensor::plot_ptc(&r, &out.join("ptc.png"))?;
    report::write_json(&out.join("ptc.json"), &r)?;
    say!("wrote {}", out.display());
    Ok(())
}

fn simulate(path: &Path, explain: bool, out: &Path, lib: &Library) -> Result<()> {
    let exp = load(path)?;
    let materials = specmux::scene::Materials::load(lib)?;
    let rig = specmux::rig::Rig::build(&exp, lib, &materials)?;
    let pipeline = specmux::forward::Pipeline::build(&exp, &rig, &materials)?;
    say!("{}", pipeline.explain());
    if explain {
        return Ok(());
    }
    let (state, times) = pipeline.run()?;
    let frame = state
        .frame
        .ok_or_else(|| Error::Numerical("no frame was produced".into()))?;
    exr_io::write(&out.join("frame.exr"), &frame, &["Y".to_string()])?;
    report::plane_png(&out.join("frame.png"), &frame, 0)?;
    if let Some(scene) = &state.scene {
        exr_io::write(
            &out.join("truth.exr"),
            &scene.cube,
            &band_names(&scene.grid),
        )?;
    }
    report::write_json(&out.join("simulate.json"), &times)?;
    for t in &times {
        say!("{:<15} {:>8.4} s", t.stage, t.seconds);
    }
    say!("wrote {}", out.display());
    Ok(())
}

fn reconstruct(
    frame_path: &Path,
    exp: Option<&Path>,
    truth: Option<&Path>,
    out: &Path,
    lib: &Library,
) -> Result<()> {
    let mut exp = match exp {
        Some(p) => load(p)?,
        None => Experiment::prototype(),
    };
    let (frame, _) = exr_io::read(frame_path)?;
    if frame.planes != 1 {
        return Err(Error::Exr {
            path: frame_path.to_path_buf(),
            msg: format!("a frame has one channel, this file has {}", frame.planes),
        });
    }
    exp.scene.size = [frame.width, frame.height];
    exp.validate()?;
    let materials = specmux::scene::Materials::load(lib)?;
    let rig = specmux::rig::Rig::build(&exp, lib, &materials)?;
    let patterns = specmux::forward::patterns_for(&exp, &rig)?;
    let recon = specmux::recon::Reconstructor::new(&exp, &rig, patterns.as_ref())?;
    let r = recon.run(&frame, None)?;
    let [t_demux, t_gap, t_unmix] = r.seconds;
    let (cube, stats) = (r.cube, r.unmix);
    exr_io::write(&out.join("cube.exr"), &cube, &band_names(&rig.grid))?;
    say!(
        "demultiplex {t_demux:.4} s, de-alias {t_gap:.4} s, unmix {t_unmix:.4} s ({} pixels bound by r ≥ 0)",
        stats.constrained_pixels
    );
    if let Some(tp) = truth {
        let (tc, _) = exr_io::read(tp)?;
        let m = specmux::metrics::compare(&tc, &cube)?;
        say!(
            "against {}: PSNR {:.2} dB, SSIM {:.4}, NRMSE {:.4}, SAM {:.2}°",
            tp.display(),
            m.psnr_db,
            m.ssim,
            m.nrmse,
            m.sam_deg
        );
        report::write_json(&out.join("metrics.json"), &m)?;
    }
    say!("wrote {}", out.display());
    Ok(())
}
