//! The reconstruction of one rig on the GPU — the frame's dark/flat correction (on the host,
//! when the rig has one), demultiplexing, GAP or GAP-TV de-aliasing, the crosstalk mix, the
//! exact non-negative unmixing, or for the joint method its seed and iterations — in one
//! submission per frame, built from the core's `Reconstructor` so both give the same cube.

use crate::context::GpuContext;
use crate::demux::GpuDemux;
use crate::error::{GpuError, Result};
use crate::gap::GpuGap;
use crate::joint::GpuJoint;
use crate::mix::GpuMix;
use crate::unmix::GpuUnmixer;
use specmux_core::calibration::DarkFlat;
use specmux_core::gap::GapStats;
use specmux_core::joint::{Joint, JointStats, Prior};
use specmux_core::noise::NoiseModel;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::unmix::UnmixStats;
use specmux_core::Cube;

/// What one frame's run reports: the unmixing's counters and, with GAP, its residuals; with
/// the joint method its objective (and default unmixing counters, as on the CPU).
#[derive(Clone, Debug, Default)]
pub struct GpuRun {
    pub unmix: UnmixStats,
    /// Default (no iterations) for the `fourier` and joint methods.
    pub gap: GapStats,
    pub joint: Option<JointStats>,
}

/// Demultiplexer, de-aliaser, mix and unmixer of one rig on the GPU, chained through buffers
/// that stay there.
pub struct GpuReconstructor {
    pub demux: GpuDemux,
    /// GAP on the demultiplexed planes z (None for `fourier`).
    pub gap: Option<GpuGap>,
    /// x = M z after GAP (without GAP the demodulation kernel mixes; None without crosstalk).
    mix: Option<GpuMix>,
    pub unmix: GpuUnmixer,
    /// The joint method: the seed α₀ = H⁻¹Fᵀx̂ (a mix of the channels into α's planes) and the
    /// iterations, which write the cube into the unmixer's output (None for the other methods).
    joint: Option<(GpuMix, GpuJoint)>,
    /// The camera's noise model the joint method weighs each frame's data term by (None: ω = 1),
    /// and the experiment file its errors name.
    noise: Option<(NoiseModel, String)>,
    dark_flat: Option<DarkFlat>,
    /// The channels the unmixing reads, copied for `demultiplex` and `dealias`.
    channels_staging: wgpu::Buffer,
}

impl GpuReconstructor {
    /// Mirror `recon`'s demultiplexer, GAP or joint solver, crosstalk inverse and unmixer.
    pub fn new(ctx: &GpuContext, recon: &Reconstructor) -> Result<GpuReconstructor> {
        let (w, h) = recon.demux.size();
        let npx = w * h;
        let demix = recon.demix.as_deref();
        let (demux, gap, mix) = match &recon.gap {
            None => (GpuDemux::new(ctx, &recon.demux, demix)?, None, None),
            Some(g) => {
                let demux = GpuDemux::new(ctx, &recon.demux, None)?;
                let gap = GpuGap::new(ctx, g, demux.frame(), demux.output())?;
                let mix = demix
                    .map(|m| GpuMix::new(ctx, m, demux.output(), npx))
                    .transpose()?;
                (demux, Some(gap), mix)
            }
        };
        let channels = mix.as_ref().map_or(demux.output(), GpuMix::output);
        let unmix = GpuUnmixer::new(ctx, &recon.unmixer, npx, channels)?;
        let joint = match &recon.joint {
            None => None,
            Some(j) => {
                gpu_joint_supported(j)?;
                let t = recon.unmixer.tables();
                let gj = GpuJoint::new(ctx, j, demux.frame(), unmix.output(), t.gains)?;
                let c = recon.unmixer.channels();
                let rows: Vec<Vec<f64>> = t
                    .unconstrained
                    .chunks_exact(c)
                    .map(<[f64]>::to_vec)
                    .collect();
                let seed = GpuMix::into(ctx, &rows, demux.output(), npx, gj.alpha_buffer())?;
                Some((seed, gj))
            }
        };
        Ok(GpuReconstructor {
            channels_staging: ctx.readback("channels staging", channels.size()),
            demux,
            gap,
            mix,
            unmix,
            joint,
            noise: (recon.joint.as_ref())
                .zip(recon.joint_noise())
                .map(|(j, nm)| (*nm, j.file().to_string())),
            dark_flat: recon.calibration.dark_flat.clone(),
        })
    }

    /// Linearise (host) and upload a raw frame, with the joint method's noise weights of it.
    fn upload(&self, ctx: &GpuContext, frame: &Cube) -> Result<()> {
        let linear = match &self.dark_flat {
            Some(df) => std::borrow::Cow::Owned(df.apply(frame)?),
            None => std::borrow::Cow::Borrowed(frame),
        };
        if let (Some((nm, file)), Some((_, j))) = (&self.noise, &self.joint) {
            let weights = nm
                .weights(frame, &linear, self.dark_flat.as_ref())
                .map_err(|e| e.within(file, "reconstruct.joint.noise_weights", true))?;
            j.set_weights(ctx, &weights)?;
        }
        self.demux.upload(ctx, &linear)
    }

    /// The buffer of channel planes the unmixing reads (the joint method's Fα after `dealias`).
    fn channels(&self, dealias: bool) -> &wgpu::Buffer {
        match (&self.joint, &self.mix) {
            (Some((_, j)), _) if dealias => j.channels(),
            (_, Some(m)) => m.output(),
            _ => self.demux.output(),
        }
    }

