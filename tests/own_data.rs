//! A user's own data through the command line (docs/inputs.md): cubes, curves, frames and
//! calibration frames of their own, built-in scene names everywhere, .npy output, the JSON
//! report's schema, and a binary that works from any folder.

use specmux_core::Cube;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::tmpdir;

/// Run `specmux ARGS` in folder `cwd`; return (success, stdout, stderr).
fn specmux_in(cwd: &Path, args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_specmux"))
        .current_dir(cwd)
        .env_remove("SPECMUX_SPECTRA")
        .args(args)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The command must succeed; its stdout.
fn ok(cwd: &Path, args: &[&str]) -> String {
    let (ok, out, err) = specmux_in(cwd, args);
    assert!(ok, "specmux {args:?} failed: {err}");
    out
}

/// The command must fail with one line that contains every `must`.
fn refused(cwd: &Path, args: &[&str], must: &[&str]) -> String {
    let (ok, _, err) = specmux_in(cwd, args);
    assert!(!ok, "specmux {args:?} should fail");
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "one line expected: {err}"
    );
    assert!(!err.contains("panicked"), "{err}");
    for m in must {
        assert!(err.contains(m), "`{m}` missing from: {err}");
    }
    err
}

/// A JSON file the run wrote.
fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The PSNR printed on a line `against …: PSNR x dB`.
fn psnr(stdout: &str) -> f64 {
    let line = stdout.lines().find(|l| l.contains("PSNR")).expect(stdout);
    let after = line.split("PSNR ").nth(1).unwrap();
    after.split(' ').next().unwrap().parse().unwrap()
}

/// `method = "auto"` (the default) says what it picked and from which device's table, in the
/// text and in reconstruct.json; on the CPU it reads the CPU's table, and with `auto_table` the
/// bench report it names.
#[test]
fn auto_says_which_device_table_it_picked_from() {
    let scratch = tmpdir("own-auto");
    let d = scratch.path();
    ok(d, &["demo", "--size", "64", "--out", "demo"]);
    let cpu = "[scene]\nsource = \"dead-leaves\"\nsize = [64, 64]\n[compute]\ndevice = \"cpu\"\n";
    std::fs::write(d.join("cpu.toml"), cpu).unwrap();
    let args = ["reconstruct", "demo/frame.exr", "--experiment", "cpu.toml"];
    let text = ok(d, &[&args[..], &["--out", "rec"]].concat());
    assert!(
        text.contains("auto: ") && text.contains("on two CPU threads"),
        "{text}"
    );
    let json = std::fs::read_to_string(d.join("rec/reconstruct.json")).unwrap();
    let report: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(report["auto"]["measured_on"], "two CPU threads", "{json}");
    // Its pick is the joint method: its run is reported as in demo's report.json.
    let picked = report["auto"]["iterations"].as_u64();
    assert_eq!(report["joint"]["iterations"].as_u64(), picked, "{json}");
    assert!(
        text.contains("joint: ") && text.contains("joint prior tv"),
        "{text}"
    );
    // At its defaults: the design's trained spectral prior, the TV weights refreshed once.
    assert_eq!(report["joint"]["spectral_prior"], "trained", "{json}");
    assert_eq!(report["joint"]["reweight_rounds"], 1, "{json}");
    assert!(text.contains("(spectral: trained)"), "{text}");
    // With `[reconstruct] auto_table` it picks from a bench report of this machine instead.
    ok(
        d,
        &[
            "bench",
            "dead-leaves",
            "--size",
            "64",
            "--repeats",
            "1",
            "--out",
            "b",
        ],
    );
    let own = format!("{cpu}[reconstruct]\nauto_table = \"b/bench.json\"\n");
    std::fs::write(d.join("own.toml"), own).unwrap();
    let args = ["reconstruct", "demo/frame.exr", "--experiment", "own.toml"];
    let text = ok(d, &[&args[..], &["--out", "rec-own"]].concat());
    assert!(text.contains("on the bench report b/bench.json"), "{text}");
}

