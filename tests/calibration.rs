//! The core's calibration from captured frames: on an ideal rig it finds the design's carriers;
//! on a rig whose DMD image is rotated and scaled (a mismatch the design did not expect) it
//! finds the carriers as imaged and the reconstruction corrects for them.

use specmux_core::calibration::{Calibration, MeasuredCarrier};
use specmux_core::fft::dtft_at;
use specmux_core::metrics;
use specmux_core::reconstructor::Reconstructor;
use specmux_core::spectral::Library;
use specmux_core::Carrier;
use specmux_twin::experiment::Experiment;
use specmux_twin::forward::{Pipeline, Simulated};
use specmux_twin::rig::Rig;
use specmux_twin::run;
use specmux_twin::scene::Materials;

/// A 256 × 256 Fourier-only experiment on `source` with `extra` TOML.
fn experiment(source: &str, extra: &str) -> Experiment {
    let text = format!(
        "[scene]\nsource = \"{source}\"\nsize = [256, 256]\n[reconstruct.gap]\nmethod = \"fourier\"\n{extra}"
    );
    Experiment::from_toml(&text, "test.toml").unwrap()
}

fn simulate(exp: &Experiment) -> (Rig, Simulated) {
    let lib = Library::default_root();
    let m = Materials::load(&lib).unwrap();
    let rig = Rig::build(exp, &lib, &m).unwrap();
    let (sim, _) = Pipeline::build(exp, &rig, &m).unwrap().run().unwrap();
    (rig, sim)
}

/// Largest frequency error (cycles/px) and phase error (rad) of `measured` against `truth`.
fn errors(measured: &[MeasuredCarrier], truth: &[Carrier]) -> (f64, f64) {
    measured
        .iter()
        .zip(truth)
        .fold((0.0, 0.0), |(df, dp), (m, t)| {
            let c = m.carrier;
            let f = (c.fx - t.fx).abs().max((c.fy - t.fy).abs());
            let p = (c.phase_rad - t.phase_rad + std::f64::consts::PI)
                .rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            (df.max(f), dp.max(p.abs()))
        })
}

const PHASES: &str = "[rig.carriers]\nphases_deg = [0, 35, 70, 105, 140, 175]\n";
const CAMERA: &str = "[rig.sensor]\n";

#[test]
fn an_ideal_rig_gives_back_the_design_carriers() {
    for extra in ["", CAMERA] {
        let exp = experiment("dead-leaves", &format!("{PHASES}{extra}"));
        let (rig, sim) = simulate(&exp);
        let cal = run::calibration(&exp, &rig, &sim, None).unwrap();
        let (df, dp) = errors(&cal.carriers, &rig.carriers);
        println!(
            "ideal rig{}: |Δf| ≤ {df:.2e} cycles/px, |Δφ| ≤ {dp:.2e} rad",
            extra.trim()
        );
        assert!(df < 1e-3, "frequency off by {df}");
        assert!(dp < 1e-2, "phase off by {dp}");
    }
}

const MISALIGNED: &str = "[rig.alignment]\nrotation_deg = 0.4\nmagnification = 1.003\n";

/// The carriers at the design's bins with the amplitude found there: what a reconstruction
/// that trusts the design (and only measures gains) would use.
fn trusting_the_design(cal: &Calibration, design: &[Carrier]) -> Calibration {
    let p = &cal.patterns;
    let mut out = cal.clone();
    for (k, (m, d)) in out.carriers.iter_mut().zip(design).enumerate() {
        let a = dtft_at(p.plane(k), p.width, p.height, d.fx, d.fy);
        m.carrier = Carrier {
            phase_rad: a.arg(),
            ..*d
        };
        m.amplitude = [a.re, a.im];
    }
    out
}

fn cube_psnr(exp: &Experiment, rig: &Rig, sim: &Simulated, cal: &Calibration) -> f64 {
    let r = Reconstructor::new(&exp.reconstruct, &rig.design(), cal, &exp.file).unwrap();
    let out = r.run(&sim.frame, None).unwrap();
    metrics::compare(&sim.scene.cube, &out.cube)
        .unwrap()
        .psnr_db
}

#[test]
fn a_rotated_and_scaled_dmd_image_is_found_and_corrected() {
    let exp = experiment("shaded-objects", &format!("{PHASES}{CAMERA}{MISALIGNED}"));
    let (rig, sim) = simulate(&exp);
    let cal = run::calibration(&exp, &rig, &sim, None).unwrap();
    let (df, dp) = errors(&cal.carriers, &rig.imaged_carriers);
    let (shift, _) = errors(&cal.carriers, &rig.carriers);
    println!("misaligned rig: carriers moved up to {shift:.2e} cycles/px, found to {df:.2e}, phase {dp:.2e} rad");
    assert!(
        shift > 1e-3,
        "the misalignment should move the carriers ({shift})"
    );
    assert!(df < 1e-3 && dp < 1e-2, "found to {df} cycles/px, {dp} rad");

    let calibrated = cube_psnr(&exp, &rig, &sim, &cal);
    let trusting = cube_psnr(&exp, &rig, &sim, &trusting_the_design(&cal, &rig.carriers));
    let aligned = {
        let exp = experiment("shaded-objects", &format!("{PHASES}{CAMERA}"));
        let (rig, sim) = simulate(&exp);
        cube_psnr(
            &exp,
            &rig,
            &sim,
            &run::calibration(&exp, &rig, &sim, None).unwrap(),
        )
    };
    println!("cube PSNR: aligned rig {aligned:.2} dB; misaligned, calibrated {calibrated:.2} dB, trusting the design {trusting:.2} dB");
    assert!(calibrated > trusting + 3.0, "{calibrated} vs {trusting}");
    assert!(
        calibrated > aligned - 1.0,
        "{calibrated} vs aligned {aligned}"
    );
}
