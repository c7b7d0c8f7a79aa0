//! GAP de-aliasing on the GPU against the core, kernel by kernel and whole: the wavelet
//! transform against `Dwt2`, the threshold's selection against a sort, the TV denoiser against
//! `TvDenoiser`, the projection (GAP-TV with λ = 0, which leaves only it) and whole GAP and
//! GAP-TV runs against `Gap::run` from the same frame and seed.
//!
//! Tolerances (relative L2 over the planes, f64 reference sums of the CPU's f32 values):
//! - wavelet, 2e-6: every level of analysis or synthesis sums 2–4 products per value, so each
//!   level adds ~1 ulp (6e-8) of the values; three levels each way are ~4e-7 at most; what the
//!   GPU may fuse into an FMA differs from the CPU by less than that.
//! - selection: exact (the same bits); it sorts the same f32 values.
//! - projection, 1e-6 (three iterations): J ≤ 6 products summed per pixel, one division.
//! - residuals, relative to the first: 1e-6 for the projection (an f32 tree sum on the GPU
//!   against the CPU's f64 rows), 1e-4 for whole runs (the iterates' own difference).
//! - TV, 2e-6: each dual step is a few ulps per value and Chambolle's iteration is a
//!   contraction of the dual field, so rounding does not grow with the steps.
//! - whole runs, 20 iterations, 1e-4: the projection is non-expansive and the shrinkage and TV
//!   steps are 1-Lipschitz (the threshold, an order statistic, moves by no more than the
//!   scores do), so the two runs separate by at most the sum of the per-iteration rounding
//!   (~20 × 1e-6), plus the seed's; 5× room on that.
//!
//! A dropped sub-band, a wrong filter tap or an off-by-one rank gives errors of 1e-2 or more.

mod common;

use specmux_core::carriers::{default_layout, Carrier};
use specmux_core::demux::Demux;
use specmux_core::gap::{Gap, GapConfig, Method};
use specmux_core::tv::TvDenoiser;
use specmux_core::wavelet::{Dwt2, Wavelet};
use specmux_core::Cube;
use specmux_gpu::gap::GpuGap;
use specmux_gpu::select::GpuSelect;
use specmux_gpu::tv::GpuTv;
use specmux_gpu::wavelet::GpuDwt2;
use specmux_gpu::{wgpu, GpuContext};

/// ‖gpu − cpu‖ / ‖cpu‖ over all values.
fn rel(gpu: &[f32], cpu: &[f32]) -> f64 {
    let want: Vec<f64> = cpu.iter().map(|&v| v as f64).collect();
    common::rel_l2(gpu, &want)
}

/// Record `f` into one compute pass and submit.
fn run_pass(ctx: &GpuContext, f: impl FnOnce(&mut wgpu::ComputePass)) {
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    f(&mut enc.begin_compute_pass(&Default::default()));
    ctx.queue.submit([enc.finish()]);
}

#[test]
fn wavelet_transform_matches_the_core_both_ways() {
    let Some(ctx) = common::context() else { return };
    let (w, h, planes) = (64, 48, 3);
    for (wavelet, levels) in [(Wavelet::Daubechies4, 3), (Wavelet::Haar, 4)] {
        let dwt = Dwt2::new(w, h, levels, wavelet, "t").unwrap();
        let x = common::noise(w * h * planes, 1);
        let buf = common::upload(&ctx, "planes", &x);
        let gpu = GpuDwt2::new(&ctx, &dwt, planes, &buf).unwrap();
        run_pass(&ctx, |cp| gpu.record_forward(cp));
        let got = ctx.read::<f32>(&buf, x.len()).unwrap();
        let mut want = x.clone();
        let mut scratch = vec![0.0; w * h];
        for plane in want.chunks_mut(w * h) {
            dwt.forward(plane, &mut scratch);
        }
        let e = rel(&got, &want);
        eprintln!("{wavelet:?} analysis: relative L2 {e:.2e}");
        assert!(e < 2e-6, "{wavelet:?} analysis: {e:.2e}");
        // Synthesis from the CPU's coefficients.
        ctx.queue.write_buffer(&buf, 0, bytemuck::cast_slice(&want));
        run_pass(&ctx, |cp| gpu.record_inverse(cp));
        let got = ctx.read::<f32>(&buf, x.len()).unwrap();
        for plane in want.chunks_mut(w * h) {
            dwt.inverse(plane, &mut scratch);
        }
        let e = rel(&got, &want);
        eprintln!("{wavelet:?} synthesis: relative L2 {e:.2e}");
        assert!(e < 2e-6, "{wavelet:?} synthesis: {e:.2e}");
    }
}