#[test]
fn reconstruct_refuses_a_frame_without_its_experiment_and_frames_it_cannot_read() {
    let scratch = tmpdir("own-refuse");
    let d = scratch.path();
    ok(d, &["demo", "--size", "64", "--out", "demo"]);
    refused(
        d,
        &["reconstruct", "demo/frame.exr"],
        &["demo/frame.exr", "--experiment"],
    );
    // The 8-bit PNG beside the frame is a preview.
    refused(
        d,
        &[
            "reconstruct",
            "demo/frame.png",
            "--experiment",
            "dead-leaves",
        ],
        &["demo/frame.png", "16-bit"],
    );
    // A path that is not there is said so, with or without an extension.
    for missing in ["no/such/frame", "no/such/frame.exr"] {
        let args = ["reconstruct", missing, "--experiment", "dead-leaves"];
        refused(d, &args, &[missing, "No such file"]);
    }
    // A TIFF that is not one (a truncated header) names the file.
    std::fs::write(d.join("frame.tif"), b"II*\0").unwrap();
    refused(
        d,
        &["reconstruct", "frame.tif", "--experiment", "dead-leaves"],
        &["frame.tif"],
    );
    // Values whose Fourier transform or products leave f32's range: refused, naming the pixel
    // and the value.
    let mut big = vec![1.0f32; 64 * 64];
    big[2 * 64 + 5] = 3e38;
    for (name, data, must) in [
        (
            "big.exr",
            big,
            [
                "pixel (5, 2) is 3e38",
                "64×64 frame's values must lie within ±2.4e32",
                "scale the frame",
            ],
        ),
        (
            "tiny.exr",
            vec![1e-33f32; 64 * 64],
            ["is 1e-33, under 1e-30", "(", "scale the frame"],
        ),
    ] {
        let frame = Cube::from_vec(64, 64, 1, data).unwrap();
        specmux_io::exr::write(&d.join(name), &frame, &["Y".to_string()]).unwrap();
        let args = ["reconstruct", name, "--experiment", "dead-leaves"];
        refused(d, &args, &[&[name][..], &must[..]].concat());
    }
    // A 16-bit PNG holds raw DN: an experiment without a camera cannot read it.
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(64, 64, image::Luma([1000]));
    img.save(d.join("raw.png")).unwrap();
    refused(
        d,
        &["reconstruct", "raw.png", "--experiment", "dead-leaves"],
        &["rig.sensor", "raw.png"],
    );
}

#[test]
fn built_in_scene_names_work_in_every_command_and_a_bad_size_names_the_flag() {
    let scratch = tmpdir("own-names");
    let d = scratch.path();
    let out = ok(d, &["simulate", "dead-leaves", "--explain"]);
    assert!(out.contains("scene"), "{out}");
    refused(d, &["simulate", "nope"], &["nope", "built-in scene"]);
    // The default method and GAP-TV take any side; GAP's wavelet only sides it can split.
    ok(d, &["demo", "--size", "100", "--out", "auto-100"]);
    for (method, side) in [("gap-tv", "100"), ("gap", "96")] {
        let file = format!("{method}.toml");
        let toml = format!("[scene]\nsource = \"dead-leaves\"\n[reconstruct.gap]\nmethod = \"{method}\"\niterations = 2\n");
        std::fs::write(d.join(&file), toml).unwrap();
        ok(
            d,
            &["demo", "--scene", &file, "--size", side, "--out", method],
        );
    }
    refused(
        d,
        &["demo", "--scene", "gap.toml", "--size", "100"],
        &["--size", "100", "96 or 112"],
    );
    // The crop sweep runs GAP beside the Fourier estimate unless told not to.
    let sweep = [
        "sweep-crop",
        "dead-leaves",
        "--size",
        "40",
        "--out",
        "sweep",
    ];
    refused(d, &sweep, &["reconstruct.gap.levels", "40×40", "--no-gap"]);
    ok(d, &[&sweep[..], &["--no-gap"]].concat());
}

