//! Orthogonal 2-D discrete wavelet transform with periodic boundaries (Mallat layout, in place):
//! the sparsifying basis T of the paper's GAP de-aliasing, X = T W. Orthogonality makes Tᵀ = T⁻¹,
//! so analysis is the adjoint of synthesis and shrinking W is shrinking X in a rotated basis.

use crate::error::Error;
use crate::error::Result;
use serde::{Deserialize, Serialize};

/// The mother wavelet: Haar (2 taps) or Daubechies' 4-tap orthogonal wavelet (db2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Wavelet {
    Haar,
    Daubechies4,
}

impl Wavelet {
    /// The low-pass (scaling) filter h, normalised to Σh² = 1, Σh = √2.
    pub fn lowpass(self) -> Vec<f64> {
        match self {
            Wavelet::Haar => vec![std::f64::consts::FRAC_1_SQRT_2; 2],
            Wavelet::Daubechies4 => {
                let s3 = 3f64.sqrt();
                let d = 4.0 * 2f64.sqrt();
                vec![
                    (1.0 + s3) / d,
                    (3.0 + s3) / d,
                    (3.0 - s3) / d,
                    (1.0 - s3) / d,
                ]
            }
        }
    }
}

/// A planned multi-level transform for one `w × h` image size.
#[derive(Clone, Debug)]
pub struct Dwt2 {
    pub w: usize,
    pub h: usize,
    pub levels: usize,
    lo: Vec<f32>,
    /// The quadrature-mirror high-pass g[n] = (−1)ⁿ h[L−1−n].
    hi: Vec<f32>,
}

impl Dwt2 {
    /// `levels` ≥ 1 splits; each side must be divisible by 2^levels and the band split last must
    /// still hold the whole filter. `file` names the configuration for the error message.
    pub fn new(w: usize, h: usize, levels: usize, wavelet: Wavelet, file: &str) -> Result<Dwt2> {
        let lo64 = wavelet.lowpass();
        let taps = lo64.len();
        let fits = |l: usize, n: usize| l < 32 && n % (1 << l) == 0 && n >> (l.max(1) - 1) >= taps;
        if levels == 0 || !fits(levels, w) || !fits(levels, h) {
            let most = (1..32).take_while(|&l| fits(l, w) && fits(l, h)).last();
            let allowed = most.map_or("no level".to_string(), |l| format!("1 to {l} levels"));
            return Err(Error::config(
                file,
                "reconstruct.gap.levels",
                levels,
                &format!(
                    "a {w}×{h} frame allows {allowed} (2^L must divide both sides and the last band split keep ≥ {taps} pixels)"
                ),
            ));
        }
        let hi = (0..taps)
            .map(|n| {
                let v = lo64[taps - 1 - n] as f32;
                if n % 2 == 0 {
                    v
                } else {
                    -v
                }
            })
            .collect();
        Ok(Dwt2 {
            w,
            h,
            levels,
            lo: lo64.iter().map(|&v| v as f32).collect(),
            hi,
        })
    }

    /// The low-pass and high-pass analysis filters (h, g) in f32, as the transform applies them.
    pub fn filters(&self) -> (&[f32], &[f32]) {
        (&self.lo, &self.hi)
    }

