//! Tests of the timing model against hand-solved cases, brute-force sampling and properties.

use super::*;
use crate::timing::schedule::GaussLegendre;
use crate::timing::schedule::Schedule;
use crate::timing::weights::exposure_energy;
use crate::timing::weights::GL_ORDER;
use specmux_core::crosstalk::crosstalk_inverse;
use specmux_core::Error;

fn assert_matrix(w: &[Vec<f64>], expect: impl Fn(usize, usize) -> f64, tol: f64) {
    for (i, row) in w.iter().enumerate() {
        for (k, &v) in row.iter().enumerate() {
            let e = expect(i, k);
            assert!(
                (v - e).abs() <= tol,
                "w[{i}][{k}] = {v}, expected {e} (±{tol})\n{w:?}"
            );
        }
    }
}

#[test]
fn defaults_are_the_prototype_and_valid() {
    let c = TimingConfig::default();
    c.validate("test").unwrap();
    assert_eq!(c.wheel.segments_deg, vec![60.0; 6]);
    assert_eq!(c.wheel.rate_hz, 1000.0);
    assert_eq!(c.dmd.max_rate_hz, 20_000.0);
    assert_eq!(c.camera.frame_rate_hz, 24.0);
    assert!((c.camera.exposure_s * c.wheel.rate_hz - 40.0).abs() < 1e-12);
}

#[test]
fn aligned_whole_turns_give_the_identity() {
    let tw = weights(&TimingConfig::default()).unwrap();
    assert_matrix(&tw.w, |i, k| if i == k { 1.0 } else { 0.0 }, 1e-12);
    assert_eq!(tw.spoke_fraction, 0.0);
    assert!(
        tw.warnings
            .iter()
            .all(|w| !w.contains("not a whole number")),
        "{:?}",
        tw.warnings
    );
}

#[test]
fn unequal_segments_give_n_times_their_fraction() {
    let mut c = TimingConfig::default();
    c.wheel.segments_deg = vec![90.0, 30.0, 60.0, 60.0, 45.0, 75.0];
    let tw = weights(&c).unwrap();
    let segs = c.wheel.segments_deg.clone();
    assert_matrix(
        &tw.w,
        |i, k| if i == k { 6.0 * segs[i] / 360.0 } else { 0.0 },
        1e-12,
    );
}

#[test]
fn fractional_exposure_by_hand() {
    // 40.5 turns from the index pulse: segments 0–2 are seen 41 times, 3–5 only 40 times.
    // w_ii = (N/T)·count·(T_turn/N) = count/40.5.
    let mut c = TimingConfig::default();
    c.camera.exposure_s = 0.0405;
    let tw = weights(&c).unwrap();
    assert_matrix(
        &tw.w,
        |i, k| match (i == k, i < 3) {
            (false, _) => 0.0,
            (true, true) => 41.0 / 40.5,
            (true, false) => 40.0 / 40.5,
        },
        1e-12,
    );
    assert!((tw.turns_per_exposure - 40.5).abs() < 1e-9);
    assert!(tw.warnings.iter().any(|w| w.contains("not a whole number")));
}

#[test]
fn exposure_starting_mid_segment_by_hand() {
    // Start half-way through segment 1 and last 12.25 segment times: the window [1.5, 13.75)
    // in segment units sees segment 1 for 0.5 + 1 + 0.75 and every other segment twice.
    let mut c = TimingConfig::default();
    let seg = 1e-3 / 6.0;
    c.camera.start_s = 1.5 * seg;
    c.camera.exposure_s = 12.25 * seg;
    let tw = weights(&c).unwrap();
    // Window [1.5, 13.75) in segment units; segment i occupies [i + 6n, i + 1 + 6n).
    let mut seen = [0.0f64; 6];
    for n in 0..4 {
        for (i, s) in seen.iter_mut().enumerate() {
            let lo = (i + 6 * n) as f64;
            *s += ((lo + 1.0).min(13.75) - lo.max(1.5)).max(0.0);
        }
    }
    assert_eq!(seen, [2.0, 2.25, 2.0, 2.0, 2.0, 2.0]);
    assert_matrix(
        &tw.w,
        |i, k| if i == k { seen[i] * 6.0 / 12.25 } else { 0.0 },
        1e-12,
    );
}

