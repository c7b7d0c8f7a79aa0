//! GAP de-aliasing speed on the prototype's 768×768×6: one iteration of GAP (wavelet) and of
//! GAP-TV, and, printed before the timings, the iterations and wall time needed to come within
//! 1 dB of the converged PSNR on a dead-leaves frame (ideal patterns of the default layout).
//! Run: `RAYON_NUM_THREADS=2 cargo bench --bench gap -- --warm-up-time 1 --measurement-time 5`.

use criterion::Criterion;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use specmux_core::carriers::default_layout;
use specmux_core::demux::Demux;
use specmux_core::gap::Gap;
use specmux_core::gap::GapConfig;
use specmux_core::gap::Method;
use specmux_core::Cube;
use specmux_twin::scene::dead_leaves;
use std::time::Instant;

const N: usize = 768;

/// (truth, patterns, frame, Fourier seed): six channels sharing dead-leaves edges.
fn case() -> (Cube, Cube, Cube, Cube) {
    let labels = dead_leaves::labels(N, N, 16, 7);
    let mut rng = Pcg64::seed_from_u64(107);
    let spectra: Vec<[f32; 6]> = (0..16)
        .map(|_| std::array::from_fn(|_| rng.gen_range(0.05..1.0)))
        .collect();
    let mut x = Cube::zeros(N, N, 6);
    for (k, plane) in x.planes_mut().enumerate() {
        for (v, &l) in plane.iter_mut().zip(&labels) {
            *v = spectra[l as usize][k];
        }
    }
    let carriers = default_layout();
    let s_data = carriers
        .iter()
        .flat_map(|c| c.ideal_pattern(N, N))
        .collect();
    let s = Cube::from_vec(N, N, 6, s_data).unwrap();
    let y_data = (0..N * N)
        .map(|p| (0..6).map(|k| x.plane(k)[p] * s.plane(k)[p]).sum())
        .collect();
    let y = Cube::from_vec(N, N, 1, y_data).unwrap();
    let xh = Demux::new(N, N, &carriers, 0.25).run(&y).unwrap();
    (x, s, y, xh)
}

/// Iterations and seconds to come within 1 dB of the PSNR after `max_it` iterations.
fn convergence(method: Method, (x, s, y, xh): &(Cube, Cube, Cube, Cube)) {
    let max_it = 100;
    let cfg = GapConfig {
        method,
        iterations: max_it,
        ..Default::default()
    };
    let gap = Gap::new(s, &cfg, "bench").unwrap();
    let (_, stats) = gap.run(y, xh, Some(x)).unwrap();
    let p = &stats.psnr_db;
    let target = p[max_it] - 1.0;
    let k = p.iter().position(|&v| v >= target).unwrap();
    let t0 = Instant::now();
    let mut st = gap.start(y, xh).unwrap();
    for _ in 0..k {
        gap.step(&mut st);
    }
    println!(
        "{method:?}: seed {:.2} dB, {max_it} iterations {:.2} dB, within 1 dB after {k} iterations ({:.2} dB) in {:.3} s",
        p[0],
        p[max_it],
        p[k],
        t0.elapsed().as_secs_f64()
    );
}

fn main() {
    let data = case();
    convergence(Method::Gap, &data);
    convergence(Method::GapTv, &data);
    let (_, s, y, xh) = &data;
    let mut c = Criterion::default().sample_size(10).configure_from_args();
    for (name, method) in [
        ("gap_iteration_768x768x6", Method::Gap),
        ("gap_tv_iteration_768x768x6", Method::GapTv),
    ] {
        let gap = Gap::new(
            s,
            &GapConfig {
                method,
                ..Default::default()
            },
            "bench",
        )
        .unwrap();
        let mut st = gap.start(y, xh).unwrap();
        c.bench_function(name, |b| b.iter(|| gap.step(&mut st)));
    }
    c.final_summary();
}
