//! Modulation carriers: the spatial frequencies ω_i of the sinusoids s_i = 1 + cos(2π ω_i·p + φ_i),
//! their default layout, and the check that the crop windows around 0 and ±ω_i stay apart.

use crate::error::Error;
use crate::error::Result;
use crate::Cube;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// One carrier: frequency in cycles per pixel along x (columns) and y (rows), and a phase.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Carrier {
    pub fx: f64,
    pub fy: f64,
    pub phase_rad: f64,
}

impl Carrier {
    /// The ideal grey pattern 1 + cos(2π(fx·x + fy·y) + φ) on a `width × height` grid.
    pub fn ideal_pattern(&self, width: usize, height: usize) -> Vec<f32> {
        let tau = std::f64::consts::TAU;
        let mut out = vec![0.0f32; width * height];
        // cos(a + b) = cos a cos b − sin a sin b, with the row and column phases tabulated once.
        let (cx, sx): (Vec<f64>, Vec<f64>) = (0..width)
            .map(|x| (tau * self.fx * x as f64).sin_cos())
            .map(|(s, c)| (c, s))
            .unzip();
        for (y, row) in out.chunks_exact_mut(width).enumerate() {
            let (sy, cy) = (tau * self.fy * y as f64 + self.phase_rad).sin_cos();
            for (x, v) in row.iter_mut().enumerate() {
                // 1 + cos ≥ 0; rounding must not leave an intensity of −1e-31 at the troughs.
                *v = (1.0 + cx[x] * cy - sx[x] * sy).max(0.0) as f32;
            }
        }
        out
    }

    /// The ideal patterns of several carriers, one plane each (computed in parallel).
    pub fn ideal_patterns(carriers: &[Carrier], width: usize, height: usize) -> Cube {
        let mut p = Cube::zeros(width, height, carriers.len());
        p.planes_mut()
            .collect::<Vec<_>>()
            .into_par_iter()
            .zip(carriers)
            .for_each(|(plane, c)| plane.copy_from_slice(&c.ideal_pattern(width, height)));
        p
    }

    /// This carrier moved to the nearest bin of a `width × height` FFT, kept within the
    /// Nyquist band (on an odd axis, bin (n+1)/2 is bin −(n−1)/2).
    pub fn snapped(&self, width: usize, height: usize) -> Carrier {
        let on_grid = |f: f64, n: usize| {
            let k = Carrier::bin(f, n);
            let half = n as i64 / 2;
            let k = if k > half {
                k - n as i64
            } else if k < -half {
                k + n as i64
            } else {
                k
            };
            k as f64 / n as f64
        };
        Carrier {
            fx: on_grid(self.fx, width),
            fy: on_grid(self.fy, height),
            ..*self
        }
    }

    /// Centre bin of the +ω window on an `n`-point axis (frequency × n, rounded).
    pub fn bin(f: f64, n: usize) -> i64 {
        (f * n as f64).round() as i64
    }
}

/// The default six carriers: with a crop of 0.25 the Fourier plane tiles 4 × 4; the DC tile and
/// the three self-conjugate tiles ((½,0), (0,½), (½,½)) are excluded, leaving six ± pairs.
pub fn default_layout() -> Vec<Carrier> {
    [
        (0.25, 0.0),
        (0.0, 0.25),
        (0.25, 0.25),
        (-0.25, 0.25),
        (0.5, 0.25),
        (0.25, 0.5),
    ]
    .into_iter()
    .map(|(fx, fy)| Carrier {
        fx,
        fy,
        phase_rad: 0.0,
    })
    .collect()
}

/// Window size in bins for a crop fraction on an `n`-point axis.
pub fn window_bins(crop: f64, n: usize) -> usize {
    (crop * n as f64).round() as usize
}

/// Circular distance between two bins on an `n`-point axis.
fn circ_dist(a: i64, b: i64, n: usize) -> i64 {
    let d = (a - b).rem_euclid(n as i64);
    d.min(n as i64 - d)
}

/// Refuse layouts whose crop windows (DC and ±ω_i, each `crop` of the width and height) overlap
/// or whose carriers lie outside the Nyquist band. `file` names the experiment for messages.
pub fn check_layout(
    carriers: &[Carrier],
    crop: f64,
    width: usize,
    height: usize,
    file: &str,
) -> Result<()> {
    let (wx, wy) = (
        window_bins(crop, width) as i64,
        window_bins(crop, height) as i64,
    );
    if wx < 2 || wy < 2 {
        return Err(Error::config(
            file,
            "reconstruct.crop",
            crop,
            "the crop window is smaller than two frequency bins",
        ));
    }
    let mut centres: Vec<(String, i64, i64)> = vec![("DC".into(), 0, 0)];
    for (i, c) in carriers.iter().enumerate() {
        if !(c.fx.abs() <= 0.5 && c.fy.abs() <= 0.5 && c.phase_rad.is_finite()) {
            return Err(Error::config(
                file,
                &format!("rig.carriers.frequencies[{i}]"),
                format!("[{}, {}]", c.fx, c.fy),
                "carrier frequencies must lie in [-0.5, 0.5] cycles/pixel",
            ));
        }
        let (bx, by) = (Carrier::bin(c.fx, width), Carrier::bin(c.fy, height));
        centres.push((format!("+ω{i}"), bx, by));
        centres.push((format!("-ω{i}"), -bx, -by));
    }
    for a in 0..centres.len() {
        for b in a + 1..centres.len() {
            let (na, xa, ya) = &centres[a];
            let (nb, xb, yb) = &centres[b];
            if circ_dist(*xa, *xb, width) < wx && circ_dist(*ya, *yb, height) < wy {
                return Err(Error::config(
                    file,
                    "rig.carriers.frequencies",
                    format!("{na} at bin ({xa},{ya}) and {nb} at bin ({xb},{yb})"),
                    &format!("crop windows of {wx}×{wy} bins overlap; move the carriers apart or reduce reconstruct.crop"),
                ));
            }
        }
    }
    Ok(())
}

