//! The stages of the light path as an experiment wires them: only the sections present are
//! built, the timing weights and the camera reach the frame, and the reconstruction undoes
//! both (crosstalk inverse, dark/flat calibration).

use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Cube;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::Pipeline;
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;

const SEGMENT_S: f64 = 1e-3 / 6.0;

fn experiment(extra: &str) -> Experiment {
    experiment_on("dead-leaves", extra)
}

/// A 64 × 64 experiment on `source`, Fourier-only, with `extra` TOML sections.
fn experiment_on(source: &str, extra: &str) -> Experiment {
    let text = format!(
        "[scene]\nsource = \"{source}\"\nsize = [64, 64]\n[reconstruct.gap]\nmethod = \"fourier\"\n{extra}"
    );
    Experiment::from_toml(&text, "test.toml").unwrap()
}

fn setup(exp: &Experiment) -> (Rig, Materials) {
    let lib = Library::default_root();
    let materials = Materials::load(&lib).unwrap();
    (Rig::build(exp, &lib, &materials).unwrap(), materials)
}

/// The reconstructor the core builds for `exp` from the twin's calibration captures.
fn reconstructor(exp: &Experiment) -> specmux_core::Result<Reconstructor> {
    let (rig, m) = setup(exp);
    let (sim, _) = Pipeline::build(exp, &rig, &m)?.run()?;
    run::reconstructor(exp, &rig, &sim, None)
}

fn delays(fraction: f64) -> String {
    let d = fraction * SEGMENT_S;
    format!("[rig.timing.dmd]\ndelays_s = [{d}, {d}, {d}, {d}, {d}, {d}]\n")
}

fn rel_rms(a: &[f32], b: &[f32]) -> f64 {
    let num: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (num / den).sqrt()
}

#[test]
fn explain_lists_only_the_stages_asked_for() {
    let names = |exp: &Experiment| -> Vec<&'static str> {
        let (rig, m) = setup(exp);
        Pipeline::build(exp, &rig, &m)
            .unwrap()
            .stages()
            .iter()
            .map(|s| s.name())
            .collect()
    };
    assert_eq!(
        names(&experiment("")),
        ["scene", "colour-wheel", "ideal-patterns", "multiplex"]
    );
    let full = experiment(
        "[rig.dmd]\nwidth = 64\nheight = 64\n[rig.fourier_filter]\n[rig.lens]\n[rig.timing]\n[rig.sensor]\n",
    );
    assert_eq!(
        names(&full),
        [
            "scene",
            "colour-wheel",
            "dmd-dither",
            "relay-fourier-filter",
            "lens",
            "pixel-sampling",
            "exposure-timing",
            "multiplex",
            "sensor"
        ]
    );
    assert_eq!(
        names(&experiment("[rig.lens]\n")),
        [
            "scene",
            "colour-wheel",
            "grey-modulator",
            "modulator-spectrum",
            "lens",
            "pixel-sampling",
            "multiplex"
        ]
    );
}

/// y = Σ_k (Σ_i w_ik x_i) s_k, checked pixel by pixel against the weights of the timing model.
#[test]
fn timing_weights_mix_the_channels_into_the_frame() {
    let exp = experiment(&format!("[rig.timing]\n{}", delays(0.3)));
    let (rig, m) = setup(&exp);
    let (st, _) = Pipeline::build(&exp, &rig, &m).unwrap().run().unwrap();
    let w = specmux_twin::timing::weights(exp.rig.timing.as_ref().unwrap())
        .unwrap()
        .w;
    assert!(
        (w[0][0] - 0.7).abs() < 1e-6 && (w[1][0] - 0.3).abs() < 1e-6,
        "{w:?}"
    );
    assert!(
        (w[0][5] - 0.3).abs() < 1e-6 && w[0][1].abs() < 1e-9,
        "{w:?}"
    );
    let (x, s, y) = (st.channels, st.patterns, st.frame);
    for p in (0..x.pixels()).step_by(97) {
        let want: f64 = (0..6)
            .map(|k| {
                let z: f64 = (0..6).map(|i| w[i][k] * x.plane(i)[p] as f64).sum();
                z * s.plane(k)[p] as f64
            })
            .sum();
        assert!(
            (y.data[p] as f64 - want).abs() < 1e-5 * want.abs().max(1.0),
            "pixel {p}"
        );
    }
}

