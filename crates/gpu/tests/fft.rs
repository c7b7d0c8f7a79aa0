//! The GPU FFT against a naive DFT (f64, direct summation) and against the core's Fft2.
//!
//! Tolerance: a radix-r FFT in f32 has a relative rms error of order ε·log₂N (ε = 6e-8), at
//! most ~1e-6 at N = 768²; seen here (lavapipe): ≤ 2.2e-7. The bound, 4e-6 relative L2, leaves
//! that 18× room and is 10⁵ below what a twiddle table read one entry off gives (0.6, tried).

mod common;

use specmux_core::fft::Fft2;
use specmux_gpu::fft::{radices, Direction, GpuFft2};
use specmux_gpu::{GpuContext, GpuError};

const TOL: f64 = 4e-6;

/// Direct 2-D DFT of interleaved complex planes, sign −1 (forward) or +1.
fn naive_dft(x: &[f32], w: usize, h: usize, sign: f64) -> Vec<f64> {
    let tau = std::f64::consts::TAU;
    let ex: Vec<(f64, f64)> = (0..w)
        .map(|t| (tau * t as f64 / w as f64).sin_cos())
        .collect();
    let ey: Vec<(f64, f64)> = (0..h)
        .map(|t| (tau * t as f64 / h as f64).sin_cos())
        .collect();
    let mut out = vec![0.0; 2 * w * h];
    for ky in 0..h {
        for kx in 0..w {
            let (mut re, mut im) = (0.0, 0.0);
            for y in 0..h {
                for xx in 0..w {
                    let (sy, cy) = ey[(ky * y) % h];
                    let (sx, cx) = ex[(kx * xx) % w];
                    // e^{sign·i(ax + ay)}
                    let (c, s) = (cx * cy - sx * sy, sign * (sx * cy + cx * sy));
                    let (a, b) = (x[2 * (y * w + xx)] as f64, x[2 * (y * w + xx) + 1] as f64);
                    re += a * c - b * s;
                    im += a * s + b * c;
                }
            }
            out[2 * (ky * w + kx)] = re;
            out[2 * (ky * w + kx) + 1] = im;
        }
    }
    out
}

/// Upload interleaved complex planes, transform on the GPU, read back.
fn gpu_fft(
    ctx: &GpuContext,
    x: &[f32],
    w: usize,
    h: usize,
    planes: usize,
    dir: Direction,
) -> Vec<f32> {
    let buf = ctx.storage("data", (x.len() * 4) as u64);
    ctx.queue.write_buffer(&buf, 0, bytemuck::cast_slice(x));
    let fft = GpuFft2::new(ctx, &buf, w, h, planes).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    fft.encode(&mut enc, &buf, dir);
    ctx.queue.submit([enc.finish()]);
    ctx.read(&buf, x.len()).unwrap()
}

#[test]
fn radices_cover_2_3_5_and_refuse_other_primes() {
    assert_eq!(radices(768), Some(vec![4, 4, 4, 4, 3]));
    assert_eq!(radices(512), Some(vec![4, 4, 4, 4, 2]));
    assert_eq!(radices(30), Some(vec![2, 3, 5]));
    assert_eq!(radices(14), None);
    assert_eq!(radices(0), None);
}

#[test]
fn forward_and_inverse_match_a_naive_dft() {
    let Some(ctx) = common::context() else { return };
    // Every radix, odd pass counts, non-square planes, two planes per batch.
    for (w, h) in [(8, 8), (16, 12), (20, 6), (30, 45), (64, 48), (2, 5)] {
        let planes = 2;
        let x = common::noise(2 * w * h * planes, (w * 100 + h) as u64);
        for (dir, sign) in [(Direction::Forward, -1.0), (Direction::Inverse, 1.0)] {
            let got = gpu_fft(&ctx, &x, w, h, planes, dir);
            for p in 0..planes {
                let r = 2 * w * h;
                let want = naive_dft(&x[p * r..(p + 1) * r], w, h, sign);
                let err = common::rel_l2(&got[p * r..(p + 1) * r], &want);
                eprintln!("{w}×{h} plane {p} {dir:?}: {err:.2e}");
                assert!(
                    err < TOL,
                    "{w}×{h} plane {p} {dir:?}: relative L2 error {err:.2e}"
                );
            }
        }
    }
}

