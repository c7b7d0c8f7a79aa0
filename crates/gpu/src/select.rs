//! Exact selection on the GPU (shaders/select.wgsl): the value at a given rank, in ascending
//! order, among the non-negative values whose weight is non-zero — GAP's shrinkage threshold
//! λ, the score of the (m*+1)-th largest wavelet group — by a 4-pass radix select on the
//! values' bits, without a round trip to the host. It is the value a sort would put there, bit
//! for bit (the CPU's `select_nth_unstable` gives the same).

use crate::context::{groups, GpuContext, Launch};

/// The `Pass` struct of shaders/select.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PassParams {
    shift: u32,
    mask: u32,
    first: u32,
    rank: u32,
    n: u32,
    _pad: [u32; 3],
}

/// Passes of 8 bits over the 32 bits of an f32.
const PASSES: u32 = 4;
/// The most workgroups a histogram pass uses (each then strides over the values).
const MAX_GROUPS: u32 = 512;

/// The selection of one rank among `n` values, planned once.
pub struct GpuSelect {
    /// Per pass: histogram, scan.
    passes: Vec<[Launch; 2]>,
    state: wgpu::Buffer,
}

impl GpuSelect {
    /// Select the value of rank `rank` (0 = the smallest) among the `values[i] ≥ 0` with
    /// `weights[i] ≠ 0`, i < n. The caller guarantees rank < the count of such values.
    pub fn new(
        ctx: &GpuContext,
        values: &wgpu::Buffer,
        weights: &wgpu::Buffer,
        n: usize,
        rank: usize,
    ) -> GpuSelect {
        let hist = ctx.storage("select histogram", 256 * 4);
        let state = ctx.storage("select state", 8);
        let module = ctx.module("select", include_str!("shaders/select.wgsl"));
        let hist_groups = groups(n, 256).clamp(1, MAX_GROUPS);
        let passes = (0..PASSES)
            .map(|p| {
                let shift = 24 - 8 * p;
                let uniform = ctx.uniform(
                    "select pass",
                    &PassParams {
                        shift,
                        // The bits above this pass's digit (none in the first pass).
                        mask: if p == 0 { 0 } else { !0u32 << (shift + 8) },
                        first: (p == 0) as u32,
                        rank: rank as u32,
                        n: n as u32,
                        _pad: [0; 3],
                    },
                );
                [
                    Launch::new(
                        ctx,
                        &module,
                        "histogram",
                        &[values, weights, &hist, &state, &uniform],
                        [hist_groups, 1, 1],
                    ),
                    Launch::new(ctx, &module, "scan", &[&hist, &state, &uniform], [1, 1, 1]),
                ]
            })
            .collect();
        GpuSelect { passes, state }
    }

    /// Record the selection; afterwards word 0 of `result()` holds the value's bits.
    pub fn record(&self, cp: &mut wgpu::ComputePass) {
        self.passes.iter().flatten().for_each(|l| l.record(cp));
    }

    /// The buffer whose first word is the selected value's bits.
    pub fn result(&self) -> &wgpu::Buffer {
        &self.state
    }
}
