//! End-to-end checks of both design commands on small frames: the designed layout is never worse
//! than the paper's on the scenes it was designed on, and what each command writes is included
//! by an experiment file unchanged.

use specmux_core::spectral::Library;
use specmux_design::carriers::{self, CarrierArgs};
use specmux_design::filters::{self, FilterArgs};
use specmux_design::layout::Guard;
use specmux_twin::scene::Materials;
use specmux_twin::{Experiment, Rig};
use std::path::{Path, PathBuf};
use tempfile::TempDir;

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(rel)
}

/// A fresh scratch folder `specmux-design-{tag}-*`, removed when the returned guard drops.
fn temp(tag: &str) -> TempDir {
    tempfile::Builder::new()
        .prefix(&format!("specmux-design-{tag}-"))
        .tempdir()
        .unwrap()
}

fn carrier_args(out: PathBuf) -> CarrierArgs {
    CarrierArgs {
        size: 64,
        crop: vec![0.2],
        window: vec!["square".into()],
        scenes: vec![repo("scenes/bars.toml"), repo("scenes/prototype.toml")],
        scenes_dir: repo("scenes"),
        cube: Vec::new(),
        guard: Guard::Harmonics,
        harmonic: 0.0,
        restarts: 6,
        candidates: 2,
        coherent: false,
        experiment: None,
        seed: 1,
        out,
    }
}

#[test]
fn a_designed_layout_is_never_worse_than_the_papers_on_its_design_scenes() {
    let lib = Library::default_root();
    let scratch = temp("c0");
    let d = carriers::design(&carrier_args(scratch.path().join("out")), &lib).unwrap();
    assert_eq!(d.simulation_scenes, ["bars", "dead-leaves"]);
    let (paper, chosen) = (&d.candidates[0], &d.candidates[d.chosen]);
    assert!(paper.label.starts_with("paper"));
    for (c, p) in chosen.ideal.iter().zip(&paper.ideal) {
        assert!(
            c.cube_psnr_db >= p.cube_psnr_db,
            "{}: {} < {}",
            c.scene,
            c.cube_psnr_db,
            p.cube_psnr_db
        );
    }
    // Predicted and simulated crosstalk agree to a few dB on every channel of the paper's layout.
    for (k, o) in paper.ideal.iter().enumerate() {
        for (p, s) in paper.predicted_db[k]
            .iter()
            .zip(o.leak_db.as_ref().unwrap())
        {
            assert!(
                (p - s).abs() < 3.0,
                "{}: predicted {p} simulated {s}",
                o.scene
            );
        }
    }
}

#[test]
fn the_carrier_section_is_included_by_an_experiment_unchanged() {
    let scratch = temp("c1");
    let out = scratch.path().join("out");
    carriers::run(&carrier_args(out.clone()), &Library::default_root()).unwrap();
    let section = std::fs::read_to_string(out.join("carriers.toml")).unwrap();
    let text = format!("[scene]\nsource = \"bars\"\nsize = [64, 64]\n\n{section}");
    let e = Experiment::from_toml(&text, "included.toml").unwrap();
    assert_eq!(e.rig.carriers.frequencies.as_ref().map(Vec::len), Some(6));
    Experiment::load(&out.join("experiment.toml")).unwrap();
    for f in ["fourier_paper.png", "report.json"] {
        assert!(out.join(f).exists(), "{f}");
    }
}

/// A copy of spectra/ without generated curves, so the test writes its own.
fn library_copy(dir: &Path) -> Library {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for e in std::fs::read_dir(from).unwrap() {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap();
            if p.is_dir() && name != "design" {
                copy(&p, &to.join(name));
            } else if p.is_file() {
                std::fs::copy(&p, to.join(name)).unwrap();
            }
        }
    }
    copy(&repo("spectra"), dir);
    Library::new(dir)
}