#[test]
fn matches_the_core_fft_on_a_768_frame_and_round_trips() {
    let Some(ctx) = common::context() else { return };
    let (w, h) = (768, 768);
    let img: Vec<f32> = common::noise(w * h, 5).iter().map(|v| v + 0.5).collect();
    let x: Vec<f32> = img.iter().flat_map(|&v| [v, 0.0]).collect();
    let got = gpu_fft(&ctx, &x, w, h, 1, Direction::Forward);
    // The core stores the half plane kx ≤ w/2, column-major.
    let half = Fft2::new(w, h).forward(&img);
    let (mut gpu_half, mut cpu_half) = (Vec::new(), Vec::new());
    for kx in 0..=w / 2 {
        for ky in 0..h {
            gpu_half.extend_from_slice(&got[2 * (ky * w + kx)..2 * (ky * w + kx) + 2]);
            let c = half.data[kx * h + ky];
            cpu_half.extend([c.re as f64, c.im as f64]);
        }
    }
    let err = common::rel_l2(&gpu_half, &cpu_half);
    eprintln!("768² against core Fft2: {err:.2e}");
    assert!(err < TOL, "GPU against core Fft2: {err:.2e}");
    let back = gpu_fft(&ctx, &got, w, h, 1, Direction::Inverse);
    let n = (w * h) as f32;
    let back: Vec<f32> = back.iter().map(|v| v / n).collect();
    let err = common::rel_l2(&back, &x.iter().map(|&v| v as f64).collect::<Vec<_>>());
    eprintln!("768² round trip: {err:.2e}");
    assert!(err < TOL, "round trip: {err:.2e}");
}

#[test]
fn a_length_with_a_factor_of_seven_is_refused() {
    let Some(ctx) = common::context() else { return };
    let buf = ctx.storage("data", 14 * 8 * 8);
    match GpuFft2::new(&ctx, &buf, 14, 8, 1) {
        Err(GpuError::Unsupported(m)) => assert!(m.contains("14×8"), "{m}"),
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a 14-point FFT was planned"),
    }
}

/// The GPU FFT through the core's `FftBackend` trait against the CPU's `Fft2` through the
/// same calls: forward half spectra, the full inverse, a cropped inverse (the first columns
/// only, as a demultiplexer keeps) and the size errors. Same bound as above.
#[test]
fn the_gpu_backend_gives_the_cpu_backends_answers() {
    use specmux_core::fft_backend::FftBackend;
    use specmux_gpu::fft_backend::GpuFftBackend;
    let Some(ctx) = common::context() else { return };
    for (w, h) in [(48, 30), (20, 45), (15, 12)] {
        let (cpu, gpu) = (Fft2::new(w, h), GpuFftBackend::new(&ctx, w, h).unwrap());
        let backends: [&dyn FftBackend; 2] = [&cpu, &gpu];
        let x = common::noise(w * h, 9);
        let [sc, sg] = backends.map(|b| b.forward(&x).unwrap());
        let flat = |s: &[specmux_core::Complex32]| -> Vec<f32> {
            s.iter().flat_map(|c| [c.re, c.im]).collect()
        };
        let want: Vec<f64> = flat(&sc.data).iter().map(|&v| v as f64).collect();
        let e = common::rel_l2(&flat(&sg.data), &want);
        eprintln!("{w}×{h} forward through the trait: {e:.2e}");
        assert!(e < TOL, "{w}×{h} forward: {e:.2e}");
        // A spectrum that is not Hermitian in its DC column (as a crop leaves it) and cut
        // after 3 columns: both sides take the same real part.
        let mut cols = sc.data[..3 * h].to_vec();
        cols[1].im += 0.7;
        for c in [&sc.data[..], &cols[..]] {
            let [rc, rg] = backends.map(|b| b.inverse(c).unwrap());
            let want: Vec<f64> = rc.iter().map(|&v| v as f64).collect();
            let e = common::rel_l2(&rg, &want);
            eprintln!("{w}×{h} inverse of {} columns: {e:.2e}", c.len() / h);
            assert!(
                e < TOL,
                "{w}×{h} inverse of {} columns: {e:.2e}",
                c.len() / h
            );
        }
        assert!(gpu.forward(&x[1..]).is_err() && gpu.inverse(&sc.data[1..]).is_err());
        assert!(gpu.device().starts_with("GPU "));
    }
}
