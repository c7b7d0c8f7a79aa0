//! The forward model's 4f-relay pair sums on the GPU (shaders/pair_sums.wgsl): for the bins a
//! Fourier mask passes, S(q) = Σ value_a·conj(value_b)·∫(pair weights over the wavelengths both
//! pass) at q = k_a − k_b, qx ≥ 0 — the twin's `optics::relay::pair_sums`, one invocation per
//! cell, in f32 with the error bounded as docs/gpu.md states. One upload, one kernel (dispatched
//! once per chunk of 64 columns and window of 256 rows), one read-back per call; it takes plain
//! bins, not the twin's.

use crate::context::{linear_groups, GpuContext};
use crate::error::{GpuError, Result};

/// A wavelength interval (nm) in which a bin passes, with the cumulative pair weights
/// (weight, first moment) below its lower end and through its upper end.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PassInterval {
    pub lo: f64,
    pub hi: f64,
    pub c_lo: [f64; 2],
    pub c_hi: [f64; 2],
}

/// A frequency bin the mask passes: its indices, complex value and 1–3 disjoint intervals.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PairBin {
    pub kx: i64,
    pub ky: i64,
    pub value: [f64; 2],
    pub intervals: [PassInterval; 3],
    /// How many of `intervals` are used (1 to 3).
    pub n: usize,
}

/// The sums on the cells qx ∈ 0..=qx_max, qy ∈ −qy_max..=qy_max, cell (qx, qy) at
/// qx·(2·qy_max + 1) + qy + qy_max: (S0.re, S0.im, S1.re, S1.im).
pub struct PairSumGrid {
    pub qx_max: i64,
    pub qy_max: i64,
    pub sums: Vec<[f32; 4]>,
}

/// The `Interval` struct of shaders/pair_sums.wgsl (ends as ranks, weights as f32 hi + lo).
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuInterval {
    lo: u32,
    hi: u32,
    _pad: [u32; 2],
    c_lo: [f32; 4],
    c_hi: [f32; 4],
}

/// The `Bin` struct of shaders/pair_sums.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuBin {
    value: [f32; 2],
    n: u32,
    _pad: u32,
    iv: [GpuInterval; 3],
}

/// The `Params` struct of shaders/pair_sums.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    ncols: u32,
    qy_max: u32,
    ncells: u32,
    ca0: u32,
    ka0: i32,
    _pad: [u32; 3],
}

/// Columns kx_a per dispatch (`CHUNK` in shaders/pair_sums.wgsl).
const CHUNK: usize = 64;

/// Rows ky_a per dispatch (`ROWS` in shaders/pair_sums.wgsl).
const ROWS: i64 = 256;

/// The pair-sum kernel, compiled once; buffers are made per call (the bin count varies).
pub struct GpuPairSums {
    pipeline: wgpu::ComputePipeline,
}

impl GpuPairSums {
    /// Compile the kernel on `ctx`.
    pub fn new(ctx: &GpuContext) -> GpuPairSums {
        let module = ctx.module("pair sums", include_str!("shaders/pair_sums.wgsl"));
        GpuPairSums {
            pipeline: ctx.pipeline(&module, "pair_sums"),
        }
    }

    /// The pair sums of `bins`, sorted by (kx, ky) without repeats. Unsorted bins, a count of
    /// intervals outside 1–3, a value or weight that is not a finite f32 or a NaN end is a
    /// shape error; a grid of sums larger than the device's buffers is `Unsupported`.
    pub fn run(&self, ctx: &GpuContext, bins: &[PairBin]) -> Result<PairSumGrid> {
        check(bins)?;
        let Some((kx0, qx_max, qy_max)) = reach(ctx, bins)? else {
            return Ok(PairSumGrid {
                qx_max: 0,
                qy_max: 0,
                sums: vec![[0.0; 4]],
            });
        };
        let ncols = qx_max as usize + 1;
        let ncells = ncols * (2 * qy_max as usize + 1);
        let (runs, cols) = runs(bins, kx0, ncols);
        let sums = ctx.storage("pair sums", ncells as u64 * 32);
        let staging = ctx.readback("pair sums staging", sums.size());
        let inputs = [
            &ctx.storage_init("pair bins", &gpu_bins(bins)),
            &ctx.storage_init("pair runs", &runs),
            &ctx.storage_init("pair columns", &cols),
            &sums,
        ];
        let shape = Params {
            ncols: ncols as u32,
            qy_max: qy_max as u32,
            ncells: ncells as u32,
            ca0: 0,
            ka0: 0,
            _pad: [0; 3],
        };
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.record(ctx, &mut enc, inputs, shape, &windows(bins, kx0));
        enc.copy_buffer_to_buffer(&sums, 0, &staging, 0, sums.size());
        ctx.queue.submit([enc.finish()]);
        let mut out = vec![[0.0f32; 4]; 2 * ncells];
        ctx.read_into(&staging, &mut out)?;
        Ok(PairSumGrid {
            qx_max,
            qy_max,
            sums: out.into_iter().step_by(2).collect(),
        })
    }

