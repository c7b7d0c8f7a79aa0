//! The stability suite: stiff and extreme inputs, one test per case. Each asserts a finite,
//! bounded, documented result or a one-line refusal that names the key, and prints one line
//! `STABILITY | case | outcome` (docs/stability.md is made from
//! `cargo test --test stability -- --nocapture --test-threads 1`).

use nalgebra::DMatrix;
use specmux_core::carriers::default_layout;
use specmux_core::demux::Demux;
use specmux_core::fft::Fft2;
use specmux_core::spectral::Library;
use specmux_core::unmix::Unmixer;
use specmux_core::{Cube, Error};
use specmux_twin::experiment::Experiment;
use specmux_twin::run::{self, RunReport};
use std::process::Command;
use tempfile::TempDir;

mod common;

/// Print the outcome of a case for docs/stability.md.
fn record(case: &str, outcome: &str) {
    println!("STABILITY | {case} | {}", outcome.replace('|', "/"));
}

/// A 64 × 64 Fourier-only experiment with `extra` TOML (merged after `[scene]`).
fn toml(extra: &str) -> String {
    format!("[scene]\nsize = [64, 64]\n{extra}\n[reconstruct.gap]\nmethod = \"fourier\"\n")
}

/// Parse and run an experiment end to end on `lib`.
fn run_with(text: &str, lib: &Library) -> Result<RunReport, Error> {
    let exp = Experiment::from_toml(text, "case.toml")?;
    run::run(&exp, lib).map(|(r, _)| r)
}

fn run_toml(extra: &str) -> Result<RunReport, Error> {
    run_with(&toml(extra), &Library::default_root())
}

/// Assert a one-line refusal naming every `needle`; record it.
fn refused(case: &str, r: Result<RunReport, Error>, needles: &[&str]) {
    let e = match r {
        Ok(rep) => panic!("{case}: accepted, cube {:.2} dB", cube_psnr(&rep)),
        Err(e) => e.to_string(),
    };
    assert_eq!(e.lines().count(), 1, "{case}: {e}");
    for n in needles {
        assert!(e.contains(n), "{case}: `{n}` missing from: {e}");
    }
    record(case, &format!("refused: `{e}`"));
}

fn cube_psnr(rep: &RunReport) -> f64 {
    rep.results
        .iter()
        .find(|r| r.stage == "unmix")
        .unwrap()
        .psnr_db
}

/// Assert every figure of the report is finite (SAM may be undefined); record the cube's.
fn finite(case: &str, rep: &RunReport) {
    for r in &rep.results {
        assert!(
            r.psnr_db.is_finite() && r.ssim.is_finite() && r.nrmse.is_finite(),
            "{case}: {r:?}"
        );
        assert!(r.sam_deg.map_or(true, f64::is_finite), "{case}: {r:?}");
    }
    let u = rep.results.iter().find(|r| r.stage == "unmix").unwrap();
    let warn = if rep.warnings.is_empty() {
        String::new()
    } else {
        format!("; warnings: {}", rep.warnings.join("; "))
    };
    record(
        case,
        &format!(
            "finite: cube {:.2} dB, SAM {}°{warn}",
            u.psnr_db,
            specmux_core::metrics::show(u.sam_deg, 2)
        ),
    );
}

/// A scratch folder `specmux-stab-{tag}-*`, removed when the returned guard drops.
fn temp(tag: &str) -> TempDir {
    common::tmpdir(&format!("stab-{tag}"))
}

/// A copy of spectra/ whose `name` curve is replaced by `csv`, and the guard of its folder.
fn library_with(tag: &str, name: &str, csv: &str) -> (TempDir, Library) {
    let scratch = temp(tag);
    let dst = common::spectra_copy(scratch.path());
    std::fs::write(
        dst.join(format!("{name}.csv")),
        format!("# provenance: stability test\n{csv}"),
    )
    .unwrap();
    (scratch, Library::new(dst))
}

// ---------------------------------------------------------------- unmixing

/// F = rows nearly equal: row i = base + ε·eᵢ, so cond(F) grows as 1/ε.
fn near_identical(eps: f64) -> DMatrix<f64> {
    DMatrix::from_fn(6, 6, |i, j| {
        1.0 + 0.1 * j as f64 + if i == j { eps } else { 0.0 }
    })
}

