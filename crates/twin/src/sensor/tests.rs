//! Checks of the camera model: hand-solved cases, the Poisson statistics, the rails, determinism
//! and the EMVA 1288 photon-transfer measurement of the simulated camera.

use super::*;
use specmux_core::calibration::calibrate;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;

fn uniform(sensor: &Sensor, level_e: f32) -> Cube {
    Cube::from_vec(
        sensor.width(),
        sensor.height(),
        1,
        vec![level_e; sensor.width() * sensor.height()],
    )
    .unwrap()
}

/// A camera whose DN are its electrons: K = 1, no offset, read noise, dark current or maps.
fn electron_counter() -> SensorConfig {
    SensorConfig {
        gain_dn_per_e: 1.0,
        read_noise_e: 0.0,
        dark_current_e_per_s: 0.0,
        black_offset_dn: 0.0,
        bits: 16,
        prnu_fraction: 0.0,
        dsnu_e: 0.0,
        full_well_e: 1e6,
        ..Default::default()
    }
}

/// Poisson index of dispersion D = Σ(x − x̄)²/x̄ follows χ² with N − 1 degrees of freedom when
/// mean = variance; with N = 65536, |D − (N − 1)| ≤ 4.9·√(2(N − 1)) holds with probability
/// 1 − 1e-6 (normal limit of χ²). A variance off by 2 % from the mean fails it.
#[test]
fn shot_noise_mean_equals_variance_in_electrons() {
    let sensor = Sensor::new(&electron_counter(), 256, 256).unwrap();
    for (i, &lambda) in [2.5f32, 250.0, 5000.0].iter().enumerate() {
        let frame = sensor.capture(&uniform(&sensor, lambda), i as u64).unwrap();
        let n = frame.data.len() as f64;
        let mean = frame.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let d = frame
            .data
            .iter()
            .map(|&v| (v as f64 - mean).powi(2))
            .sum::<f64>()
            / mean;
        let bound = 4.9 * (2.0 * (n - 1.0)).sqrt();
        assert!(
            (d - (n - 1.0)).abs() < bound,
            "λ={lambda}: D={d:.0}, N−1={}",
            n - 1.0
        );
        // The mean itself: standard error √(λ/N).
        let se = (lambda as f64 / n).sqrt();
        assert!(
            (mean - lambda as f64).abs() < 5.0 * se,
            "λ={lambda}: mean {mean}"
        );
    }
}

#[test]
fn dark_current_adds_its_own_shot_noise() {
    // 400 e⁻/s for 0.5 s at the reference temperature: 200 dark e⁻, Poisson like the light.
    let cfg = SensorConfig {
        dark_current_e_per_s: 400.0,
        exposure_s: 0.5,
        temperature_c: 30.0,
        ..electron_counter()
    };
    let sensor = Sensor::new(&cfg, 256, 256).unwrap();
    assert!((sensor.dark_electrons() - 200.0).abs() < 1e-9);
    let frame = sensor.capture(&uniform(&sensor, 50.0), 0).unwrap();
    let n = frame.data.len() as f64;
    let mean = frame.data.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = frame
        .data
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    assert!(
        (mean - 250.0).abs() < 5.0 * (250.0 / n).sqrt(),
        "mean {mean}"
    );
    assert!(
        (var / mean - 1.0).abs() < 4.9 * (2.0 / n).sqrt(),
        "var {var} mean {mean}"
    );
}

#[test]
fn output_is_integer_dn_within_the_adc_range() {
    // Offset 0 with read noise: the dark level sits on the bottom rail, half the pixels below it.
    let cfg = SensorConfig {
        black_offset_dn: 0.0,
        bits: 10,
        ..Default::default()
    };
    let sensor = Sensor::new(&cfg, 64, 64).unwrap();
    let max = sensor.max_dn() as f32;
    assert_eq!(max, 1023.0);
    let (mut zeros, mut tops) = (0, 0);
    for (i, level) in [0.0f32, 100.0, 3000.0, 4100.0, 1e5].iter().enumerate() {
        let frame = sensor.capture(&uniform(&sensor, *level), i as u64).unwrap();
        for &v in &frame.data {
            assert!(v.fract() == 0.0 && (0.0..=max).contains(&v), "{v}");
            zeros += (v == 0.0) as usize;
            tops += (v == max) as usize;
        }
    }
    assert!(
        zeros > 0 && tops > 0,
        "both rails are reached: {zeros} {tops}"
    );
}

