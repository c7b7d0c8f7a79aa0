//! An edge-preserving smoother for the plug-and-play joint method: W = I − γL, L the Laplacian of
//! the 8-neighbour pixel graph whose edge weights exp(−‖g_p − g_q‖²/h²) come from a guide g
//! (joint over its J planes, so every coefficient image shares the guide's edges, as a joint
//! bilateral filter; floored at 1 % so the graph stays connected), γ = 1/(2 max degree). W is symmetric with eigenvalues in [0, 1]
//! (Gershgorin: λmax(L) ≤ 2 max degree) and keeps constants, so for a fixed guide it is the
//! proximal operator of the convex ½αᵀ(W⁺ − I)α (docs/joint.md, "Plug-and-play").

use crate::error::{Error, Result};
use rayon::prelude::*;

/// Neighbour offsets (dx, dy) and their spatial weights: axial 1, diagonal ½.
const NEIGHBOURS: [(i64, i64, f32); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, 0.5),
    (-1, -1, 0.5),
    (1, -1, 0.5),
    (-1, 1, 0.5),
];

/// Least edge weight (times the spatial weight): the graph stays connected, so only constant
/// fields are kept by W whatever the guide (else an isolated pixel's α would be free).
const FLOOR: f64 = 0.01;

/// W = I − γL for one guide: the 8 edge weights of every pixel (0 off the frame) and γ.
pub struct GraphSmoother {
    w: usize,
    h: usize,
    weights: Vec<[f32; 8]>,
    gamma: f32,
}

