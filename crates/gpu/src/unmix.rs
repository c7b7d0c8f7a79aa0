//! The per-pixel non-negative unmixing on the GPU (shaders/unmix.wgsl), built from the core's
//! factored `Unmixer`: the fast path r = P x̂ for every pixel and, for the pixels it queues
//! (a band went negative), the exact dual active-set solve in f32. Counters of constrained pixels and iterations come
//! back as the core's `UnmixStats`; a pixel that fails is an error, as on the CPU.

use crate::context::{groups, GpuContext};
use crate::error::{GpuError, Result};
use specmux_core::unmix::{UnmixStats, Unmixer, MAX_BANDS, MAX_BASIS, MAX_CHANNELS};
use specmux_core::Cube;

// shaders/unmix.wgsl declares these maxima (replaced by the rig's sizes, which
// `Unmixer::new` keeps within them), reads L⁻ᵀ with the core's stride of 8 and keeps the
// working set in a 64-bit mask.
const _: () = assert!(MAX_BASIS == 8 && MAX_BANDS == 64 && MAX_CHANNELS == 16);

/// Threads per workgroup of the unmixing kernel.
const WORKGROUP: u32 = 64;
/// A band counts as violated below −TOL·scale (the CPU's 1e-12 is below f32 resolution; this is
/// ~8 ulps of the pixel's largest band).
pub const TOL: f32 = 1e-6;
/// ‖d₂‖² ≤ DEPENDENT·‖d‖²: the new band depends on the active ones (CPU 1e-13; f32 rounding of
/// d alone gives ~1e-13, so the f32 threshold is 1000× that).
pub const DEPENDENT: f32 = 1e-10;

/// The `Params` struct of shaders/unmix.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    npx: u32,
    off_unc: u32,
    off_basis: u32,
    off_binv: u32,
    off_gain: u32,
    off_linv: u32,
    tol: f32,
    dependent: f32,
}

/// The unmixer of one rig and frame size, bound to its input planes on the GPU.
pub struct GpuUnmixer {
    pub bands: usize,
    pub channels: usize,
    npx: usize,
    /// `project` and `solve_queued` with their bind groups.
    kernels: [(wgpu::ComputePipeline, wgpu::BindGroup); 2],
    cube: wgpu::Buffer,
    stats: wgpu::Buffer,
    stats_staging: wgpu::Buffer,
    cube_staging: wgpu::Buffer,
}

impl GpuUnmixer {
    /// Mirror `unmixer` for frames of `npx` pixels whose channel planes live in `xhat`
    /// (channels × npx f32, e.g. `GpuDemux::output`).
    pub fn new(
        ctx: &GpuContext,
        unmixer: &Unmixer,
        npx: usize,
        xhat: &wgpu::Buffer,
    ) -> Result<GpuUnmixer> {
        let (m, c) = (unmixer.bands(), unmixer.channels());
        let (tables, params) = pack(unmixer, npx);
        let tables = ctx.storage_init("unmix tables", &tables);
        let uniform = ctx.uniform("unmix params", &params);
        let cube = ctx.storage("cube", (m * npx * 4) as u64);
        let stats = ctx.storage("unmix stats", 32);
        let queue = ctx.storage("unmix queue", (npx * 4) as u64);
        let module = ctx.module("unmix", &source(unmixer));
        let kernels = ["project", "solve_queued"].map(|entry| {
            let pipeline = ctx.pipeline(&module, entry);
            let bind = ctx.bind(&pipeline, &[xhat, &cube, &tables, &stats, &uniform, &queue]);
            (pipeline, bind)
        });
        Ok(GpuUnmixer {
            bands: m,
            channels: c,
            npx,
            kernels,
            cube_staging: ctx.readback("cube staging", (m * npx * 4) as u64),
            stats_staging: ctx.readback("unmix stats staging", 32),
            cube,
            stats,
        })
    }

