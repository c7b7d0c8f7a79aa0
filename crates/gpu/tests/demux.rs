//! GPU demultiplexing against the core's `Demux::run` (+ `Cube::mix`) on frames that are not
//! band-limited, with every window shape, sub-bin carrier offsets and a crosstalk mix.
//!
//! Tolerance: each x̂ plane within 2e-5 of the CPU's, relative L2 over the plane. Both sides
//! are f32 FFTs (relative error ~ε·log₂N ≈ 1e-6 of the frame); a window keeps ~crop² of the
//! frame's energy, so relative to the plane the error is up to 1/crop = 4× larger, and the
//! carriers' gains of ½ double it again; seen here (lavapipe): ≤ 1.2e-6. A broken twiddle
//! or a dropped sub-bin ramp gives errors of 0.6 to 1 (tried).

mod common;

use specmux_core::calibration::MeasuredCarrier;
use specmux_core::carriers::{default_layout, Carrier};
use specmux_core::demux::{Demux, WindowShape, SUPER_GAUSSIAN_ORDER};
use specmux_core::Cube;
use specmux_gpu::demux::GpuDemux;

const TOL: f64 = 2e-5;

fn frame(w: usize, h: usize, seed: u64) -> Cube {
    let data = common::noise(w * h, seed).iter().map(|v| 3.0 + v).collect();
    Cube::from_vec(w, h, 1, data).unwrap()
}

fn carriers() -> Vec<Carrier> {
    default_layout()
        .into_iter()
        .enumerate()
        .map(|(i, c)| Carrier {
            phase_rad: 0.4 * i as f64,
            ..c
        })
        .collect()
}

/// Per plane, ‖gpu − cpu‖ / ‖cpu‖; panics above TOL.
fn assert_close(gpu: &Cube, cpu: &Cube, what: &str) {
    assert_eq!(
        (gpu.width, gpu.height, gpu.planes),
        (cpu.width, cpu.height, cpu.planes)
    );
    for k in 0..cpu.planes {
        let want: Vec<f64> = cpu.plane(k).iter().map(|&v| v as f64).collect();
        let err = common::rel_l2(gpu.plane(k), &want);
        eprintln!("{what}: plane {k} relative L2 error {err:.2e}");
        assert!(err < TOL, "{what}: plane {k} relative L2 error {err:.2e}");
    }
}

#[test]
fn matches_the_core_demux_for_every_window_shape() {
    let Some(ctx) = common::context() else { return };
    let (w, h) = (96, 64);
    let y = frame(w, h, 1);
    for shape in [
        WindowShape::Square,
        WindowShape::Circular,
        WindowShape::SuperGaussian,
    ] {
        let d = Demux::new(w, h, &carriers(), 0.25)
            .with_window(shape, SUPER_GAUSSIAN_ORDER)
            .unwrap();
        let gpu = GpuDemux::new(&ctx, &d, None)
            .unwrap()
            .run(&ctx, &y)
            .unwrap();
        assert_close(&gpu, &d.run(&y).unwrap(), &format!("{shape:?}"));
    }
}

#[test]
fn sub_bin_carriers_and_the_crosstalk_mix_match() {
    let Some(ctx) = common::context() else { return };
    let (w, h) = (80, 60);
    let measured: Vec<MeasuredCarrier> = carriers()
        .iter()
        .enumerate()
        .map(|(i, c)| MeasuredCarrier {
            carrier: Carrier {
                fx: c.fx + 0.3 / w as f64,
                fy: c.fy - 0.2 * i as f64 / h as f64,
                ..*c
            },
            amplitude: [0.3 + 0.01 * i as f64, -0.2],
            white_level: 1.0,
            shift: [0.0; 2],
            prominence: None,
        })
        .collect();
    let d = Demux::new(w, h, &carriers(), 0.25)
        .with_calibration(&measured)
        .unwrap();
    assert!(
        d.offsets.iter().all(|o| o[0] != 0.0),
        "the test needs off-grid carriers"
    );
    let mix: Vec<Vec<f64>> = (0..6)
        .map(|i| {
            (0..6)
                .map(|k| if i == k { 1.1 } else { -0.03 * (i + k) as f64 })
                .collect()
        })
        .collect();
    let y = frame(w, h, 2);
    let gpu = GpuDemux::new(&ctx, &d, Some(&mix)).unwrap();
    assert_close(
        &gpu.run(&ctx, &y).unwrap(),
        &d.run(&y).unwrap().mix(&mix).unwrap(),
        "sub-bin + mix",
    );
}

#[test]
fn buffers_reused_across_frames_hold_no_stale_data() {
    let Some(ctx) = common::context() else { return };
    let (w, h) = (64, 48);
    let d = Demux::new(w, h, &carriers(), 0.25);
    let gpu = GpuDemux::new(&ctx, &d, None).unwrap();
    for seed in [3, 4, 5] {
        let y = frame(w, h, seed);
        assert_close(
            &gpu.run(&ctx, &y).unwrap(),
            &d.run(&y).unwrap(),
            &format!("frame {seed}"),
        );
    }
}

#[test]
fn wrong_frames_are_refused() {
    let Some(ctx) = common::context() else { return };
    let d = Demux::new(32, 32, &carriers(), 0.25);
    let gpu = GpuDemux::new(&ctx, &d, None).unwrap();
    assert!(gpu
        .run(&ctx, &frame(32, 16, 1))
        .unwrap_err()
        .to_string()
        .contains("32×16"));
    let mut bad = frame(32, 32, 1);
    bad.data[5] = f32::NAN;
    assert!(gpu.run(&ctx, &bad).unwrap_err().to_string().contains("NaN"));
}

