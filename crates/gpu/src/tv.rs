//! Vectorial TV denoising on the GPU (shaders/tv.wgsl): Chambolle's dual projection, the
//! core's `TvDenoiser` step for step in f32, on planes that stay on the GPU. The dual field is
//! kept between calls (GAP-TV warm-starts it across iterations) and cleared per frame; λ is
//! read from a GPU buffer, so a λ computed on the GPU needs no round trip.

use crate::context::{groups, GpuContext, Launch};

/// The `Params` struct of shaders/tv.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    w: u32,
    h: u32,
    planes: u32,
    _pad: u32,
}

/// The TV denoiser of `planes` w × h planes held in one buffer.
pub struct GpuTv {
    iterations: usize,
    /// g = div p − f/λ; the dual update; f − λ div p.
    kernels: [Launch; 3],
    px: wgpu::Buffer,
    py: wgpu::Buffer,
}

impl GpuTv {
    /// Denoise the planes of `f` in place with `iterations` dual steps per call. `lambda`:
    /// a buffer whose second f32 is λ (the list shaders/gap.wgsl's `finish` writes).
    pub fn new(
        ctx: &GpuContext,
        f: &wgpu::Buffer,
        lambda: &wgpu::Buffer,
        (w, h, planes): (usize, usize, usize),
        iterations: usize,
    ) -> GpuTv {
        let bytes = (w * h * planes * 4) as u64;
        let (px, py, g) = (
            ctx.storage("tv px", bytes),
            ctx.storage("tv py", bytes),
            ctx.storage("tv g", bytes),
        );
        let params = Params {
            w: w as u32,
            h: h as u32,
            planes: planes as u32,
            _pad: 0,
        };
        let uniform = ctx.uniform("tv params", &params);
        let src = include_str!("shaders/tv.wgsl");
        let line = "const TAU: f32 = 0.25;";
        assert!(src.contains(line), "shaders/tv.wgsl declares {line}");
        let tau = specmux_core::tv::TAU;
        let module = ctx.module(
            "tv",
            &src.replace(line, &format!("const TAU: f32 = {tau:?};")),
        );
        let (gx, gy) = (groups(w, 16), groups(h, 16));
        let launch = |entry, bound: &[(u32, &wgpu::Buffer)], z| {
            let mut all = bound.to_vec();
            all.extend([(1, &px), (2, &py), (4, lambda), (5, &uniform)]);
            Launch::bound(ctx, &module, entry, &all, [gx, gy, z])
        };
        let kernels = [
            launch("tv_g", &[(0, f), (3, &g)], planes as u32),
            launch("tv_dual", &[(3, &g)], 1),
            launch("tv_out", &[(0, f)], planes as u32),
        ];
        GpuTv {
            iterations,
            kernels,
            px,
            py,
        }
    }

    /// Record the zeroing of the dual field (a new frame starts cold, as on the CPU).
    pub fn reset(&self, enc: &mut wgpu::CommandEncoder) {
        enc.clear_buffer(&self.px, 0, None);
        enc.clear_buffer(&self.py, 0, None);
    }

    /// Record one denoising call: the dual steps, then f ← f − λ div p.
    pub fn record(&self, cp: &mut wgpu::ComputePass) {
        for _ in 0..self.iterations {
            self.kernels[0].record(cp);
            self.kernels[1].record(cp);
        }
        self.kernels[2].record(cp);
    }
}
