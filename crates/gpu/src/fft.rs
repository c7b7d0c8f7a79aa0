//! Batched 2-D complex FFT of `planes` row-major `w × h` planes in one GPU buffer: Stockham
//! autosort passes of radix 4, 2, 3 and 5 (shaders/fft.wgsl), rows then columns, ping-ponging
//! with a scratch buffer of the same size. A length with a prime factor above 5 is refused
//! (`GpuError::Unsupported`): the prototype's 768 = 4⁴·3 and every power of two are covered,
//! and a Bluestein fallback would triple the cost of the sizes that need it.
//!
//! Unnormalised both ways, like rustfft: `inverse(forward(x)) = w·h·x`.

use crate::context::{groups, GpuContext};
use crate::error::{GpuError, Result};

/// Threads per workgroup of the FFT kernels (shaders/fft.wgsl).
const WORKGROUP: u32 = 64;

/// The radices of a length, largest first (4s, then one 2, then 3s and 5s), or None when a
/// prime factor above 5 remains.
pub fn radices(n: usize) -> Option<Vec<u32>> {
    if n == 0 {
        return None;
    }
    let mut rest = n;
    let mut out = Vec::new();
    for r in [4usize, 2, 3, 5] {
        while rest % r == 0 {
            out.push(r as u32);
            rest /= r;
        }
    }
    (rest == 1).then_some(out)
}

/// Kernel parameters of one pass (the `Pass` struct of shaders/fft.wgsl).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PassParams {
    n: u32,
    ns: u32,
    elem_stride: u32,
    line_stride: u32,
    lines: u32,
    plane_stride: u32,
    lines_fastest: u32,
    tw_offset: u32,
    dir: f32,
    _pad: [u32; 3],
}

/// One recorded pass: its pipeline, its two bind groups (data → scratch, scratch → data) and
/// its dispatch size.
struct Pass {
    radix: u32,
    bind: [wgpu::BindGroup; 2],
    dispatch: [u32; 3],
}

/// Direction of a transform.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// Σ x e^{−2πi k·p/N}.
    Forward,
    /// Σ X e^{+2πi k·p/N}, not divided by N.
    Inverse,
}

/// A planned 2-D FFT over one data buffer of `planes` complex `w × h` planes.
pub struct GpuFft2 {
    pub w: usize,
    pub h: usize,
    pub planes: usize,
    pipelines: [wgpu::ComputePipeline; 4],
    forward: Vec<Pass>,
    inverse: Vec<Pass>,
    scratch: wgpu::Buffer,
    data_bytes: u64,
}

impl GpuFft2 {
    /// Plan both directions on `data` (`planes·w·h` vec2<f32> values). The buffer must live as
    /// long as the plan; it is transformed in place.
    pub fn new(
        ctx: &GpuContext,
        data: &wgpu::Buffer,
        w: usize,
        h: usize,
        planes: usize,
    ) -> Result<GpuFft2> {
        let (rx, ry) = match (radices(w), radices(h)) {
            (Some(a), Some(b)) => (a, b),
            _ => {
                return Err(GpuError::Unsupported(format!(
                    "GPU FFT of {w}×{h}: each side must be a product of 2, 3 and 5"
                )))
            }
        };
        let data_bytes = (planes * w * h * 8) as u64;
        let scratch = ctx.storage("fft scratch", data_bytes);
        let twiddles = ctx.storage_init(
            "fft twiddles",
            &[twiddle_table(w), twiddle_table(h)].concat(),
        );
        let module = ctx.module("fft", include_str!("shaders/fft.wgsl"));
        let pipelines = ["radix2", "radix3", "radix4", "radix5"].map(|e| ctx.pipeline(&module, e));
        let plan = Plan {
            w,
            h,
            planes,
            rx: &rx,
            ry: &ry,
        };
        let record = |dir: f32| -> Vec<Pass> {
            plan.params(dir)
                .into_iter()
                .map(|p| {
                    let uniform = ctx.uniform("fft pass", &p);
                    let radix = plan.radix_of(&p);
                    let pipe = &pipelines[radix_slot(radix)];
                    let bind = [(data, &scratch), (&scratch, data)]
                        .map(|(s, d)| ctx.bind(pipe, &[s, d, &twiddles, &uniform]));
                    Pass {
                        radix,
                        bind,
                        dispatch: plan.dispatch(&p),
                    }
                })
                .collect()
        };
        let (forward, inverse) = (record(-1.0), record(1.0));
        Ok(GpuFft2 {
            w,
            h,
            planes,
            pipelines,
            forward,
            inverse,
            scratch,
            data_bytes,
        })
    }

