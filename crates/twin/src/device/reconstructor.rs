//! A rig's reconstruction on the device a run opened, built once and run on frame after frame:
//! the core's `Reconstructor` on the CPU, or specmux-gpu's chain built from it (feature `gpu`)
//! where the device is a GPU with a kernel for it (plug-and-play and frame sides with a prime
//! factor above 5 have none: the CPU's).

use super::OpenDevice;
use specmux_core::gap::GapStats;
use specmux_core::joint::JointStats;
use specmux_core::reconstructor::{Reconstruction, Reconstructor};
use specmux_core::unmix::UnmixStats;
use specmux_core::{Cube, Result};
#[cfg(feature = "gpu")]
use std::time::Instant;

/// The reconstructor and, on a GPU, its chain with the cube buffer it reads back into. Frames
/// may come from several threads: the CPU runs them side by side, the GPU one at a time (its
/// chain's buffers are one frame's).
pub struct DeviceReconstructor {
    recon: Reconstructor,
    #[cfg(feature = "gpu")]
    gpu: Option<std::sync::Mutex<GpuChain>>,
    describe: String,
}

/// The GPU's context, its chain, and the cube buffer it reads back into, kept across frames.
#[cfg(feature = "gpu")]
type GpuChain = (
    specmux_gpu::GpuContext,
    Box<specmux_gpu::GpuReconstructor>,
    Cube,
);

/// One frame's run: the cube; seconds from the frame in host memory to the cube in host memory
/// (uploads and read-backs included), each stage's (NaN on a GPU, which runs them in one
/// submission), the counters, and the de-aliased channels where asked for.
pub struct FrameRun {
    pub cube: Cube,
    pub seconds: f64,
    pub stage_seconds: [f64; 3],
    pub gap: GapStats,
    pub unmix: UnmixStats,
    pub joint: Option<JointStats>,
    pub dealiased: Option<Cube>,
}

impl DeviceReconstructor {
    /// `recon` on `device`: the GPU's chain where the device is one and has a kernel for the
    /// method and the frame (plug-and-play and sides with a prime factor above 5 have none),
    /// else the CPU, and [`DeviceReconstructor::describe`] says why.
    pub fn new(device: &OpenDevice, recon: Reconstructor) -> Result<DeviceReconstructor> {
        #[cfg(feature = "gpu")]
        if let Some(ctx) = device.gpu() {
            use specmux_gpu::{GpuError, GpuReconstructor};
            let (gpu, describe) = match GpuReconstructor::new(ctx, &recon) {
                Ok(g) => {
                    let cube = g.output_cube();
                    let chain = (ctx.clone(), Box::new(g), cube);
                    (Some(std::sync::Mutex::new(chain)), device.describe())
                }
                Err(GpuError::Unsupported(why)) => {
                    let cpu = OpenDevice::cpu().describe();
                    let why = format!("{cpu}: the GPU has no kernel for this: {why}");
                    (None, why)
                }
                Err(e) => return Err(e.into()),
            };
            return Ok(DeviceReconstructor {
                recon,
                gpu,
                describe,
            });
        }
        Ok(DeviceReconstructor {
            recon,
            #[cfg(feature = "gpu")]
            gpu: None,
            describe: device.describe(),
        })
    }

    /// The core's reconstructor (its demultiplexer, unmixer, calibration and `auto` pick).
    pub fn reconstructor(&self) -> &Reconstructor {
        &self.recon
    }

    /// "cpu" or "gpu": where the frames run.
    pub fn device(&self) -> &'static str {
        #[cfg(feature = "gpu")]
        if self.gpu.is_some() {
            return "gpu";
        }
        "cpu"
    }

    /// Where the frames run, in words ("CPU, 2 threads", "GPU NAME (…)", or the CPU and why).
    pub fn describe(&self) -> &str {
        &self.describe
    }

    /// Reconstruct `frame`, timed; with `dealiased`, the channels after de-aliasing too (on a
    /// GPU one more submission, outside the time, as is the copy of the cube it read back).
    pub fn run(&self, frame: &Cube, dealiased: bool) -> Result<FrameRun> {
        #[cfg(feature = "gpu")]
        if let Some(chain) = &self.gpu {
            return gpu_run(&mut lock(chain), frame, dealiased);
        }
        let out = self.recon.run(frame, None)?;
        Ok(FrameRun {
            cube: out.cube,
            seconds: out.seconds.iter().sum(),
            stage_seconds: out.seconds,
            gap: out.gap,
            unmix: out.unmix,
            joint: out.joint,
            dealiased: dealiased.then_some(out.xgap),
        })
    }

    /// Every stage's output of `frame` — x̂, the de-aliased channels, the cube — as the core's
    /// `Reconstructor::run` gives them (`exposed`: the true channels GAP traces its PSNR
    /// against, on the CPU). On a GPU three submissions from the raw frame: x̂, the de-aliased
    /// channels, then the whole chain, whose time is the frame's; each stage's seconds are the
    /// difference between the runs that end after it and before it.
    pub fn stages(&self, frame: &Cube, exposed: Option<&Cube>) -> Result<Reconstruction> {
        #[cfg(feature = "gpu")]
        if let Some(chain) = &self.gpu {
            let mut chain = lock(chain);
            let (ctx, g, _) = &*chain;
            let t = Instant::now();
            let xhat = g.demultiplex(ctx, frame)?;
            let t_demux = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let (xgap, gap) = g.dealias(ctx, frame)?;
            let t_gap = (t.elapsed().as_secs_f64() - t_demux).max(0.0);
            let run = gpu_run(&mut chain, frame, false)?;
            return Ok(Reconstruction {
                xhat,
                xgap,
                cube: run.cube,
                gap,
                joint: run.joint,
                unmix: run.unmix,
                seconds: [t_demux, t_gap, (run.seconds - t_demux - t_gap).max(0.0)],
            });
        }
        self.recon.run(frame, exposed)
    }
}

/// The GPU chain, for one frame at a time (a thread that panicked holding it left no state a
/// later frame reads: every run rewrites the chain's buffers from the frame).
#[cfg(feature = "gpu")]
fn lock(chain: &std::sync::Mutex<GpuChain>) -> std::sync::MutexGuard<'_, GpuChain> {
    chain
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// [`DeviceReconstructor::run`] on the GPU's chain.
#[cfg(feature = "gpu")]
fn gpu_run(chain: &mut GpuChain, frame: &Cube, dealiased: bool) -> Result<FrameRun> {
    let (ctx, g, cube) = chain;
    let t = Instant::now();
    let run = g.run_into(ctx, frame, cube)?;
    let seconds = t.elapsed().as_secs_f64();
    let (dealiased, gap) = match dealiased {
        true => {
            let (x, gap) = g.dealias(ctx, frame)?;
            (Some(x), gap)
        }
        false => (None, run.gap),
    };
    Ok(FrameRun {
        cube: cube.clone(),
        seconds,
        stage_seconds: [f64::NAN; 3],
        gap,
        unmix: run.unmix,
        joint: run.joint,
        dealiased,
    })
}
