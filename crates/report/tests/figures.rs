//! The report's figures are written and are not blank.

use specmux_report::{ptc::plot_ptc, timeline::timeline_png};
use specmux_twin::sensor::{default_levels, photon_transfer, Sensor, SensorConfig};
use specmux_twin::timing::TimingConfig;

/// The path `name` in a fresh scratch folder, and the folder's guard (it removes it on drop).
fn temp(name: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let d = tempfile::Builder::new()
        .prefix("specmux-figures-")
        .tempdir()
        .unwrap();
    let path = d.path().join(name);
    (d, path)
}

#[test]
fn photon_transfer_png_is_written() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 64, 64).unwrap();
    let r = photon_transfer(&sensor, &default_levels(cfg.full_well_e)).unwrap();
    let (_scratch, path) = temp("ptc.png");
    plot_ptc(&r, &path).unwrap();
    let png = image::open(&path).unwrap();
    assert_eq!((png.width(), png.height()), (900, 600));
}

#[test]
fn timeline_png_is_written() {
    let mut c = TimingConfig::default();
    c.wheel.spot_diameter_mm = 1.0;
    c.wheel.spot_radius_mm = 20.0;
    c.camera.exposure_s = 0.0405;
    let (_scratch, path) = temp("timeline.png");
    timeline_png(&c, &[], &path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!(img.width(), 1500);
    // Not blank: the panels drew coloured pixels.
    let coloured = img
        .pixels()
        .filter(|p| p.0.iter().max().unwrap() - p.0.iter().min().unwrap() > 60)
        .count();
    assert!(coloured > 10_000, "{coloured}");
}

#[test]
fn timeline_segments_take_the_filters_colours() {
    let c = TimingConfig::default();
    let chips: Vec<[u8; 3]> = (0..6).map(|i| [200, 20 + 30 * i as u8, 10]).collect();
    let (_scratch, path) = temp("timeline-chips.png");
    timeline_png(&c, &chips, &path).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    for chip in &chips {
        let n = img.pixels().filter(|p| p.0 == *chip).count();
        assert!(n > 500, "chip {chip:?}: {n} pixels");
    }
}

#[test]
fn trigger_chain_draws_every_lane_in_its_window() {
    use specmux_report::timeline::{trigger_chain_png, Lane};
    let lanes = vec![
        Lane {
            name: "wheel index pulse".into(),
            edges: (0..50).map(|k| k as f64 * 1e-3).collect(),
            spans: vec![],
        },
        Lane {
            name: "camera exposure".into(),
            edges: vec![],
            spans: vec![(0.002, 0.042)],
        },
    ];
    let windows = vec![
        ("a frame".to_string(), 0.0, 0.05),
        ("zoom".to_string(), 0.0015, 0.0045),
    ];
    let (_scratch, path) = temp("trigger-chain.png");
    trigger_chain_png(&path, &lanes, &windows).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (1500, 2 * (70 + 80)));
    let coloured = img
        .pixels()
        .filter(|p| p.0.iter().max().unwrap() - p.0.iter().min().unwrap() > 40)
        .count();
    assert!(coloured > 20_000, "{coloured}");
}