    /// Record the transform of the data buffer into `enc` (no submission: a stage chains it
    /// with its other kernels in one command buffer).
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder, data: &wgpu::Buffer, dir: Direction) {
        let passes = match dir {
            Direction::Forward => &self.forward,
            Direction::Inverse => &self.inverse,
        };
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            for (i, p) in passes.iter().enumerate() {
                cp.set_pipeline(&self.pipelines[radix_slot(p.radix)]);
                cp.set_bind_group(0, &p.bind[i % 2], &[]);
                cp.dispatch_workgroups(p.dispatch[0], p.dispatch[1], p.dispatch[2]);
            }
        }
        if passes.len() % 2 == 1 {
            enc.copy_buffer_to_buffer(&self.scratch, 0, data, 0, self.data_bytes);
        }
    }
}

/// Index of a radix's pipeline in `GpuFft2::pipelines`.
fn radix_slot(r: u32) -> usize {
    match r {
        2 => 0,
        3 => 1,
        4 => 2,
        _ => 3,
    }
}

/// exp(−2πi t/n) for t < n, computed in f64.
fn twiddle_table(n: usize) -> Vec<[f32; 2]> {
    (0..n)
        .map(|t| {
            let a = -std::f64::consts::TAU * t as f64 / n as f64;
            [a.cos() as f32, a.sin() as f32]
        })
        .collect()
}

/// The passes of one 2-D transform: radices along x (rows), then along y (columns).
struct Plan<'a> {
    w: usize,
    h: usize,
    planes: usize,
    rx: &'a [u32],
    ry: &'a [u32],
}

impl Plan<'_> {
    /// Parameters of every pass, rows first. `ns` grows by each radix in turn.
    fn params(&self, dir: f32) -> Vec<PassParams> {
        let (w, h) = (self.w as u32, self.h as u32);
        let mut out = Vec::new();
        // (length, radices, element stride, line stride, lines, lines fastest, twiddle offset)
        let axes = [(w, self.rx, 1, w, h, 0, 0), (h, self.ry, w, 1, w, 1, w)];
        for (n, rs, es, ls, lines, fast, tw) in axes {
            let mut ns = 1;
            for &r in rs {
                out.push(PassParams {
                    n,
                    ns,
                    elem_stride: es,
                    line_stride: ls,
                    lines,
                    plane_stride: w * h,
                    lines_fastest: fast,
                    tw_offset: tw,
                    dir,
                    _pad: [0; 3],
                });
                ns *= r;
            }
        }
        out
    }

    /// The radix of a pass: the ratio of the next pass's `ns` to its own, read off the radix
    /// lists by position.
    fn radix_of(&self, p: &PassParams) -> u32 {
        let rs = if p.lines_fastest == 1 {
            self.ry
        } else {
            self.rx
        };
        let mut ns = 1;
        for &r in rs {
            if ns == p.ns {
                return r;
            }
            ns *= r;
        }
        unreachable!("a pass's ns is a prefix product of its radices")
    }

    /// Workgroups: x over (j or lines), y over (lines or j), z over planes.
    fn dispatch(&self, p: &PassParams) -> [u32; 3] {
        let jobs = (p.n / self.radix_of(p)) as usize;
        if p.lines_fastest == 1 {
            [
                groups(p.lines as usize, WORKGROUP),
                jobs as u32,
                self.planes as u32,
            ]
        } else {
            [groups(jobs, WORKGROUP), p.lines, self.planes as u32]
        }
    }
}
