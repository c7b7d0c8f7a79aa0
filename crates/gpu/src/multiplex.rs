//! The forward model's multiplex on the GPU (shaders/multiplex.wgsl): y = Σ_k z_k ⊙ s̃_k per
//! pixel, the twin's `multiplex::multiplex` in the same order of summation. Buffers are made
//! once per size; a frame is one upload of z and s̃ (or of z alone, the patterns kept), one
//! kernel and one read-back of y.

use crate::context::{linear_groups, GpuContext, Launch};
use crate::error::{GpuError, Result};
use specmux_core::Cube;

/// The `Params` struct of shaders/multiplex.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    npx: u32,
    planes: u32,
    _pad: [u32; 2],
}

/// The multiplex of `planes` planes of w × h on the GPU, its buffers made once.
pub struct GpuMultiplex {
    w: usize,
    h: usize,
    planes: usize,
    z: wgpu::Buffer,
    s: wgpu::Buffer,
    y: wgpu::Buffer,
    staging: wgpu::Buffer,
    launch: Launch,
}

impl GpuMultiplex {
    /// The kernel for `planes` images of w × h.
    pub fn new(ctx: &GpuContext, (w, h, planes): (usize, usize, usize)) -> Result<GpuMultiplex> {
        if w * h == 0 || planes == 0 {
            return Err(GpuError::Shape(format!(
                "multiplex: patterns of {w}×{h}×{planes}"
            )));
        }
        let npx = w * h;
        let bytes = (npx * planes * 4) as u64;
        let (z, patterns, y) = (
            ctx.storage("multiplex z", bytes),
            ctx.storage("multiplex patterns", bytes),
            ctx.storage("multiplex y", (npx * 4) as u64),
        );
        let uniform = ctx.uniform(
            "multiplex params",
            &Params {
                npx: npx as u32,
                planes: planes as u32,
                _pad: [0; 2],
            },
        );
        let module = ctx.module("multiplex", include_str!("shaders/multiplex.wgsl"));
        let launch = Launch::new(
            ctx,
            &module,
            "multiplex",
            &[&z, &patterns, &y, &uniform],
            linear_groups(npx, 256),
        );
        Ok(GpuMultiplex {
            w,
            h,
            planes,
            staging: ctx.readback("multiplex staging", y.size()),
            z,
            s: patterns,
            y,
            launch,
        })
    }

    /// Upload the patterns s̃ (this kernel's shape); they stay until replaced.
    pub fn upload_patterns(&self, ctx: &GpuContext, s: &Cube) -> Result<()> {
        self.check(s, "patterns")?;
        ctx.queue
            .write_buffer(&self.s, 0, bytemuck::cast_slice(&s.data));
        Ok(())
    }

    /// One-line shape error unless `c` has this kernel's planes of w × h.
    fn check(&self, c: &Cube, what: &str) -> Result<()> {
        if (c.width, c.height, c.planes) != (self.w, self.h, self.planes) {
            return Err(GpuError::Shape(format!(
                "multiplex: {what} {}×{}×{} for {}×{}×{}",
                c.width, c.height, c.planes, self.w, self.h, self.planes
            )));
        }
        Ok(())
    }

    /// The images z the kernel reads (a producer on the GPU may write them here).
    pub fn input(&self) -> &wgpu::Buffer {
        &self.z
    }

    /// The frame y on the GPU.
    pub fn output(&self) -> &wgpu::Buffer {
        &self.y
    }

    /// Record the multiplex of the current z.
    pub fn record(&self, cp: &mut wgpu::ComputePass) {
        self.launch.record(cp);
    }

    /// y of `z` against the uploaded patterns: one upload, one kernel, one read-back.
    pub fn run_with_patterns(&self, ctx: &GpuContext, z: &Cube) -> Result<Cube> {
        self.check(z, "images")?;
        ctx.queue
            .write_buffer(&self.z, 0, bytemuck::cast_slice(&z.data));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.record(&mut enc.begin_compute_pass(&Default::default()));
        enc.copy_buffer_to_buffer(&self.y, 0, &self.staging, 0, self.y.size());
        ctx.queue.submit([enc.finish()]);
        let mut y = Cube::zeros(self.w, self.h, 1);
        ctx.read_into(&self.staging, &mut y.data)?;
        Ok(y)
    }

    /// y of `z` against `s`: both uploaded, one kernel, one read-back.
    pub fn run(&self, ctx: &GpuContext, z: &Cube, s: &Cube) -> Result<Cube> {
        self.upload_patterns(ctx, s)?;
        self.run_with_patterns(ctx, z)
    }

    /// (w, h, planes) of the images this kernel takes.
    pub fn shape(&self) -> (usize, usize, usize) {
        (self.w, self.h, self.planes)
    }
}