#[test]
fn selection_gives_the_sorted_value_bit_for_bit() {
    let Some(ctx) = common::context() else { return };
    let n = 5000;
    // Non-negative values with many ties (a coarse grid), exact zeros, a huge one and
    // tiny subnormal-range ones; every seventh value carries weight 0 and is not a candidate.
    let values: Vec<f32> = common::noise(n, 2)
        .iter()
        .enumerate()
        .map(|(i, v)| match i % 11 {
            0 => 0.0,
            1 => (v.abs() * 8.0).round() / 8.0,
            2 => 1e-39 * v.abs(),
            3 => 3e37 * v.abs(),
            _ => v.abs(),
        })
        .collect();
    let weights: Vec<f32> = (0..n).map(|i| (i % 7 != 3) as u8 as f32).collect();
    let mut sorted: Vec<f32> = values
        .iter()
        .zip(&weights)
        .filter(|(_, &w)| w != 0.0)
        .map(|(&v, _)| v)
        .collect();
    sorted.sort_by(f32::total_cmp);
    let (vb, wb) = (
        common::upload(&ctx, "values", &values),
        common::upload(&ctx, "weights", &weights),
    );
    let m = sorted.len();
    for rank in [0, 1, m / 11, m / 2, m - 2, m - 1] {
        let sel = GpuSelect::new(&ctx, &vb, &wb, n, rank);
        run_pass(&ctx, |cp| sel.record(cp));
        let got = f32::from_bits(ctx.read::<u32>(sel.result(), 1).unwrap()[0]);
        assert_eq!(got.to_bits(), sorted[rank].to_bits(), "rank {rank} of {m}");
    }
}

#[test]
fn tv_denoiser_matches_the_core_with_a_warm_start() {
    let Some(ctx) = common::context() else { return };
    let (w, h, planes) = (40, 24, 4);
    let f0: Vec<f32> = common::noise(w * h * planes, 3)
        .iter()
        .enumerate()
        .map(|(i, v)| v + ((i % w) > w / 2) as u8 as f32)
        .collect();
    let lambda = 0.3f32;
    let buf = common::upload(&ctx, "f", &f0);
    let lam = common::upload(&ctx, "lambda", &[1u32, lambda.to_bits()]);
    let gpu = GpuTv::new(&ctx, &buf, &lam, (w, h, planes), 5);
    let mut cpu = TvDenoiser::new(w, h, planes);
    let mut want = f0.clone();
    // Two calls: the second starts from the first's dual field on both sides.
    for call in 0..2 {
        run_pass(&ctx, |cp| gpu.record(cp));
        cpu.denoise(&mut want, lambda, 5);
        let got = ctx.read::<f32>(&buf, want.len()).unwrap();
        let e = rel(&got, &want);
        eprintln!("TV call {call}: relative L2 {e:.2e}");
        assert!(e < 2e-6, "TV call {call}: {e:.2e}");
        assert!(rel(&got, &f0) > 1e-2, "TV changed nothing");
    }
}

/// (frame, patterns, Fourier seed) of a 96 × 64 scene of six channels with edges and shading
/// under the default carriers' ideal patterns.
fn case() -> (Cube, Cube, Cube) {
    let (w, h) = (96, 64);
    let carriers: Vec<Carrier> = default_layout();
    let s = Carrier::ideal_patterns(&carriers, w, h);
    let blobs = common::noise(64, 4);
    let x: Vec<f32> = (0..6 * w * h)
        .map(|i| {
            let (k, p) = (i / (w * h), i % (w * h));
            let (bx, by) = ((p % w) / 24, (p / w) / 16);
            let leaf = blobs[(bx + 4 * by + 7 * k) % 64].abs();
            leaf * (0.8 + 0.2 * ((p % w) as f32 / w as f32))
        })
        .collect();
    let x = Cube::from_vec(w, h, 6, x).unwrap();
    let y: Vec<f32> = (0..w * h)
        .map(|p| (0..6).map(|k| x.plane(k)[p] * s.plane(k)[p]).sum())
        .collect();
    let y = Cube::from_vec(w, h, 1, y).unwrap();
    let seed = Demux::new(w, h, &carriers, 0.25).run(&y).unwrap();
    (y, s, seed)
}