    /// An encoder holding demultiplexing, GAP (when `dealias`) and the mix, or the joint
    /// method's seed and whole run (cube and channels Fα included). A joint run whose λ is
    /// searched submits its start and the search's trials on the way (the search needs their
    /// residuals on the host); the encoder returned holds the run after it.
    fn channels_encoder(&self, ctx: &GpuContext, dealias: bool) -> Result<wgpu::CommandEncoder> {
        let new = || ctx.device.create_command_encoder(&Default::default());
        let mut enc = new();
        self.demux.encode(&mut enc);
        if let Some(g) = self.gap.as_ref().filter(|_| dealias) {
            g.encode(&mut enc);
        }
        if let Some(m) = &self.mix {
            m.record(&mut enc.begin_compute_pass(&Default::default()));
        }
        if let Some((seed, j)) = self.joint.as_ref().filter(|_| dealias) {
            seed.record(&mut enc.begin_compute_pass(&Default::default()));
            if !j.searches() {
                j.encode(&mut enc);
                return Ok(enc);
            }
            j.encode_search_start(&mut enc);
            ctx.queue.submit([enc.finish()]);
            j.search(ctx)?;
            enc = new();
            j.encode_after_search(&mut enc);
        }
        Ok(enc)
    }

    /// The GAP run's statistics after a submission that held it.
    fn gap_stats(&self, ctx: &GpuContext) -> Result<GapStats> {
        self.gap
            .as_ref()
            .map_or(Ok(GapStats::default()), |g| g.stats(ctx))
    }

    /// The channels of a raw frame, with or without de-aliasing, read back.
    fn channels_of(&self, ctx: &GpuContext, frame: &Cube, dealias: bool) -> Result<Cube> {
        self.upload(ctx, frame)?;
        let mut enc = self.channels_encoder(ctx, dealias)?;
        let src = self.channels(dealias);
        let bytes = self.channels_staging.size();
        enc.copy_buffer_to_buffer(src, 0, &self.channels_staging, 0, bytes);
        ctx.queue.submit([enc.finish()]);
        let mut out = Cube::zeros(self.demux.w, self.demux.h, self.unmix.channels);
        ctx.read_into(&self.channels_staging, &mut out.data)?;
        Ok(out)
    }

    /// x̂ of a raw frame: the GPU twin of `Reconstructor::demultiplex`.
    pub fn demultiplex(&self, ctx: &GpuContext, frame: &Cube) -> Result<Cube> {
        self.channels_of(ctx, frame, false)
    }

    /// The channels after GAP and the crosstalk mix, or the joint method's Fα (the `xgap` of
    /// `Reconstructor::run`), and GAP's statistics.
    pub fn dealias(&self, ctx: &GpuContext, frame: &Cube) -> Result<(Cube, GapStats)> {
        let x = self.channels_of(ctx, frame, true)?;
        if let Some((_, j)) = &self.joint {
            j.stats(ctx)?;
        }
        Ok((x, self.gap_stats(ctx)?))
    }

    /// Record the unmixing unless the joint method made the cube already.
    fn encode_unmix(&self, enc: &mut wgpu::CommandEncoder) {
        if self.joint.is_none() {
            self.unmix.encode(enc);
        }
    }

    /// The statistics of a submission that held a whole run.
    fn run_stats(&self, ctx: &GpuContext) -> Result<GpuRun> {
        Ok(match &self.joint {
            Some((_, j)) => GpuRun {
                joint: Some(j.stats(ctx)?),
                ..Default::default()
            },
            None => GpuRun {
                gap: self.gap_stats(ctx)?,
                unmix: self.unmix.stats(ctx)?,
                joint: None,
            },
        })
    }

    /// The cube of a raw frame, read back into `cube` (bands × w × h, kept by the caller from
    /// frame to frame): the GPU twin of `Reconstructor::run`'s cube.
    pub fn run_into(&self, ctx: &GpuContext, frame: &Cube, cube: &mut Cube) -> Result<GpuRun> {
        self.upload(ctx, frame)?;
        let mut enc = self.channels_encoder(ctx, true)?;
        self.encode_unmix(&mut enc);
        self.unmix.encode_readback(&mut enc);
        ctx.queue.submit([enc.finish()]);
        let run = self.run_stats(ctx)?;
        self.unmix.read_cube(ctx, cube)?;
        Ok(run)
    }

    /// The same chain with the cube left on the GPU (`self.unmix.output()`), for a consumer
    /// that stays there (display, GPU metrics); returns once the GPU is done.
    pub fn run_resident(&self, ctx: &GpuContext, frame: &Cube) -> Result<GpuRun> {
        self.upload(ctx, frame)?;
        let mut enc = self.channels_encoder(ctx, true)?;
        self.encode_unmix(&mut enc);
        ctx.queue.submit([enc.finish()]);
        self.run_stats(ctx)
    }

    /// An empty output cube of the right size for `run_into`.
    pub fn output_cube(&self) -> Cube {
        Cube::zeros(self.demux.w, self.demux.h, self.unmix.bands)
    }
}

/// The GPU runs the joint method's TV prior (plain or reweighted; λ fixed or by the
/// discrepancy principle; with or without noise weights); the plug-and-play prior is CPU-only
/// and refused here with the key to change.
fn gpu_joint_supported(j: &Joint) -> Result<()> {
    match j.tables().config.prior {
        Prior::Tv => Ok(()),
        Prior::Pnp => Err(GpuError::Unsupported(
            "reconstruct.joint.prior = \"pnp\" runs on the CPU only (the GPU runs the TV prior)"
                .into(),
        )),
    }
}