/// With a DMD delay each carrier holds a mix of channels, z = Wᵀx. On channels band-limited
/// inside their crop windows demultiplexing is exact, so the correction (Wᵀ)⁻¹ must give back x
/// to rounding, and without it the channels stay mixed by a quarter.
#[test]
fn crosstalk_correction_undoes_a_dmd_delay() {
    let (w, h) = (64, 64);
    let tau = std::f64::consts::TAU;
    let x: Vec<Vec<f32>> = (0..6)
        .map(|i| {
            (0..w * h)
                .map(|p| {
                    let (u, v) = ((p % w) as f64 / w as f64, (p / w) as f64 / h as f64);
                    (2.0 + (tau * (2.0 * u + 0.3 * i as f64)).cos()
                        + 0.5 * (tau * (3.0 * v - u)).sin()) as f32
                })
                .collect()
        })
        .collect();
    let xhat = |correction: &str| -> Cube {
        let exp = experiment(&format!(
            "[rig.timing]\n{}[reconstruct]\ncrosstalk = \"{correction}\"\n",
            delays(0.25)
        ));
        let (rig, _) = setup(&exp);
        let wts = specmux_twin::timing::weights(exp.rig.timing.as_ref().unwrap())
            .unwrap()
            .w;
        let mut y = vec![0f32; w * h];
        for (k, c) in rig.carriers.iter().enumerate() {
            let s = c.ideal_pattern(w, h);
            for p in 0..w * h {
                let z: f64 = (0..6).map(|i| wts[i][k] * x[i][p] as f64).sum();
                y[p] += (z * s[p] as f64) as f32;
            }
        }
        let r = reconstructor(&exp).unwrap();
        r.run(&Cube::from_vec(w, h, 1, y).unwrap(), None)
            .unwrap()
            .xhat
    };
    let truth: Vec<f32> = x.concat();
    let corrected = rel_rms(&xhat("timing").data, &truth);
    let mixed = rel_rms(&xhat("none").data, &truth);
    assert!(corrected < 1e-5, "corrected {corrected}");
    assert!(mixed > 0.05, "uncorrected {mixed}");
}

/// Half a segment of delay makes W = (I + P)/2 with P the cyclic shift: singular for six
/// segments (eigenvalue 1 + e^{iπ} = 0). The correction refuses; without it the run goes on.
#[test]
fn a_singular_crosstalk_is_refused_not_inverted() {
    let exp = experiment(&format!("[rig.timing]\n{}", delays(0.5)));
    let err = reconstructor(&exp).err().expect("refused");
    assert!(err.to_string().contains("ill-conditioned"), "{err}");
    let exp = experiment(&format!(
        "[rig.timing]\n{}[reconstruct]\ncrosstalk = \"none\"\n",
        delays(0.5)
    ));
    assert!(reconstructor(&exp).is_ok());
}