    /// One dispatch over every cell per window (`ca0`, `ka0`) of [`windows`].
    fn record(
        &self,
        ctx: &GpuContext,
        enc: &mut wgpu::CommandEncoder,
        inputs: [&wgpu::Buffer; 4],
        shape: Params,
        windows: &[(u32, i32)],
    ) {
        let binds: Vec<wgpu::BindGroup> = (windows.iter())
            .map(|&(ca0, ka0)| {
                let params = Params { ca0, ka0, ..shape };
                let u = ctx.uniform("pair params", &params);
                let [b, r, c, s] = inputs;
                ctx.bind(&self.pipeline, &[b, r, c, s, &u])
            })
            .collect();
        let mut cp = enc.begin_compute_pass(&Default::default());
        cp.set_pipeline(&self.pipeline);
        let [x, y, z] = linear_groups(shape.ncells as usize, 64);
        for bind in &binds {
            cp.set_bind_group(0, bind, &[]);
            cp.dispatch_workgroups(x, y, z);
        }
    }
}

/// The dispatches' windows (first column − kx0, first row ky_a): each chunk of CHUNK columns
/// cut into windows of ROWS rows over the rows its bins span, so that no invocation runs over
/// more than CHUNK columns and ROWS rows of bins a.
fn windows(bins: &[PairBin], kx0: i64) -> Vec<(u32, i32)> {
    let mut spans: Vec<(u32, i64, i64)> = Vec::new();
    for b in bins {
        let ca0 = ((b.kx - kx0) as usize / CHUNK * CHUNK) as u32;
        match spans.last_mut() {
            Some((c, lo, hi)) if *c == ca0 => (*lo, *hi) = ((*lo).min(b.ky), (*hi).max(b.ky)),
            _ => spans.push((ca0, b.ky, b.ky)),
        }
    }
    let rows = |&(ca0, lo, hi): &(u32, i64, i64)| {
        (lo..=hi)
            .step_by(ROWS as usize)
            .map(move |ka0| (ca0, ka0 as i32))
    };
    spans.iter().flat_map(rows).collect()
}

/// (kx0, qx_max, qy_max) of non-empty `bins`, or None for none; `Unsupported` when the sums
/// (32 bytes a cell: sum and compensation) or the bins exceed one storage buffer.
fn reach(ctx: &GpuContext, bins: &[PairBin]) -> Result<Option<(i64, i64, i64)>> {
    let (Some(first), Some(last)) = (bins.first(), bins.last()) else {
        return Ok(None);
    };
    let (ky0, ky1) = bins
        .iter()
        .fold((i64::MAX, i64::MIN), |(a, b), x| (a.min(x.ky), b.max(x.ky)));
    let (qx_max, qy_max) = (last.kx - first.kx, ky1 - ky0);
    let ncells = (qx_max + 1) as u128 * (2 * qy_max + 1) as u128;
    let limit = ctx.device.limits().max_storage_buffer_binding_size as u128;
    let bin_bytes = (bins.len() * std::mem::size_of::<GpuBin>()) as u128;
    if ncells * 32 > limit || bin_bytes > limit {
        return Err(GpuError::Unsupported(format!(
            "pair sums: {} bins over {ncells} cells, more than one buffer of {limit} bytes holds",
            bins.len()
        )));
    }
    Ok(Some((first.kx, qx_max, qy_max)))
}

