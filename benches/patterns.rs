//! Generating and imaging the six 768 × 768 patterns of the prototype rig (done once per rig):
//! Floyd–Steinberg and in-band-feedback dithering, coherent 4f filtering of each wheel band
//! (streaks, exact over λ) and of a 532 nm line, lens and pixels.
use criterion::{criterion_group, criterion_main, Criterion};
use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::optics::dither::DitherMethod;
use specmux_twin::optics::fourier_filter::Light;
use specmux_twin::optics::imaging::imaged_patterns;
use specmux_twin::optics::imaging::OpticsConfig;
use specmux_twin::rig::Rig;
use specmux_twin::scene::Materials;

fn patterns(c: &mut Criterion) {
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let rig = Rig::build(&Experiment::prototype(), &lib, &materials).expect("prototype rig");
    let spectra = rig.pattern_spectra().unwrap();
    let mut g = c.benchmark_group("patterns");
    g.sample_size(10);
    for (m, light) in [
        (DitherMethod::FloydSteinberg, Light::Channel),
        (DitherMethod::InBandFeedback, Light::Channel),
        (DitherMethod::FloydSteinberg, Light::Line),
    ] {
        let mut cfg = OpticsConfig::prototype();
        if let Some(d) = cfg.dmd.as_mut() {
            d.dither = m;
        }
        if let Some(f) = cfg.fourier_filter.as_mut() {
            f.light = light;
        }
        let lights = cfg.pattern_lights(&spectra).unwrap();
        g.bench_function(
            format!("six_768_{}_coherent_{light:?}", m.name()).to_lowercase(),
            |b| b.iter(|| imaged_patterns(&cfg, &rig.carriers, &lights, 768, 768).unwrap()),
        );
    }
    g.finish();
}

criterion_group!(benches, patterns);
criterion_main!(benches);
