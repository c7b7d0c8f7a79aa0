//! The command line's grammar: clap's definitions of every command and flag (docs in README.md).

use clap::{Parser, Subcommand};
use specmux_controller::commands as controller;
use specmux_core::reconstructor::ComputeDevice;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "specmux",
    version,
    about = "Digital twin of a Fourier-spectral-multiplexing snapshot hyperspectral camera"
)]
pub struct Cli {
    /// Folder of spectral CSV curves (default: $SPECMUX_SPECTRA, else the library embedded in
    /// this binary).
    #[arg(long, global = true)]
    pub spectra: Option<PathBuf>,
    /// Keep the imaged patterns of every optical chain and the calibration captures of every rig
    /// and camera in this folder, and read them back when a later run uses the same chain or
    /// rig (default: $SPECMUX_PATTERN_CACHE; unset: no cache).
    #[arg(long, global = true, value_name = "DIR")]
    pub pattern_cache: Option<PathBuf>,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run an experiment end to end (default: the 2019 prototype on the dead-leaves scene),
    /// print the error of every stage against the truth and its run time, write the files.
    Demo {
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
        #[arg(long, default_value = "dead-leaves")]
        scene: String,
        /// Override the frame size (square), e.g. 256 for a quick look.
        #[arg(long)]
        size: Option<usize>,
        #[arg(long, default_value = "out/demo")]
        out: PathBuf,
        /// Also write every EXR as NumPy .npy (float32; a cube as bands × height × width).
        #[arg(long)]
        npy: bool,
    },
    /// Simulate the frame the camera would record for an experiment, the true cube and the
    /// calibration frames (calibration/: what `reconstruct --calibration` reads).
    Simulate {
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
        experiment: String,
        /// Print the stages that would run, and run nothing.
        #[arg(long)]
        explain: bool,
        #[arg(long, default_value = "out/simulate")]
        out: PathBuf,
        /// Also write every EXR as NumPy .npy.
        #[arg(long)]
        npy: bool,
    },
    /// Work–precision study: simulate the frame once, reconstruct it with Fourier, GAP, GAP-TV
    /// and the joint method (TV and plug-and-play priors; with a [rig.sensor] also noise-weighted
    /// and with the discrepancy λ) over a grid of iterations, crops and window shapes; table
    /// (stdout, JSON, Markdown) and a plot of final-cube PSNR against median run time with the
    /// Pareto front.
    Bench {
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
        experiment: String,
        #[arg(long, default_value = "out/bench")]
        out: PathBuf,
        /// Timed runs per setting; the median is reported.
        #[arg(long, default_value_t = 5)]
        repeats: usize,
        /// Override the frame size (square).
        #[arg(long)]
        size: Option<usize>,
        /// Where to reconstruct: cpu, gpu (needs the gpu feature and an adapter) or auto; the
        /// default is the experiment's [compute] device. Settings without a GPU kernel (the
        /// plug-and-play prior) stay on the CPU; the table and plot say where each ran.
        #[arg(long, value_parser = ["cpu", "gpu", "auto"])]
        device: Option<String>,
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
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
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
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
        experiment: String,
        #[arg(long, default_value = "out/patterns")]
        out: PathBuf,
        /// Override the frame size (square); a `[rig.dmd]` keeps its own mirror count.
        #[arg(long)]
        size: Option<usize>,
        /// Dithering study instead: every dither × illumination at these pinhole radii (µm,
        /// comma-separated), the experiment's other optics kept (study.md, study.json).
        #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
        study: Option<Vec<f64>>,
    },
    /// Timing report: the weight matrix w_ik of one exposure, the operator's warnings and a
    /// timeline PNG (wheel segment, pattern shown, exposure window).
    Timing {
        /// A built-in scene (dead-leaves, shaded-objects, bars) or an experiment file.
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
        /// Also write the raw frames and an EMVA 1288 descriptor (emva1288/) for the reference
        /// analysis (tools/emva/referee.py).
        #[arg(long)]
        emva: bool,
        #[arg(long, default_value = "out/ptc")]
        out: PathBuf,
    },
    /// Design tools: the wheel's filter set and the carrier layout, scored by simulation.
    Design {
        #[command(subcommand)]
        what: specmux_design::DesignCommand,
    },
    /// Reconstruct a cube from a frame (one-channel EXR, or 16-bit PNG of raw DN) with the rig
    /// of the experiment that recorded it, or every frame of a recording folder
    /// (`acquire`/`rehearse`) with the calibration acquired in it.
    Reconstruct {
        /// The frame (one-channel EXR, or 16-bit PNG or TIFF), or a recording's folder.
        frame: PathBuf,
        /// The experiment file (or built-in scene name) whose rig recorded the frame: required.
        #[arg(long)]
        experiment: Option<String>,
        /// A folder of measured calibration frames: dark.exr, flat.exr, pattern-1.exr … (as
        /// `simulate` writes them); without it the twin simulates the rig's calibration.
        #[arg(long)]
        calibration: Option<PathBuf>,
        /// A truth cube (EXR) to report the error against.
        #[arg(long)]
        truth: Option<PathBuf>,
        #[arg(long, default_value = "out/reconstruct")]
        out: PathBuf,
        /// Also write the cube as NumPy .npy.
        #[arg(long)]
        npy: bool,
    },
    /// Calibrate and acquire on the simulated rig (virtual clock), reconstruct every frame with
    /// the acquired calibration and print its error against the truth (docs/controller.md).
    Rehearse(controller::RunArgs),
    /// The same plan on the simulated (`--backend sim`) or real rig; OME-TIFF files.
    Acquire {
        #[command(flatten)]
        run: controller::RunArgs,
        /// The devices: `sim` (the twin's, on a virtual clock) or `real` (--camera, --wheel-port,
        /// --alp-lib).
        #[arg(long, default_value = "sim", value_parser = ["sim", "real"])]
        backend: String,
        #[command(flatten)]
        real: specmux_controller::real::RealRigArgs,
    },
}

/// `--device` (clap has checked it is one of cpu, gpu, auto).
pub fn device_of(name: String) -> ComputeDevice {
    match name.as_str() {
        "gpu" => ComputeDevice::Gpu,
        "auto" => ComputeDevice::Auto,
        _ => ComputeDevice::Cpu,
    }
}