#[test]
fn saturation_gives_the_full_well_rail_and_the_adc_rail() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 128, 64).unwrap();
    let rail = (cfg.gain_dn_per_e * cfg.full_well_e + cfg.black_offset_dn).round();
    assert_eq!(sensor.saturation_dn(), rail);
    let bright = sensor
        .capture(&uniform(&sensor, 10.0 * cfg.full_well_e as f32), 0)
        .unwrap();
    assert!(
        bright.data.iter().all(|&v| v as f64 == rail),
        "full-well rail {rail}"
    );
    // The rail read back through K and the offset is the full well.
    assert!(((rail - cfg.black_offset_dn) / cfg.gain_dn_per_e - cfg.full_well_e).abs() <= 2.0);

    // With a gain that maps the full well beyond 2^bits − 1 the ADC saturates first.
    let hot = SensorConfig {
        gain_dn_per_e: 1.0,
        ..cfg
    };
    let sensor = Sensor::new(&hot, 128, 64).unwrap();
    assert_eq!(sensor.saturation_dn(), 4095.0);
    let bright = sensor.capture(&uniform(&sensor, 6000.0), 0).unwrap();
    assert!(bright.data.iter().all(|&v| v == 4095.0));
}

#[test]
fn zero_light_gives_the_dark_level() {
    // Everything off: exactly the black offset.
    let quiet = SensorConfig {
        black_offset_dn: 37.0,
        ..electron_counter()
    };
    let sensor = Sensor::new(&quiet, 32, 32).unwrap();
    let dark = sensor.capture(&uniform(&sensor, 0.0), 3).unwrap();
    assert!(dark.data.iter().all(|&v| v == 37.0));

    // The default camera: mean = offset + K·μ_dark within 5 standard errors of the mean, the
    // per-pixel variance being K²(σ_r² + μ_dark + dsnu²) + 1/12.
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 256, 256).unwrap();
    let dark = sensor.capture(&uniform(&sensor, 0.0), 0).unwrap();
    let n = dark.data.len() as f64;
    let mean = dark.data.iter().map(|&v| v as f64).sum::<f64>() / n;
    let k = cfg.gain_dn_per_e;
    let var = k * k * (cfg.read_noise_e.powi(2) + sensor.dark_electrons() + cfg.dsnu_e.powi(2))
        + 1.0 / 12.0;
    let expected = cfg.black_offset_dn + k * sensor.dark_electrons();
    assert!(
        (mean - expected).abs() < 5.0 * (var / n).sqrt(),
        "{mean} vs {expected}"
    );
}

#[test]
fn same_seed_same_bits_whatever_the_thread_count() {
    let sensor = Sensor::new(&SensorConfig::default(), 96, 80).unwrap();
    let mean = Cube::from_vec(
        96,
        80,
        1,
        (0..96 * 80).map(|i| (i % 97) as f32 * 40.0).collect(),
    )
    .unwrap();
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let again = Sensor::new(&SensorConfig::default(), 96, 80).unwrap();
                (
                    again.capture(&mean, 7).unwrap(),
                    again.prnu_map().unwrap().to_vec(),
                )
            })
    };
    let (one, prnu_one) = run(1);
    let (two, prnu_two) = run(2);
    assert_eq!(one.data, two.data);
    assert_eq!(prnu_one, prnu_two);
    assert_eq!(one.data, sensor.capture(&mean, 7).unwrap().data);
    // Another frame index, or another camera seed, gives other noise.
    assert_ne!(one.data, sensor.capture(&mean, 8).unwrap().data);
    let other = Sensor::new(
        &SensorConfig {
            seed: 2,
            ..Default::default()
        },
        96,
        80,
    )
    .unwrap();
    assert_ne!(one.data, other.capture(&mean, 7).unwrap().data);
}

#[test]
fn stages_not_asked_for_draw_nothing() {
    let sensor = Sensor::new(&electron_counter(), 8, 8).unwrap();
    assert!(sensor.prnu_map().is_none() && sensor.dsnu_map().is_none());
    let sensor = Sensor::new(&SensorConfig::default(), 8, 8).unwrap();
    assert!(sensor.prnu_map().is_some() && sensor.dsnu_map().is_some());
}

