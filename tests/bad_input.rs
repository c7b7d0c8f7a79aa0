//! Bad input gets a one-line error that names the file and the field, and a non-zero exit:
//! never a panic, never NaN.

use std::path::Path;
use std::process::Command;

mod common;
use common::{spectra_copy, tmpdir};

/// Run `specmux simulate` on an experiment text; return (success, stderr).
fn simulate(dir: &Path, toml: &str, spectra: Option<&Path>) -> (bool, String) {
    let exp = dir.join("exp.toml");
    std::fs::write(&exp, toml).unwrap();
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_specmux"));
    if let Some(s) = spectra {
        cmd.arg("--spectra").arg(s);
    }
    let out = cmd
        .arg("simulate")
        .arg(&exp)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn assert_one_line_error(ok: bool, err: &str, must_contain: &[&str]) {
    assert!(!ok, "the command should fail");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "one line expected, got:\n{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    for m in must_contain {
        assert!(err.contains(m), "`{m}` missing from: {err}");
    }
}

const SMALL: &str = "[scene]\nsize = [64, 64]\n";

#[test]
fn missing_spectrum_file() {
    let scratch = tmpdir("bad-missing");
    let d = scratch.path();
    let toml = format!("{SMALL}[rig.wheel]\nfilters = [\"wheel/red\", \"wheel/nope\", \"wheel/blue\", \"paper/a\", \"paper/b\", \"paper/c\"]\n");
    let (ok, err) = simulate(d, &toml, None);
    assert_one_line_error(ok, &err, &["exp.toml", "rig.wheel.filters[1]", "nope.csv"]);
}

#[test]
fn malformed_csv() {
    let scratch = tmpdir("bad-malformed");
    let d = scratch.path();
    let s = spectra_copy(d);
    let f = s.join("wheel/green.csv");
    let text = std::fs::read_to_string(&f)
        .unwrap()
        .replacen("\n5", "\n5x", 1);
    std::fs::write(&f, text).unwrap();
    let (ok, err) = simulate(d, SMALL, Some(&s));
    assert_one_line_error(
        ok,
        &err,
        &["green.csv:", "not a number", "rig.wheel.filters[1]"],
    );
}

#[test]
fn nan_in_a_curve() {
    let scratch = tmpdir("bad-nan");
    let d = scratch.path();
    let s = spectra_copy(d);
    let f = s.join("camera/mono_qe.csv");
    let mut lines: Vec<String> = std::fs::read_to_string(&f)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let last = lines.len() - 3;
    let wl = lines[last].split(',').next().unwrap().to_string();
    lines[last] = format!("{wl},NaN");
    std::fs::write(&f, lines.join("\n")).unwrap();
    let (ok, err) = simulate(d, SMALL, Some(&s));
    assert_one_line_error(ok, &err, &["mono_qe.csv:", "not finite", "rig.camera.qe"]);
}

#[test]
fn a_segment_that_passes_no_light_cannot_form_a_pattern() {
    // An infrared filter (750–800 nm) on a 400–700 nm rig: its pattern through the 4f filter
    // would be dark, so the experiment is refused by the filter's key.
    let scratch = tmpdir("bad-dark-segment");
    let d = scratch.path();
    let s = spectra_copy(d);
    std::fs::write(
        s.join("wheel/ir.csv"),
        "# test: an infrared long-pass\nwavelength_nm,value\n750,1\n800,1\n",
    )
    .unwrap();
    let toml = format!(
        "{SMALL}[rig.wheel]\nfilters = [\"wheel/ir\", \"wheel/green\", \"wheel/blue\", \"paper/a\", \"paper/b\", \"paper/c\"]\n[rig.dmd]\n[rig.fourier_filter]\n"
    );
    let (ok, err) = simulate(d, &toml, Some(&s));
    assert_one_line_error(
        ok,
        &err,
        &["exp.toml", "rig.wheel.filters[0]", "wheel/ir", "no light"],
    );
}

#[test]
fn negative_wavelength_step() {
    let scratch = tmpdir("bad-step");
    let d = scratch.path();
    let (ok, err) = simulate(d, "[scene]\nwavelengths_nm = [400, 700, -10]\n", None);
    assert_one_line_error(ok, &err, &["exp.toml", "scene.wavelengths_nm[2]", "-10"]);
}