/// Direct inverse 2-D DFT (f64, unnormalised) of one interleaved complex plane.
fn naive_inverse(z: &[f32], w: usize, h: usize) -> Vec<f64> {
    let tau = std::f64::consts::TAU;
    let mut rows = vec![(0.0, 0.0); w * h];
    for y in 0..h {
        for x in 0..w {
            let mut acc = (0.0, 0.0);
            for kx in 0..w {
                let (s, c) = (tau * (kx * x % w) as f64 / w as f64).sin_cos();
                let (a, b) = (z[2 * (y * w + kx)] as f64, z[2 * (y * w + kx) + 1] as f64);
                acc = (acc.0 + a * c - b * s, acc.1 + a * s + b * c);
            }
            rows[y * w + x] = acc;
        }
    }
    let mut out = vec![0.0; 2 * w * h];
    for y in 0..h {
        for x in 0..w {
            let mut acc = (0.0, 0.0);
            for ky in 0..h {
                let (s, c) = (tau * (ky * y % h) as f64 / h as f64).sin_cos();
                let (a, b) = rows[ky * w + x];
                acc = (acc.0 + a * c - b * s, acc.1 + a * s + b * c);
            }
            out[2 * (y * w + x)] = acc.0;
            out[2 * (y * w + x) + 1] = acc.1;
        }
    }
    out
}

#[test]
fn each_stage_matches_its_cpu_reference() {
    use specmux_gpu::demux::STAGES;
    let Some(ctx) = common::context() else { return };
    let (w, h) = (96, 64);
    let d = Demux::new(w, h, &carriers(), 0.25);
    let gpu = GpuDemux::new(&ctx, &d, None).unwrap();
    let y = frame(w, h, 6);
    gpu.upload(&ctx, &y).unwrap();
    let (spec_buf, z_buf) = gpu.intermediates();
    let mut after = Vec::new();
    for stage in 0..STAGES {
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        gpu.encode_stage(&mut enc, stage);
        ctx.queue.submit([enc.finish()]);
        after.push((
            ctx.read::<f32>(spec_buf, 2 * w * h).unwrap(),
            ctx.read::<f32>(z_buf, 12 * w * h).unwrap(),
        ));
    }
    let mut bad = Vec::new();
    let mut check = |what: String, got: &[f32], want: &[f64]| {
        let err = common::rel_l2(got, want);
        eprintln!("{what}: {err:.2e}");
        if err.is_nan() || err >= TOL {
            bad.push(format!("{what}: {err:.2e}"));
        }
    };
    // Stage 1: the spectrum against the core's FFT (Hermitian half extended).
    let half = d.spectrum(&y.data);
    let full: Vec<f64> = (0..w * h)
        .flat_map(|i| {
            let v = half.at((i % w) as i64, (i / w) as i64);
            [v.re as f64, v.im as f64]
        })
        .collect();
    check("forward FFT".into(), &after[1].0, &full);
    let plane = 2 * w * h;
    for k in 0..6 {
        // Stage 2: the crop of the GPU's spectrum, done here.
        let (win, g) = (d.windows[k], 1.0 / d.gains[k]);
        let spec = &after[1].0;
        let crop: Vec<f64> = (0..w * h)
            .flat_map(|i| {
                let (u, v) = ((i % w) as i64, (i / w) as i64);
                let (hx, hy) = ((win.wx / 2) as i64, (win.wy / 2) as i64);
                let dx = if u >= win.wx as i64 - hx {
                    u - w as i64
                } else {
                    u
                };
                let dy = if v >= win.wy as i64 - hy {
                    v - h as i64
                } else {
                    v
                };
                if dx < -hx || dy < -hy {
                    return [0.0, 0.0];
                }
                let kx = (win.cx + dx).rem_euclid(w as i64) as usize;
                let ky = (win.cy + dy).rem_euclid(h as i64) as usize;
                let s = specmux_core::Complex64::new(
                    spec[2 * (ky * w + kx)] as f64,
                    spec[2 * (ky * w + kx) + 1] as f64,
                ) * g;
                [s.re, s.im]
            })
            .collect();
        check(
            format!("crop, window {k}"),
            &after[2].1[k * plane..(k + 1) * plane],
            &crop,
        );
        // Stage 3: the inverse FFT of the GPU's crop, as a direct inverse DFT.
        let z = &after[2].1[k * plane..(k + 1) * plane];
        let got = &after[3].1[k * plane..(k + 1) * plane];
        check(
            format!("inverse FFT, window {k}"),
            got,
            &naive_inverse(z, w, h),
        );
        // Stage 4 (on-grid carriers, identity mix): Re(z)/(w·h).
        let out = ctx.read::<f32>(gpu.output(), 6 * w * h).unwrap();
        let want: Vec<f64> = got
            .chunks(2)
            .map(|c| c[0] as f64 / (w * h) as f64)
            .collect();
        check(
            format!("demodulation, plane {k}"),
            &out[k * w * h..(k + 1) * w * h],
            &want,
        );
    }
    assert!(bad.is_empty(), "stages off their references: {bad:?}");
    // All stages in one submission give what the staged run gave.
    let one = gpu.run(&ctx, &y).unwrap();
    let staged = ctx.read::<f32>(gpu.output(), 6 * w * h).unwrap();
    let err = common::rel_l2(
        &one.data,
        &staged.iter().map(|&v| v as f64).collect::<Vec<_>>(),
    );
    assert!(
        err < 1e-6,
        "one submission against stage by stage: {err:.2e}"
    );
    assert_close(&one, &d.run(&y).unwrap(), "one submission");
}
