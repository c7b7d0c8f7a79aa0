//! Mitsuba 3 spectral renders as scenes (tools/mitsuba/, docs/mitsuba.md). A render's truth file
//! holds hat-weighted band averages m_b / w_b of the radiance; the twin reads a cube as the
//! piecewise-linear spectrum Σ_b c_b hat_b, so the nodal values are c = G⁻¹m (G the hat Gram
//! matrix): the L2 projection of the rendered radiance onto the twin's spectra. A hat average
//! is not a nodal value: using it as one would blur every spectrum by the hat a second time.

use crate::scene::Quantity;
use crate::scene::SceneConfig;
use rayon::prelude::*;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::spectral::Curve;
use specmux_core::spectral::Grid;
use specmux_core::Cube;
use std::path::{Path, PathBuf};

/// Prefix of a Mitsuba scene source: `mitsuba:<path prefix>` names `<prefix>_truth.exr`.
pub const PREFIX: &str = "mitsuba:";

/// The wheel file's channel names, in wheel order (tools/mitsuba/render.py).
pub const WHEEL_CHANNELS: [&str; 6] = ["f0_red", "f1_green", "f2_blue", "f3_a", "f4_b", "f5_c"];

/// Check the keys a Mitsuba source constrains: a render is radiance, and its path is not empty.
pub fn check(s: &SceneConfig, file: &str) -> Result<()> {
    let Some(prefix) = s.source.strip_prefix(PREFIX) else {
        return Ok(());
    };
    if prefix.is_empty() {
        return Err(Error::config(
            file,
            "scene.source",
            format!("\"{}\"", s.source),
            "needs the render's path prefix, e.g. \"mitsuba:renders/chart\" for renders/chart_truth.exr",
        ));
    }
    if s.quantity != Quantity::Radiance {
        return Err(Error::config(
            file,
            "scene.quantity",
            "\"reflectance\"",
            "a Mitsuba render is a radiance cube: set quantity = \"radiance\"",
        ));
    }
    Ok(())
}

/// ∫ hat_b dλ on the grid's span: the step, half of it for the two end hats.
pub fn hat_widths(grid: &Grid) -> Vec<f64> {
    (0..grid.count)
        .map(|b| {
            if b == 0 || b + 1 == grid.count {
                grid.step_nm / 2.0
            } else {
                grid.step_nm
            }
        })
        .collect()
}

/// The hat Gram matrix G_bb' = ∫ hat_b hat_b' dλ, tridiagonal: (diagonal, off-diagonal) with
/// 2h/3 on the diagonal (h/3 at both ends) and h/6 beside it, h the step.
pub fn hat_gram(grid: &Grid) -> (Vec<f64>, Vec<f64>) {
    let h = grid.step_nm;
    let diag = hat_widths(grid).iter().map(|w| w * 2.0 / 3.0).collect();
    (diag, vec![h / 6.0; grid.count - 1])
}

/// Solves G c = m for one pixel after another with G's factors computed once (Thomas algorithm;
/// G is symmetric, diagonally dominant, so no pivoting is needed).
pub struct HatSolver {
    off: Vec<f64>,
    /// Modified super-diagonal c'_k of the forward sweep.
    upper: Vec<f64>,
    /// 1 / (d_k − a_k c'_{k−1}) of the forward sweep.
    inv_pivot: Vec<f64>,
}

impl HatSolver {
    pub fn new(grid: &Grid) -> HatSolver {
        let (diag, off) = hat_gram(grid);
        let n = diag.len();
        let (mut upper, mut inv_pivot) = (vec![0.0; n], vec![0.0; n]);
        for k in 0..n {
            let below = if k > 0 {
                off[k - 1] * upper[k - 1]
            } else {
                0.0
            };
            inv_pivot[k] = 1.0 / (diag[k] - below);
            if k + 1 < n {
                upper[k] = off[k] * inv_pivot[k];
            }
        }
        HatSolver {
            off,
            upper,
            inv_pivot,
        }
    }