/// A 48 × 32 cube of 16 bands 450–600 nm, channels named as specmux names them.
fn write_cube(path: &Path) -> Cube {
    write_cube_times(path, 1.0)
}

/// [`write_cube`] with every value times `k`.
fn write_cube_times(path: &Path, k: f32) -> Cube {
    let (w, h, n) = (48, 32, 16);
    let data = (0..w * h * n)
        .map(|i| k * (0.2 + 0.6 * ((i % 97) as f32 / 97.0)))
        .collect();
    let cube = Cube::from_vec(w, h, n, data).unwrap();
    let names: Vec<String> = (0..n)
        .map(|k| specmux_io::exr::band_name(450.0 + 10.0 * k as f64))
        .collect();
    specmux_io::exr::write(path, &cube, &names).unwrap();
    cube
}

#[test]
fn an_exr_scene_of_negative_or_overflowing_light_is_refused_by_its_key() {
    let scratch = tmpdir("own-extreme-cube");
    let d = scratch.path();
    for (name, k, must) in [
        (
            "neg",
            -1.0,
            &[
                "neg.exr",
                "pixel (0, 0) of channel `0450.0nm` is -0.2",
                "a radiance cannot be negative",
            ][..],
        ),
        // Finite values whose light overflows f32 on the way to the camera.
        (
            "huge",
            3e38,
            &[
                "`scene.source` = exr:huge.exr",
                "overflows f32 at pixel (0, 0)",
                "scale the scene",
            ][..],
        ),
        // A frame beyond what the reconstruction's FFT holds: named by the scene, not "NaN".
        (
            "big",
            1e35,
            &[
                "`scene.source` = exr:big.exr",
                "out of range: pixel (0, 0) is 2.400655e35",
                "±6.5e32",
            ][..],
        ),
    ] {
        write_cube_times(&d.join(format!("{name}.exr")), k);
        let exp = format!("{name}.toml");
        let toml = format!("[scene]\nsource = \"exr:{name}.exr\"\nquantity = \"radiance\"\n");
        std::fs::write(d.join(&exp), toml).unwrap();
        refused(d, &["demo", "--scene", &exp, "--out", "o"], must);
    }
}

#[test]
fn an_exr_scene_takes_its_size_and_bands_from_the_file_and_must_say_its_quantity() {
    let scratch = tmpdir("own-exr");
    let d = scratch.path();
    std::fs::create_dir_all(d.join("exp")).unwrap();
    let cube = write_cube(&d.join("exp/mine.exr"));
    let exp = |extra: &str| {
        std::fs::write(
            d.join("exp/e.toml"),
            format!("[scene]\nsource = \"exr:mine.exr\"\n{extra}"),
        )
        .unwrap();
    };
    exp("");
    refused(
        d,
        &["simulate", "exp/e.toml"],
        &["exp/e.toml", "scene.quantity", "mine.exr"],
    );
    exp("quantity = \"reflectance\"\nsize = [64, 64]\n");
    refused(
        d,
        &["simulate", "exp/e.toml"],
        &["scene.size", "[64, 64]", "48×32"],
    );
    exp("quantity = \"reflectance\"\n");
    ok(d, &["simulate", "exp/e.toml", "--out", "sim"]);
    let (truth, names) = specmux_io::exr::read(&d.join("sim/truth.exr")).unwrap();
    assert_eq!((truth.width, truth.height, truth.planes), (48, 32, 16));
    assert_eq!(truth.data, cube.data);
    assert_eq!(names[15], "0600.0nm");
    let (frame, _) = specmux_io::exr::read(&d.join("sim/frame.exr")).unwrap();
    assert_eq!((frame.width, frame.height), (48, 32));
}

