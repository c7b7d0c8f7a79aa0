//! The spectral limit on the reflectance library's held-out half: the RMS error of unmixing
//! exact channels x = L r (no spatial error, no non-negativity) with the paper's curvature
//! penalty at several η and with the basis's trained Gaussian prior at several scales k.
//! `cargo run --release -p specmux-twin --example spectral_prior -- scenes/prototype.toml`
//! (docs/joint.md, "The trained spectral prior").

use nalgebra::DMatrix;
use specmux_core::spectral::basis::sample_matrix;
use specmux_core::spectral::Library;
use specmux_core::unmix::curvature;
use specmux_twin::scene::Materials;
use specmux_twin::{Experiment, Rig};
use std::path::Path;

fn main() -> specmux_core::Result<()> {
    let file = std::env::args()
        .nth(1)
        .unwrap_or("scenes/prototype.toml".into());
    let exp = Experiment::load(Path::new(&file))?;
    let lib = Library::default_root();
    let materials = Materials::load(&lib)?;
    let rig = Rig::build(&exp, &lib, &materials)?;
    let (b, light) = (rig.basis.vectors.clone(), rig.lit_projection());
    let f = &light * &b;
    let truth = sample_matrix(&materials.held_out, &rig.grid)?;
    let x = &light * &truth;
    let rms = |penalty: &DMatrix<f64>| -> f64 {
        let h = f.transpose() * &f + penalty;
        let alpha = h.try_inverse().expect("H is positive definite") * f.transpose() * &x;
        ((&b * alpha - &truth).norm_squared() / truth.len() as f64).sqrt()
    };
    let floor = &b * (b.transpose() * &truth) - &truth;
    println!(
        "{} held-out spectra; projection onto the basis alone: rms {:.5}",
        truth.ncols(),
        (floor.norm_squared() / truth.len() as f64).sqrt()
    );
    for eta in [20.0, 50.0, 100.0, 200.0, 500.0] {
        let p = curvature(&b, eta / rig.grid.step_nm.powi(4));
        println!("curvature η = {eta:>5}: rms {:.5}", rms(&p));
    }
    let trained = rig
        .basis
        .coefficient_prior(&light)
        .expect("a trained prior");
    for k in [0.1, 0.3, 1.0, 3.0] {
        println!("trained prior × {k:>3}: rms {:.5}", rms(&(&trained * k)));
    }
    Ok(())
}
