//! x_i = Σ_k M_ik z_k per pixel on the GPU (shaders/mix.wgsl): the exposure crosstalk's
//! inverse applied after de-aliasing, as the core's `Reconstructor::to_channels` does (without
//! GAP the demodulation kernel applies it instead, for free).

use crate::context::{linear_groups, GpuContext, Launch};
use crate::error::{GpuError, Result};

/// The `Params` struct of shaders/mix.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    npx: u32,
    planes_in: u32,
    planes_out: u32,
    _pad: u32,
}

/// The mix of one buffer of planes into another, planned once.
pub struct GpuMix {
    launch: Launch,
    out: wgpu::Buffer,
}

impl GpuMix {
    /// Mix the planes of `z` (m[0].len() planes of `npx` f32) by `m` (rows = output planes)
    /// into a buffer of its own.
    pub fn new(ctx: &GpuContext, m: &[Vec<f64>], z: &wgpu::Buffer, npx: usize) -> Result<GpuMix> {
        let out = ctx.storage("mixed planes", (m.len() * npx * 4) as u64);
        GpuMix::into(ctx, m, z, npx, &out)
    }

    /// The same mix written into the first planes of `out` (another stage's buffer).
    pub fn into(
        ctx: &GpuContext,
        m: &[Vec<f64>],
        z: &wgpu::Buffer,
        npx: usize,
        out: &wgpu::Buffer,
    ) -> Result<GpuMix> {
        let (rows, cols) = (m.len(), m.first().map_or(0, Vec::len));
        if rows == 0 || m.iter().any(|r| r.len() != cols) {
            return Err(GpuError::Shape(format!(
                "a mixing matrix of {rows} rows of unequal or zero length"
            )));
        }
        let bytes = |planes: usize| (planes * npx * 4) as u64;
        if bytes(rows) > out.size() || bytes(cols) > z.size() {
            return Err(GpuError::Shape(format!(
                "a {rows}×{cols} mix of {npx} pixels between buffers of {} and {} bytes",
                z.size(),
                out.size()
            )));
        }
        let flat: Vec<f32> = m.iter().flatten().map(|&v| v as f32).collect();
        let uniform = ctx.uniform(
            "mix params",
            &Params {
                npx: npx as u32,
                planes_in: cols as u32,
                planes_out: rows as u32,
                _pad: 0,
            },
        );
        let module = ctx.module("mix", include_str!("shaders/mix.wgsl"));
        let matrix = ctx.storage_init("mix matrix", &flat);
        let launch = Launch::new(
            ctx,
            &module,
            "mix",
            &[z, out, &matrix, &uniform],
            linear_groups(npx, 256),
        );
        Ok(GpuMix {
            launch,
            out: out.clone(),
        })
    }

    /// Record the mix.
    pub fn record(&self, cp: &mut wgpu::ComputePass) {
        self.launch.record(cp);
    }

    /// The mixed planes.
    pub fn output(&self) -> &wgpu::Buffer {
        &self.out
    }
}