#[test]
fn curves_given_as_csv_paths_are_read_beside_the_experiment() {
    let scratch = tmpdir("own-csv");
    let d = scratch.path();
    let lib = Path::new(env!("CARGO_MANIFEST_DIR")).join("spectra");
    std::fs::create_dir_all(d.join("exp/curves")).unwrap();
    for (from, to) in [
        ("wheel/red", "curves/red.csv"),
        ("camera/mono_qe", "qe.csv"),
        ("illuminants/D65", "d65.csv"),
    ] {
        std::fs::copy(lib.join(format!("{from}.csv")), d.join("exp").join(to)).unwrap();
    }
    let base = "[scene]\nsize = [64, 64]\n";
    let own_light = "[scene]\nsize = [64, 64]\nilluminant = \"d65.csv\"\n";
    let wheel = |red: &str| {
        format!("[rig.wheel]\nfilters = [\"{red}\", \"wheel/green\", \"wheel/blue\", \"paper/a\", \"paper/b\", \"paper/c\"]\n")
    };
    std::fs::write(
        d.join("exp/lib.toml"),
        format!("{base}{}", wheel("wheel/red")),
    )
    .unwrap();
    let own = format!(
        "{own_light}{}[rig.camera]\nqe = \"qe.csv\"\n",
        wheel("curves/red.csv")
    );
    std::fs::write(d.join("exp/own.toml"), own).unwrap();
    ok(d, &["simulate", "exp/lib.toml", "--out", "a"]);
    ok(d, &["simulate", "exp/own.toml", "--out", "b"]);
    // The figures light the cube with the experiment's own illuminant file too.
    ok(d, &["demo", "--scene", "exp/own.toml", "--out", "c"]);
    assert!(d.join("c/comparison.png").exists());
    let frame = |dir: &str| {
        specmux_io::exr::read(&d.join(dir).join("frame.exr"))
            .unwrap()
            .0
    };
    assert_eq!(
        frame("a").data,
        frame("b").data,
        "the same curves, read from the user's files"
    );
    std::fs::remove_file(d.join("exp/qe.csv")).unwrap();
    refused(
        d,
        &["simulate", "exp/own.toml"],
        &["exp/own.toml", "rig.camera.qe", "exp/qe.csv"],
    );
}

const MISALIGNED: &str = "[rig.alignment]\nrotation_deg = 0.4\nmagnification = 1.003\n";

