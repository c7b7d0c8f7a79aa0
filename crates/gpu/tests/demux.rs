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