#[test]
fn unmix_nearly_identical_filters_cond_1e2_to_1e12() {
    let b = DMatrix::<f64>::identity(6, 6);
    for eps in [1e-1, 1e-3, 1e-5, 1e-7, 1e-9] {
        let case = format!("unmixing: nearly identical filters, ε = {eps:e}");
        match Unmixer::new(&near_identical(eps), &b, 0.0) {
            Ok(u) => {
                let x = Cube::from_vec(1, 1, 6, vec![1.0, 1.1, 1.2, 1.3, 1.4, 1.5]).unwrap();
                let (r, _) = u.unmix(&x).unwrap();
                assert!(r.all_finite(), "{case}");
                record(
                    &case,
                    &format!("solved, cond {:.1e}, finite", u.condition()),
                );
            }
            Err(e) => {
                let m = e.to_string();
                assert!(m.contains("condition number"), "{case}: {m}");
                record(&case, &format!("refused: `{m}`"));
            }
        }
    }
}

#[test]
fn unmix_eta_from_zero_to_1e300() {
    for eta in ["0", "1e-6", "1e6", "1e300"] {
        let case = format!("unmixing: η = {eta}");
        match run_toml(&format!("[reconstruct]\neta = {eta}\n")) {
            Ok(rep) => finite(&case, &rep),
            Err(e) => {
                let m = e.to_string();
                assert!(
                    m.contains("reconstruct.eta") || m.contains("rig.wheel.filters"),
                    "{case}: {m}"
                );
                record(&case, &format!("refused: `{m}`"));
            }
        }
    }
}

#[test]
fn unmix_basis_larger_than_the_filters() {
    refused(
        "unmixing: basis of 7 for 6 filters",
        run_toml("[reconstruct]\nbasis = 7\n"),
        &["reconstruct.basis", "7"],
    );
}

#[test]
fn unmix_rank_deficient_wheel() {
    let six = "[rig.wheel]\nfilters = [\"wheel/red\", \"wheel/red\", \"wheel/red\", \"wheel/red\", \"wheel/red\", \"wheel/red\"]\n";
    refused(
        "unmixing: six identical filters (rank 1)",
        run_toml(six),
        &["rig.wheel.filters", "condition number"],
    );
}

// ---------------------------------------------------------------- light

const SENSOR: &str = "[rig.sensor]\n";

#[test]
fn light_a_few_electrons() {
    for e in ["1", "10"] {
        let case = format!("light: {e} e⁻ at full scale");
        let rep = run_toml(&format!("{SENSOR}electrons_at_full_scale = {e}\n")).unwrap();
        finite(&case, &rep);
        // At 1 e⁻ (read noise 3.16 e⁻) the captures hold no carrier: the calibration says so.
        let weak = rep.warnings.iter().any(|w| w.contains("do not stand out"));
        assert_eq!(weak, e == "1", "{case}: {:?}", rep.warnings);
    }
}

/// A lens whose NA cuts every carrier (cut-off 2·NA/λ ≈ 0.0004 cycles/µm against the carriers'
/// ≥ 0.007 on 13.68 µm mirrors): the patterns reach the camera as their mean alone, and the
/// calibration names each carrier that does not stand out of its capture.
#[test]
fn optics_a_lens_that_cuts_the_carriers() {
    let case = "optics: lens NA 1e-4 (no carrier reaches the camera)";
    let rep = run_toml("[rig.lens]\nna = 1e-4\n[rig.sensor]\n").unwrap();
    finite(case, &rep);
    let weak = rep.warnings.iter().find(|w| w.contains("do not stand out"));
    let named = |k: usize| weak.is_some_and(|w| w.contains(&format!("pattern {k} at")));
    assert!((0..6).all(named), "{:?}", rep.warnings);
}

#[test]
fn light_most_pixels_saturated() {
    let rep = run_toml(&format!("{SENSOR}electrons_at_full_scale = 150000\n")).unwrap();
    let s = rep.frame.saturated_pixels;
    assert!(s > rep.frame.pixels / 2, "{s} of {}", rep.frame.pixels);
    assert!(
        rep.warnings.iter().any(|w| w.contains("saturated")),
        "{:?}",
        rep.warnings
    );
    finite(
        "light: ten times the full well (most pixels saturated)",
        &rep,
    );
}