impl GraphSmoother {
    /// Edge weights from `guide` (pixel-major, `j` values per pixel, `w × h` pixels); `edge`
    /// scales h² = edge² · mean over the axial edges of ‖g_p − g_q‖² (scale free; a constant
    /// guide gives weights 1).
    pub fn new(guide: &[f32], w: usize, h: usize, j: usize, edge: f64) -> Result<GraphSmoother> {
        if w == 0 || h == 0 || j == 0 || guide.len() != w * h * j {
            return Err(Error::Shape(format!(
                "smoother: guide of {} values for {w}×{h} pixels of {j}",
                guide.len()
            )));
        }
        if !(edge.is_finite() && edge > 0.0) || guide.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "smoother: edge scale {edge} must be finite and > 0 and the guide finite"
            )));
        }
        let dist = |p: usize, q: usize| -> f64 {
            (0..j)
                .map(|k| (guide[p * j + k] as f64 - guide[q * j + k] as f64).powi(2))
                .sum()
        };
        let axial: f64 = (0..w * h)
            .into_par_iter()
            .map(|p| {
                let (x, y) = (p % w, p / w);
                let right = if x + 1 < w { dist(p, p + 1) } else { 0.0 };
                let down = if y + 1 < h { dist(p, p + w) } else { 0.0 };
                right + down
            })
            .sum();
        let edges = (w - 1) * h + w * (h - 1);
        let mean = if edges > 0 { axial / edges as f64 } else { 0.0 };
        let inv_h2 = if mean > 0.0 {
            1.0 / (edge * edge * mean)
        } else {
            0.0
        };
        let weights: Vec<[f32; 8]> = (0..w * h)
            .into_par_iter()
            .map(|p| {
                let (x, y) = ((p % w) as i64, (p / w) as i64);
                let mut out = [0.0f32; 8];
                for (o, &(dx, dy, s)) in out.iter_mut().zip(&NEIGHBOURS) {
                    let (qx, qy) = (x + dx, y + dy);
                    if qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64 {
                        let q = qy as usize * w + qx as usize;
                        let e = (-dist(p, q) * inv_h2).exp();
                        *o = s * (FLOOR + (1.0 - FLOOR) * e) as f32;
                    }
                }
                out
            })
            .collect();
        let max_degree = weights
            .iter()
            .map(|e| e.iter().sum::<f32>())
            .fold(0.0f32, f32::max);
        Ok(GraphSmoother {
            w,
            h,
            gamma: if max_degree > 0.0 {
                0.5 / max_degree
            } else {
                0.0
            },
            weights,
        })
    }

    /// out = W u for a pixel-major field of `j` values per pixel.
    pub fn apply(&self, u: &[f32], j: usize, out: &mut [f32]) {
        let (w, h, g) = (self.w, self.h, self.gamma);
        out.par_chunks_mut(w * j).enumerate().for_each(|(y, row)| {
            for x in 0..w {
                let p = y * w + x;
                let e = &self.weights[p];
                let degree: f32 = e.iter().sum();
                let o = &mut row[x * j..(x + 1) * j];
                for (k, v) in o.iter_mut().enumerate() {
                    *v = (1.0 - g * degree) * u[p * j + k];
                }
                for (&wq, &(dx, dy, _)) in e.iter().zip(&NEIGHBOURS) {
                    if wq == 0.0 {
                        continue;
                    }
                    let q = ((y as i64 + dy) as usize) * w + (x as i64 + dx) as usize;
                    for (k, v) in o.iter_mut().enumerate() {
                        *v += g * wq * u[q * j + k];
                    }
                }
            }
        });
        debug_assert_eq!(out.len(), w * h * j);
    }

    /// u ← Wⁿu (`scratch` as long as u).
    pub fn smooth(&self, u: &mut [f32], j: usize, passes: usize, scratch: &mut [f32]) {
        for _ in 0..passes {
            self.apply(u, j, scratch);
            u.copy_from_slice(scratch);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A 3 × 1 image, guide (0, 0, 1), edge 1: the axial differences are 0 and 1, so h² = ½;
    /// w₀₁ = 1, w₁₂ = e = 0.01 + 0.99e⁻², degrees (1, 1 + e, e), γ = 1/(2(1 + e)).
    /// W(1, 0, 0) = (1 − γ, γ, 0) and W(0, 0, 1) = (0, γe, 1 − γe).
    #[test]
    fn a_three_pixel_case_computed_by_hand() {
        let s = GraphSmoother::new(&[0.0, 0.0, 1.0], 3, 1, 1, 1.0).unwrap();
        let e2 = 0.01 + 0.99 * (-2.0f64).exp();
        let g = 1.0 / (2.0 * (1.0 + e2));
        let mut out = [0.0f32; 3];
        s.apply(&[1.0, 0.0, 0.0], 1, &mut out);
        let want = [1.0 - g, g, 0.0];
        for (o, w) in out.iter().zip(want) {
            assert!((*o as f64 - w).abs() < 1e-6, "{out:?} against {want:?}");
        }
        s.apply(&[0.0, 0.0, 1.0], 1, &mut out);
        let want = [0.0, g * e2, 1.0 - g * e2];
        for (o, w) in out.iter().zip(want) {
            assert!((*o as f64 - w).abs() < 1e-6, "{out:?} against {want:?}");
        }
    }

    #[test]
    fn bad_guides_are_refused() {
        assert!(GraphSmoother::new(&[0.0; 5], 3, 1, 2, 1.0).is_err());
        assert!(GraphSmoother::new(&[0.0, f32::NAN, 0.0], 3, 1, 1, 1.0).is_err());
        assert!(GraphSmoother::new(&[0.0; 3], 3, 1, 1, 0.0).is_err());
    }

    fn field(len: usize) -> impl Strategy<Value = Vec<f32>> {
        proptest::collection::vec(-1.0f32..1.0, len)
    }

    proptest! {
        /// For any guide: ⟨Wu, v⟩ = ⟨u, Wv⟩ (symmetric), 0 ≤ ⟨Wu, u⟩ ≤ ‖u‖² (eigenvalues in
        /// [0, 1]: W is a proximal operator) and W keeps a constant field.
        #[test]
        fn the_smoother_is_symmetric_with_eigenvalues_in_0_1(
            guide in field(5 * 4 * 2), u in field(5 * 4 * 2), v in field(5 * 4 * 2),
            edge in 0.1f64..5.0, c in -3.0f32..3.0,
        ) {
            let s = GraphSmoother::new(&guide, 5, 4, 2, edge).unwrap();
            let (mut wu, mut wv) = (vec![0.0f32; 40], vec![0.0f32; 40]);
            s.apply(&u, 2, &mut wu);
            s.apply(&v, 2, &mut wv);
            let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| *x as f64 * *y as f64).sum::<f64>();
            let uu = dot(&u, &u);
            prop_assert!((dot(&wu, &v) - dot(&u, &wv)).abs() < 1e-5 * (1.0 + uu));
            let q = dot(&wu, &u);
            prop_assert!(q >= -1e-5 * uu && q <= uu * (1.0 + 1e-5), "{} of {}", q, uu);
            let constant = vec![c; 40];
            s.apply(&constant, 2, &mut wu);
            prop_assert!(wu.iter().all(|x| (x - c).abs() < 1e-5));
        }
    }
}