/// The GPU's run of `cfg` on `case()`, against the CPU's: (relative L2 of the planes, worst
/// difference of a residual relative to the first one: after a few iterations the residual is
/// itself at the level of rounding, where a relative difference says nothing).
fn compare_runs(ctx: &GpuContext, cfg: &GapConfig) -> (f64, f64) {
    let (y, s, seed) = case();
    let gap = Gap::new(&s, cfg, "t").unwrap();
    let (cpu, cpu_stats) = gap.run(&y, &seed, None).unwrap();
    let frame = common::upload(ctx, "frame", &y.data);
    let est = common::upload(ctx, "estimate", &seed.data);
    let gpu = GpuGap::new(ctx, &gap, &frame, &est).unwrap();
    // Twice through the same buffers (the seed uploaded again): the second run is checked.
    for _ in 0..2 {
        ctx.queue
            .write_buffer(&est, 0, bytemuck::cast_slice(&seed.data));
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        gpu.encode(&mut enc);
        ctx.queue.submit([enc.finish()]);
    }
    let stats = gpu.stats(ctx).unwrap();
    let got = ctx.read::<f32>(&est, seed.data.len()).unwrap();
    assert_eq!(stats.residual_rms.len(), cfg.iterations);
    let first = cpu_stats.residual_rms[0];
    let worst_residual = stats
        .residual_rms
        .iter()
        .zip(&cpu_stats.residual_rms)
        .map(|(g, c)| (g - c).abs() / first)
        .fold(0.0, f64::max);
    // The run did something: the planes moved well away from the seed.
    assert!(
        rel(&got, &seed.data) > 1e-2,
        "{cfg:?} left the seed as it was"
    );
    (rel(&got, &cpu.data), worst_residual)
}

#[test]
fn projection_matches_the_core_plain_and_accelerated() {
    let Some(ctx) = common::context() else { return };
    for accelerate in [false, true] {
        // GAP-TV with λ = 0: the TV step leaves the iterate alone, the projection is all.
        let cfg = GapConfig {
            method: Method::GapTv,
            iterations: 3,
            tv_weight: 0.0,
            accelerate,
            ..Default::default()
        };
        let (e, r) = compare_runs(&ctx, &cfg);
        eprintln!("projection, accelerate {accelerate}: relative L2 {e:.2e}, residuals {r:.2e}");
        assert!(
            e < 1e-6 && r < 1e-6,
            "accelerate {accelerate}: {e:.2e} {r:.2e}"
        );
    }
}

#[test]
fn gap_and_gap_tv_runs_match_the_core() {
    let Some(ctx) = common::context() else { return };
    for (method, wavelet, keep) in [
        (Method::Gap, Wavelet::Daubechies4, 0.2),
        (Method::Gap, Wavelet::Haar, 0.05),
        (Method::Gap, Wavelet::Daubechies4, 1.0),
        (Method::GapTv, Wavelet::Daubechies4, 0.2),
    ] {
        let cfg = GapConfig {
            method,
            wavelet,
            keep,
            levels: 3,
            iterations: 20,
            ..Default::default()
        };
        let (e, r) = compare_runs(&ctx, &cfg);
        eprintln!("{method:?} {wavelet:?} keep {keep}: relative L2 {e:.2e}, residuals {r:.2e}");
        assert!(
            e < 1e-4 && r < 1e-4,
            "{method:?} {wavelet:?} keep {keep}: {e:.2e} {r:.2e}"
        );
    }
}

#[test]
fn a_non_finite_result_is_an_error() {
    let Some(ctx) = common::context() else { return };
    let (y, s, mut seed) = case();
    let cfg = GapConfig {
        method: Method::Gap,
        ..Default::default()
    };
    let gap = Gap::new(&s, &cfg, "t").unwrap();
    seed.data[100] = f32::INFINITY;
    let frame = common::upload(&ctx, "frame", &y.data);
    let est = common::upload(&ctx, "estimate", &seed.data);
    let gpu = GpuGap::new(&ctx, &gap, &frame, &est).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    gpu.encode(&mut enc);
    ctx.queue.submit([enc.finish()]);
    let e = gpu.stats(&ctx).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
}
