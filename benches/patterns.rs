//! Generating and imaging the six 768 × 768 patterns of the prototype rig (done once per rig):
//! Floyd–Steinberg and in-band-feedback dithering, coherent 4f filtering of each wheel band
//! (streaks, exact over λ) and of a 532 nm line, lens and pixels; and the whole forward model
//! of `scenes/full-rig.toml` at 768 × 768 (scene to sensor, every optical stage), whose stage
//! times are printed once, and the same with its patterns read from a warm pattern cache.
use criterion::{criterion_group, criterion_main, Criterion};
use specmux_core::spectral::Library;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::optics::dither::DitherMethod;
use specmux_twin::optics::fourier_filter::Light;
use specmux_twin::optics::imaging::imaged_patterns;
use specmux_twin::optics::imaging::OpticsConfig;
use specmux_twin::pattern_cache::PatternCache;
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

/// `specmux simulate scenes/full-rig.toml` without writing files: the forward pipeline's run.
fn full_rig(c: &mut Criterion) {
    eprintln!("rayon threads: {}", rayon::current_num_threads());
    let lib = Library::default_root();
    let materials = Materials::load(&lib).expect("spectra/ is readable");
    let exp = Experiment::load(std::path::Path::new("scenes/full-rig.toml")).expect("full rig");
    let rig = Rig::build(&exp, &lib, &materials).expect("full rig");
    let pipeline = Pipeline::build(&exp, &rig, &materials)
        .expect("full-rig pipeline")
        .with_pattern_cache(None);
    for t in pipeline.run().expect("a forward run").1 {
        eprintln!("{t:?}");
    }
    let dir = std::env::temp_dir().join(format!("specmux-bench-cache-{}", std::process::id()));
    let cache = PatternCache::open(&dir).expect("a pattern cache in the temporary folder");
    let cached = Pipeline::build(&exp, &rig, &materials)
        .expect("full-rig pipeline")
        .with_pattern_cache(Some(cache));
    cached.run().expect("a forward run that fills the cache");
    for t in cached.run().expect("a forward run from the cache").1 {
        eprintln!("cached: {t:?}");
    }
    let mut g = c.benchmark_group("forward");
    g.sample_size(10);
    g.bench_function("full_rig_768", |b| b.iter(|| pipeline.run().unwrap()));
    g.bench_function("full_rig_768_cached_patterns", |b| {
        b.iter(|| cached.run().unwrap())
    });
    g.finish();
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, patterns, full_rig);
criterion_main!(benches);
