//! The reconstruction of one rig on the GPU — the frame's dark/flat correction (on the host,
//! when the rig has one), demultiplexing, GAP or GAP-TV de-aliasing, the crosstalk mix, the
//! exact non-negative unmixing — in one submission per frame, built from the core's
//! `Reconstructor` so both give the same cube. The joint method is not on the GPU.

use crate::context::GpuContext;
use crate::demux::GpuDemux;
use crate::error::{GpuError, Result};
use crate::gap::GpuGap;
use crate::mix::GpuMix;
use crate::unmix::GpuUnmixer;
use specmux_core::calibration::DarkFlat;
use specmux_core::gap::GapStats;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::unmix::UnmixStats;
use specmux_core::Cube;

/// What one frame's run reports: the unmixing's counters and, with GAP, its residuals.
#[derive(Clone, Debug, Default)]
pub struct GpuRun {
    pub unmix: UnmixStats,
    /// Default (no iterations) for the `fourier` method.
    pub gap: GapStats,
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
    dark_flat: Option<DarkFlat>,
    /// The channels the unmixing reads, copied for `demultiplex` and `dealias`.
    channels_staging: wgpu::Buffer,
}

impl GpuReconstructor {
    /// Mirror `recon`'s demultiplexer, GAP, crosstalk inverse and unmixer.
    pub fn new(ctx: &GpuContext, recon: &Reconstructor) -> Result<GpuReconstructor> {
        if recon.joint.is_some() {
            return Err(GpuError::Unsupported(
                "the joint method's iterations (method = \"joint\")".into(),
            ));
        }
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
        Ok(GpuReconstructor {
            channels_staging: ctx.readback("channels staging", channels.size()),
            demux,
            gap,
            mix,
            unmix,
            dark_flat: recon.calibration.dark_flat.clone(),
        })
    }

    /// Linearise (host) and upload a raw frame.
    fn upload(&self, ctx: &GpuContext, frame: &Cube) -> Result<()> {
        match &self.dark_flat {
            Some(df) => self.demux.upload(ctx, &df.apply(frame)?),
            None => self.demux.upload(ctx, frame),
        }
    }

    /// The buffer of channel planes the unmixing reads.
    fn channels(&self) -> &wgpu::Buffer {
        self.mix
            .as_ref()
            .map_or(self.demux.output(), GpuMix::output)
    }

    /// Record demultiplexing, GAP (when `dealias`) and the mix into `enc`.
    fn encode_channels(&self, enc: &mut wgpu::CommandEncoder, dealias: bool) {
        self.demux.encode(enc);
        if let Some(g) = self.gap.as_ref().filter(|_| dealias) {
            g.encode(enc);
        }
        if let Some(m) = &self.mix {
            m.record(&mut enc.begin_compute_pass(&Default::default()));
        }
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
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.encode_channels(&mut enc, dealias);
        let bytes = self.channels().size();
        enc.copy_buffer_to_buffer(self.channels(), 0, &self.channels_staging, 0, bytes);
        ctx.queue.submit([enc.finish()]);
        let mut out = Cube::zeros(self.demux.w, self.demux.h, self.unmix.channels);
        ctx.read_into(&self.channels_staging, &mut out.data)?;
        Ok(out)
    }

    /// x̂ of a raw frame: the GPU twin of `Reconstructor::demultiplex`.
    pub fn demultiplex(&self, ctx: &GpuContext, frame: &Cube) -> Result<Cube> {
        self.channels_of(ctx, frame, false)
    }

    /// The channels after GAP and the crosstalk mix (the `xgap` of `Reconstructor::run`),
    /// and GAP's statistics.
    pub fn dealias(&self, ctx: &GpuContext, frame: &Cube) -> Result<(Cube, GapStats)> {
        let x = self.channels_of(ctx, frame, true)?;
        Ok((x, self.gap_stats(ctx)?))
    }

    /// The cube of a raw frame, read back into `cube` (bands × w × h, kept by the caller from
    /// frame to frame): the GPU twin of `Reconstructor::run`'s cube.
    pub fn run_into(&self, ctx: &GpuContext, frame: &Cube, cube: &mut Cube) -> Result<GpuRun> {
        self.upload(ctx, frame)?;
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.encode_channels(&mut enc, true);
        self.unmix.encode(&mut enc);
        self.unmix.encode_readback(&mut enc);
        ctx.queue.submit([enc.finish()]);
        let run = GpuRun {
            gap: self.gap_stats(ctx)?,
            unmix: self.unmix.stats(ctx)?,
        };
        self.unmix.read_cube(ctx, cube)?;
        Ok(run)
    }

    /// The same chain with the cube left on the GPU (`self.unmix.output()`), for a consumer
    /// that stays there (display, GPU metrics); returns once the GPU is done.
    pub fn run_resident(&self, ctx: &GpuContext, frame: &Cube) -> Result<GpuRun> {
        self.upload(ctx, frame)?;
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.encode_channels(&mut enc, true);
        self.unmix.encode(&mut enc);
        ctx.queue.submit([enc.finish()]);
        Ok(GpuRun {
            gap: self.gap_stats(ctx)?,
            unmix: self.unmix.stats(ctx)?,
        })
    }

    /// An empty output cube of the right size for `run_into`.
    pub fn output_cube(&self) -> Cube {
        Cube::zeros(self.demux.w, self.demux.h, self.unmix.bands)
    }
}
