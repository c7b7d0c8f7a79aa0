//! The light that forms a pattern: its wheel segment's band T_i·L·QE (what the camera weighs
//! the pattern by), or a single line for a laser-lit rig. Diffraction scales with λ, so the 4f
//! filter and the lens see each wavelength differently; this module gives the exact weight of
//! any wavelength interval and its moments about the band's centroid.

// `!(x > y)` is deliberate: it is true for NaN too.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::spectral::Curve;

/// Spectral weight of one pattern's light, normalised to a total of 1.
#[derive(Clone, Debug, PartialEq)]
pub enum PatternLight {
    /// Monochromatic light at this wavelength (nm).
    Line(f64),
    /// A band: the weight is piecewise linear through `(wl_nm[k], w[k])` and zero outside.
    Band(Band),
}

/// A piecewise-linear spectral weight with cumulative moments about its centroid λc:
/// `cum[k][p]` = ∫ from the first knot to knot k of w(λ)·(λ − λc)^p dλ, p = 0..3.
#[derive(Clone, Debug, PartialEq)]
pub struct Band {
    wl_nm: Vec<f64>,
    w: Vec<f64>,
    centroid_nm: f64,
    cum: Vec<[f64; 4]>,
}

/// ∫_a^b (α + β u) u^p du for p = 0..3 (u measured from the centroid).
fn piece_moments(a: f64, b: f64, alpha: f64, beta: f64) -> [f64; 4] {
    let pw = |x: f64, n: i32| x.powi(n);
    std::array::from_fn(|p| {
        let p = p as i32;
        alpha * (pw(b, p + 1) - pw(a, p + 1)) / (p + 1) as f64
            + beta * (pw(b, p + 2) - pw(a, p + 2)) / (p + 2) as f64
    })
}

impl PatternLight {
    /// The band of a curve (non-negative, with some light), normalised to unit total weight.
    pub fn band(curve: &Curve) -> Result<PatternLight> {
        let (wl, v) = (curve.wavelengths(), curve.values());
        if let Some(k) = v.iter().position(|&x| x < 0.0) {
            return Err(Error::Curve {
                name: curve.name.clone(),
                msg: format!("negative spectral weight {} at {} nm", v[k], wl[k]),
            });
        }
        let total: f64 = wl
            .windows(2)
            .zip(v.windows(2))
            .map(|(x, y)| 0.5 * (y[0] + y[1]) * (x[1] - x[0]))
            .sum();
        if !(total > 0.0) {
            return Err(Error::Curve {
                name: curve.name.clone(),
                msg: "the pattern's light has no power".into(),
            });
        }
        let w: Vec<f64> = v.iter().map(|x| x / total).collect();
        let first: f64 = wl
            .windows(2)
            .zip(w.windows(2))
            .map(|(x, y)| {
                let (h, a) = (x[1] - x[0], x[0]);
                // ∫ (y0 + (y1 − y0)(λ − a)/h) λ dλ over [a, a + h]
                h * (y[0] * (a + h / 2.0) + (y[1] - y[0]) * (a / 2.0 + h / 3.0))
            })
            .sum();
        let mut band = Band {
            wl_nm: wl.to_vec(),
            w,
            centroid_nm: first,
            cum: vec![[0.0; 4]; wl.len()],
        };
        for k in 1..wl.len() {
            let m = band.piece(k - 1, wl[k - 1], wl[k]);
            band.cum[k] = std::array::from_fn(|p| band.cum[k - 1][p] + m[p]);
        }
        Ok(PatternLight::Band(band))
    }

    /// The weighted mean wavelength, nm.
    pub fn centroid_nm(&self) -> f64 {
        match self {
            PatternLight::Line(l) => *l,
            PatternLight::Band(b) => b.centroid_nm,
        }
    }

    /// The wavelengths that carry light: [first, last] nm.
    pub fn support_nm(&self) -> (f64, f64) {
        match self {
            PatternLight::Line(l) => (*l, *l),
            PatternLight::Band(b) => {
                let lit = |k: &usize| b.w[*k] > 0.0 || b.w.get(k + 1).is_some_and(|&x| x > 0.0);
                let i = (0..b.w.len()).find(lit).unwrap_or(0);
                let j = (0..b.w.len())
                    .rev()
                    .find(|&k| k == 0 || lit(&(k - 1)))
                    .unwrap_or(0);
                (b.wl_nm[i], b.wl_nm[j])
            }
        }
    }