#[test]
fn fixed_pattern_maps_have_the_configured_spread() {
    // Sample std of N Gaussian values: relative standard error 1/√(2N); bound 5 of them.
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 256, 256).unwrap();
    let n = (256 * 256) as f64;
    for (map, centre, sigma) in [
        (sensor.prnu_map().unwrap(), 1.0, cfg.prnu_fraction),
        (sensor.dsnu_map().unwrap(), 0.0, cfg.dsnu_e),
    ] {
        let mean = map.iter().map(|&v| v as f64).sum::<f64>() / n;
        let sd = (map.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert!(
            (mean - centre).abs() < 5.0 * sigma / n.sqrt(),
            "mean {mean}"
        );
        assert!(
            (sd / sigma - 1.0).abs() < 5.0 / (2.0 * n).sqrt(),
            "sd {sd} vs {sigma}"
        );
    }
}

#[test]
fn bad_input_is_refused() {
    let err = Sensor::new(
        &SensorConfig {
            bits: 0,
            ..Default::default()
        },
        4,
        4,
    )
    .unwrap_err();
    assert!(err.to_string().contains("rig.sensor.bits"), "{err}");
    assert!(Sensor::new(&SensorConfig::default(), 0, 4).is_err());
    let sensor = Sensor::new(&SensorConfig::default(), 4, 4).unwrap();
    let mut mean = uniform(&sensor, 10.0);
    mean.data[5] = -1.0;
    let msg = sensor.capture(&mean, 0).unwrap_err().to_string();
    assert!(msg.contains("pixel (1, 1)") && msg.contains("-1"), "{msg}");
    mean.data[5] = f32::NAN;
    assert!(sensor.capture(&mean, 0).is_err());
    assert!(sensor.capture(&Cube::zeros(4, 4, 2), 0).is_err());
    assert!(sensor.dark_frame(0).is_err());
    assert!(sensor.flat_frame(-5.0, 2).is_err());
}

#[test]
fn relative_frame_maps_full_scale_to_the_configured_electrons() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 2, 2).unwrap();
    let frame = Cube::from_vec(2, 2, 1, vec![0.0, 0.5, 2.0, 4.0]).unwrap();
    let e = sensor.electrons_from_relative(&frame, 2.0).unwrap();
    let s = cfg.electrons_at_full_scale as f32;
    assert_eq!(e.data, vec![0.0, 0.25 * s, s, 2.0 * s]);
    for bad in [-0.5f32, f32::NAN] {
        let mut f = frame.clone();
        f.data[1] = bad;
        assert!(sensor.electrons_from_relative(&f, 2.0).is_err());
    }
    assert!(sensor.electrons_from_relative(&frame, 0.0).is_err());
    assert!(sensor
        .electrons_from_relative(&frame, f32::INFINITY)
        .is_err());
}

/// 1 µW/cm² = 0.01 W/m² of 550 nm light (a triangle 549–551 nm of peak 0.01 W·m⁻²·nm⁻¹, whose
/// λ-weighted integral is exactly 550 nm × 0.01 W/m² by symmetry) on a 3.45 µm pixel for 1 ms
/// with QE 1: photons = P·t/(hc/λ) = 0.01 × (3.45e-6)² × 1e-3 × 550e-9 / (6.62607015e-34 ×
/// 299792458) = 1.190 25e-16 J / 3.611 7e-19 J = 329.55.
#[test]
fn radiometry_hand_case() {
    let e = Curve::new("550 nm", vec![549.0, 550.0, 551.0], vec![0.0, 0.01, 0.0]).unwrap();
    let qe = Curve::constant("qe", 400.0, 700.0, 1.0).unwrap();
    let got = photo_electrons(&e, &qe, (3.45e-6f64).powi(2), 1e-3).unwrap();
    let hand: f64 = 0.01 * 3.45e-6 * 3.45e-6 * 1e-3 * 550e-9 / (6.626_070_15e-34 * 299_792_458.0);
    assert!((hand - 329.55).abs() < 0.01, "{hand}");
    assert!((got - hand).abs() < 1e-9 * hand, "{got} vs {hand}");
    // QE scales it, and the sensor applies its own pitch and exposure.
    let half = Curve::constant("qe", 400.0, 700.0, 0.5).unwrap();
    let cfg = SensorConfig {
        pixel_pitch_um: 3.45,
        exposure_s: 1e-3,
        ..Default::default()
    };
    let sensor = Sensor::new(&cfg, 3, 2).unwrap();
    let frame = sensor
        .electrons_from_irradiance(SpectralIrradiance::Uniform(&e), &half)
        .unwrap();
    assert!(frame
        .data
        .iter()
        .all(|&v| (v as f64 - 0.5 * hand).abs() < 1e-4));
    let bad_qe = Curve::constant("qe", 400.0, 700.0, 1.2).unwrap();
    assert!(photo_electrons(&e, &bad_qe, 1e-11, 1e-3).is_err());
}