#[test]
fn measured_calibration_frames_are_used_by_reconstruct() {
    let scratch = tmpdir("own-cal");
    let d = scratch.path();
    let base = "[scene]\nsource = \"shaded-objects\"\nsize = [256, 256]\n[reconstruct.gap]\nmethod = \"fourier\"\n[rig.sensor]\n";
    std::fs::write(d.join("rig.toml"), format!("{base}{MISALIGNED}")).unwrap();
    std::fs::write(d.join("design.toml"), base).unwrap();
    // The rig as built (misaligned) records the frame and its calibration frames.
    ok(d, &["simulate", "rig.toml", "--out", "rec"]);
    for f in ["dark", "flat", "pattern-1", "pattern-6"] {
        assert!(d.join(format!("rec/calibration/{f}.exr")).is_file(), "{f}");
    }
    // Reconstruct with `exp`'s rig, calibrated from the recorded frames or not, into `out`.
    let run = |exp: &str, cal: bool, out: &str| {
        let mut a = vec!["reconstruct", "rec/frame.exr", "--experiment", exp];
        a.extend(["--truth", "rec/truth.exr", "--out", out]);
        if cal {
            a.extend(["--calibration", "rec/calibration"]);
        }
        let text = ok(d, &a);
        (psnr(&text), text)
    };
    let (with, text) = run("design.toml", true, "with");
    assert!(
        text.contains("calibration: files in rec/calibration"),
        "{text}"
    );
    let (without, text) = run("design.toml", false, "without");
    assert!(text.contains("simulated captures"), "{text}");
    // The design alone misses the carriers the misalignment moved; the recorded frames find
    // them, exactly as the twin's own captures of the misaligned rig do (EXR keeps f32 exact).
    let (twin, _) = run("rig.toml", false, "twin");
    eprintln!("with the files {with:.2} dB, without {without:.2} dB, the rig's own {twin:.2} dB");
    assert!(
        with > without + 6.0 && (with - twin).abs() < 0.01,
        "with the files {with:.2} dB, without {without:.2} dB, the rig's own {twin:.2} dB"
    );
    // The same raw frame saved as a 16-bit TIFF, as camera software does, gives the same cube.
    let (frame, _) = specmux_io::exr::read(&d.join("rec/frame.exr")).unwrap();
    let dn: Vec<u16> = frame.data.iter().map(|&v| v as u16).collect();
    assert!(frame.data.iter().zip(&dn).all(|(&v, &n)| v == f32::from(n)));
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(256, 256, dn)
        .unwrap()
        .save(d.join("rec/frame.tif"))
        .unwrap();
    let mut a = vec![
        "reconstruct",
        "rec/frame.tif",
        "--experiment",
        "design.toml",
    ];
    a.extend([
        "--truth",
        "rec/truth.exr",
        "--calibration",
        "rec/calibration",
    ]);
    let tif = psnr(&ok(d, &[&a[..], &["--out", "tif"]].concat()));
    assert_eq!(tif, with, "TIFF {tif} dB against EXR {with} dB");
    let report = read_json(&d.join("with/reconstruct.json"));
    assert!(report["calibration"]["source"]
        .as_str()
        .unwrap()
        .contains("rec/calibration"));
    // The camera's noise model and the recorded dark frame give the frame's SNR; it is high.
    let snr = report["mean_snr"].as_f64().unwrap();
    assert!(
        snr > 10.0 && report["warnings"] == serde_json::json!([]),
        "{report}"
    );
    // A folder that lacks a pattern is refused by name.
    std::fs::remove_file(d.join("rec/calibration/pattern-6.exr")).unwrap();
    let a = [
        "reconstruct",
        "rec/frame.exr",
        "--experiment",
        "design.toml",
    ];
    refused(
        d,
        &[&a[..], &["--calibration", "rec/calibration"]].concat(),
        &["pattern-6.exr"],
    );
}

/// Shape and samples of a little-endian float32 `.npy` file (the format numpy writes).
fn read_npy(path: &Path) -> (Vec<usize>, Vec<f32>) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
    let n = u16::from_le_bytes([b[8], b[9]]) as usize;
    let header = std::str::from_utf8(&b[10..10 + n]).unwrap();
    assert!(header.contains("'descr': '<f4'") && header.contains("'fortran_order': False"));
    let shape = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap();
    let shape = shape
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().unwrap())
        .collect();
    let data = b[10 + n..]
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    (shape, data)
}

/// The keys and JSON types docs/report-schema.md lists for `file` (rows `| file | key | type |`).
fn schema_rows(file: &str) -> Vec<(String, String)> {
    let doc = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/report-schema.md"),
    )
    .unwrap();
    doc.lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (cells.len() > 4 && cells[1] == file)
                .then(|| (cells[2].trim_matches('`').to_string(), cells[3].to_string()))
        })
        .collect()
}

/// Every documented key is present with its documented type.
fn check_schema(file: &str, report: &serde_json::Value) {
    let rows = schema_rows(file);
    assert!(
        rows.len() > 5,
        "docs/report-schema.md lists no keys for {file}"
    );
    for (key, ty) in rows {
        let v = key
            .split('.')
            .fold(report, |v, k| match k.strip_suffix("[]") {
                Some(array) => &v[array][0],
                None => &v[k],
            });
        let fits = match ty.as_str() {
            "integer" => v.is_u64(),
            "number" => v.is_number(),
            "string" => v.is_string(),
            "array" => v.is_array(),
            "object" => v.is_object(),
            "number or null" => v.is_number() || v.is_null(),
            "object or null" => v.is_object() || v.is_null(),
            "array or null" => v.is_array() || v.is_null(),
            t => panic!("unknown type `{t}` for {key}"),
        };
        assert!(fits, "{file}: `{key}` should be {ty}, is {v}");
    }
}