    /// The wavelength below which a fraction `q` of the light lies.
    pub fn quantile_nm(&self, q: f64) -> f64 {
        match self {
            PatternLight::Line(l) => *l,
            PatternLight::Band(b) => {
                let k = b
                    .cum
                    .partition_point(|c| c[0] < q)
                    .clamp(1, b.wl_nm.len() - 1);
                // Bisection inside the piece: the cumulative weight is monotone there.
                let (mut lo, mut hi) = (b.wl_nm[k - 1], b.wl_nm[k]);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if b.at(mid)[0] < q {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                0.5 * (lo + hi)
            }
        }
    }

    /// ∫ w(λ)·(λ − λc)^p dλ over wavelengths below λ nm, p = 0..3 (a line at λ is not below).
    pub fn below(&self, l: f64) -> [f64; 4] {
        match self {
            PatternLight::Line(l0) => [if l > *l0 { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0],
            PatternLight::Band(b) => b.at(l),
        }
    }

    /// The same up to and including λ (a line at λ is included; a band is the same).
    pub fn through(&self, l: f64) -> [f64; 4] {
        match self {
            PatternLight::Line(l0) => [if l >= *l0 { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0],
            PatternLight::Band(b) => b.at(l),
        }
    }

    /// ∫ w(λ)·(λ − λc)^p dλ over the closed interval [lo, hi] nm for p = 0..3 (zero if empty).
    pub fn moments(&self, lo: f64, hi: f64) -> [f64; 4] {
        if !(hi >= lo) {
            return [0.0; 4];
        }
        let (x, y) = (self.through(hi), self.below(lo));
        std::array::from_fn(|p| x[p] - y[p])
    }
}

impl Band {
    /// ∫ w·u^p over [a, b] ⊂ piece k (u = λ − λc).
    fn piece(&self, k: usize, a: f64, b: f64) -> [f64; 4] {
        let (t0, t1) = (self.wl_nm[k], self.wl_nm[k + 1]);
        let beta = (self.w[k + 1] - self.w[k]) / (t1 - t0);
        // w = w_k + β(λ − t0) = (w_k + β(λc − t0)) + β u
        let alpha = self.w[k] + beta * (self.centroid_nm - t0);
        piece_moments(a - self.centroid_nm, b - self.centroid_nm, alpha, beta)
    }

    /// Cumulative moments from the first knot to λ.
    fn at(&self, l: f64) -> [f64; 4] {
        let n = self.wl_nm.len();
        if l <= self.wl_nm[0] {
            return [0.0; 4];
        }
        if l >= self.wl_nm[n - 1] {
            return self.cum[n - 1];
        }
        let k = self.wl_nm.partition_point(|&t| t <= l) - 1;
        let m = self.piece(k, self.wl_nm[k], l);
        std::array::from_fn(|p| self.cum[k][p] + m[p])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band(wl: Vec<f64>, v: Vec<f64>) -> PatternLight {
        PatternLight::band(&Curve::new("test", wl, v).unwrap()).unwrap()
    }

    #[test]
    fn flat_band_moments_by_hand() {
        // w = 1/100 on [500, 600]: λc = 550, ∫ u² = 2·50³/3/100, ∫ over [500, 525] = 1/4.
        let b = band(vec![500.0, 600.0], vec![3.0, 3.0]);
        assert!((b.centroid_nm() - 550.0).abs() < 1e-12);
        let m = b.moments(0.0, 1000.0);
        assert!((m[0] - 1.0).abs() < 1e-14 && m[1].abs() < 1e-10 && m[3].abs() < 1e-6);
        assert!(
            (m[2] - 2.0 * 50f64.powi(3) / 3.0 / 100.0).abs() < 1e-9,
            "{m:?}"
        );
        assert!((b.moments(500.0, 525.0)[0] - 0.25).abs() < 1e-14);
        assert_eq!(b.moments(610.0, 700.0), [0.0; 4]);
        assert_eq!(b.moments(560.0, 540.0), [0.0; 4]);
        assert!((b.quantile_nm(0.3) - 530.0).abs() < 1e-9);
        assert_eq!(b.support_nm(), (500.0, 600.0));
    }

    #[test]
    fn triangle_band_centroid_and_split() {
        // A ramp 0 → 1 on [400, 500]: λc = 400 + 2/3·100; half the weight lies above 400 + 100/√2.
        let b = band(vec![400.0, 500.0], vec![0.0, 1.0]);
        assert!((b.centroid_nm() - (400.0 + 200.0 / 3.0)).abs() < 1e-9);
        let split = 400.0 + 100.0 / 2f64.sqrt();
        assert!((b.moments(split, 500.0)[0] - 0.5).abs() < 1e-12);
        assert!((b.quantile_nm(0.5) - split).abs() < 1e-9);
        // The first moment about the centroid vanishes; the moments add over adjacent intervals.
        assert!(b.moments(400.0, 500.0)[1].abs() < 1e-10);
        let (x, y, z) = (
            b.moments(400.0, 430.0),
            b.moments(430.0, 500.0),
            b.moments(400.0, 500.0),
        );
        for p in 0..4 {
            assert!(
                (x[p] + y[p] - z[p]).abs() < 1e-9 * z[p].abs().max(1.0),
                "p = {p}"
            );
        }
    }

    #[test]
    fn line_and_bad_bands() {
        let l = PatternLight::Line(532.0);
        assert_eq!(l.moments(530.0, 535.0), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(l.moments(532.0, 535.0), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(l.moments(530.0, 532.0), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(l.moments(532.0, 532.0), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(l.moments(533.0, 535.0), [0.0; 4]);
        assert_eq!(l.support_nm(), (532.0, 532.0));
        let dark = Curve::new("dark", vec![400.0, 500.0], vec![0.0, 0.0]).unwrap();
        assert!(PatternLight::band(&dark).is_err());
        let neg = Curve::new("neg", vec![400.0, 500.0], vec![1.0, -0.1]).unwrap();
        assert!(PatternLight::band(&neg)
            .unwrap_err()
            .to_string()
            .contains("negative"));
    }

    #[test]
    fn support_skips_dark_ends() {
        let b = band(
            vec![380.0, 400.0, 450.0, 500.0, 520.0],
            vec![0.0, 0.0, 1.0, 0.0, 0.0],
        );
        assert_eq!(b.support_nm(), (400.0, 500.0));
    }
}