/// The ideal prototype's reconstructor at 64² (no camera), built from its captures.
fn ideal_reconstructor() -> (specmux_core::reconstructor::Reconstructor, Cube) {
    reconstructor_of(&toml(""))
}

/// The reconstructor of an experiment `text` built from its captures, and its frame.
fn reconstructor_of(text: &str) -> (specmux_core::reconstructor::Reconstructor, Cube) {
    let exp = Experiment::from_toml(text, "case.toml").unwrap();
    let lib = Library::default_root();
    let m = specmux_twin::scene::Materials::load(&lib).unwrap();
    let rig = specmux_twin::rig::Rig::build(&exp, &lib, &m).unwrap();
    let (sim, _) = specmux_twin::forward::Pipeline::build(&exp, &rig, &m)
        .unwrap()
        .run()
        .unwrap();
    (
        run::reconstructor(&exp, &rig, &sim, None).unwrap(),
        sim.frame,
    )
}

#[test]
fn light_a_single_hot_pixel() {
    let (r, mut frame) = ideal_reconstructor();
    frame.data[64 * 30 + 30] = 1e6;
    let out = r.run(&frame, None).unwrap();
    assert!(out.cube.all_finite());
    record(
        "light: one hot pixel at 1e6 × the frame",
        "finite (the hot pixel's ringing stays in its window)",
    );
}

#[test]
fn light_frames_scaled_by_1e_minus20_and_1e20() {
    let (r, frame) = ideal_reconstructor();
    let base = r.run(&frame, None).unwrap().cube;
    for k in [1e-20f32, 1e20] {
        let mut f = frame.clone();
        f.data.iter_mut().for_each(|v| *v *= k);
        let c = r.run(&f, None).unwrap().cube;
        assert!(c.all_finite(), "×{k}");
        // The unmixing is homogeneous: the cube scales with the frame (to f32 rounding).
        let rel = c
            .data
            .iter()
            .zip(&base.data)
            .map(|(a, b)| ((a / k) - b).abs() as f64)
            .fold(0.0, f64::max)
            / base.max() as f64;
        assert!(rel < 1e-4, "×{k}: {rel}");
        record(
            &format!("light: frame × {k:e}"),
            &format!("finite, cube × {k:e} to {rel:.1e} of its peak"),
        );
    }
}

#[test]
fn light_frames_at_the_ends_of_the_range_every_method_takes() {
    use specmux_core::cube::{FRAME_MIN, FRAME_SUM_MAX};
    for method in ["fourier", "gap", "gap-tv", "joint"] {
        let text = format!("[scene]\nsize = [64, 64]\n[reconstruct.gap]\nmethod = \"{method}\"\n");
        let (r, frame) = reconstructor_of(&text);
        let peak = frame.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let top = FRAME_SUM_MAX / (64.0 * 64.0);
        let scaled = |to: f32| {
            let mut f = frame.clone();
            f.data.iter_mut().for_each(|v| *v *= to / peak);
            r.run(&f, None).map(|o| o.cube)
        };
        // Inside the range: a finite cube; past either end: refused, naming the frame.
        for to in [top, FRAME_MIN] {
            let cube = scaled(to).unwrap();
            assert!(cube.all_finite(), "{method} at {to:e}");
        }
        for to in [2.0 * top, 0.5 * FRAME_MIN] {
            let e = scaled(to).unwrap_err().to_string();
            assert!(
                e.contains("frame: ") && e.contains("scale the frame"),
                "{method}: {e}"
            );
        }
        record(
            &format!("light: frame peak at {top:.1e} and at {FRAME_MIN:e}, {method}"),
            "finite; at twice / half of them refused: `frame: … scale the frame`",
        );
    }
}

#[test]
fn light_a_zero_frame() {
    let (r, frame) = ideal_reconstructor();
    let out = r
        .run(&Cube::zeros(frame.width, frame.height, 1), None)
        .unwrap();
    assert!(out.cube.data.iter().all(|&v| v == 0.0));
    let m = specmux_core::metrics::compare(
        &Cube::from_vec(64, 64, 31, vec![0.5; 64 * 64 * 31]).unwrap(),
        &out.cube,
    )
    .unwrap();
    assert_eq!(m.sam_deg, None);
    assert!(m.flags.iter().any(|f| f.contains("zero everywhere")));
    record(
        "light: an all-zero frame",
        &format!("zero cube, flagged: {}", m.flags.join("; ")),
    );
}