    /// Overwrite `m` (hat integrals m_b = ∫ hat_b L dλ) with the nodal values c = G⁻¹m.
    pub fn solve(&self, m: &mut [f64]) {
        let n = m.len();
        for k in 0..n {
            let below = if k > 0 {
                self.off[k - 1] * m[k - 1]
            } else {
                0.0
            };
            m[k] = (m[k] - below) * self.inv_pivot[k];
        }
        for k in (0..n.saturating_sub(1)).rev() {
            m[k] -= self.upper[k] * m[k + 1];
        }
    }
}

/// Nodal cube c = G⁻¹m from a cube of hat averages m_b / w_b (planes on `grid`), in f64 per pixel.
pub fn nodal_from_hat_means(means: &Cube, grid: &Grid) -> Result<Cube> {
    if means.planes != grid.count {
        return Err(Error::Shape(format!(
            "{} hat-average planes for a grid of {} bands",
            means.planes, grid.count
        )));
    }
    let solver = HatSolver::new(grid);
    let widths = hat_widths(grid);
    let n = means.pixels();
    let nodal: Vec<Vec<f32>> = (0..n)
        .into_par_iter()
        .map(|p| {
            let mut m: Vec<f64> = (0..grid.count)
                .map(|b| f64::from(means.plane(b)[p]) * widths[b])
                .collect();
            solver.solve(&mut m);
            m.into_iter().map(|v| v as f32).collect()
        })
        .collect();
    let mut out = Cube::zeros(means.width, means.height, grid.count);
    for (p, c) in nodal.iter().enumerate() {
        for (b, v) in c.iter().enumerate() {
            out.plane_mut(b)[p] = *v;
        }
    }
    Ok(out)
}

/// The two files of a render with path prefix `prefix`.
pub fn truth_path(prefix: &Path) -> PathBuf {
    suffixed(prefix, "_truth.exr")
}

pub fn wheel_path(prefix: &Path) -> PathBuf {
    suffixed(prefix, "_wheel.exr")
}

fn suffixed(prefix: &Path, suffix: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_os_string();
    s.push(suffix);
    PathBuf::from(s)
}

/// Read an EXR whose channels must be exactly `names` (`what` says whence) in this order, with
/// finite values.
fn read_named(path: &Path, names: &[String], what: &str) -> Result<Cube> {
    let (cube, found) = specmux_io::exr::read(path)?;
    let err = |msg: String| Error::Exr {
        path: path.to_path_buf(),
        msg,
    };
    if found.len() != names.len() {
        return Err(err(format!(
            "{} channels, expected {} ({} … {}: {what})",
            found.len(),
            names.len(),
            names[0],
            names[names.len() - 1]
        )));
    }
    if let Some((f, n)) = found.iter().zip(names).find(|(f, n)| f != n) {
        return Err(err(format!("channel `{f}` where `{n}` was expected")));
    }
    if let Some(at) = specmux_io::exr::first_value(&cube, names, |v| !v.is_finite()) {
        return Err(err(format!("{at}: a render's values must be finite")));
    }
    Ok(cube)
}

/// Read `<prefix>_truth.exr`: hat averages on `grid` (channels named `specmux_io::exr::band_name`).
pub fn read_truth(path: &Path, grid: &Grid) -> Result<Cube> {
    let names: Vec<String> = grid
        .wavelengths()
        .into_iter()
        .map(specmux_io::exr::band_name)
        .collect();
    let what = "the bands of scene.wavelengths_nm; render on that grid or set it to the render's";
    read_named(path, &names, what)
}

/// Read `<prefix>_wheel.exr`: x_i = ∫ S_i L dλ, channels `WHEEL_CHANNELS`.
pub fn read_wheel(path: &Path) -> Result<Cube> {
    read_named(
        path,
        &WHEEL_CHANNELS.map(String::from),
        "the wheel's channels",
    )
}