#[test]
fn npy_outputs_and_the_report_schema_from_an_installed_binary_in_an_empty_folder() {
    // The binary copied out of the build tree, run from an empty folder: nothing of the
    // checkout is near it, and SPECMUX_SPECTRA is unset.
    let scratch = tmpdir("own-install");
    let d = scratch.path();
    let bin_dir = d.join("bin");
    std::fs::create_dir_all(&bin_dir).unwrap();
    let bin: PathBuf = bin_dir.join("specmux");
    std::fs::copy(env!("CARGO_BIN_EXE_specmux"), &bin).unwrap();
    let work = d.join("empty");
    std::fs::create_dir_all(&work).unwrap();
    // The installed binary in `work`, with the embedded library; it must succeed.
    let run = |args: &[&str]| {
        let out = Command::new(&bin)
            .current_dir(&work)
            .env_remove("SPECMUX_SPECTRA")
            .args(args)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {err}");
    };
    run(&["demo", "--size", "64", "--npy"]);
    let demo = work.join("out/demo");
    let report = read_json(&demo.join("report.json"));
    assert_eq!(
        report["spectra"],
        format!("embedded (specmux {})", env!("CARGO_PKG_VERSION"))
    );
    assert_eq!(report["specmux_version"], env!("CARGO_PKG_VERSION"));
    check_schema("report.json", &report);
    for (stem, shape) in [
        ("cube", vec![31, 64, 64]),
        ("truth", vec![31, 64, 64]),
        ("channels", vec![6, 64, 64]),
        ("frame", vec![64, 64]),
    ] {
        let (s, data) = read_npy(&demo.join(format!("{stem}.npy")));
        assert_eq!(s, shape, "{stem}");
        let (exr, _) = specmux_io::exr::read(&demo.join(format!("{stem}.exr"))).unwrap();
        assert_eq!(data, exr.data, "{stem}.npy holds the EXR's samples");
    }
    // simulate --npy: the calibration frames' EXRs too.
    std::fs::write(work.join("small.toml"), "[scene]\nsize = [64, 64]\n").unwrap();
    run(&["simulate", "small.toml", "--npy", "--out", "sim"]);
    let cal = work.join("sim/calibration");
    let (s, data) = read_npy(&cal.join("pattern-6.npy"));
    let (exr, _) = specmux_io::exr::read(&cal.join("pattern-6.exr")).unwrap();
    assert_eq!(
        (s, data),
        (vec![64, 64], exr.data),
        "pattern-6.npy holds the EXR's samples"
    );
    // The demo's truth is the scene simulate renders for the same experiment.
    assert_eq!(
        read_npy(&work.join("sim/truth.npy")),
        read_npy(&demo.join("truth.npy")),
        "demo's truth.npy is not simulate's"
    );
    // reconstruct.json, from the same binary with a --spectra folder: its provenance says so.
    let lib = Path::new(env!("CARGO_MANIFEST_DIR")).join("spectra");
    let out = Command::new(&bin)
        .current_dir(&work)
        .args([
            "--spectra",
            lib.to_str().unwrap(),
            "reconstruct",
            "out/demo/frame.exr",
        ])
        .args(["--experiment", "dead-leaves", "--out", "rec"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rec = read_json(&work.join("rec/reconstruct.json"));
    assert_eq!(rec["spectra"], lib.display().to_string());
    check_schema("reconstruct.json", &rec);
}

/// A frame recorded with almost no light is reconstructed with a warning that its signal is
/// under its noise and one that its calibration captures hold no carrier, in the text and in
/// reconstruct.json.
#[test]
fn reconstruct_warns_of_a_frame_under_its_noise() {
    let scratch = tmpdir("own-dim");
    let d = scratch.path();
    let exp = "[scene]\nsize = [64, 64]\n[reconstruct.gap]\nmethod = \"fourier\"\n[rig.sensor]\nelectrons_at_full_scale = 1e-6\n";
    std::fs::write(d.join("dim.toml"), exp).unwrap();
    ok(d, &["simulate", "dim.toml", "--out", "rec"]);
    let text = ok(
        d,
        &[
            "reconstruct",
            "rec/frame.exr",
            "--experiment",
            "dim.toml",
            "--calibration",
            "rec/calibration",
            "--out",
            "out",
        ],
    );
    assert!(
        text.contains("warning: the frame's mean signal is")
            && text.contains("warning: calibration: carriers that do not stand out"),
        "{text}"
    );
    let report = read_json(&d.join("out/reconstruct.json"));
    assert!(report["mean_snr"].as_f64().unwrap() < 1.0, "{report}");
    assert_eq!(report["warnings"].as_array().unwrap().len(), 2, "{report}");
}

#[test]
fn reconstruct_says_when_the_frame_overrides_the_experiments_size() {
    let scratch = tmpdir("own-size");
    let d = scratch.path();
    let exp =
        |n: usize| format!("[scene]\nsize = [{n}, {n}]\n[reconstruct.gap]\nmethod = \"fourier\"\n");
    std::fs::write(d.join("e64.toml"), exp(64)).unwrap();
    std::fs::write(d.join("e32.toml"), exp(32)).unwrap();
    ok(d, &["simulate", "e64.toml", "--out", "sim"]);
    let args = |e: &'static str| {
        [
            "reconstruct",
            "sim/frame.exr",
            "--experiment",
            e,
            "--out",
            "out",
        ]
    };
    let text = ok(d, &args("e32.toml"));
    assert!(
        text.contains("warning: e32.toml: scene.size = [32, 32], but the frame is 64×64: the frame's size is used"),
        "{text}"
    );
    let report = read_json(&d.join("out/reconstruct.json"));
    assert_eq!(report["warnings"].as_array().unwrap().len(), 1, "{report}");
    // The experiment that made the frame: nothing to say.
    assert!(!ok(d, &args("e64.toml")).contains("scene.size"));
}

/// The stage names `simulate` printed with their seconds.
fn stages_run(stdout: &str) -> Vec<&str> {
    (stdout.lines())
        .filter(|l| l.trim_end().ends_with(" s") && !l.starts_with("total"))
        .filter_map(|l| l.split_whitespace().next())
        .collect()
}

#[test]
fn the_command_line_keeps_patterns_and_captures_in_the_pattern_cache() {
    let scratch = tmpdir("own-cache");
    let d = scratch.path();
    std::fs::write(
        d.join("rig.toml"),
        "[scene]\nsize = [48, 40]\n[rig.dmd]\nwidth = 48\nheight = 40\n[rig.fourier_filter]\n\
         [rig.lens]\n[rig.sensor]\n",
    )
    .unwrap();
    let run = |out: &str| {
        ok(
            d,
            &[
                "--pattern-cache",
                "kept",
                "simulate",
                "rig.toml",
                "--out",
                out,
            ],
        )
    };
    let first = run("a");
    assert!(
        stages_run(&first).contains(&"relay-fourier-filter"),
        "{first}"
    );
    let mut kept: Vec<_> = std::fs::read_dir(d.join("kept"))
        .unwrap()
        .map(|e| e.unwrap().path().extension().unwrap().to_owned())
        .collect();
    kept.sort();
    assert_eq!(kept, ["captures", "patterns"], "{first}");
    let second = run("b");
    let stages = stages_run(&second);
    assert!(stages.contains(&"pattern-cache"), "{second}");
    assert!(stages.contains(&"calibration-cache"), "{second}");
    for made in ["relay-fourier-filter", "calibration-captures"] {
        assert!(!stages.contains(&made), "{second}");
    }
}