// ---------------------------------------------------------------- carriers

fn carriers(list: &str) -> String {
    format!("[rig.carriers]\nfrequencies = {list}\n")
}

#[test]
fn carriers_beyond_nyquist() {
    let c =
        carriers("[[0.25, 0], [0, 0.25], [0.25, 0.25], [-0.25, 0.25], [0.6, 0.25], [0.25, 0.5]]");
    refused(
        "carriers: one beyond Nyquist (0.6)",
        run_toml(&c),
        &["rig.carriers.frequencies[4]", "0.6"],
    );
}

#[test]
fn carriers_at_nyquist() {
    // The default layout has (0.5, 0.25) and (0.25, 0.5): on the Nyquist lines.
    finite(
        "carriers: two on the Nyquist lines (the default layout)",
        &run_toml("").unwrap(),
    );
}

#[test]
fn carriers_coincident() {
    let c =
        carriers("[[0.25, 0], [0.25, 0], [0.25, 0.25], [-0.25, 0.25], [0.5, 0.25], [0.25, 0.5]]");
    refused(
        "carriers: two coincident",
        run_toml(&c),
        &["rig.carriers.frequencies", "+ω0", "+ω1", "overlap"],
    );
}

#[test]
fn carriers_off_the_bin_grid() {
    let c =
        carriers("[[0.2, 0], [0, 0.25], [0.25, 0.25], [-0.25, 0.25], [0.5, 0.25], [0.25, 0.5]]");
    refused(
        "carriers: off the bin grid (0.2 on 64 px)",
        run_toml(&format!("{c}[reconstruct]\ncrop = 0.2\n")),
        &["frequencies[0]", "nearest on the grid"],
    );
}

#[test]
fn carriers_windows_overlapping() {
    refused(
        "carriers: crop 0.3 (windows overlap)",
        run_toml("[reconstruct]\ncrop = 0.3\n"),
        &["overlap", "reconstruct.crop"],
    );
}

#[test]
fn carriers_one_on_anothers_second_harmonic() {
    // 2·(0.125, 0) = (0.25, 0): coherent optics put channel 0's harmonic in channel 1's window.
    let c = carriers(
        "[[0.125, 0.25], [0.25, 0.5], [0.375, 0.125], [-0.375, 0.125], [0.5, 0.25], [0.125, 0.5]]",
    );
    let rep = run_toml(&format!("{c}[reconstruct]\ncrop = 0.125\n")).unwrap();
    assert!(
        rep.warnings.iter().any(|w| w.contains("2ω0")),
        "{:?}",
        rep.warnings
    );
    finite("carriers: one on another's 2ω", &rep);
}

// ---------------------------------------------------------------- sizes

#[test]
fn sizes_too_small_for_a_frame() {
    refused(
        "sizes: 1 × 1",
        run_with("[scene]\nsize = [1, 1]\n", &Library::default_root()),
        &["scene.size[0]", "16"],
    );
    refused(
        "sizes: 7 × 13",
        run_with("[scene]\nsize = [7, 13]\n", &Library::default_root()),
        &["scene.size[0]", "7"],
    );
}

#[test]
fn sizes_prime_odd_non_square_demultiplexing() {
    // The core on a 17 × 13 frame: prime, odd, non-square; carriers on its bins.
    let (w, h) = (17, 13);
    let c: Vec<_> = default_layout()
        .into_iter()
        .map(|c| c.snapped(w, h))
        .collect();
    let y = Cube::from_vec(w, h, 1, (0..w * h).map(|p| 1.0 + (p % 7) as f32).collect()).unwrap();
    let out = Demux::new(w, h, &c, 0.25).run(&y).unwrap();
    assert!(out.all_finite());
    record(
        "sizes: 17 × 13 demultiplexed (prime, odd, non-square)",
        "finite",
    );
}