/// A band cube is read as piecewise linear between band centres, so a cube that is constant
/// over the pixels equals the uniform curve through its band values; and it is linear.
#[test]
fn band_cube_matches_the_curve_through_its_bands() {
    let grid = Grid::new(450.0, 50.0, 5).unwrap();
    let values = [0.02, 0.05, 0.01, 0.03, 0.04];
    let qe = Curve::new("qe", vec![400.0, 550.0, 750.0], vec![0.3, 0.7, 0.2]).unwrap();
    let sensor = Sensor::new(&SensorConfig::default(), 3, 2).unwrap();
    let mut cube = Cube::zeros(3, 2, 5);
    for (k, v) in values.iter().enumerate() {
        cube.plane_mut(k).fill(*v as f32);
    }
    cube.plane_mut(2)[4] = 0.03; // one pixel differs in band 2
    let bands = sensor
        .electrons_from_irradiance(
            SpectralIrradiance::Bands {
                cube: &cube,
                grid: &grid,
            },
            &qe,
        )
        .unwrap();
    let curve = Curve::from_grid("e", &grid, values.to_vec()).unwrap();
    let flat = sensor
        .electrons_from_irradiance(SpectralIrradiance::Uniform(&curve), &qe)
        .unwrap();
    assert!((bands.data[0] - flat.data[0]).abs() < 1e-5 * flat.data[0]);
    // Linearity: the extra 0.02 W·m⁻²·nm⁻¹ in band 2 adds the band-2 hat's electrons.
    let mut bump = vec![0.0; 5];
    bump[2] = 0.02;
    let hat = Curve::from_grid("bump", &grid, bump).unwrap();
    let extra = photo_electrons(&hat, &qe, 25e-12, SensorConfig::default().exposure_s).unwrap();
    assert!(((bands.data[4] - bands.data[0]) as f64 - extra).abs() < 1e-4 * extra);
    let wrong = Cube::zeros(3, 2, 4);
    assert!(sensor
        .electrons_from_irradiance(
            SpectralIrradiance::Bands {
                cube: &wrong,
                grid: &grid
            },
            &qe
        )
        .is_err());
}

/// Dark subtraction and flat division remove the fixed patterns (offset, DSNU, PRNU) of a
/// uniform scene: what is left is the temporal noise of the raw frame, increased by the flat's
/// temporal noise (1/L of it), σ_cal² = σ_raw²(1 + 1/L) to first order in σ/S. The sample
/// variance of N pixels has relative standard error √(2/N); the bound is 5 of them.
#[test]
fn calibration_removes_the_fixed_patterns() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 256, 256).unwrap();
    let level = 8000.0;
    let l = 16;
    let dark = sensor.dark_frame(l).unwrap();
    let flat = sensor.flat_frame(level, l).unwrap();
    let scene = uniform(&sensor, level as f32);
    let (a, b) = (
        sensor.capture(&scene, 0).unwrap(),
        sensor.capture(&scene, 1).unwrap(),
    );
    let n = a.data.len() as f64;
    let stats = |c: &Cube| {
        let m = c.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        (
            m,
            c.data.iter().map(|&v| (v as f64 - m).powi(2)).sum::<f64>() / (n - 1.0),
        )
    };
    let temporal = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
        .sum::<f64>()
        / (2.0 * n);
    let (_, raw_var) = stats(&a);
    let cal = calibrate(&a, &dark, &flat).unwrap();
    let (_, cal_var) = stats(&cal);
    // Dark-frame noise enters twice more, K²σ_dark²/L each, negligible but counted.
    let dark_var =
        cfg.gain_dn_per_e.powi(2) * (cfg.read_noise_e.powi(2) + sensor.dark_electrons()) / l as f64;
    let expected = temporal * (1.0 + 1.0 / l as f64) + dark_var;
    assert!(
        (cal_var / expected - 1.0).abs() < 5.0 * (2.0 / n).sqrt(),
        "calibrated variance {cal_var:.1} vs {expected:.1}"
    );
    // The raw frame carried PRNU on top: (K·level·prnu)² = 400 DN² more.
    assert!(raw_var > expected + 300.0, "raw {raw_var:.1}");
}