/// S_i as the renders integrate it: T_i·QE sampled every 1 nm on [lo, hi] nm, linear in between,
/// zero outside. It differs from the exact product T_i·QE within each 1 nm (up to 2.3e-5 of a
/// channel), more than the Monte Carlo noise of the broadband channels.
pub fn sampled_sensitivity(filter: &Curve, qe: &Curve, lo_nm: u32, hi_nm: u32) -> Result<Curve> {
    let wl: Vec<f64> = (lo_nm..=hi_nm).map(f64::from).collect();
    let v = wl.iter().map(|&l| filter.eval(l) * qe.eval(l)).collect();
    Curve::new(format!("{}·QE (1 nm)", filter.name), wl, v)
}

/// The radiance of a `mitsuba:` source: the truth file's nodal cube on the experiment grid.
pub fn cube(cfg: &SceneConfig, file: &str, grid: &Grid) -> Result<Cube> {
    let rel = cfg.source.trim_start_matches(PREFIX);
    let path = truth_path(&cfg.path(rel, file));
    let means = read_truth(&path, grid)?;
    let [w, h] = cfg.size;
    if [means.width, means.height] != [w, h] {
        return Err(Error::config(
            file,
            "scene.size",
            format!("[{w}, {h}]"),
            &format!(
                "{} is {}×{}: set scene.size = [{}, {}]",
                path.display(),
                means.width,
                means.height,
                means.width,
                means.height
            ),
        ));
    }
    nodal_from_hat_means(&means, grid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::Experiment;
    use specmux_core::spectral::integrate_product;
    use specmux_io::exr as exr_io;

    fn gram_dense(g: &Grid) -> Vec<Vec<f64>> {
        (0..g.count)
            .map(|a| {
                (0..g.count)
                    .map(|b| integrate_product(&[&Curve::hat(g, a), &Curve::hat(g, b)]).unwrap())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn gram_matches_the_hat_integrals() {
        let g = Grid::VISIBLE;
        let (d, o) = hat_gram(&g);
        let dense = gram_dense(&g);
        for a in 0..g.count {
            for b in 0..g.count {
                let want = match a.abs_diff(b) {
                    0 => d[a],
                    1 => o[a.min(b)],
                    _ => 0.0,
                };
                assert!((dense[a][b] - want).abs() < 1e-12, "G[{a}][{b}]");
            }
        }
        assert_eq!((d[0], d[15], o[3]), (10.0 / 3.0, 20.0 / 3.0, 10.0 / 6.0));
    }

    #[test]
    fn flat_radiance_has_flat_nodes() {
        // L = 1: every hat average is 1 (the end hats too), and G⁻¹m = 1 by hand: row b of G
        // sums to w_b.
        let g = Grid::VISIBLE;
        let ones = Cube::from_vec(1, 1, g.count, vec![1.0; g.count]).unwrap();
        let c = nodal_from_hat_means(&ones, &g).unwrap();
        assert!(
            c.data.iter().all(|v| (v - 1.0).abs() < 1e-6),
            "{:?}",
            c.data
        );
    }

    #[test]
    fn piecewise_linear_radiance_is_recovered_exactly() {
        // For L = Σ c_b hat_b, m = G c: the solve must return c (f64, to rounding).
        let g = Grid::VISIBLE;
        let c: Vec<f64> = (0..g.count)
            .map(|b| 1.0 + (b as f64 * 0.7).sin() * 0.8)
            .collect();
        let l = Curve::from_grid("L", &g, c.clone()).unwrap();
        let mut m: Vec<f64> = (0..g.count)
            .map(|b| integrate_product(&[&Curve::hat(&g, b), &l]).unwrap())
            .collect();
        HatSolver::new(&g).solve(&mut m);
        for (a, b) in m.iter().zip(&c) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    #[test]
    fn solve_is_linear_and_inverts_the_gram_matrix() {
        let g = Grid::new(400.0, 10.0, 7).unwrap();
        let dense = gram_dense(&g);
        let s = HatSolver::new(&g);
        let x: Vec<f64> = (0..7).map(|k| (k as f64 * 1.3).cos()).collect();
        let y: Vec<f64> = (0..7).map(|k| k as f64 * 0.25 - 0.5).collect();
        let mut mx: Vec<f64> = dense
            .iter()
            .map(|r| r.iter().zip(&x).map(|(a, b)| a * b).sum())
            .collect();
        let mut my: Vec<f64> = dense
            .iter()
            .map(|r| r.iter().zip(&y).map(|(a, b)| a * b).sum())
            .collect();
        let mut mix: Vec<f64> = mx.iter().zip(&my).map(|(a, b)| 2.0 * a - 3.0 * b).collect();
        s.solve(&mut mx);
        s.solve(&mut my);
        s.solve(&mut mix);
        for k in 0..7 {
            assert!((mx[k] - x[k]).abs() < 1e-12);
            assert!((my[k] - y[k]).abs() < 1e-12);
            assert!((mix[k] - (2.0 * x[k] - 3.0 * y[k])).abs() < 1e-12);
        }
    }

    #[test]
    fn sampled_sensitivity_is_zero_outside_and_exact_on_the_samples() {
        let t = Curve::new("t", vec![380.0, 780.0], vec![0.0, 1.0]).unwrap();
        let qe = Curve::constant("qe", 300.0, 900.0, 0.5).unwrap();
        let s = sampled_sensitivity(&t, &qe, 400, 700).unwrap();
        assert_eq!(s.support(), (400.0, 700.0));
        assert_eq!(s.eval(399.5), 0.0);
        assert!((s.eval(550.0) - 0.5 * 170.0 / 400.0).abs() < 1e-15);
    }

    fn write_exr(dir: &Path, file: &str, w: usize, h: usize, names: &[String]) -> PathBuf {
        let p = dir.join(file);
        let cube = Cube::from_vec(w, h, names.len(), vec![0.5; w * h * names.len()]).unwrap();
        exr_io::write(&p, &cube, names).unwrap();
        p
    }

    #[test]
    fn bad_files_and_keys_are_named() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-mitsuba-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let g = Grid::VISIBLE;
        let mut names: Vec<String> = g.wavelengths().into_iter().map(exr_io::band_name).collect();
        names.pop();
        let p = write_exr(dir, "short_truth.exr", 16, 16, &names);
        let e = read_truth(&p, &g).unwrap_err().to_string();
        assert!(
            e.contains("short_truth.exr")
                && e.contains("30 channels")
                && e.contains("scene.wavelengths_nm"),
            "{e}"
        );
        names.push("0705.0nm".into());
        let p = write_exr(dir, "shifted_truth.exr", 16, 16, &names);
        let e = read_truth(&p, &g).unwrap_err().to_string();
        assert!(e.contains("`0705.0nm`") && e.contains("`0700.0nm`"), "{e}");
        names.pop();
        names.push("0700.0nm".into());
        write_exr(dir, "ok_truth.exr", 16, 16, &names);

        let exp_file = dir.join("e.toml").display().to_string();
        let toml = "[scene]\nsource = \"mitsuba:ok\"\nquantity = \"radiance\"\nsize = [32, 32]\n";
        let exp = Experiment::from_toml(toml, &exp_file).unwrap();
        let e = cube(&exp.scene, &exp.file, &g).unwrap_err().to_string();
        assert!(e.contains("scene.size") && e.contains("16×16"), "{e}");
        let exp = Experiment::from_toml(&toml.replace("32, 32", "16, 16"), &exp_file).unwrap();
        let c = cube(&exp.scene, &exp.file, &g).unwrap();
        assert!(c.data.iter().all(|v| (v - 0.5).abs() < 1e-6));

        let e = Experiment::from_toml(&toml.replace("radiance", "reflectance"), &exp_file)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scene.quantity"), "{e}");
        let e = Experiment::from_toml("[scene]\nsource = \"mitsuba:\"\n", &exp_file)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scene.source"), "{e}");
    }
}
