//! Generating and imaging the six 768 × 768 patterns of the prototype rig (done once per rig):
//! Floyd–Steinberg and in-band-feedback dithering, coherent 4f filtering, lens and pixels.
use criterion::{criterion_group, criterion_main, Criterion};
use specmux::optics::carriers::default_layout;
use specmux::optics::dither::DitherMethod;
use specmux::optics::imaging::{imaged_patterns, OpticsConfig};

fn patterns(c: &mut Criterion) {
    let carriers = default_layout();
    let mut g = c.benchmark_group("patterns");
    g.sample_size(10);
    for m in [DitherMethod::FloydSteinberg, DitherMethod::InBandFeedback] {
        let mut cfg = OpticsConfig::prototype();
        if let Some(d) = cfg.dmd.as_mut() {
            d.dither = m;
        }
        g.bench_function(format!("six_768_{}_coherent", m.name()), |b| {
            b.iter(|| imaged_patterns(&cfg, &carriers, 768, 768).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, patterns);
criterion_main!(benches);