#[test]
fn delay_of_one_segment_is_a_cyclic_permutation() {
    let mut c = TimingConfig::default();
    c.dmd.delays_s = vec![1e-3 / 6.0; 6];
    let tw = weights(&c).unwrap();
    assert_matrix(
        &tw.w,
        |i, k| if i == (k + 1) % 6 { 1.0 } else { 0.0 },
        1e-12,
    );
    assert!(
        tw.warnings
            .iter()
            .any(|w| w.contains("only 0.0 % of pattern 5's light comes through segment 5")),
        "{:?}",
        tw.warnings
    );
}

#[test]
fn index_offset_of_one_segment_is_the_opposite_permutation() {
    // The spot is one segment ahead when the pulse fires: during pattern k's slot the spot
    // angle is 60k + 60 + τ (0 ≤ τ < 60), i.e. segment k+1.
    let mut c = TimingConfig::default();
    c.wheel.index_offset_deg = 60.0;
    let tw = weights(&c).unwrap();
    assert_matrix(
        &tw.w,
        |i, k| if i == (k + 1) % 6 { 1.0 } else { 0.0 },
        1e-12,
    );
    c.wheel.index_offset_deg = -60.0;
    let tw = weights(&c).unwrap();
    assert_matrix(
        &tw.w,
        |i, k| if (i + 1) % 6 == k { 1.0 } else { 0.0 },
        1e-12,
    );
}

#[test]
fn delay_of_half_a_segment_splits_each_pattern_by_hand() {
    let mut c = TimingConfig::default();
    c.dmd.delays_s = vec![0.5e-3 / 6.0; 6];
    let tw = weights(&c).unwrap();
    assert_matrix(
        &tw.w,
        |i, k| if i == k || i == (k + 1) % 6 { 0.5 } else { 0.0 },
        1e-12,
    );
    // (I + P)/2 with an even number of segments is singular: the alternating vector is lost.
    let err = crosstalk_inverse(&tw.w).unwrap_err();
    assert!(matches!(err, Error::Numerical(_)), "{err}");
    assert!(err.to_string().contains("condition number"), "{err}");
}

#[test]
fn dark_time_by_hand() {
    // Dark 50 µs at the end of each 166.67 µs slot: w_kk = (166.67 − 50)/166.67.
    let mut c = TimingConfig::default();
    c.dmd.dark_time_s = 50e-6;
    let tw = weights(&c).unwrap();
    let seg = 1e-3 / 6.0;
    assert_matrix(
        &tw.w,
        |i, k| if i == k { (seg - 50e-6) / seg } else { 0.0 },
        1e-12,
    );
}

#[test]
fn faster_than_the_dmd_is_refused() {
    let mut c = TimingConfig::default();
    c.wheel.rate_hz = 5000.0; // segments last 33.3 µs < 50 µs
    let err = weights(&c).unwrap_err();
    match &err {
        Error::Config { key, value, .. } => {
            assert_eq!(key, "rig.timing.wheel.rate_hz");
            assert_eq!(value, "5000");
        }
        e => panic!("unexpected {e}"),
    }
    // The same wheel on a faster DMD is accepted.
    c.dmd.max_rate_hz = 40_000.0;
    weights(&c).unwrap();
    // A dark time leaving less than one picture for the pattern is refused on its own key.
    let mut c = TimingConfig::default();
    c.dmd.dark_time_s = 130e-6;
    let err = c.validate("f.toml").unwrap_err();
    assert!(
        err.to_string().contains("rig.timing.dmd.dark_time_s"),
        "{err}"
    );
    // A dark gap between two patterns shorter than a picture time is refused.
    let mut c = TimingConfig::default();
    c.dmd.delays_s = vec![0.0, 0.0, 0.0, 20e-6, 20e-6, 20e-6];
    let err = c.validate("f.toml").unwrap_err();
    assert!(err.to_string().contains("rig.timing.dmd.delays_s"), "{err}");
    assert!(err.to_string().contains("dark gap of 20.000 µs"), "{err}");
    // Overlapping patterns are refused.
    let mut c = TimingConfig::default();
    c.dmd.delays_s = vec![60e-6, 0.0, 0.0, 0.0, 0.0, 0.0];
    let err = c.validate("f.toml").unwrap_err();
    assert!(err.to_string().contains("still shows"), "{err}");
}

/// A change to a valid configuration.
type Mutation = Box<dyn Fn(&mut TimingConfig)>;