/// The EMVA 1288 measurement of the simulated default camera returns what it was given.
/// Bounds, all 5 standard errors, from the N = 65536 pixels of each frame:
/// - K: the fit's standard error from Var(σ̂_y²) = 2σ_y⁴/(N − 1) at each level (≤ 1 % of K);
/// - σ_d (read noise with the dark current's shot noise, √(σ_r² + μ_dark)): from
///   Var(σ̂_dark²) = 2σ_dark⁴/(N − 1) and the error of K;
/// - DSNU, PRNU: against the realised maps; the spatial variance of an L-frame average has
///   relative error √(2/N) on (fixed + temporal/L), and the subtracted temporal/L part too;
/// - full well: the EMVA saturation capacity is the mean at the variance maximum, which comes
///   when the upper tail of the per-pixel signals (spread σ_s = √(μ_e.sat + (PRNU·μ_e.sat)² +
///   σ_r² + DSNU²), temporal and fixed together) reaches the clip: for Gaussian tails the loss
///   of variance overtakes the linear rise between 2 and 3 σ_s below it (2.7 σ_s = 530 e⁻ for
///   these defaults, from the variance of the clipped Gaussian averaged over the maps); the
///   bound is 4 σ_s below the full well and one level step above.
#[test]
fn photon_transfer_recovers_the_camera() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 256, 256).unwrap();
    let fw = cfg.full_well_e;
    let step = fw / 150.0;
    let levels = default_levels(fw);
    assert_eq!(
        (levels[26], levels[27], levels.len()),
        (13_500.0, 13_600.0, 53)
    );
    let r = photon_transfer(&sensor, &levels).unwrap();
    let n = r.pixels as f64;
    let k = cfg.gain_dn_per_e;

    assert!(
        r.k_stderr_dn_per_e < 0.01 * k,
        "stderr {}",
        r.k_stderr_dn_per_e
    );
    assert!(
        (r.k_dn_per_e - k).abs() < 5.0 * r.k_stderr_dn_per_e,
        "K {} ± {}",
        r.k_dn_per_e,
        r.k_stderr_dn_per_e
    );

    let sigma_d = (cfg.read_noise_e.powi(2) + sensor.dark_electrons()).sqrt();
    let var_rel =
        (2.0 / (n - 1.0)).sqrt() * r.dark_variance_dn2 / (r.dark_variance_dn2 - 1.0 / 12.0);
    let sd_rel = 0.5 * var_rel.hypot(2.0 * r.k_stderr_dn_per_e / k);
    assert!(!r.quantisation_limited);
    assert!(
        (r.read_noise_e / sigma_d - 1.0).abs() < 5.0 * sd_rel,
        "σ_d {} vs {sigma_d} (±{:.2} %)",
        r.read_noise_e,
        100.0 * sd_rel
    );

    let spread =
        (fw + (cfg.prnu_fraction * fw).powi(2) + cfg.read_noise_e.powi(2) + cfg.dsnu_e.powi(2))
            .sqrt();
    assert!(
        r.full_well_e > fw - 4.0 * spread && r.full_well_e < fw + step,
        "saturation capacity {} vs full well {fw} (σ_s = {spread:.0})",
        r.full_well_e
    );

    let map_sd = |m: &[f32]| {
        let mean = m.iter().map(|&v| v as f64).sum::<f64>() / n;
        (m.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    };
    let l = r.nonuniformity_frames as f64;
    let temporal_dark = r.dark_variance_dn2 / l;
    let dsnu_true = map_sd(sensor.dsnu_map().unwrap());
    let fixed_dark = (k * dsnu_true).powi(2);
    let s2_dark_sd = (2.0 / n).sqrt() * (fixed_dark + temporal_dark).hypot(temporal_dark);
    let dsnu_rel = 0.5 * (s2_dark_sd / fixed_dark).hypot(2.0 * r.k_stderr_dn_per_e / k);
    assert!(
        (r.dsnu_e / dsnu_true - 1.0).abs() < 5.0 * dsnu_rel,
        "DSNU {} vs {dsnu_true} (±{:.2} %)",
        r.dsnu_e,
        100.0 * dsnu_rel
    );

    let prnu_true = map_sd(sensor.prnu_map().unwrap());
    let half = r
        .points
        .iter()
        .find(|p| p.level_e == r.prnu_level_e)
        .unwrap();
    let signal = half.mean_dn - r.dark_mean_dn;
    let fixed_half = (signal * prnu_true).powi(2);
    let temporal_half = half.variance_dn2 / l;
    let s2_half_sd =
        (2.0 / n).sqrt() * (fixed_half + fixed_dark + temporal_half).hypot(temporal_half);
    let prnu_rel = 0.5 * s2_half_sd.hypot(s2_dark_sd) / fixed_half;
    assert!(
        (r.prnu_fraction / prnu_true - 1.0).abs() < 5.0 * prnu_rel,
        "PRNU {} vs {prnu_true} (±{:.2} %)",
        r.prnu_fraction,
        100.0 * prnu_rel
    );
    // The PRNU level is the one nearest 50 % of saturation: within half a level step (250 e⁻).
    let half_e = signal / r.k_dn_per_e;
    assert!(
        (half_e - 0.5 * r.full_well_e).abs() <= 250.0,
        "PRNU at {half_e} e⁻"
    );
}

