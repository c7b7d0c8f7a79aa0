//! The orthogonal 2-D periodic wavelet transform of J planes on the GPU (shaders/wavelet.wgsl),
//! built from the core's `Dwt2` (its size, levels and f32 filters) so both give the same
//! coefficients in the same Mallat layout: per level, a rows split and a columns split of the
//! top-left block, out of place between the data and one scratch buffer of the same size.

use crate::context::{groups, GpuContext, Launch};
use crate::error::{GpuError, Result};
use specmux_core::wavelet::Dwt2;

/// Filter taps the shader holds (Haar has 2, Daubechies-4 has 4).
const MAX_TAPS: usize = 4;

/// The `Level` struct of shaders/wavelet.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Level {
    w: u32,
    bw: u32,
    bh: u32,
    npx: u32,
    taps: u32,
    _pad: [u32; 3],
}

/// The transform of `planes` planes held in one buffer, planned for both directions.
pub struct GpuDwt2 {
    /// Per level, finest first: the rows and the columns split.
    forward: Vec<[Launch; 2]>,
    /// Per level, coarsest first: the columns and the rows synthesis.
    inverse: Vec<[Launch; 2]>,
}

impl GpuDwt2 {
    /// Plan `dwt` on the `planes` planes of `data` (planes × w × h f32), transformed in place.
    pub fn new(ctx: &GpuContext, dwt: &Dwt2, planes: usize, data: &wgpu::Buffer) -> Result<Self> {
        let (lo, hi) = dwt.filters();
        let taps = lo.len();
        if taps > MAX_TAPS {
            return Err(GpuError::Unsupported(format!(
                "a wavelet of {taps} taps (at most {MAX_TAPS})"
            )));
        }
        let mut f = [0.0f32; 2 * MAX_TAPS];
        f[..taps].copy_from_slice(lo);
        f[MAX_TAPS..MAX_TAPS + taps].copy_from_slice(hi);
        let filters = ctx.storage_init("wavelet filters", &f);
        let (w, h, npx) = (dwt.w, dwt.h, dwt.w * dwt.h);
        let scratch = ctx.storage("wavelet scratch", (planes * npx * 4) as u64);
        let module = ctx.module("wavelet", include_str!("shaders/wavelet.wgsl"));
        let level = |lev: usize| {
            let (bw, bh) = (w >> lev, h >> lev);
            let uniform = ctx.uniform(
                "wavelet level",
                &Level {
                    w: w as u32,
                    bw: bw as u32,
                    bh: bh as u32,
                    npx: npx as u32,
                    taps: taps as u32,
                    _pad: [0; 3],
                },
            );
            let launch = |entry: &str, src: &wgpu::Buffer, dst: &wgpu::Buffer, nx: usize, ny| {
                let groups = [groups(nx, 16), groups(ny, 16), planes as u32];
                Launch::new(ctx, &module, entry, &[src, dst, &filters, &uniform], groups)
            };
            (
                [
                    launch("rows_forward", data, &scratch, bw / 2, bh),
                    launch("cols_forward", &scratch, data, bw, bh / 2),
                ],
                [
                    launch("cols_inverse", data, &scratch, bw, bh),
                    launch("rows_inverse", &scratch, data, bw, bh),
                ],
            )
        };
        let (forward, mut inverse): (Vec<_>, Vec<_>) = (0..dwt.levels).map(level).unzip();
        inverse.reverse();
        Ok(GpuDwt2 { forward, inverse })
    }

    /// Record the analysis W = Tᵀ X of every plane.
    pub fn record_forward(&self, cp: &mut wgpu::ComputePass) {
        self.forward.iter().flatten().for_each(|l| l.record(cp));
    }

    /// Record the synthesis X = T W of every plane.
    pub fn record_inverse(&self, cp: &mut wgpu::ComputePass) {
        self.inverse.iter().flatten().for_each(|l| l.record(cp));
    }
}