    /// Detail level of each coefficient position: 1 = finest … `levels` = coarsest, 0 = the
    /// coarse scaling (approximation) band.
    pub fn level_map(&self) -> Vec<u8> {
        let (w, h, l) = (self.w, self.h, self.levels);
        let mut out = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                out[y * w + x] = if x < w >> l && y < h >> l {
                    0
                } else {
                    // The coarsest level whose block (w, h) / 2^(lev−1) still contains (x, y).
                    (1..=l)
                        .rev()
                        .find(|&lev| x < w >> (lev - 1) && y < h >> (lev - 1))
                        .unwrap_or(1) as u8
                };
            }
        }
        out
    }

    /// Analysis W = Tᵀ X in place; `scratch` holds at least w·h values.
    pub fn forward(&self, img: &mut [f32], scratch: &mut [f32]) {
        for lev in 0..self.levels {
            let (bw, bh) = (self.w >> lev, self.h >> lev);
            self.rows_forward(img, scratch, bw, bh);
            self.cols_forward(img, scratch, bw, bh);
        }
    }

    /// Synthesis X = T W in place; `scratch` holds at least w·h values.
    pub fn inverse(&self, coef: &mut [f32], scratch: &mut [f32]) {
        for lev in (0..self.levels).rev() {
            let (bw, bh) = (self.w >> lev, self.h >> lev);
            self.cols_inverse(coef, scratch, bw, bh);
            self.rows_inverse(coef, scratch, bw, bh);
        }
    }

    /// One split of the first `bw` values of each of the first `bh` rows into [a | d].
    fn rows_forward(&self, img: &mut [f32], scratch: &mut [f32], bw: usize, bh: usize) {
        let half = bw / 2;
        let row_buf = &mut scratch[..bw];
        for r in 0..bh {
            let row = &mut img[r * self.w..r * self.w + bw];
            row_buf.copy_from_slice(row);
            for i in 0..half {
                let (mut a, mut d) = (0.0f32, 0.0f32);
                let taps = self.lo.len();
                if 2 * i + taps <= bw {
                    // Interior: no wrap, no modulo.
                    let win = &row_buf[2 * i..2 * i + taps];
                    for ((&v, &l), &g) in win.iter().zip(&self.lo).zip(&self.hi) {
                        a += l * v;
                        d += g * v;
                    }
                } else {
                    for (n, (&l, &g)) in self.lo.iter().zip(&self.hi).enumerate() {
                        let v = row_buf[(2 * i + n) % bw];
                        a += l * v;
                        d += g * v;
                    }
                }
                row[i] = a;
                row[half + i] = d;
            }
        }
    }

    /// Inverse of `rows_forward`: x[(2i+n) mod bw] += h[n]·a_i + g[n]·d_i.
    fn rows_inverse(&self, img: &mut [f32], scratch: &mut [f32], bw: usize, bh: usize) {
        let half = bw / 2;
        let row_buf = &mut scratch[..bw];
        for r in 0..bh {
            let row = &mut img[r * self.w..r * self.w + bw];
            row_buf.fill(0.0);
            let taps = self.lo.len();
            for i in 0..half {
                let (a, d) = (row[i], row[half + i]);
                if 2 * i + taps <= bw {
                    let win = &mut row_buf[2 * i..2 * i + taps];
                    for ((o, &l), &g) in win.iter_mut().zip(&self.lo).zip(&self.hi) {
                        *o += l * a + g * d;
                    }
                } else {
                    for (n, (&l, &g)) in self.lo.iter().zip(&self.hi).enumerate() {
                        row_buf[(2 * i + n) % bw] += l * a + g * d;
                    }
                }
            }
            row.copy_from_slice(row_buf);
        }
    }

    /// Column split as whole-row linear combinations (contiguous, vectorisable): output row i of
    /// the top half is Σ_n h[n]·row[(2i+n) mod bh], of the bottom half Σ_n g[n]·row[…].
    fn cols_forward(&self, img: &mut [f32], scratch: &mut [f32], bw: usize, bh: usize) {
        let half = bh / 2;
        for i in 0..half {
            let (top, bot) = scratch[..bh * bw].split_at_mut(half * bw);
            let a = &mut top[i * bw..(i + 1) * bw];
            let d = &mut bot[i * bw..(i + 1) * bw];
            a.fill(0.0);
            d.fill(0.0);
            for (n, (&l, &g)) in self.lo.iter().zip(&self.hi).enumerate() {
                let src = (2 * i + n) % bh;
                let row = &img[src * self.w..src * self.w + bw];
                for ((av, dv), &v) in a.iter_mut().zip(d.iter_mut()).zip(row) {
                    *av += l * v;
                    *dv += g * v;
                }
            }
        }
        for r in 0..bh {
            img[r * self.w..r * self.w + bw].copy_from_slice(&scratch[r * bw..(r + 1) * bw]);
        }
    }

    /// Inverse of `cols_forward`.
    fn cols_inverse(&self, img: &mut [f32], scratch: &mut [f32], bw: usize, bh: usize) {
        let half = bh / 2;
        let out = &mut scratch[..bh * bw];
        out.fill(0.0);
        for i in 0..half {
            let a = &img[i * self.w..i * self.w + bw];
            let d = &img[(half + i) * self.w..(half + i) * self.w + bw];
            for (n, (&l, &g)) in self.lo.iter().zip(&self.hi).enumerate() {
                let dst = (2 * i + n) % bh;
                let row = &mut out[dst * bw..(dst + 1) * bw];
                for ((o, &av), &dv) in row.iter_mut().zip(a).zip(d) {
                    *o += l * av + g * dv;
                }
            }
        }
        for r in 0..bh {
            img[r * self.w..r * self.w + bw].copy_from_slice(&out[r * bw..(r + 1) * bw]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    fn random(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = Pcg64::seed_from_u64(seed);
        (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect()
    }

    #[test]
    fn haar_one_level_on_2x2_by_hand() {
        // [[a, b], [c, d]] → rows: ((a+b)/√2, (a−b)/√2); then columns, giving
        // LL = (a+b+c+d)/2, HL = (a−b+c−d)/2, LH = (a+b−c−d)/2, HH = (a−b−c+d)/2.
        let d = Dwt2::new(2, 2, 1, Wavelet::Haar, "t").unwrap();
        let mut img = vec![1.0f32, 2.0, 3.0, 5.0];
        let mut s = vec![0.0; 4];
        d.forward(&mut img, &mut s);
        let want = [5.5f32, -1.5, -2.5, 0.5];
        for (g, w) in img.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{img:?}");
        }
        d.inverse(&mut img, &mut s);
        for (g, w) in img.iter().zip([1.0f32, 2.0, 3.0, 5.0]) {
            assert!((g - w).abs() < 1e-6);
        }
    }

    #[test]
    fn haar_two_levels_on_a_ramp_by_hand() {
        // Row x = [0, 1, 2, 3] (4×1 image is not 2-D; use 4×4 rows all equal): the column split
        // of identical rows leaves zero vertical details and scales the averages by √2.
        let d = Dwt2::new(4, 4, 2, Wavelet::Haar, "t").unwrap();
        let mut img: Vec<f32> = (0..16).map(|p| (p % 4) as f32).collect();
        let mut s = vec![0.0; 16];
        d.forward(&mut img, &mut s);
        // Level 1 row split: a = (1, 5)/√2, d = (−1, −1)/√2; column split of 4 equal rows:
        // ×√2 in the top half, 0 in the bottom. Level 2 on the 2×2 block [[1, 5], [1, 5]]:
        // rows → (6/√2, −4/√2); columns → LL = 6, HL = −4, LH = HH = 0.
        let want: [f32; 16] = [
            6.0, -4.0, -1.0, -1.0, 0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
        ];
        for (k, (g, w)) in img.iter().zip(want).enumerate() {
            assert!((g - w).abs() < 1e-5, "coefficient {k}: {img:?}");
        }
        assert_eq!(
            d.level_map(),
            vec![0, 2, 1, 1, 2, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1]
        );
    }

    #[test]
    fn perfect_reconstruction_and_parseval_for_both_wavelets() {
        for wav in [Wavelet::Haar, Wavelet::Daubechies4] {
            let (w, h) = (64, 32);
            let d = Dwt2::new(w, h, 3, wav, "t").unwrap();
            let x = random(w * h, 3);
            let mut c = x.clone();
            let mut s = vec![0.0; w * h];
            d.forward(&mut c, &mut s);
            let e = |v: &[f32]| v.iter().map(|&a| a as f64 * a as f64).sum::<f64>();
            assert!((e(&c) - e(&x)).abs() < 1e-4 * e(&x), "{wav:?}: Parseval");
            // Orthogonality also means ⟨T ᵀx, Tᵀz⟩ = ⟨x, z⟩ for two different images.
            let z = random(w * h, 4);
            let mut cz = z.clone();
            d.forward(&mut cz, &mut s);
            let dot = |a: &[f32], b: &[f32]| {
                a.iter()
                    .zip(b)
                    .map(|(&p, &q)| p as f64 * q as f64)
                    .sum::<f64>()
            };
            assert!((dot(&c, &cz) - dot(&x, &z)).abs() < 1e-3);
            d.inverse(&mut c, &mut s);
            let err = c
                .iter()
                .zip(&x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(err < 1e-5, "{wav:?}: reconstruction error {err}");
        }
    }

    #[test]
    fn daubechies4_kills_linear_ramps_in_the_details() {
        // db2 has two vanishing moments: a periodic-free interior linear ramp gives zero details
        // except where the periodic wrap makes a jump.
        let (w, h) = (32, 8);
        let d = Dwt2::new(w, h, 1, Wavelet::Daubechies4, "t").unwrap();
        let mut img: Vec<f32> = (0..w * h).map(|p| (p % w) as f32).collect();
        let mut s = vec![0.0; w * h];
        d.forward(&mut img, &mut s);
        // Row details d_i for i = 0..14 use x[2i..2i+3] without wrapping.
        for r in 0..h / 2 {
            for i in 0..w / 2 - 1 {
                assert!(img[r * w + w / 2 + i].abs() < 1e-4, "row {r} detail {i}");
            }
        }
    }

    #[test]
    fn sizes_that_do_not_split_are_refused_naming_the_key() {
        let e = Dwt2::new(100, 64, 3, Wavelet::Haar, "x.toml")
            .unwrap_err()
            .to_string();
        // 100 = 4·25: two levels divide it; the message says how many.
        assert!(
            e.contains("reconstruct.gap.levels")
                && e.contains("a 100×64 frame allows 1 to 2 levels"),
            "{e}"
        );
        let odd = Dwt2::new(101, 64, 1, Wavelet::Haar, "x").unwrap_err();
        assert!(odd.to_string().contains("allows no level"), "{odd}");
        assert!(Dwt2::new(64, 64, 0, Wavelet::Haar, "x").is_err());
        // 8 pixels split 3 times leaves a 2-pixel band split last: too short for 4 taps.
        assert!(Dwt2::new(8, 8, 3, Wavelet::Daubechies4, "x").is_err());
        assert!(Dwt2::new(8, 8, 2, Wavelet::Daubechies4, "x").is_ok());
    }
}