#[test]
fn sizes_prime_fft_lengths_round_trip() {
    let (w, h) = (127, 131);
    let img: Vec<f32> = (0..w * h)
        .map(|p| ((p * 7919) % 101) as f32 / 101.0)
        .collect();
    let f = Fft2::new(w, h);
    let back = f.inverse(&f.forward(&img).data);
    let err = back
        .iter()
        .zip(&img)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(err < 1e-5, "{err}");
    record(
        "sizes: 127 × 131 FFT round trip (prime lengths)",
        &format!("max error {err:.1e}"),
    );
}

#[test]
fn sizes_beyond_the_memory() {
    refused(
        "sizes: 8192 × 8192 (44 GB)",
        run_with("[scene]\nsize = [8192, 8192]\n", &Library::default_root()),
        &["scene.size", "GB"],
    );
}

// ---------------------------------------------------------------- spectra

fn filter_case(case: &str, csv: &str, needles: &[&str]) {
    let (_scratch, lib) = library_with(&case.replace(' ', "-"), "wheel/green", csv);
    refused(case, run_with(&toml(""), &lib), needles);
}

#[test]
fn spectra_one_sample() {
    filter_case(
        "spectra: a filter with one sample",
        "wavelength_nm,t\n500,0.5\n",
        &["green", "two samples"],
    );
}

#[test]
fn spectra_unsorted_wavelengths() {
    filter_case(
        "spectra: unsorted wavelengths",
        "wavelength_nm,t\n500,0.5\n400,0.5\n700,0.5\n",
        &["green"],
    );
}

#[test]
fn spectra_duplicate_wavelengths() {
    filter_case(
        "spectra: duplicate wavelengths",
        "wavelength_nm,t\n400,0.5\n500,0.5\n500,0.6\n700,0.5\n",
        &["green"],
    );
}

#[test]
fn spectra_negative_transmittance() {
    filter_case(
        "spectra: a negative transmittance",
        "wavelength_nm,t\n400,0.5\n550,-0.1\n700,0.5\n",
        &["rig.wheel.filters[1]", "negative"],
    );
}

#[test]
fn spectra_not_finite() {
    filter_case(
        "spectra: NaN in a filter",
        "wavelength_nm,t\n400,0.5\n550,NaN\n700,0.5\n",
        &["green"],
    );
    filter_case(
        "spectra: inf in a filter",
        "wavelength_nm,t\n400,0.5\n550,inf\n700,0.5\n",
        &["green"],
    );
}

#[test]
fn spectra_filter_outside_the_grid() {
    filter_case(
        "spectra: a filter that passes only 900–1000 nm",
        "wavelength_nm,t\n380,0\n899,0\n900,1\n1000,1\n",
        &["rig.wheel.filters[1]", "no light"],
    );
}

#[test]
fn spectra_all_zero_illuminant_and_qe() {
    let zero = "wavelength_nm,v\n380,0\n780,0\n";
    let (_scratch, lib) = library_with("zero-light", "illuminants/D65", zero);
    refused(
        "spectra: an all-zero illuminant",
        run_with(&toml(""), &lib),
        &["scene.illuminant"],
    );
    let (_scratch, lib) = library_with("zero-qe", "camera/mono_qe", zero);
    refused(
        "spectra: an all-zero QE",
        run_with(&toml(""), &lib),
        &["rig.camera.qe"],
    );
}

// ---------------------------------------------------------------- timing

#[test]
fn timing_exposure_shorter_than_a_segment() {
    let t = "[rig.timing.camera]\nexposure_s = 1e-4\n";
    match run_toml(t) {
        Ok(rep) => finite("timing: exposure 0.1 ms (shorter than a segment)", &rep),
        Err(e) => {
            let m = e.to_string();
            assert!(m.contains("rig.timing") && m.contains("case.toml"), "{m}");
            record(
                "timing: exposure 0.1 ms (shorter than a segment)",
                &format!("refused: `{m}`"),
            );
        }
    }
}

#[test]
fn timing_dmd_faster_than_allowed() {
    refused(
        "timing: DMD rate above its maximum",
        run_toml("[rig.timing.dmd]\nmax_rate_hz = 1000\n"),
        &["rig.timing"],
    );
}

#[test]
fn timing_zero_rotation() {
    refused(
        "timing: a wheel that does not turn",
        run_toml("[rig.timing.wheel]\nrate_hz = 0\n"),
        &["rig.timing.wheel.rate_hz"],
    );
}

