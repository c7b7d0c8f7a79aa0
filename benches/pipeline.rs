//! Demultiplexing + unmixing of one 768×768 frame of the prototype (the real-time path), on the
//! edge-rich default scene (most pixels' unconstrained spectra dip below zero, so the exact QP
//! runs on them), on the smooth CAVE-like scene the paper's figures describe, and on the full
//! rig of `scenes/full-rig.toml` (noisy raw frame, dark/flat correction, calibrated patterns,
//! the exposure's crosstalk undone); with a fresh output cube per frame and with one kept from
//! frame to frame. Throughput is one frame per iteration, so criterion's "thrpt" is in frames/s;
//! the rayon thread count is printed. Run from the repository's root (as `cargo bench` does).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;

fn bench(c: &mut Criterion) {
    eprintln!("rayon threads: {}", rayon::current_num_threads());
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let scenes = [
        ("dead-leaves", Experiment::prototype()),
        (
            "shaded-objects",
            Experiment::from_toml(
                "[scene]\nsource = \"shaded-objects\"\nseed = 11\n",
                "shaded-objects",
            )
            .expect("a valid experiment"),
        ),
        (
            "full-rig",
            Experiment::load(std::path::Path::new("scenes/full-rig.toml"))
                .expect("scenes/full-rig.toml"),
        ),
    ];
    for (name, exp) in scenes {
        let rig = Rig::build(&exp, &lib, &materials).expect("the scene's rig");
        let (state, _) = Pipeline::build(&exp, &rig, &materials)
            .unwrap()
            .run()
            .unwrap();
        let frame = state.frame.clone();
        let recon = run::reconstructor(&exp, &rig, &state, None).unwrap();
        let xhat = recon.demultiplex(&frame).unwrap();
        let (_, stats) = recon.unmix(&xhat).unwrap();
        let crosstalk = recon.demix.is_some();
        eprintln!("{name}: {stats:?}, crosstalk undone: {crosstalk}");
        let mut g = c.benchmark_group(format!("768x768 {name}"));
        g.sample_size(20);
        g.throughput(Throughput::Elements(1));
        g.bench_function("demultiplex", |b| {
            b.iter(|| recon.demultiplex(&frame).unwrap())
        });
        g.bench_function("unmix", |b| b.iter(|| recon.unmix(&xhat).unwrap()));
        g.bench_function("demultiplex+unmix", |b| {
            b.iter(|| recon.unmix(&recon.demultiplex(&frame).unwrap()).unwrap())
        });
        // A camera loop keeps its cubes: the 73 MB of 31 bands and the 14 MB of channels are
        // not cleared and faulted in again each frame.
        let mut cube = recon.unmix(&xhat).unwrap().0;
        let mut x = xhat.clone();
        g.bench_function("demultiplex+unmix, output reused", |b| {
            b.iter(|| {
                recon.demultiplex_into(&frame, &mut x).unwrap();
                recon.unmixer.unmix_into(&x, &mut cube).unwrap()
            })
        });
        g.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