#[test]
fn exr_with_the_wrong_channel_count() {
    let scratch = tmpdir("bad-exr");
    let d = scratch.path();
    let cube = specmux_core::Cube::zeros(64, 64, 5);
    let names: Vec<String> = (0..5)
        .map(|k| specmux_io::exr::band_name(400.0 + 10.0 * k as f64))
        .collect();
    specmux_io::exr::write(&d.join("five.exr"), &cube, &names).unwrap();
    // The grid written in the experiment (not taken from the file's channel names) disagrees.
    let toml = format!("{SMALL}source = \"exr:five.exr\"\nquantity = \"radiance\"\nwavelengths_nm = [400, 700, 10]\n");
    let (ok, err) = simulate(d, &toml, None);
    assert_one_line_error(ok, &err, &["five.exr", "5 channels", "31 bands"]);
}

#[test]
fn unknown_key() {
    let scratch = tmpdir("bad-key");
    let d = scratch.path();
    let (ok, err) = simulate(d, "[rig.wheel]\nfilterz = []\n", None);
    assert_one_line_error(ok, &err, &["exp.toml:2", "filterz"]);
}

#[test]
fn out_of_range_values_in_the_light_path_sections() {
    let scratch = tmpdir("bad-ranges");
    let d = scratch.path();
    for (toml, key, value) in [
        ("[rig.sensor]\nbits = 40\n", "rig.sensor.bits", "40"),
        (
            "[rig.sensor]\nprnu_fraction = -0.1\n",
            "rig.sensor.prnu_fraction",
            "-0.1",
        ),
        (
            "[rig.timing.dmd]\nmax_rate_hz = nan\n",
            "rig.timing.dmd.max_rate_hz",
            "NaN",
        ),
        (
            "[rig.timing.wheel]\nsegments_deg = [60, 60, 60, 60, 60, 50]\n",
            "rig.timing.wheel.segments_deg",
            "50",
        ),
        (
            "[rig.fourier_filter]\npinhole_radius_um = 0\n",
            "rig.fourier_filter.pinhole_radius_um",
            "0",
        ),
        ("[rig.lens]\nna = 2\n", "rig.lens.na", "2"),
        // Refused deep in the optical chain, which does not know the file: named at its boundary.
        (
            "[rig.dmd]\nwidth = 32\nheight = 32\n",
            "rig.dmd.width",
            "32×32 mirrors",
        ),
        (
            "[rig.dmd]\n[rig.fourier_filter]\npinhole_radius_um = 0.001\n",
            "rig.fourier_filter.pinhole_radius_um",
            "0.001",
        ),
        (
            "[rig.dmd]\n[rig.fourier_filter]\npinhole_radius_um = 100000\n",
            "rig.fourier_filter.pinhole_radius_um",
            "100000",
        ),
        (
            "[reconstruct]\ncrosstalk_weights = [[1, 0]]\n",
            "reconstruct.crosstalk_weights",
            "[[1.0, 0.0]]",
        ),
    ] {
        let (ok, err) = simulate(d, toml, None);
        assert_one_line_error(ok, &err, &["exp.toml", key, value]);
    }
}

#[test]
fn values_at_the_ends_of_the_f64_range_are_shown_in_exponent_form() {
    let scratch = tmpdir("bad-extreme");
    let d = scratch.path();
    for (toml, key, value) in [
        ("[rig.lens]\nna = 1e308\n", "rig.lens.na", "= 1e308:"),
        ("[rig.lens]\nna = -1e-300\n", "rig.lens.na", "= -1e-300:"),
        // Refused while reading the file (not an integer): the value as written, shown short.
        (
            "[rig.sensor]\nbits = 1e308\n",
            "rig.sensor.bits",
            "= 1e308:",
        ),
        // A figure derived from it, in the reason.
        (
            "[rig.dmd]\n[rig.fourier_filter]\npinhole_radius_um = 1e-300\n",
            "rig.fourier_filter.pinhole_radius_um",
            "= 1e-300:",
        ),
    ] {
        let (ok, err) = simulate(d, toml, None);
        assert_one_line_error(ok, &err, &["exp.toml", key, value]);
        let longest = err.split(|c: char| !c.is_ascii_digit()).map(str::len).max();
        assert!(
            longest < Some(25),
            "a number of {longest:?} digits in: {err}"
        );
    }
}

