//! GAP and GAP-TV de-aliasing on the GPU (shaders/gap.wgsl with the wavelet, selection and TV
//! kernels), built from the core's `Gap` — its patterns, 1/Σs², group weights, wavelet and
//! settings — so both run the same iterations: the projection onto {Y = S X} (accelerated or
//! not), then the wavelet group shrinkage with its exact threshold, or the TV denoising with
//! λ from the seed's mean |x|. The iterate stays on the GPU from the demultiplexed seed to the
//! unmixing; per frame only the residuals and a non-finite count come back (a few bytes).

use crate::context::{linear_groups, GpuContext, Launch};
use crate::error::{GpuError, Result};
use crate::select::GpuSelect;
use crate::tv::GpuTv;
use crate::wavelet::GpuDwt2;
use specmux_core::gap::{Gap, GapStats, Method};

/// Threads per workgroup of shaders/gap.wgsl.
const WORKGROUP: u32 = 256;

/// The `Params` struct of shaders/gap.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    npx: u32,
    planes: u32,
    accelerate: u32,
    _pad: u32,
}

/// The `Finish` struct of shaders/gap.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Finish {
    partials: u32,
    scale: f32,
    _pad: [u32; 2],
}

/// GAP's denoising step on the GPU.
enum Denoiser {
    /// Wavelet analysis, group scores, the threshold's selection, shrinkage, synthesis.
    Wavelet {
        dwt: GpuDwt2,
        score: Launch,
        select: Option<GpuSelect>,
        shrink: Launch,
    },
    /// λ = tv_weight · mean |seed| (two sums), then the TV denoiser.
    Tv { lambda: [Launch; 2], tv: GpuTv },
}

/// The GAP solver of one rig on the GPU, bound to the frame and the iterate buffers.
pub struct GpuGap {
    pub iterations: usize,
    /// Copies the frame to Y_acc at the start of a run.
    frame: wgpu::Buffer,
    y_acc: wgpu::Buffer,
    /// The projection and the sum of its residuals.
    project: [Launch; 2],
    denoiser: Denoiser,
    non_finite: Launch,
    /// [count, Σe²/n per iteration …] and [count, λ] (the `List` of shaders/gap.wgsl).
    residuals: wgpu::Buffer,
    lambda: wgpu::Buffer,
    /// The non-finite count.
    counter: wgpu::Buffer,
    /// Residuals then the counter, copied for the host.
    staging: wgpu::Buffer,
}