#[test]
fn timing_absurd_offsets() {
    refused(
        "timing: a DMD delay of 1e9 s",
        run_toml("[rig.timing.dmd]\ndelays_s = [1e9, 0, 0, 0, 0, 0]\n"),
        &["rig.timing.dmd.delays_s"],
    );
    refused(
        "timing: an index offset of NaN",
        run_toml("[rig.timing.wheel]\nindex_offset_deg = nan\n"),
        &["rig.timing.wheel.index_offset_deg"],
    );
    // Half a segment (83.333… µs at 1000 rev/s) typed to five digits: W is nearly singular
    // (condition 2.5e5), and its inverse would multiply the demultiplexing leak that much.
    let half = ["8.3333e-5"; 6].join(", ");
    refused(
        "timing: half a segment of DMD delay, typed to five digits, corrected",
        run_toml(&format!(
            "[reconstruct]\ncrosstalk = \"timing\"\n[rig.timing.dmd]\ndelays_s = [{half}]\n"
        )),
        &["rig.timing", "condition number", "crosstalk = \"none\""],
    );
}

// ---------------------------------------------------------------- dynamic range and precision

#[test]
fn dynamic_range_reflectances_of_1e_minus6() {
    let (r, frame) = ideal_reconstructor();
    let base = r.run(&frame, None).unwrap().cube;
    let mut f = frame.clone();
    f.data.iter_mut().for_each(|v| *v *= 1e-6);
    let c = r.run(&f, None).unwrap().cube;
    let rel = c
        .data
        .iter()
        .zip(&base.data)
        .map(|(a, b)| (a * 1e6 - b).abs() as f64)
        .fold(0.0, f64::max)
        / base.max() as f64;
    assert!(rel < 1e-4, "{rel}");
    record(
        "dynamic range: reflectances × 1e-6",
        &format!("finite, same cube to {rel:.1e} of its peak"),
    );
}

#[test]
fn precision_f32_demultiplexing_against_f64() {
    // A single carrier term x·cos(2π ω·p): the f32 path against the same crop done in f64 by
    // direct DFT sums (64 × 64), loss bounded by f32 rounding.
    let (w, h) = (64usize, 64usize);
    let c = default_layout();
    let x: Vec<f64> = (0..w * h)
        .map(|p| 1.0 + 0.5 * ((p % w) as f64 / w as f64 * std::f64::consts::TAU).cos())
        .collect();
    let y: Vec<f32> = (0..w * h)
        .map(|p| {
            let (px, py) = ((p % w) as f64, (p / w) as f64);
            (x[p] * (1.0 + (std::f64::consts::TAU * (c[0].fx * px + c[0].fy * py)).cos())) as f32
        })
        .collect();
    let out = Demux::new(w, h, &c, 0.25)
        .run(&Cube::from_vec(w, h, 1, y).unwrap())
        .unwrap();
    let err = out
        .plane(0)
        .iter()
        .zip(&x)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0, f64::max);
    assert!(err < 1e-5, "{err}");
    record(
        "precision: f32 demultiplexing of a band-limited channel vs f64 truth",
        &format!("max error {err:.1e}"),
    );
}

// ---------------------------------------------------------------- configuration

#[test]
fn config_values_out_of_range() {
    for (case, extra, key) in [
        (
            "config: crop 0",
            "[reconstruct]\ncrop = 0\n",
            "reconstruct.crop",
        ),
        (
            "config: crop 0.6",
            "[reconstruct]\ncrop = 0.6\n",
            "reconstruct.crop",
        ),
        (
            "config: calibration frames 0",
            "[calibration]\nframes = 0\n",
            "calibration.frames",
        ),
        (
            "config: carrier search 0 bins",
            "[calibration]\nsearch_bins = 0\n",
            "calibration.search_bins",
        ),
        (
            "config: DMD image rotated 10°",
            "[rig.alignment]\nrotation_deg = 10\n",
            "rig.alignment.rotation_deg",
        ),
        (
            "config: 1e9 GAP iterations",
            "[scene]\nsize = [64, 64]\n[reconstruct.gap]\niterations = 1000000000\n",
            "reconstruct.gap.iterations",
        ),
        (
            "config: band step 1e-4 nm",
            "[scene]\nwavelengths_nm = [400, 700, 1e-4]\n",
            "scene.wavelengths_nm",
        ),
        (
            "config: a negative sensor gain",
            "[rig.sensor]\ngain_dn_per_e = -1\n",
            "rig.sensor.gain_dn_per_e",
        ),
    ] {
        let text = if extra.starts_with("[scene]") {
            extra.to_string()
        } else {
            toml(extra)
        };
        refused(case, run_with(&text, &Library::default_root()), &[key]);
    }
}