/// A raw frame (DN, with offset, PRNU, DSNU and noise) is brought back to the noiseless frame's
/// units by the dark and flat frames: the mean within 0.5 %, the rest within the shot noise.
#[test]
fn raw_frames_are_calibrated_back_to_the_noiseless_frame() {
    let noiseless = {
        let exp = experiment("");
        let (rig, m) = setup(&exp);
        let (st, _) = Pipeline::build(&exp, &rig, &m).unwrap().run().unwrap();
        (st.frame, st.full_scale)
    };
    let exp = experiment(
        "[rig.sensor]\nfull_well_e = 200000\nbits = 16\nelectrons_at_full_scale = 50000\n",
    );
    let (rig, m) = setup(&exp);
    let (st, _) = Pipeline::build(&exp, &rig, &m).unwrap().run().unwrap();
    assert!(st.raw);
    let raw = st.frame;
    assert!(
        raw.data.iter().all(|v| v.fract() == 0.0),
        "raw frames hold integer DN"
    );
    let r = reconstructor(&exp).unwrap();
    let mut cal = r.calibration.linearise(&raw).unwrap().into_owned();
    let (y, fs) = noiseless;
    // Linear units are DN above dark at the flat's mean gain: y · K · e⁻(full scale) / full scale.
    let mean = |c: &[f32]| c.iter().map(|v| *v as f64).sum::<f64>() / c.len() as f64;
    let k = exp.rig.sensor.as_ref().unwrap().gain_dn_per_e;
    let scale = mean(&cal.data) / mean(&y.data);
    assert!(
        (scale / (k * 50_000.0 / fs as f64) - 1.0).abs() < 5e-3,
        "{scale}"
    );
    cal.data
        .iter_mut()
        .for_each(|v| *v = (*v as f64 / scale) as f32);
    // Shot noise: σ/y = 1/√(y·e_fs/fs) per pixel; the flat's own noise averages over 16 frames.
    let e_per_unit = 50_000.0 / fs as f64;
    let expected: f64 = (y.data.iter().map(|v| *v as f64 / e_per_unit).sum::<f64>()
        / y.data.iter().map(|v| (*v as f64).powi(2)).sum::<f64>())
    .sqrt();
    let got = rel_rms(&cal.data, &y.data);
    assert!(
        got < 1.5 * expected && got > 0.5 * expected,
        "{got} vs shot noise {expected}"
    );
}

#[test]
fn the_channel_table_reports_the_de_aliased_channels_beside_the_demultiplexed() {
    let lib = Library::default_root();
    let (fourier, _) = run::run(&experiment(""), &lib).unwrap();
    assert!(fourier
        .channels
        .iter()
        .all(|c| c.final_psnr_db == c.psnr_db));
    let text = "[scene]\nsource = \"dead-leaves\"\nsize = [64, 64]\n[reconstruct.gap]\nmethod = \"joint\"\n";
    let (joint, _) = run::run(&Experiment::from_toml(text, "test.toml").unwrap(), &lib).unwrap();
    for c in &joint.channels {
        assert!(c.final_psnr_db > c.psnr_db + 1.0, "{c:?}");
    }
    assert!(joint.table().contains("final dB"));
}

/// The real-time loop's demultiplexing into a cube it keeps (the crosstalk undone in place) gives
/// the bits of the channels formed step by step into new cubes, with and without a crosstalk
/// correction, whatever the kept cube held; a cube of the wrong size is refused.
#[test]
fn demultiplexing_into_a_kept_cube_gives_the_same_bits() {
    for correction in ["timing", "none"] {
        let exp = experiment(&format!(
            "[rig.timing]\n{}[reconstruct]\ncrosstalk = \"{correction}\"\n",
            delays(0.25)
        ));
        let (rig, m) = setup(&exp);
        let (sim, _) = Pipeline::build(&exp, &rig, &m).unwrap().run().unwrap();
        let r = run::reconstructor(&exp, &rig, &sim, None).unwrap();
        // The channels formed step by step: demultiplexed z, then mixed into a new cube.
        let z = r
            .demux
            .run(&r.calibration.linearise(&sim.frame).unwrap())
            .unwrap();
        let fresh = r.to_channels(&z).unwrap();
        let mut kept = Cube::from_vec(64, 64, 6, vec![f32::NAN; 64 * 64 * 6]).unwrap();
        r.demultiplex_into(&sim.frame, &mut kept).unwrap();
        assert_eq!(r.demix.is_some(), correction == "timing");
        assert!(
            kept.data
                .iter()
                .zip(&fresh.data)
                .all(|(a, b)| a.to_bits() == b.to_bits()),
            "{correction}"
        );
        let err = r
            .demultiplex_into(&sim.frame, &mut Cube::zeros(64, 64, 5))
            .unwrap_err();
        assert!(err.to_string().contains("64×64×5"), "{err}");
    }
}