/// Shape error unless the bins are sorted by (kx, ky) without repeats, each with 1–3 intervals,
/// values and weights finite f32, interval ends not NaN and the indices within ±2³⁰.
fn check(bins: &[PairBin]) -> Result<()> {
    let bad = |i: usize, why: &str| Err(GpuError::Shape(format!("pair sums: bin {i} {why}")));
    for (i, b) in bins.iter().enumerate() {
        if !(1..=3).contains(&b.n) {
            return bad(i, &format!("has {} intervals (1 to 3)", b.n));
        }
        if b.kx.abs().max(b.ky.abs()) >= 1 << 30 {
            return bad(i, "has an index beyond ±2³⁰");
        }
        let ivs = &b.intervals[..b.n];
        let weights = ivs
            .iter()
            .flat_map(|v| [v.c_lo, v.c_hi].into_iter().flatten());
        // Finite in f32 (the kernel's type), so also in f64.
        if !(b.value.iter().copied().chain(weights)).all(|v| (v as f32).is_finite()) {
            return bad(i, "has a value or weight that is not a finite f32");
        }
        // Ends are only compared (as ranks): ±∞ is an open end, NaN has no place.
        if ivs.iter().any(|v| v.lo.is_nan() || v.hi.is_nan()) {
            return bad(i, "has a NaN interval end");
        }
        if i > 0 && (bins[i - 1].kx, bins[i - 1].ky) >= (b.kx, b.ky) {
            return bad(i, "is not after the previous one in (kx, ky) order");
        }
    }
    Ok(())
}

/// Runs of consecutive ky within a column, (first ky, length, first bin, 0), and per column
/// c = kx − kx0 the offsets of its runs (ncols + 1 entries).
fn runs(bins: &[PairBin], kx0: i64, ncols: usize) -> (Vec<[i32; 4]>, Vec<u32>) {
    let mut runs: Vec<[i32; 4]> = Vec::new();
    let mut cols = vec![0u32; ncols + 1];
    for (i, b) in bins.iter().enumerate() {
        let extends = i > 0 && bins[i - 1].kx == b.kx && bins[i - 1].ky + 1 == b.ky;
        match runs.last_mut() {
            Some(r) if extends => r[1] += 1,
            _ => {
                runs.push([b.ky as i32, 1, i as i32, 0]);
                cols[(b.kx - kx0) as usize + 1] += 1;
            }
        }
    }
    for c in 1..=ncols {
        cols[c] += cols[c - 1];
    }
    (runs, cols)
}

/// The bins in the shader's layout: values in f32, interval ends as their ranks among all
/// ends (so comparisons are the f64 ones), cumulative weights split into f32 hi + lo.
fn gpu_bins(bins: &[PairBin]) -> Vec<GpuBin> {
    let used = |b: &PairBin| b.intervals[..b.n].to_vec();
    // + 0.0 makes −0 and 0 one end, as f64 comparison sees them.
    let mut ends: Vec<f64> = (bins.iter().flat_map(used))
        .flat_map(|v| [v.lo + 0.0, v.hi + 0.0])
        .collect();
    ends.sort_by(f64::total_cmp);
    ends.dedup();
    let rank = |x: f64| ends.partition_point(|&e| e < x) as u32;
    let split = |c: [f64; 2]| {
        let hi = c.map(|v| v as f32);
        let lo = [0, 1].map(|k| (c[k] - hi[k] as f64) as f32);
        [hi[0], lo[0], hi[1], lo[1]]
    };
    let interval = |v: &PassInterval| GpuInterval {
        lo: rank(v.lo),
        hi: rank(v.hi),
        c_lo: split(v.c_lo),
        c_hi: split(v.c_hi),
        ..Default::default()
    };
    bins.iter()
        .map(|b| {
            let mut iv = [GpuInterval::default(); 3];
            for (g, v) in iv.iter_mut().zip(&b.intervals[..b.n]) {
                *g = interval(v);
            }
            GpuBin {
                value: b.value.map(|v| v as f32),
                n: b.n as u32,
                _pad: 0,
                iv,
            }
        })
        .collect()
}
