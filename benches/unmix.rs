//! Unmixing a 768×768 frame of six channels into 31 bands on the prototype rig, for the two
//! regimes of the per-pixel QP: the true channels of the default scene (the spectral limit:
//! few pixels need the exact solver) and the Fourier estimates (most pixels do), and the metrics
//! of a 768×768×31 cube.

use criterion::{criterion_group, criterion_main, Criterion};
use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;

fn bench(c: &mut Criterion) {
    let exp = Experiment::prototype();
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let rig = Rig::build(&exp, &lib, &materials).expect("prototype rig");
    let (state, _) = Pipeline::build(&exp, &rig, &materials)
        .unwrap()
        .run()
        .unwrap();
    let recon = run::reconstructor(&exp, &rig, &state, None).unwrap();
    let channels = state.channels;
    let xhat = recon.demultiplex(&state.frame).unwrap();
    let truth = state.scene.cube;
    let mut g = c.benchmark_group("unmix 768x768 6ch to 31 bands");
    g.sample_size(20);
    for (name, x) in [("true channels", &channels), ("fourier estimates", &xhat)] {
        let (_, stats) = recon.unmix(x).unwrap();
        eprintln!("{name}: {stats:?}");
        g.bench_function(name, |b| b.iter(|| recon.unmix(x).unwrap()));
    }
    g.finish();
    let (cube, _) = recon.unmix(&xhat).unwrap();
    let mut g = c.benchmark_group("metrics");
    g.sample_size(10);
    g.bench_function("compare_768x768x31", |b| {
        b.iter(|| specmux_core::metrics::compare(&truth, &cube).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