/// Where a carrier's second harmonic 2ω_i (which coherent 4f optics add to the pattern) falls
/// inside another carrier's window (or its mirror's): one note per collision, naming both.
pub fn harmonic_collisions(
    carriers: &[Carrier],
    crop: f64,
    width: usize,
    height: usize,
) -> Vec<String> {
    let (wx, wy) = (
        window_bins(crop, width) as i64,
        window_bins(crop, height) as i64,
    );
    let inside = |ax: i64, ay: i64, bx: i64, by: i64| {
        2 * circ_dist(ax, bx, width) < wx && 2 * circ_dist(ay, by, height) < wy
    };
    let mut notes = Vec::new();
    for (i, a) in carriers.iter().enumerate() {
        let (hx, hy) = (
            2 * Carrier::bin(a.fx, width),
            2 * Carrier::bin(a.fy, height),
        );
        for (j, b) in carriers.iter().enumerate().filter(|(j, _)| *j != i) {
            let (bx, by) = (Carrier::bin(b.fx, width), Carrier::bin(b.fy, height));
            if inside(hx, hy, bx, by) || inside(hx, hy, -bx, -by) {
                notes.push(format!(
                    "2ω{i} = ({:.4}, {:.4}) cycles/px falls in channel {j}'s window: with coherent 4f optics channel {i}'s harmonic leaks into channel {j}",
                    2.0 * a.fx,
                    2.0 * a.fy
                ));
            }
        }
    }
    notes
}

/// `[rig.carriers]`: frequencies (cycles/pixel, [fx, fy]) and phases; absent = the default
/// 4×4-tile layout.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CarrierConfig {
    pub frequencies: Option<Vec<[f64; 2]>>,
    pub phases_deg: Option<Vec<f64>>,
}

impl CarrierConfig {
    /// The carriers as configured (the default layout when no frequencies are given).
    pub fn carriers(&self) -> Vec<Carrier> {
        let mut c = match &self.frequencies {
            None => default_layout(),
            Some(f) => f
                .iter()
                .map(|&[fx, fy]| Carrier {
                    fx,
                    fy,
                    phase_rad: 0.0,
                })
                .collect(),
        };
        if let Some(p) = &self.phases_deg {
            for (c, p) in c.iter_mut().zip(p) {
                c.phase_rad = p.to_radians();
            }
        }
        c
    }

    /// The carriers on a `width × height` frame's FFT bin grid, and a note per carrier moved.
    /// The default layout is given in fractions of the frame and is snapped to the nearest
    /// bins (the shift reported); frequencies the user wrote must lie on the grid, else the
    /// error names the key and the nearest valid frequency.
    pub fn on_grid(
        &self,
        width: usize,
        height: usize,
        file: &str,
    ) -> Result<(Vec<Carrier>, Vec<String>)> {
        let mut carriers = self.carriers();
        let mut notes = Vec::new();
        for (i, c) in carriers.iter_mut().enumerate() {
            let snapped = c.snapped(width, height);
            let shift = [snapped.fx - c.fx, snapped.fy - c.fy];
            if shift == [0.0, 0.0] {
                continue;
            }
            let nearest = format!(
                "[{}, {}] (bins {}/{width}, {}/{height})",
                snapped.fx,
                snapped.fy,
                Carrier::bin(c.fx, width),
                Carrier::bin(c.fy, height)
            );
            if self.frequencies.is_some() {
                return Err(Error::config(
                    file,
                    &format!("rig.carriers.frequencies[{i}]"),
                    format!("[{}, {}]", c.fx, c.fy),
                    &format!("is off the FFT bin grid of a {width}×{height} frame (the crop windows would smear it); nearest on the grid: {nearest}"),
                ));
            }
            notes.push(format!(
                "default carrier {i} ({}, {}) snapped to the {width}×{height} bin grid: {nearest}, shift ({:+.5}, {:+.5}) cycles/px",
                c.fx, c.fy, shift[0], shift[1]
            ));
            *c = snapped;
        }
        Ok((carriers, notes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_layout_tiles_the_plane_at_quarter_crop() {
        check_layout(&default_layout(), 0.25, 768, 768, "t").unwrap();
        // Any larger crop makes neighbouring windows collide.
        assert!(check_layout(&default_layout(), 0.26, 768, 768, "t").is_err());
    }

    #[test]
    fn ideal_pattern_matches_the_formula() {
        let c = Carrier {
            fx: 0.1,
            fy: -0.2,
            phase_rad: 0.3,
        };
        let p = c.ideal_pattern(7, 5);
        for y in 0..5 {
            for x in 0..7 {
                let want =
                    1.0 + (std::f64::consts::TAU * (0.1 * x as f64 - 0.2 * y as f64) + 0.3).cos();
                assert!((p[y * 7 + x] as f64 - want).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn out_of_band_carrier_is_refused_with_its_index() {
        let mut l = default_layout();
        l[3].fx = 0.7;
        let e = check_layout(&l, 0.25, 768, 768, "x.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("frequencies[3]"), "{e}");
    }
}