impl GpuGap {
    /// Mirror `gap` on the GPU: `frame` holds the measurement Y (w × h f32), `estimate` the
    /// seed's J planes, replaced by the de-aliased ones. Every buffer is made here, once.
    pub fn new(
        ctx: &GpuContext,
        gap: &Gap,
        frame: &wgpu::Buffer,
        estimate: &wgpu::Buffer,
    ) -> Result<GpuGap> {
        let t = gap.tables();
        let cfg = t.config;
        if !matches!(
            (cfg.method, t.dwt),
            (Method::Gap, Some(_)) | (Method::GapTv, _)
        ) {
            return Err(GpuError::Unsupported(format!(
                "method {:?} in GAP (gap with its wavelet and gap-tv only)",
                cfg.method
            )));
        }
        let (npx, planes) = (t.w * t.h, t.planes);
        let params = Params {
            npx: npx as u32,
            planes: planes as u32,
            accelerate: cfg.accelerate as u32,
            _pad: 0,
        };
        let uniform = ctx.uniform("gap params", &params);
        let module = module(ctx);
        let pixels = linear_groups(npx, WORKGROUP);
        let values = linear_groups(npx * planes, WORKGROUP);
        let patterns = ctx.storage_init("gap patterns", t.patterns);
        let inv_energy = ctx.storage_init("gap 1/energy", t.inv_energy);
        let y_acc = ctx.storage("gap y_acc", (npx * 4) as u64);
        let partials = ctx.storage("gap partials", (count(values) * 4) as u64);
        let residuals = ctx.storage("gap residuals", (4 * (cfg.iterations + 1)) as u64);
        let lambda = ctx.storage("gap-tv lambda", 8);
        let counter = ctx.storage("gap non-finite", 4);
        let project = [
            Launch::new(
                ctx,
                &module,
                "project",
                &[
                    estimate,
                    &patterns,
                    frame,
                    &y_acc,
                    &inv_energy,
                    &partials,
                    &uniform,
                ],
                pixels,
            ),
            finish(
                ctx,
                &module,
                &partials,
                pixels,
                1.0 / npx as f64,
                &residuals,
            ),
        ];
        // The core builds the wavelet for GAP only: without it the method is GAP-TV.
        let denoiser = match t.dwt {
            None => Denoiser::Tv {
                lambda: abs_sum(
                    ctx,
                    &module,
                    estimate,
                    (npx, planes),
                    cfg.tv_weight / (npx * planes) as f64,
                    &partials,
                    &lambda,
                ),
                tv: GpuTv::new(
                    ctx,
                    estimate,
                    &lambda,
                    (t.w, t.h, planes),
                    cfg.tv_iterations,
                ),
            },
            Some(dwt) => {
                let beta = ctx.storage_init("gap beta", t.beta);
                let scores = ctx.storage("gap scores", (npx * 4) as u64);
                let select = gap
                    .threshold_rank()
                    .map(|rank| GpuSelect::new(ctx, &scores, &beta, npx, rank));
                // λ = 0 when every group is kept: a zeroed word stands for it.
                let zero = ctx.storage("gap zero threshold", 4);
                let threshold = select.as_ref().map_or(&zero, |s| s.result());
                Denoiser::Wavelet {
                    dwt: GpuDwt2::new(ctx, dwt, planes, estimate)?,
                    score: Launch::new(
                        ctx,
                        &module,
                        "score",
                        &[estimate, &beta, &scores, &uniform],
                        pixels,
                    ),
                    shrink: Launch::new(
                        ctx,
                        &module,
                        "shrink",
                        &[estimate, &beta, &scores, threshold, &uniform],
                        pixels,
                    ),
                    select,
                }
            }
        };
        let non_finite = non_finite(ctx, &module, estimate, (npx, planes), &counter);
        Ok(GpuGap {
            iterations: cfg.iterations,
            frame: frame.clone(),
            y_acc,
            project,
            denoiser,
            non_finite,
            staging: ctx.readback("gap staging", residuals.size() + 4),
            residuals,
            lambda,
            counter,
        })
    }

    /// Record a whole run on the current frame and seed: the resets, `iterations` iterations,
    /// the non-finite check and the copy of the residuals for `stats`.
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder) {
        enc.copy_buffer_to_buffer(&self.frame, 0, &self.y_acc, 0, self.y_acc.size());
        for b in [&self.residuals, &self.lambda, &self.counter] {
            enc.clear_buffer(b, 0, None);
        }
        if let Denoiser::Tv { tv, .. } = &self.denoiser {
            tv.reset(enc);
        }
        {
            let mut cp = enc.begin_compute_pass(&Default::default());
            if let Denoiser::Tv { lambda, .. } = &self.denoiser {
                lambda.iter().for_each(|l| l.record(&mut cp));
            }
            for _ in 0..self.iterations {
                self.step(&mut cp);
            }
            self.non_finite.record(&mut cp);
        }
        let r = self.residuals.size();
        enc.copy_buffer_to_buffer(&self.residuals, 0, &self.staging, 0, r);
        enc.copy_buffer_to_buffer(&self.counter, 0, &self.staging, r, 4);
    }

    /// One iteration: project, then denoise.
    fn step(&self, cp: &mut wgpu::ComputePass) {
        self.project.iter().for_each(|l| l.record(cp));
        match &self.denoiser {
            Denoiser::Wavelet {
                dwt,
                score,
                select,
                shrink,
            } => {
                dwt.record_forward(cp);
                score.record(cp);
                if let Some(s) = select {
                    s.record(cp);
                }
                shrink.record(cp);
                dwt.record_inverse(cp);
            }
            Denoiser::Tv { tv, .. } => tv.record(cp),
        }
    }

    /// After the submission that held `encode`: the run's residual RMS per iteration (no PSNR:
    /// the truth is not on the GPU; no time: the run is part of one submission), or an error
    /// when the result holds a NaN or an infinite value, as on the CPU.
    pub fn stats(&self, ctx: &GpuContext) -> Result<GapStats> {
        let mut words = vec![0u32; (self.staging.size() / 4) as usize];
        ctx.read_into(&self.staging, &mut words)?;
        let non_finite = words[words.len() - 1];
        if non_finite > 0 {
            return Err(GpuError::Numerical(format!(
                "GAP produced {non_finite} non-finite values after {} iterations",
                self.iterations
            )));
        }
        let n = words[0] as usize;
        Ok(GapStats {
            iterations: self.iterations,
            residual_rms: words[1..=n]
                .iter()
                .map(|&b| (f32::from_bits(b) as f64).sqrt())
                .collect(),
            ..Default::default()
        })
    }
}