#[test]
fn bad_values_name_their_key() {
    let cases: Vec<(Mutation, &str)> = vec![
        (
            Box::new(|c| c.wheel.segments_deg = vec![60.0; 5]),
            "rig.timing.wheel.segments_deg",
        ),
        (
            Box::new(|c| c.wheel.segments_deg[2] = f64::NAN),
            "rig.timing.wheel.segments_deg[2]",
        ),
        (
            Box::new(|c| c.wheel.rate_hz = 0.0),
            "rig.timing.wheel.rate_hz",
        ),
        (
            Box::new(|c| c.wheel.spot_diameter_mm = -1.0),
            "rig.timing.wheel.spot_diameter_mm",
        ),
        (
            Box::new(|c| c.wheel.spot_diameter_mm = 30.0),
            "rig.timing.wheel.spot_diameter_mm",
        ),
        (
            Box::new(|c| c.wheel.spot_radius_mm = f64::INFINITY),
            "rig.timing.wheel.spot_radius_mm",
        ),
        (
            Box::new(|c| c.dmd.delays_s = vec![0.0; 3]),
            "rig.timing.dmd.delays_s",
        ),
        (
            Box::new(|c| c.dmd.delays_s = vec![0.0, 2e-3, 0.0, 0.0, 0.0, 0.0]),
            "rig.timing.dmd.delays_s[1]",
        ),
        (
            Box::new(|c| c.camera.exposure_s = 0.0),
            "rig.timing.camera.exposure_s",
        ),
        (
            Box::new(|c| c.camera.exposure_s = 0.041),
            "rig.timing.camera.exposure_s",
        ),
        (
            Box::new(|c| c.camera.frame_rate_hz = 200.0),
            "rig.timing.camera.frame_rate_hz",
        ),
        (
            Box::new(|c| c.camera.start_s = -1.0),
            "rig.timing.camera.start_s",
        ),
    ];
    for (edit, key) in cases {
        let mut c = TimingConfig::default();
        edit(&mut c);
        let err = c.validate("exp.toml").unwrap_err();
        match &err {
            Error::Config { key: k, file, .. } => {
                assert_eq!(k, key, "{err}");
                assert_eq!(file, "exp.toml");
            }
            e => panic!("{key}: unexpected {e}"),
        }
    }
}

#[test]
fn unknown_keys_are_refused_and_toml_round_trips() {
    let c: TimingConfig = toml::from_str("[wheel]\nrate_hz = 500.0\n").unwrap();
    assert_eq!(c.wheel.rate_hz, 500.0);
    assert_eq!(c.camera.frame_rate_hz, 24.0);
    assert!(toml::from_str::<TimingConfig>("[wheel]\nrate = 500.0\n").is_err());
    let text = toml::to_string(&TimingConfig::default()).unwrap();
    let back: TimingConfig = toml::from_str(&text).unwrap();
    assert_eq!(back.wheel.segments_deg, vec![60.0; 6]);
}

#[test]
fn disk_fraction_matches_a_pixel_count() {
    // Area of the unit disk beyond x = −u (x > −u), counted on a fine grid.
    let m = 2000;
    for &u in &[-0.9, -0.5, -0.1, 0.0, 0.3, 0.75, 0.99] {
        let (mut inside, mut past) = (0usize, 0usize);
        for a in 0..m {
            for b in 0..m {
                let x = -1.0 + 2.0 * (a as f64 + 0.5) / m as f64;
                let y = -1.0 + 2.0 * (b as f64 + 0.5) / m as f64;
                if x * x + y * y <= 1.0 {
                    inside += 1;
                    if x > -u {
                        past += 1;
                    }
                }
            }
        }
        let counted = past as f64 / inside as f64;
        assert!(
            (disk_fraction_past(u) - counted).abs() < 2e-4,
            "u = {u}: {} vs {counted}",
            disk_fraction_past(u)
        );
    }
    assert_eq!(disk_fraction_past(-1.0), 0.0);
    assert!((disk_fraction_past(1.0) - 1.0).abs() < 1e-15);
    for &u in &[0.1, 0.4, 0.8] {
        assert!((disk_fraction_past(u) + disk_fraction_past(-u) - 1.0).abs() < 1e-15);
    }
}

fn spotted() -> TimingConfig {
    let mut c = TimingConfig::default();
    c.wheel.spot_diameter_mm = 1.0;
    c.wheel.spot_radius_mm = 20.0;
    c
}