#[test]
fn the_chosen_wheel_is_included_by_an_experiment_and_builds_a_rig() {
    let scratch = temp("f0");
    let dir = scratch.path();
    let lib = library_copy(&dir.join("spectra"));
    let fam = dir.join("families.toml");
    std::fs::write(&fam, "gaussian_centres_nm = [450, 650, 100]\ngaussian_fwhm_nm = [80]\nlongpass_edges_nm = [600, 600, 40]\nshortpass_edges_nm = [500, 500, 40]\ndichroic_bands_nm = []\n").unwrap();
    let a = FilterArgs {
        catalog: None,
        choose: 6,
        families: Some(fam),
        no_families: false,
        keep: Vec::new(),
        electrons: 1e4,
        top: 3,
        simulate: 1,
        scenes: vec![repo("scenes/bars.toml")],
        scenes_dir: repo("scenes"),
        size: 48,
        experiment: None,
        out: dir.join("out"),
    };
    let dense = dir.join("dense.toml");
    std::fs::write(&dense, "gaussian_centres_nm = [380, 780, 4]\ngaussian_fwhm_nm = [80]\nlongpass_edges_nm = [600, 600, 40]\nshortpass_edges_nm = [500, 500, 40]\ndichroic_bands_nm = []\n").unwrap();
    // A count or a light level out of range is refused by its option, before any search.
    for (bad, flag) in [
        (
            FilterArgs {
                top: 0,
                ..a.clone()
            },
            "--top: `top` = 0",
        ),
        (
            FilterArgs {
                electrons: f64::NAN,
                ..a.clone()
            },
            "--electrons: `electrons` = NaN",
        ),
        (
            FilterArgs {
                choose: 0,
                ..a.clone()
            },
            "--choose: `choose` = 0",
        ),
        (
            // 3.6·10⁹ sets of six from 122 curves: hours of search, refused before it.
            FilterArgs {
                families: Some(dense.clone()),
                ..a.clone()
            },
            "combinations of the catalogue's 109 curves, more than 200000000",
        ),
        (
            FilterArgs {
                simulate: 0,
                ..a.clone()
            },
            "--simulate: `simulate` = 0",
        ),
        (
            // The option's value, not the scene file, is at fault.
            FilterArgs {
                size: 7,
                ..a.clone()
            },
            "--size 7 on ",
        ),
        (
            // The prototype has six carriers: a set of five has no layout to run on.
            FilterArgs {
                choose: 5,
                ..a.clone()
            },
            "--choose: `choose` = 5: one filter per carrier: the experiment",
        ),
    ] {
        let e = filters::run(&bad, &lib).unwrap_err().to_string();
        assert!(e.contains(flag), "{e}");
    }
    let text = filters::run(&a, &lib).unwrap();
    assert!(text.contains("462 combinations"), "{text}");
    let wheel = std::fs::read_to_string(dir.join("out/wheel.toml")).unwrap();
    let exp = Experiment::from_toml(
        &format!("[scene]\nsource = \"bars\"\nsize = [48, 48]\n{wheel}"),
        "w.toml",
    )
    .unwrap();
    let rig = Rig::build(&exp, &lib, &Materials::load(&lib).unwrap()).unwrap();
    assert_eq!(rig.wheel.filters.len(), 6);
}

/// Counts and fractions out of range are refused by their option before any work (zero
/// candidates used to end in a misleading "no feasible layout … relax the guard").
#[test]
fn carrier_options_out_of_range_are_refused_by_name() {
    let lib = Library::default_root();
    let scratch = temp("c-bad");
    let base = carrier_args(scratch.path().join("out"));
    for (bad, flag) in [
        (
            CarrierArgs {
                candidates: 0,
                ..base.clone()
            },
            "--candidates: `candidates` = 0",
        ),
        (
            CarrierArgs {
                size: 8,
                ..base.clone()
            },
            "--size: `size` = 8",
        ),
        (
            CarrierArgs {
                crop: vec![0.2, 0.7],
                ..base.clone()
            },
            "--crop: `crop` = 0.7",
        ),
        (
            CarrierArgs {
                crop: vec![0.2, 0.15, 0.2],
                ..base.clone()
            },
            "--crop: `crop` = 0.2: is listed twice",
        ),
        (
            CarrierArgs {
                harmonic: f64::NAN,
                ..base.clone()
            },
            "--harmonic: `harmonic` = NaN",
        ),
    ] {
        let e = match carriers::design(&bad, &lib) {
            Ok(_) => panic!("{flag}: accepted"),
            Err(e) => e.to_string(),
        };
        assert!(e.contains(flag), "{e}");
    }
}