// ---------------------------------------------------------------- the command line

fn specmux(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_specmux"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cli_a_raw_frame_with_nan_is_refused() {
    let scratch = temp("nan-frame");
    let d = scratch.path();
    let mut y = Cube::from_vec(64, 64, 1, vec![1.0; 64 * 64]).unwrap();
    y.data[5] = f32::NAN;
    let f = d.join("frame.exr");
    specmux_io::exr::write(&f, &y, &["Y".to_string()]).unwrap();
    let out = specmux(&[
        "reconstruct",
        f.to_str().unwrap(),
        "--experiment",
        "dead-leaves",
        "--out",
        d.join("out").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.lines().count() == 1 && err.contains("NaN"),
        "{err}"
    );
    assert!(!d.join("out").exists());
    record(
        "cli: a frame holding NaN",
        &format!("refused: `{}`", err.trim()),
    );
}

#[test]
fn cli_a_truth_of_the_wrong_size_is_refused_before_anything_is_written() {
    let scratch = temp("truth-size");
    let d = scratch.path();
    let f = d.join("frame.exr");
    specmux_io::exr::write(
        &f,
        &Cube::from_vec(64, 64, 1, vec![1.0; 64 * 64]).unwrap(),
        &["Y".to_string()],
    )
    .unwrap();
    let t = d.join("truth.exr");
    let names: Vec<String> = (0..31)
        .map(|k| specmux_io::exr::band_name(400.0 + 10.0 * k as f64))
        .collect();
    specmux_io::exr::write(&t, &Cube::zeros(32, 32, 31), &names).unwrap();
    let out = specmux(&[
        "reconstruct",
        f.to_str().unwrap(),
        "--experiment",
        "dead-leaves",
        "--truth",
        t.to_str().unwrap(),
        "--out",
        d.join("out").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("truth.exr")
            && err.contains("32 wide × 32 high × 31 planes"),
        "{err}"
    );
    assert!(!d.join("out").exists(), "nothing may be written");
    record(
        "cli: reconstruct --truth of the wrong size",
        &format!("refused before any output: `{}`", err.trim()),
    );
}

#[test]
fn cli_a_killed_run_leaves_no_file_under_the_final_names() {
    let scratch = temp("killed");
    let d = scratch.path();
    let out = d.join("out");
    let mut child = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .args(["demo", "--size", "384", "--out", out.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Kill it while it writes: once its staging folder holds a file.
    let t = std::time::Instant::now();
    let writing = loop {
        let staged = std::fs::read_dir(d).unwrap().flatten().any(|e| {
            e.file_name().to_string_lossy().contains(".staging-")
                && std::fs::read_dir(e.path()).is_ok_and(|mut r| r.next().is_some())
        });
        if staged || t.elapsed().as_secs() > 120 {
            break staged;
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    };
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(writing, "the run never started writing");
    assert!(
        !out.exists(),
        "a killed run left files under the final name"
    );
    // The next run removes the leftovers and says so.
    let next = specmux(&["demo", "--size", "64", "--out", out.to_str().unwrap()]);
    let said = String::from_utf8_lossy(&next.stdout);
    assert!(
        next.status.success() && said.contains("interrupted run"),
        "{said}"
    );
    let left: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    assert_eq!(left, vec![std::ffi::OsString::from("out")], "{left:?}");
    record(
        "outputs: a run killed while writing",
        "no file under the final name; the next run removed the staging folder and said so",
    );
}

#[test]
fn cli_two_concurrent_runs_into_one_folder_leave_one_whole_set() {
    let scratch = temp("concurrent");
    let d = scratch.path();
    let out = d.join("out");
    let run = |scene: &str| {
        Command::new(env!("CARGO_BIN_EXE_specmux"))
            .args([
                "demo",
                "--scene",
                scene,
                "--size",
                "96",
                "--out",
                out.to_str().unwrap(),
            ])
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap()
    };
    let (mut a, mut b) = (run("dead-leaves"), run("shaded-objects"));
    assert!(a.wait().unwrap().success() && b.wait().unwrap().success());
    // Every file of the set comes from the run its report names.
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    let scene = report["scene"].as_str().unwrap().to_string();
    let alone = d.join("alone");
    assert!(specmux(&[
        "demo",
        "--scene",
        &scene,
        "--size",
        "96",
        "--out",
        alone.to_str().unwrap()
    ])
    .status
    .success());
    for f in ["frame.exr", "cube.exr", "channels.exr"] {
        let same = std::fs::read(out.join(f)).unwrap() == std::fs::read(alone.join(f)).unwrap();
        assert!(same, "{f} is not {scene}'s");
    }
    record(
        "outputs: two runs into one folder at once",
        &format!(
            "one whole set ({scene}'s): frame, cube and channels match its own run byte for byte"
        ),
    );
}

#[test]
fn cli_same_seed_same_bytes_whatever_the_thread_count() {
    let scratch = temp("threads");
    let d = scratch.path();
    let run = |threads: &str, out: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_specmux"))
            .env("RAYON_NUM_THREADS", threads)
            .args([
                "demo",
                "--scene",
                "scenes/full-rig.toml",
                "--size",
                "64",
                "--out",
                d.join(out).to_str().unwrap(),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    run("1", "one");
    run("2", "two");
    for f in [
        "frame.exr",
        "cube.exr",
        "channels.exr",
        "frame.png",
        "cube_rgb.png",
    ] {
        let same = std::fs::read(d.join("one").join(f)).unwrap()
            == std::fs::read(d.join("two").join(f)).unwrap();
        assert!(same, "{f} differs between 1 and 2 threads");
    }
    record(
        "determinism: full rig on 1 and 2 threads",
        "EXR and PNG files byte-identical; report.json differs only in its *_seconds timings",
    );
}

/// Run specmux with `args`, send it SIGINT after 1.5 s, and return its exit code and stderr.
fn interrupted(args: &[&str]) -> (Option<i32>, String) {
    let child = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let sent = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(sent.success());
    let o = child.wait_with_output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// The exhaustive filter search (several seconds, millions of sets) polls Ctrl-C too: it used to
/// run to its end and stop only at the simulations after it.
#[test]
fn cli_ctrl_c_stops_the_filter_search_itself() {
    let scratch = temp("ctrl-c-design");
    let out = scratch.path().join("out");
    let args = ["design", "filters", "--size", "64", "--out"];
    let (code, err) = interrupted(&[&args[..], &[out.to_str().unwrap()]].concat());
    assert_eq!(code, Some(130), "{err}");
    assert!(err.contains("during the filter search"), "{err}");
    assert!(!out.exists(), "an interrupted design wrote its outputs");
    record(
        "cli: Ctrl-C during design filters' exhaustive search",
        "stopped within the search (exit 130, `… during the filter search`), nothing written",
    );
}

#[test]
fn cli_ctrl_c_stops_a_sweep_at_a_safe_point_and_writes_nothing() {
    let scratch = temp("ctrl-c");
    let d = scratch.path();
    let out = d.join("out");
    let values: Vec<String> = (1..=300).map(|i| i.to_string()).collect();
    let vary = format!("reconstruct.gap.iterations={}", values.join(";"));
    let (code, err) = interrupted(&[
        "sweep",
        "dead-leaves",
        "--size",
        "64",
        "--vary",
        &vary,
        "--vary",
        "reconstruct.gap.method=gap",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(130), "{err}");
    assert!(err.contains("interrupted (Ctrl-C) during"), "{err}");
    assert!(!out.exists(), "an interrupted sweep wrote its outputs");
    let left = std::fs::read_dir(d).unwrap().count();
    assert_eq!(left, 0, "an interrupted sweep left a staging folder");
    record(
        "cli: Ctrl-C during a 300-run sweep",
        "stopped at the next stage or iteration with exit 130 (`specmux: interrupted (Ctrl-C) \
         during …`); no file under the final names, no staging folder left",
    );
}
