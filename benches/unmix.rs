//! Unmixing a 768×768 frame of six channels into 31 bands with a realistic basis (uncentred PCA
//! of random smooth positive spectra), and the metrics of a 768×768×31 cube.

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64;
use specmux::recon::qp::Unmixer;
use specmux::Cube;

const BANDS: usize = 31;
const SIZE: usize = 768;

/// Random smooth positive spectra (bands × count): a floor plus three Gaussian bumps.
fn smooth_spectra(rng: &mut Pcg64, count: usize) -> DMatrix<f64> {
    let mut s = DMatrix::zeros(BANDS, count);
    for c in 0..count {
        let floor: f64 = rng.gen_range(0.02..0.2);
        let bumps: Vec<(f64, f64, f64)> = (0..3)
            .map(|_| {
                (
                    rng.gen_range(0.0..0.6),
                    rng.gen_range(0.0..31.0),
                    rng.gen_range(3.0..10.0),
                )
            })
            .collect();
        for b in 0..BANDS {
            s[(b, c)] = floor
                + bumps
                    .iter()
                    .map(|(a, mu, w)| a * (-((b as f64 - mu) / w).powi(2)).exp())
                    .sum::<f64>();
        }
    }
    s
}

/// An unmixer (6 broad filters, J = 6 PCA basis, η = 0.3), a frame of x̂ = F·(scene spectra +
/// `floor`) with 2 % noise, and the truth cube.
fn setup(floor: f64) -> (Unmixer, Cube, Cube) {
    let mut rng = Pcg64::seed_from_u64(11);
    let train = smooth_spectra(&mut rng, 200);
    let eig = nalgebra::SymmetricEigen::new(&train * train.transpose());
    let mut order: Vec<usize> = (0..BANDS).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let b = DMatrix::from_fn(BANDS, 6, |i, j| eig.eigenvectors[(i, order[j])]);
    let f = smooth_spectra(&mut rng, 6).transpose() * &b;
    let unmixer = Unmixer::new(&f, &b, 0.3).unwrap();
    // 1000 scene spectra tiled over the frame, with per-pixel noise.
    let scene = smooth_spectra(&mut rng, 1000).add_scalar(floor);
    let channels = &f * (b.transpose() * &scene);
    let noise = Normal::new(0.0, 0.02).unwrap();
    let npx = SIZE * SIZE;
    let mut xhat = Cube::zeros(SIZE, SIZE, 6);
    let mut truth = Cube::zeros(SIZE, SIZE, BANDS);
    for p in 0..npx {
        let s = (p * 7919) % 1000;
        for j in 0..6 {
            xhat.data[j * npx + p] = (channels[(j, s)] * (1.0 + noise.sample(&mut rng))) as f32;
        }
        for k in 0..BANDS {
            truth.data[k * npx + p] = scene[(k, s)] as f32;
        }
    }
    (unmixer, xhat, truth)
}

fn bench(c: &mut Criterion) {
    // Bright scene: no band goes negative, the batched linear map alone.
    let (unmixer, xhat, _) = setup(0.5);
    let (_, stats) = unmixer.unmix(&xhat).unwrap();
    eprintln!("bright scene: {stats:?}");
    c.bench_function("unmix_768x768_6ch_to_31_bands_bright", |bch| {
        bch.iter(|| unmixer.unmix(&xhat).unwrap())
    });
    // Dark scene (floors 0.02–0.2): the exact solver runs on every pixel with a negative band.
    let (unmixer, xhat, truth) = setup(0.0);
    let (cube, stats) = unmixer.unmix(&xhat).unwrap();
    eprintln!("dark scene: {stats:?}");
    c.bench_function("unmix_768x768_6ch_to_31_bands_dark", |bch| {
        bch.iter(|| unmixer.unmix(&xhat).unwrap())
    });
    let mut g = c.benchmark_group("metrics");
    g.sample_size(10);
    g.bench_function("compare_768x768x31", |bch| {
        bch.iter(|| specmux::metrics::compare(&truth, &cube).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