#[test]
fn spoke_fraction_is_n_d_over_two_pi_r_and_halfway_splits_evenly() {
    let c = spotted();
    let tw = weights(&c).unwrap();
    let first_order = 6.0 * 1.0 / (2.0 * std::f64::consts::PI * 20.0);
    // Exact N·asin(r/R)/π differs from the first-order N·d/(2πR) by (r/R)²/6 relative.
    assert!((tw.spoke_fraction / first_order - 1.0).abs() < 0.025f64.powi(2) / 6.0 * 1.01);
    assert!((tw.spoke_fraction / first_order - 1.0).abs() > 0.0);
    let s = Schedule::new(&c);
    for j in 0..6 {
        let a = s.light_fractions(s.spoke_s[j]);
        assert!(
            (a[j] - 0.5).abs() < 1e-15 && (a[(j + 5) % 6] - 0.5).abs() < 1e-15,
            "{a:?}"
        );
        assert!((a.iter().sum::<f64>() - 1.0).abs() < 1e-15);
    }
    // Half-way through a segment the light is pure.
    let a = s.light_fractions(0.5e-3 / 6.0);
    assert_eq!(a, vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
    // Aligned: each pattern loses to each neighbour the light of half a crossing, ∫_0^h (1−G)
    // = h/2 − ∫_0^h (G − ½), symmetric between the two neighbours; columns still sum to 1.
    let gl = GaussLegendre::new(GL_ORDER);
    let leak = s.half_crossing_s - s.past_spoke_integral(0.0, s.half_crossing_s, &gl);
    let leak_w = leak * 6.0 / 1e-3 * 40.0 / 40.0;
    for k in 0..6 {
        let col: f64 = tw.w.iter().map(|r| r[k]).sum();
        assert!((col - 1.0).abs() < 1e-12);
        assert!((tw.w[(k + 1) % 6][k] - leak_w).abs() < 1e-12);
        assert!((tw.w[(k + 5) % 6][k] - leak_w).abs() < 1e-12);
        assert!((tw.w[k][k] - (1.0 - 2.0 * leak_w)).abs() < 1e-12);
    }
    assert!(leak_w > 0.0);
    assert!(tw.warnings.iter().any(|w| w.contains("spoke")));
}

#[test]
fn whole_crossing_integral_is_half_the_crossing_time() {
    // ∫_{−h}^{h} G dt = h by the symmetry G(−u) = 1 − G(u).
    let s = Schedule::new(&spotted());
    let gl = GaussLegendre::new(GL_ORDER);
    let h = s.half_crossing_s;
    assert!((s.past_spoke_integral(-h, h, &gl) / h - 1.0).abs() < 1e-14);
    // Order 32 agrees with order 64 on a partial crossing.
    let gl64 = GaussLegendre::new(64);
    let (a, b) = (-0.7 * h, 0.3 * h);
    let (p32, p64) = (
        s.past_spoke_integral(a, b, &gl),
        s.past_spoke_integral(a, b, &gl64),
    );
    assert!((p32 - p64).abs() < 1e-15 * h.max(p64), "{p32} vs {p64}");
}

/// Brute force: midpoint sampling of a_i(t)·p_k(t) over the exposure, `m` samples.
fn brute_force(c: &TimingConfig, m: usize) -> Vec<Vec<f64>> {
    let s = Schedule::new(c);
    let (t0, t) = (c.camera.start_s, c.camera.exposure_s);
    let dt = t / m as f64;
    let mut w = vec![vec![0.0; s.n]; s.n];
    for q in 0..m {
        let tq = t0 + (q as f64 + 0.5) * dt;
        if let Some(k) = s.pattern_at(tq) {
            for (i, a) in s.light_fractions(tq).iter().enumerate() {
                w[i][k] += a * dt;
            }
        }
    }
    w.iter()
        .map(|r| r.iter().map(|v| v * s.n as f64 / t).collect())
        .collect()
}

#[test]
fn exact_weights_match_brute_force_sampling() {
    // A messy rig: unequal segments, big spot, index offset, delays, dark time, odd exposure.
    let mut c = TimingConfig::default();
    c.wheel.segments_deg = vec![70.0, 50.0, 65.0, 55.0, 40.0, 80.0];
    c.wheel.spot_diameter_mm = 3.0;
    c.wheel.spot_radius_mm = 15.0;
    c.wheel.index_offset_deg = 7.3;
    c.dmd.delays_s = vec![8e-6, 0.0, 5e-6, 0.0, 0.0, 3e-6];
    c.dmd.dark_time_s = 60e-6;
    c.camera.start_s = 0.137e-3;
    c.camera.exposure_s = 1.7337e-3;
    c.validate("t").unwrap();
    let exact = weights(&c).unwrap().w;
    // Midpoint error ≤ N·(jumps per entry)·dt/(2T): 1e7 samples → a few 1e-7 per entry.
    let brute = brute_force(&c, 10_000_000);
    let worst = (0..6)
        .flat_map(|i| (0..6).map(move |k| (i, k)))
        .map(|(i, k)| (exact[i][k] - brute[i][k]).abs())
        .fold(0.0, f64::max);
    eprintln!("largest |exact − brute force| = {worst:.3e}");
    assert_matrix(&exact, |i, k| brute[i][k], 1e-6);
    // And the periodic shortcut equals direct integration over the whole window.
    let s = Schedule::new(&c);
    let gl = GaussLegendre::new(GL_ORDER);
    let short = exposure_energy(&s, c.camera.start_s, c.camera.exposure_s, &gl);
    let direct = s.energy(
        c.camera.start_s,
        c.camera.start_s + c.camera.exposure_s,
        &gl,
    );
    assert_matrix(&short, |i, k| direct[i][k], 1e-15);
}

#[test]
fn crosstalk_inverse_demixes() {
    let c = spotted();
    let w = weights(&c).unwrap().w;
    let m = crosstalk_inverse(&w).unwrap();
    let x = [0.3, 1.0, 0.0, 0.7, 2.0, 0.1];
    let z: Vec<f64> = (0..6)
        .map(|k| (0..6).map(|i| w[i][k] * x[i]).sum())
        .collect();
    for i in 0..6 {
        let xi: f64 = (0..6).map(|k| m[i][k] * z[k]).sum();
        assert!((xi - x[i]).abs() < 1e-12, "{i}: {xi} vs {}", x[i]);
    }
    // A pattern never shown in the exposure: W has a zero column, refused.
    let mut c = TimingConfig::default();
    c.camera.exposure_s = 0.5e-3 / 6.0 * 9.0; // 4.5 segments: patterns 5 (and half of 4) unseen
    let tw = weights(&c).unwrap();
    assert!(tw
        .warnings
        .iter()
        .any(|w| w.contains("pattern 5 is never shown")));
    let err = crosstalk_inverse(&tw.w).unwrap_err();
    assert!(err.to_string().contains("condition number"), "{err}");
    assert!(matches!(
        crosstalk_inverse(&[vec![1.0, 0.0]]),
        Err(Error::Shape(_))
    ));
    assert!(matches!(
        crosstalk_inverse(&[vec![f64::NAN]]),
        Err(Error::Numerical(_))
    ));
}

/// Time pattern k is shown within [t0, t0+T), by interval arithmetic on the slots alone.
fn shown_time(c: &TimingConfig, k: usize) -> f64 {
    let (start, dur) = c.pattern_slots()[k];
    let p = c.period_s();
    let (a, b) = (c.camera.start_s, c.camera.start_s + c.camera.exposure_s);
    let mut total = 0.0;
    let mut n = ((a - start) / p).floor() - 1.0;
    while start + n * p < b {
        let lo = (start + n * p).max(a);
        let hi = (start + n * p + dur).min(b);
        total += (hi - lo).max(0.0);
        n += 1.0;
    }
    total
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    fn config() -> impl Strategy<Value = TimingConfig> {
        (
            prop::collection::vec(1.0f64..3.0, 3..8),
            200.0f64..2000.0,
            0.0f64..0.6,
            -180.0f64..180.0,
            prop::collection::vec(0.0f64..1.0, 8),
            0.0f64..1.0,
            0.0f64..3.0,
            0.05f64..25.0,
        )
            .prop_map(
                |(rel, rate, spot, offset, delay_frac, start, dark_frac, turns)| {
                    let sum: f64 = rel.iter().sum();
                    let n = rel.len();
                    let mut c = TimingConfig::default();
                    c.wheel.segments_deg = rel.iter().map(|r| r / sum * 360.0).collect();
                    let last: f64 = c.wheel.segments_deg[..n - 1].iter().sum();
                    c.wheel.segments_deg[n - 1] = 360.0 - last;
                    c.wheel.rate_hz = rate;
                    c.wheel.spot_radius_mm = 20.0;
                    c.wheel.spot_diameter_mm = spot
                        * 2.0
                        * 20.0
                        * (c.wheel.segments_deg.iter().cloned().fold(360.0, f64::min) / 2.0)
                            .to_radians()
                            .sin();
                    c.wheel.index_offset_deg = offset;
                    let p = 1.0 / rate;
                    let pic = 1.0 / c.dmd.max_rate_hz;
                    // Either no dark time or at least one picture; a common delay keeps the order.
                    c.dmd.dark_time_s = if dark_frac < 1.0 {
                        0.0
                    } else {
                        pic * dark_frac
                    };
                    c.dmd.delays_s = vec![delay_frac[0] * p; n];
                    c.camera.start_s = start * p;
                    c.camera.exposure_s = turns * p;
                    c.camera.frame_rate_hz =
                        1.0 / (c.camera.exposure_s + c.camera.readout_s) / 1.01;
                    c.camera.max_frame_rate_hz = 1e6;
                    c
                },
            )
            .prop_filter("a valid rig", |c| c.validate("p").is_ok())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        #[test]
        fn weights_conserve_energy_and_are_non_negative(c in config()) {
            let tw = weights(&c).unwrap();
            let n = c.segment_count();
            let scale = n as f64 / c.camera.exposure_s;
            for k in 0..n {
                let col: f64 = tw.w.iter().map(|r| r[k]).sum();
                let expect = shown_time(&c, k) * scale;
                prop_assert!((col - expect).abs() < 1e-10 * expect.max(1.0), "k={} {} vs {}", k, col, expect);
            }
            prop_assert!(tw.w.iter().flatten().all(|&v| v >= 0.0 && v.is_finite()));
        }

        #[test]
        fn light_fractions_sum_to_one(c in config(), t in 0.0f64..0.01) {
            let s = Schedule::new(&c);
            let a = s.light_fractions(t);
            prop_assert!((a.iter().sum::<f64>() - 1.0).abs() < 1e-14);
            prop_assert!(a.iter().all(|&v| (0.0..=1.0).contains(&v)));
        }
    }
}

/// The matrices quoted in docs/timing.md. Run with `-- --nocapture` to print them.
#[test]
fn doc_examples() {
    let proto = TimingConfig::default();
    let mut half_turn = proto.clone();
    half_turn.camera.exposure_s = 0.0405;
    let mut spot = proto.clone();
    spot.wheel.spot_diameter_mm = 1.0;
    let mut messy = spot.clone();
    messy.camera.exposure_s = 0.0405;
    messy.wheel.index_offset_deg = 10.0;
    let mut half_seg = proto.clone();
    half_seg.dmd.delays_s = vec![0.5e-3 / 6.0; 6];
    let cases = [
        (
            "prototype: 6 × 60°, 1000 rev/s, 40 ms from the index pulse",
            &proto,
        ),
        ("exposure of 40.5 turns", &half_turn),
        ("1 mm spot at 20 mm radius (spoke mixing)", &spot),
        ("1 mm spot, 40.5 turns, index sensor 10° late", &messy),
        ("DMD delayed by half a segment", &half_seg),
    ];
    for (title, c) in cases {
        let tw = weights(c).unwrap();
        println!(
            "### {title}\n\nturns {:.4}, spoke fraction {:.5}\n\n```",
            tw.turns_per_exposure, tw.spoke_fraction
        );
        for row in &tw.w {
            println!(
                "{}",
                row.iter()
                    .map(|v| format!("{v:8.5}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
        }
        println!("```");
        match crosstalk_inverse(&tw.w) {
            Ok(m) => {
                let diag: Vec<String> = (0..6).map(|i| format!("{:.5}", m[i][i])).collect();
                println!("\ndemixing diagonal: {}", diag.join(", "));
            }
            Err(e) => println!("\ncrosstalk_inverse: {e}"),
        }
        for w in &tw.warnings {
            println!("- {w}");
        }
        println!();
        // Every case shows each pattern through the exposure: Σ_i w_ik = shown time / (T/N).
        for k in 0..6 {
            let col: f64 = tw.w.iter().map(|r| r[k]).sum();
            assert!((col - shown_time(c, k) * 6.0 / c.camera.exposure_s).abs() < 1e-12);
        }
    }
}
