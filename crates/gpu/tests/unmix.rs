//! The GPU unmixing against the core's `Unmixer` on the prototype's design (F from its filters,
//! the PCA basis, η = 200 per nm⁴) with random channel values, most of which have no
//! non-negative spectrum, so the exact active set runs on them.
//!
//! Tolerance: each pixel's bands within 2e-4 of the pixel's largest CPU band. The fast path is
//! the same f32 arithmetic as the CPU's; the active set runs in f32 where the CPU uses f64,
//! and its error is ε·κ(H) amplified along the solve: ≤ 1.2e-5 seen on lavapipe, ≤ 2.2e-5 on
//! an H100; the bound keeps 9× margin. The active-set counters must agree too.

mod common;

use specmux_core::reconstructor::{unmixer, Design, ReconConfig};
use specmux_core::spectral::Library;
use specmux_core::unmix::Unmixer;
use specmux_core::Cube;
use specmux_gpu::unmix::GpuUnmixer;
use specmux_gpu::GpuContext;
use specmux_twin::experiment::Experiment;
use specmux_twin::rig::Rig;
use specmux_twin::scene::Materials;

const TOL: f64 = 2e-4;

fn prototype_design() -> Design {
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    Rig::build(&Experiment::prototype(), &lib, &materials)
        .unwrap()
        .design()
}

/// Channel values around the white target's, each channel scaled independently by [0, 2).
fn channels(design: &Design, w: usize, h: usize, seed: u64) -> Cube {
    let c = design.white.len();
    let u = common::noise(w * h * c, seed);
    let data = (0..c * w * h)
        .map(|i| design.white[i / (w * h)] as f32 * (1.0 + u[i]))
        .collect();
    Cube::from_vec(w, h, c, data).unwrap()
}

/// Unmix `x` on the GPU: upload, one submission, read back cube and counters.
fn gpu_unmix(ctx: &GpuContext, u: &Unmixer, x: &Cube) -> (Cube, specmux_core::unmix::UnmixStats) {
    let input = ctx.storage("xhat", (x.data.len() * 4) as u64);
    ctx.queue
        .write_buffer(&input, 0, bytemuck::cast_slice(&x.data));
    let g = GpuUnmixer::new(ctx, u, x.pixels(), &input).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    g.encode(&mut enc);
    g.encode_readback(&mut enc);
    ctx.queue.submit([enc.finish()]);
    let stats = g.stats(ctx).unwrap();
    let mut cube = Cube::zeros(x.width, x.height, u.bands());
    g.read_cube(ctx, &mut cube).unwrap();
    (cube, stats)
}

/// The largest per-pixel error relative to the pixel's largest CPU band.
fn worst_pixel_error(gpu: &Cube, cpu: &Cube) -> f64 {
    (0..cpu.pixels())
        .map(|p| {
            let (mut err, mut scale) = (0.0f64, 0.0f64);
            for k in 0..cpu.planes {
                let (a, b) = (gpu.plane(k)[p] as f64, cpu.plane(k)[p] as f64);
                err = err.max((a - b).abs());
                scale = scale.max(b.abs());
            }
            err / scale.max(f64::MIN_POSITIVE)
        })
        .fold(0.0, f64::max)
}

#[test]
fn matches_the_core_unmixer_with_and_without_output_gains() {
    let Some(ctx) = common::context() else { return };
    let design = prototype_design();
    let x = channels(&design, 64, 40, 9);
    let plain = unmixer(&ReconConfig::default(), &design).unwrap();
    let gains: Vec<f64> = (0..plain.bands()).map(|k| 0.5 + 0.05 * k as f64).collect();
    for (what, u) in [
        ("plain", plain.clone()),
        ("with gains", plain.with_output_gains(&gains).unwrap()),
    ] {
        let (cpu, cpu_stats) = u.unmix(&x).unwrap();
        let (gpu, gpu_stats) = gpu_unmix(&ctx, &u, &x);
        assert!(
            gpu.data.iter().all(|v| *v >= 0.0 && v.is_finite()),
            "{what}: negative or NaN band"
        );
        let err = worst_pixel_error(&gpu, &cpu);
        eprintln!("{what}: worst pixel error {err:.2e}; CPU {cpu_stats:?}; GPU {gpu_stats:?}");
        assert!(err < TOL, "{what}: worst pixel error {err:.2e}");
        assert!(
            cpu_stats.constrained_pixels * 3 > cpu_stats.pixels,
            "the test needs the active set"
        );
        let diff = cpu_stats
            .constrained_pixels
            .abs_diff(gpu_stats.constrained_pixels);
        assert!(
            diff * 1000 <= cpu_stats.pixels,
            "{what}: constrained pixels differ by {diff}"
        );
        assert!(gpu_stats.bound_pixels > 0 && gpu_stats.max_iterations > 0);
    }
}

#[test]
fn a_weak_smoothness_weight_still_matches() {
    let Some(ctx) = common::context() else { return };
    let design = prototype_design();
    let cfg = ReconConfig {
        eta: 2.0,
        ..ReconConfig::default()
    };
    let u = unmixer(&cfg, &design).unwrap();
    let x = channels(&design, 48, 32, 11);
    let (cpu, _) = u.unmix(&x).unwrap();
    let (gpu, _) = gpu_unmix(&ctx, &u, &x);
    let err = worst_pixel_error(&gpu, &cpu);
    eprintln!(
        "η = 2: condition {:.2e}, worst pixel error {err:.2e}",
        u.condition()
    );
    assert!(err < TOL, "η = 2: worst pixel error {err:.2e}");
}