#[test]
fn a_negative_number_after_a_flag_reaches_its_check() {
    let scratch = tmpdir("bad-negative-flag");
    let d = scratch.path();
    for (args, must) in [
        (
            &["design", "filters", "--electrons", "-5", "--size", "32"][..],
            &["--electrons", "= -5", "must be positive"][..],
        ),
        (
            &[
                "patterns",
                "scenes/prototype.toml",
                "--size",
                "32",
                "--study",
                "-3,5",
            ][..],
            &["rig.fourier_filter.pinhole_radius_um", "= -3"][..],
        ),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_specmux"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(args)
            .arg("--out")
            .arg(d.join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_one_line_error(out.status.success(), &err, must);
    }
}

#[test]
fn a_timing_that_needs_a_faster_dmd_is_refused() {
    let scratch = tmpdir("bad-dmdrate");
    let d = scratch.path();
    let toml = "[rig.timing.wheel]\nrate_hz = 10000\n";
    let (ok, err) = simulate(d, toml, None);
    assert_one_line_error(ok, &err, &["exp.toml", "rig.timing"]);
}

#[test]
fn sensor_and_timing_must_agree_on_the_exposure() {
    let scratch = tmpdir("bad-exposure");
    let d = scratch.path();
    let toml = "[rig.timing.camera]\nexposure_s = 0.02\n[rig.sensor]\n";
    let (ok, err) = simulate(d, toml, None);
    assert_one_line_error(ok, &err, &["exp.toml", "rig.sensor.exposure_s", "0.02"]);
}

#[test]
fn an_iteration_count_beside_the_default_auto_method_is_refused() {
    let scratch = tmpdir("bad-auto-iterations");
    let d = scratch.path();
    for (toml, key) in [
        (
            "[reconstruct.gap]\niterations = 50\n",
            "reconstruct.gap.iterations",
        ),
        (
            "[reconstruct.gap]\nmethod = \"auto\"\n[reconstruct.joint]\niterations = 7\n",
            "reconstruct.joint.iterations",
        ),
    ] {
        let (ok, err) = simulate(d, &format!("{SMALL}{toml}"), None);
        assert_one_line_error(ok, &err, &["exp.toml", key, "\"auto\" (the default)"]);
    }
    // Naming the method makes the count apply.
    let toml = format!("{SMALL}[reconstruct.gap]\nmethod = \"gap\"\niterations = 5\n");
    let (ok, err) = simulate(d, &toml, None);
    assert!(ok, "{err}");
}

/// `--size` outside the scene's range is refused as `scene.size` would be, not with the
/// wavelet's divisibility rule (0 divides by 16); so is the photon-transfer frames' side.
#[test]
fn a_size_outside_the_scene_range_is_refused() {
    let scratch = tmpdir("bad-size");
    let d = scratch.path();
    // `ptc --size 100000` used to abort allocating its frames.
    for (cmd, n) in [
        ("demo", "0"),
        ("demo", "8"),
        ("demo", "9000"),
        ("ptc", "0"),
        ("ptc", "100000"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_specmux"))
            .args([cmd, "--size", n, "--out"])
            .arg(d.join("out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_one_line_error(out.status.success(), &err, &["--size", n, "16 to 8192"]);
    }
}

/// `[compute] device = "gpu"` in a build without the GPU backend is refused by `simulate` and
/// `demo` as by `bench` and `reconstruct` (it ran on the CPU without a word).
#[cfg(not(feature = "gpu"))]
#[test]
fn a_gpu_device_without_the_backend_is_refused() {
    let scratch = tmpdir("bad-gpu");
    let d = scratch.path();
    let (ok, err) = simulate(d, &format!("{SMALL}[compute]\ndevice = \"gpu\"\n"), None);
    assert_one_line_error(ok, &err, &["exp.toml", "compute.device", "--features gpu"]);
}

/// A frame saturated everywhere, reconstructed with the noise weights, is refused naming the
/// key that asked for them (the error surfaced unnamed from the weights).
#[test]
fn a_frame_saturated_everywhere_names_the_noise_weights() {
    let scratch = tmpdir("bad-saturated");
    let d = scratch.path();
    let toml = format!(
        "{SMALL}[rig.sensor]\nelectrons_at_full_scale = 1e12\n[reconstruct.gap]\nmethod = \"joint\"\n[reconstruct.joint]\niterations = 5\nnoise_weights = true\n"
    );
    let exp = d.join("exp.toml");
    std::fs::write(&exp, toml).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .arg("demo")
        .arg("--scene")
        .arg(&exp)
        .arg("--out")
        .arg(d.join("out"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    let must = [
        "exp.toml",
        "reconstruct.joint.noise_weights",
        "saturation level",
    ];
    assert_one_line_error(out.status.success(), &err, &must);
    assert!(
        !d.join("out").exists(),
        "outputs appear all at once or not at all"
    );
}

/// Run `specmux ARGS…` from the repository root; return (success, stderr).
fn specmux(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.success(), err)
}

#[test]
fn an_output_folder_of_other_files_or_of_the_inputs_is_refused_before_any_work() {
    let scratch = tmpdir("bad-out");
    let d = scratch.path();
    let s = |p: &Path| p.display().to_string();
    // A folder of files no run wrote: refused by name, the file kept.
    let lab = d.join("lab");
    std::fs::create_dir(&lab).unwrap();
    std::fs::write(lab.join("important.txt"), "keep").unwrap();
    let (ok, err) = specmux(&["demo", "--size", "32", "--out", &s(&lab)]);
    assert_one_line_error(
        ok,
        &err,
        &["lab", "important.txt", "no output of a specmux run"],
    );
    assert!(lab.join("important.txt").exists());
    // A run's own folder is replaced by the next run; its frame cannot be reconstructed into it.
    let sim = d.join("sim");
    assert!(specmux(&["simulate", "dead-leaves", "--out", &s(&sim)]).0);
    assert!(specmux(&["simulate", "dead-leaves", "--out", &s(&sim)]).0);
    let frame = s(&sim.join("frame.exr"));
    let recon = ["reconstruct", &frame, "--experiment", "dead-leaves"];
    let (ok, err) = specmux(&[&recon[..], &["--out", &s(&sim)]].concat());
    assert_one_line_error(ok, &err, &["frame.exr", "an input of this run"]);
    assert!(sim.join("frame.exr").exists() && sim.join("truth.exr").exists());
    // A simulated recording is replaced by the next rehearsal, not by an acquisition's files
    // elsewhere, and not by reconstructing it into itself.
    let rec = d.join("rec");
    let rehearse = [
        "rehearse",
        "scenes/moving-spheres.toml",
        "--frames",
        "2",
        "--out",
    ];
    for _ in 0..2 {
        let (ok, err) = specmux(&[&rehearse[..], &[&s(&rec)]].concat());
        assert!(ok, "{err}");
    }
    let (ok, err) = specmux(&["reconstruct", &s(&rec), "--out", &s(&rec)]);
    assert_one_line_error(ok, &err, &["is this run's input"]);
    assert!(rec.join("frames.ome.tif").exists());
    let acquire = [
        "acquire",
        "scenes/moving-spheres.toml",
        "--frames",
        "2",
        "--out",
    ];
    let (ok, err) = specmux(&[&acquire[..], &[&s(&lab)]].concat());
    assert_one_line_error(ok, &err, &["new or empty folder", "important.txt"]);
    // The built-in scenes' names are experiments to the controller's commands too.
    let (ok, err) = specmux(&["rehearse", "dead-leaves", "--frames", "2", "--dry-run"]);
    assert!(ok, "{err}");
}

#[test]
fn a_missing_scene_file_or_spectral_library_is_named_by_its_key() {
    let scratch = tmpdir("bad-missing-source");
    let d = scratch.path();
    for (source, shown) in [
        ("exr:nope.exr", "nope.exr is not there"),
        ("mitsuba:renders/x", "renders/x_truth.exr is not there"),
    ] {
        let toml = format!("[scene]\nsource = \"{source}\"\nquantity = \"radiance\"\n");
        let (ok, err) = simulate(d, &toml, None);
        assert_one_line_error(ok, &err, &["exp.toml", "scene.source", source, shown]);
    }
    let none = d.join("no-library");
    let (ok, err) = simulate(d, SMALL, Some(&none));
    assert_one_line_error(ok, &err, &["--spectra", "no-library", "no such folder"]);
}
