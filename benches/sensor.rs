//! Noise generation of the EMVA 1288 camera for one prototype-sized frame (768 × 768): the
//! photon-transfer chain of `Sensor::capture` with the default GO-5000-class parameters, and a
//! calibration capture (`Sensor::averaged_capture`, 16 exposures averaged).

use criterion::{black_box, criterion_group, criterion_main, Criterion};
use specmux_core::Cube;
use specmux_twin::sensor::Sensor;
use specmux_twin::sensor::SensorConfig;

fn capture(c: &mut Criterion) {
    let (w, h) = (768, 768);
    let sensor = Sensor::new(&SensorConfig::default(), w, h).unwrap();
    // A scene-like frame: a ramp from dark to 80 % of the full well, so both Poisson branches
    // (Knuth below 10 e⁻, PTRS above) and the clip are exercised.
    let mean: Vec<f32> = (0..w * h)
        .map(|i| (i % w) as f32 / w as f32 * 12_000.0)
        .collect();
    let mean = Cube::from_vec(w, h, 1, mean).unwrap();
    let mut frame = 0u64;
    c.bench_function("sensor capture 768x768", |b| {
        b.iter(|| {
            frame += 1;
            black_box(sensor.capture(&mean, frame).unwrap())
        })
    });
    c.bench_function("sensor averaged capture 768x768 x16", |b| {
        b.iter(|| {
            frame += 1;
            black_box(sensor.averaged_capture(&mean, 16, frame).unwrap())
        })
    });
}

criterion_group!(benches, capture);
criterion_main!(benches);
