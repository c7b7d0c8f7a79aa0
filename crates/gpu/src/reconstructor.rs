//! The real-time path of one rig on the GPU — the frame's dark/flat correction (on the host,
//! when the rig has one), demultiplexing, the crosstalk mix, the exact non-negative unmixing —
//! in one submission per frame, built from the core's `Reconstructor` so both give the same
//! cube. GAP de-aliasing is not on the GPU yet: this is the `fourier` method's chain.

use crate::context::GpuContext;
use crate::demux::GpuDemux;
use crate::error::Result;
use crate::unmix::GpuUnmixer;
use specmux_core::calibration::DarkFlat;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::unmix::UnmixStats;
use specmux_core::Cube;

/// Demultiplexer and unmixer of one rig on the GPU, sharing the x̂ buffer.
pub struct GpuReconstructor {
    pub demux: GpuDemux,
    pub unmix: GpuUnmixer,
    dark_flat: Option<DarkFlat>,
}

impl GpuReconstructor {
    /// Mirror `recon`'s demultiplexer, crosstalk inverse and unmixer.
    pub fn new(ctx: &GpuContext, recon: &Reconstructor) -> Result<GpuReconstructor> {
        let demux = GpuDemux::new(ctx, &recon.demux, recon.demix.as_deref())?;
        let unmix = GpuUnmixer::new(ctx, &recon.unmixer, demux.w * demux.h, demux.output())?;
        Ok(GpuReconstructor {
            demux,
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

    /// x̂ of a raw frame: the GPU twin of `Reconstructor::demultiplex`.
    pub fn demultiplex(&self, ctx: &GpuContext, frame: &Cube) -> Result<Cube> {
        match &self.dark_flat {
            Some(df) => self.demux.run(ctx, &df.apply(frame)?),
            None => self.demux.run(ctx, frame),
        }
    }

    /// The cube of a raw frame, read back into `cube` (bands × w × h, kept by the caller from
    /// frame to frame): the GPU twin of `unmix_into(demultiplex(frame))`.
    pub fn run_into(&self, ctx: &GpuContext, frame: &Cube, cube: &mut Cube) -> Result<UnmixStats> {
        self.upload(ctx, frame)?;
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.demux.encode(&mut enc);
        self.unmix.encode(&mut enc);
        self.unmix.encode_readback(&mut enc);
        ctx.queue.submit([enc.finish()]);
        let stats = self.unmix.stats(ctx)?;
        self.unmix.read_cube(ctx, cube)?;
        Ok(stats)
    }

    /// The same chain with the cube left on the GPU (`self.unmix.output()`), for a consumer
    /// that stays there (display, GPU metrics); returns once the GPU is done.
    pub fn run_resident(&self, ctx: &GpuContext, frame: &Cube) -> Result<UnmixStats> {
        self.upload(ctx, frame)?;
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.demux.encode(&mut enc);
        self.unmix.encode(&mut enc);
        ctx.queue.submit([enc.finish()]);
        self.unmix.stats(ctx)
    }

    /// An empty output cube of the right size for `run_into`.
    pub fn output_cube(&self) -> Cube {
        Cube::zeros(self.demux.w, self.demux.h, self.unmix.bands)
    }
}