/// Workgroups in a dispatch.
pub(crate) fn count(g: [u32; 3]) -> usize {
    g.iter().map(|&v| v as usize).product()
}

/// shaders/gap.wgsl compiled (its sums and the non-finite count serve the joint method too).
pub(crate) fn module(ctx: &GpuContext) -> wgpu::ShaderModule {
    ctx.module("gap", include_str!("shaders/gap.wgsl"))
}

/// `finish`: scale · Σ of the `partials` of a dispatch of `groups`, appended to the list `out`.
pub(crate) fn finish(
    ctx: &GpuContext,
    module: &wgpu::ShaderModule,
    partials: &wgpu::Buffer,
    groups: [u32; 3],
    scale: f64,
    out: &wgpu::Buffer,
) -> Launch {
    let p = ctx.uniform(
        "gap finish",
        &Finish {
            partials: count(groups) as u32,
            scale: scale as f32,
            _pad: [0; 2],
        },
    );
    Launch::new(ctx, module, "finish", &[partials, out, &p], [1, 1, 1])
}

/// The `Params` uniform of `planes` planes of `npx` values (not accelerated).
fn sizes(ctx: &GpuContext, (npx, planes): (usize, usize)) -> wgpu::Buffer {
    let params = Params {
        npx: npx as u32,
        planes: planes as u32,
        accelerate: 0,
        _pad: 0,
    };
    ctx.uniform("gap sizes", &params)
}

/// `abs_sum` then `finish`: scale · Σ|v| over `planes` planes of `npx` values of `input`
/// appended to the list `out` (`partials` holds a value per workgroup of 256).
pub(crate) fn abs_sum(
    ctx: &GpuContext,
    module: &wgpu::ShaderModule,
    input: &wgpu::Buffer,
    size: (usize, usize),
    scale: f64,
    partials: &wgpu::Buffer,
    out: &wgpu::Buffer,
) -> [Launch; 2] {
    let values = linear_groups(size.0 * size.1, WORKGROUP);
    let uniform = sizes(ctx, size);
    [
        Launch::new(ctx, module, "abs_sum", &[input, partials, &uniform], values),
        finish(ctx, module, partials, values, scale, out),
    ]
}

/// `non_finite`: the count of NaN and infinite values among `planes` planes of `npx` values of
/// `input`, added to word 0 of `counter`.
pub(crate) fn non_finite(
    ctx: &GpuContext,
    module: &wgpu::ShaderModule,
    input: &wgpu::Buffer,
    size: (usize, usize),
    counter: &wgpu::Buffer,
) -> Launch {
    let values = linear_groups(size.0 * size.1, WORKGROUP);
    let uniform = sizes(ctx, size);
    Launch::new(
        ctx,
        module,
        "non_finite",
        &[input, counter, &uniform],
        values,
    )
}