#[test]
fn photon_transfer_refuses_a_series_that_does_not_saturate() {
    let sensor = Sensor::new(&SensorConfig::default(), 32, 32).unwrap();
    let msg = photon_transfer(&sensor, &[500.0, 1000.0, 2000.0, 4000.0, 8000.0])
        .unwrap_err()
        .to_string();
    assert!(msg.contains("still rises"), "{msg}");
    assert!(photon_transfer(&sensor, &[1.0, 2.0]).is_err());
    assert!(photon_transfer(&sensor, &[1.0, 2.0, 3.0, 4.0, f64::NAN]).is_err());
}

/// The frames handed to an outside referee are the ones the measurement reduced: each pair
/// gives its point's mean and variance, and the dark sequence averages to the dark frame.
#[test]
fn ptc_frames_are_the_frames_photon_transfer_measured() {
    let cfg = SensorConfig::default();
    let sensor = Sensor::new(&cfg, 32, 32).unwrap();
    let levels = default_levels(cfg.full_well_e);
    let r = photon_transfer(&sensor, &levels).unwrap();
    let f = ptc_frames(&sensor, &levels, &r).unwrap();
    assert_eq!(f.pairs.len(), r.points.len() + 1);
    assert_eq!(f.pairs[0].0, 0.0);
    let (m, v) = ptc::pair_statistics(&f.pairs[0].1[0], &f.pairs[0].1[1]);
    assert_eq!((m, v), (r.dark_mean_dn, r.dark_variance_dn2));
    for ((level, [a, b]), p) in f.pairs[1..].iter().zip(&r.points) {
        assert_eq!(*level, p.level_e);
        assert_eq!(ptc::pair_statistics(a, b), (p.mean_dn, p.variance_dn2));
    }
    let l = r.nonuniformity_frames;
    assert_eq!((f.dark_sequence.len(), f.flat_sequence.1.len()), (l, l));
    let avg = sensor.dark_frame(l).unwrap();
    let mean: Vec<f32> = (0..avg.data.len())
        .map(|i| {
            (f.dark_sequence
                .iter()
                .map(|c| c.data[i] as f64)
                .sum::<f64>()
                / l as f64) as f32
        })
        .collect();
    assert_eq!(mean, avg.data);
    assert_eq!(f.flat_sequence.0, r.prnu_level_e);
}

/// An averaged capture draws each pixel's exposures together (its sampler set up once), yet
/// it is the f64 mean of the exposures drawn one frame at a time, to the bit: at a level PTRS
/// samples and at one Knuth's method does.
#[test]
fn a_flat_frame_is_the_mean_of_its_exposures() {
    let sensor = Sensor::new(&SensorConfig::default(), 24, 16).unwrap();
    for level in [7500.0, 4.0] {
        let n = 5;
        let avg = sensor.flat_frame(level, n).unwrap();
        let frames: Vec<Cube> = (0..n)
            .map(|k| sensor.flat_exposure(level, k).unwrap())
            .collect();
        let mean: Vec<f32> = (0..avg.data.len())
            .map(|i| (frames.iter().map(|c| c.data[i] as f64).sum::<f64>() / n as f64) as f32)
            .collect();
        assert_eq!(mean, avg.data, "level {level} e⁻");
        assert_ne!(frames[0].data, frames[1].data);
    }
}