    /// Record the unmixing of the current `xhat` into `enc`, and the copy of its counters.
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder) {
        enc.clear_buffer(&self.stats, 0, None);
        // One pass per kernel: the solver reads the queue and count the projection wrote.
        let g = groups(self.npx, WORKGROUP);
        for (pipeline, bind) in &self.kernels {
            let mut cp = enc.begin_compute_pass(&Default::default());
            cp.set_pipeline(pipeline);
            cp.set_bind_group(0, bind, &[]);
            cp.dispatch_workgroups(g.min(65535), g.div_ceil(65535), 1);
        }
        enc.copy_buffer_to_buffer(&self.stats, 0, &self.stats_staging, 0, 32);
    }

    /// Record the copy of the cube to the host-visible staging buffer.
    pub fn encode_readback(&self, enc: &mut wgpu::CommandEncoder) {
        enc.copy_buffer_to_buffer(
            &self.cube,
            0,
            &self.cube_staging,
            0,
            (self.bands * self.npx * 4) as u64,
        );
    }

    /// The cube's planes (bands × npx f32) on the GPU.
    pub fn output(&self) -> &wgpu::Buffer {
        &self.cube
    }

    /// After the submission that held `encode`: the counters as `UnmixStats`, or the error of
    /// a pixel that did not converge or ended infeasible.
    pub fn stats(&self, ctx: &GpuContext) -> Result<UnmixStats> {
        let mut s = [0u32; 8];
        ctx.read_into(&self.stats_staging, &mut s)?;
        if s[4] > 0 || s[5] > 0 {
            return Err(GpuError::Numerical(format!(
                "unmixing: {} pixels did not converge in 500 active-set steps, {} ended infeasible",
                s[4], s[5]
            )));
        }
        Ok(UnmixStats {
            pixels: self.npx,
            constrained_pixels: s[0] as usize,
            bound_pixels: s[1] as usize,
            total_iterations: s[2] as usize,
            max_iterations: s[3] as usize,
        })
    }

    /// After the submission that held `encode_readback`: the cube into `out` (bands planes).
    pub fn read_cube(&self, ctx: &GpuContext, out: &mut Cube) -> Result<()> {
        if out.planes != self.bands || out.pixels() != self.npx {
            return Err(GpuError::Shape(format!(
                "output cube {}×{}×{} for {} bands of {} pixels",
                out.width, out.height, out.planes, self.bands, self.npx
            )));
        }
        ctx.read_into(&self.cube_staging, &mut out.data)
    }
}

/// shaders/unmix.wgsl with the rig's J, bands and channels written over its maxima.
fn source(unmixer: &Unmixer) -> String {
    let sizes = [
        ("MAXB", MAX_BASIS, unmixer.basis_len()),
        ("MAXM", MAX_BANDS, unmixer.bands()),
        ("MAXC", MAX_CHANNELS, unmixer.channels()),
    ];
    let mut src = include_str!("shaders/unmix.wgsl").to_string();
    for (name, max, value) in sizes {
        let line = format!("const {name}: u32 = {max}u;");
        assert!(src.contains(&line), "shaders/unmix.wgsl declares {line}");
        src = src.replace(&line, &format!("const {name}: u32 = {value}u;"));
    }
    src
}

/// The tables of shaders/unmix.wgsl in one f32 buffer — P, M, B (row-major), 1/‖b_k‖_{H⁻¹},
/// gains, L⁻ᵀ — and the parameters that locate them.
fn pack(unmixer: &Unmixer, npx: usize) -> (Vec<f32>, Params) {
    let t = unmixer.tables();
    let m = unmixer.bands();
    let mut v: Vec<f32> = t.projection.to_vec();
    let off_unc = v.len() as u32;
    v.extend(t.unconstrained.iter().map(|&x| x as f32));
    let off_basis = v.len() as u32;
    v.extend((0..m).flat_map(|k| t.basis_columns.iter().map(move |col| col[k] as f32)));
    let off_binv = v.len() as u32;
    v.extend(t.band_inv_norm.iter().map(|&x| x as f32));
    let off_gain = v.len() as u32;
    v.extend(t.gains.iter().map(|&x| x as f32));
    let off_linv = v.len() as u32;
    v.extend(t.linv_t.iter().flatten().map(|&x| x as f32));
    let params = Params {
        npx: npx as u32,
        off_unc,
        off_basis,
        off_binv,
        off_gain,
        off_linv,
        tol: TOL,
        dependent: DEPENDENT,
    };
    (v, params)
}
