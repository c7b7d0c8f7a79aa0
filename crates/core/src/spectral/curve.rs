//! Sampled spectral curves, read as piecewise-linear functions that are zero outside their
//! samples, and the exact integral of a product of such curves.

use crate::error::Error;
use crate::error::Result;
use crate::spectral::grid::Grid;

/// A piecewise-linear curve through `(wl_nm[k], value[k])`, zero outside `[wl_nm[0], wl_nm[n-1]]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Curve {
    pub name: String,
    wl_nm: Vec<f64>,
    value: Vec<f64>,
}

impl Curve {
    /// A checked curve: at least two samples, strictly increasing positive wavelengths, finite values.
    pub fn new(name: impl Into<String>, wl_nm: Vec<f64>, value: Vec<f64>) -> Result<Curve> {
        let name = name.into();
        let err = |msg: String| Error::Curve {
            name: name.clone(),
            msg,
        };
        if wl_nm.len() != value.len() {
            return Err(err(format!(
                "{} wavelengths but {} values",
                wl_nm.len(),
                value.len()
            )));
        }
        if wl_nm.len() < 2 {
            return Err(err("needs at least two samples".into()));
        }
        for (k, (&w, &v)) in wl_nm.iter().zip(&value).enumerate() {
            if !(w.is_finite() && w > 0.0) {
                return Err(err(format!(
                    "wavelength {w} at sample {k} is not a positive number"
                )));
            }
            if !v.is_finite() {
                return Err(err(format!("value {v} at {w} nm is not finite")));
            }
            if k > 0 && w <= wl_nm[k - 1] {
                return Err(err(format!(
                    "wavelengths must increase: {} nm follows {} nm",
                    w,
                    wl_nm[k - 1]
                )));
            }
        }
        Ok(Curve { name, wl_nm, value })
    }

    /// The curve sampled on a uniform grid (values are taken as given at the band centres).
    pub fn from_grid(name: impl Into<String>, grid: &Grid, value: Vec<f64>) -> Result<Curve> {
        Curve::new(name, grid.wavelengths(), value)
    }

    /// A constant curve over `[lo, hi]` nm.
    pub fn constant(name: impl Into<String>, lo: f64, hi: f64, v: f64) -> Result<Curve> {
        Curve::new(name, vec![lo, hi], vec![v, v])
    }

    /// The hat function of band `k` on `grid`: 1 at its centre, 0 at the neighbours.
    /// A cube read as piecewise linear between band centres is Σ_k r_k · hat_k.
    pub fn hat(grid: &Grid, k: usize) -> Curve {
        let c = grid.wavelength(k);
        let (mut wl, mut v) = (Vec::with_capacity(3), Vec::with_capacity(3));
        if k > 0 {
            wl.push(c - grid.step_nm);
            v.push(0.0);
        }
        wl.push(c);
        v.push(1.0);
        if k + 1 < grid.count {
            wl.push(c + grid.step_nm);
            v.push(0.0);
        }
        if wl.len() == 1 {
            // A one-band grid cannot exist (Grid::new refuses it); keep the curve valid anyway.
            wl.push(c + grid.step_nm);
            v.push(0.0);
        }
        Curve {
            name: format!("hat{k}"),
            wl_nm: wl,
            value: v,
        }
    }

    pub fn wavelengths(&self) -> &[f64] {
        &self.wl_nm
    }

    pub fn values(&self) -> &[f64] {
        &self.value
    }

    /// First and last sampled wavelength.
    pub fn support(&self) -> (f64, f64) {
        (self.wl_nm[0], *self.wl_nm.last().unwrap())
    }

    /// Value at `wl` by linear interpolation; zero outside the samples.
    pub fn eval(&self, wl: f64) -> f64 {
        let (lo, hi) = self.support();
        if !(wl >= lo && wl <= hi) {
            return 0.0;
        }
        let k = self.wl_nm.partition_point(|&w| w <= wl);
        if k == 0 {
            return self.value[0];
        }
        if k >= self.wl_nm.len() {
            return *self.value.last().unwrap();
        }
        let (w0, w1) = (self.wl_nm[k - 1], self.wl_nm[k]);
        let t = (wl - w0) / (w1 - w0);
        self.value[k - 1] * (1.0 - t) + self.value[k] * t
    }

    /// Point samples at the centres of `grid`.
    pub fn sample(&self, grid: &Grid) -> Vec<f64> {
        grid.wavelengths()
            .into_iter()
            .map(|w| self.eval(w))
            .collect()
    }

    /// The curve resampled onto `grid` (point sampling of the piecewise-linear curve).
    pub fn resample(&self, grid: &Grid) -> Curve {
        Curve {
            name: self.name.clone(),
            wl_nm: grid.wavelengths(),
            value: self.sample(grid),
        }
    }

    /// The curve multiplied by a constant.
    pub fn scaled(&self, k: f64) -> Curve {
        Curve {
            name: self.name.clone(),
            wl_nm: self.wl_nm.clone(),
            value: self.value.iter().map(|v| v * k).collect(),
        }
    }

    /// Largest value.
    pub fn max(&self) -> f64 {
        self.value.iter().cloned().fold(f64::MIN, f64::max)
    }
}

/// Gauss–Legendre nodes and weights on [-1, 1] for n = 1..=4 points (exact to degree 2n-1).
fn gauss_legendre(n: usize) -> (&'static [f64], &'static [f64]) {
    const X1: [f64; 1] = [0.0];
    const W1: [f64; 1] = [2.0];
    const X2: [f64; 2] = [-0.577_350_269_189_625_8, 0.577_350_269_189_625_8];
    const W2: [f64; 2] = [1.0, 1.0];
    const X3: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W3: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    const X4: [f64; 4] = [
        -0.861_136_311_594_052_6,
        -0.339_981_043_584_856_3,
        0.339_981_043_584_856_3,
        0.861_136_311_594_052_6,
    ];
    const W4: [f64; 4] = [
        0.347_854_845_137_453_9,
        0.652_145_154_862_546_1,
        0.652_145_154_862_546_1,
        0.347_854_845_137_453_9,
    ];
    match n {
        1 => (&X1, &W1),
        2 => (&X2, &W2),
        3 => (&X3, &W3),
        _ => (&X4, &W4),
    }
}

/// ∫ Π_k c_k(λ) dλ over all λ, exactly: between consecutive knots of all curves the product of
/// k linear pieces is a polynomial of degree k, which Gauss–Legendre with ⌈(k+1)/2⌉ nodes
/// integrates without error. Up to 7 curves are exact; more are refused.
pub fn integrate_product(curves: &[&Curve]) -> Result<f64> {
    if curves.is_empty() {
        return Ok(0.0);
    }
    if curves.len() > 7 {
        return Err(Error::Numerical(format!(
            "integrate_product is exact for at most 7 curves, got {}",
            curves.len()
        )));
    }
    let lo = curves
        .iter()
        .map(|c| c.support().0)
        .fold(f64::MIN, f64::max);
    let hi = curves
        .iter()
        .map(|c| c.support().1)
        .fold(f64::MAX, f64::min);
    if lo >= hi {
        return Ok(0.0);
    }
    let mut knots: Vec<f64> = curves
        .iter()
        .flat_map(|c| c.wl_nm.iter().cloned())
        .filter(|&w| w > lo && w < hi)
        .chain([lo, hi])
        .collect();
    knots.sort_by(|a, b| a.total_cmp(b));
    knots.dedup();
    let (xs, ws) = gauss_legendre(curves.len() / 2 + 1);
    let mut total = 0.0;
    for seg in knots.windows(2) {
        let (a, b) = (seg[0], seg[1]);
        let (mid, half) = (0.5 * (a + b), 0.5 * (b - a));
        let mut s = 0.0;
        for (x, w) in xs.iter().zip(ws) {
            let l = mid + half * x;
            s += w * curves.iter().map(|c| c.eval(l)).product::<f64>();
        }
        total += s * half;
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(step: f64) -> Curve {
        // A long-pass filter with a 10 nm linear edge 500→510 nm, sampled every `step` nm.
        let n = ((800.0 - 380.0) / step) as usize + 1;
        let wl: Vec<f64> = (0..n).map(|k| 380.0 + step * k as f64).collect();
        let v = wl
            .iter()
            .map(|&w| ((w - 500.0) / 10.0).clamp(0.0, 1.0) * 0.9)
            .collect();
        Curve::new("edge", wl, v).unwrap()
    }

    #[test]
    fn filter_edge_integral_independent_of_sampling() {
        let light = Curve::new("ramp", vec![380.0, 800.0], vec![0.2, 1.3]).unwrap();
        let fine = integrate_product(&[&edge(1.0), &light]).unwrap();
        let coarse = integrate_product(&[&edge(10.0), &light]).unwrap();
        assert!(((fine - coarse) / fine).abs() < 1e-9, "{fine} vs {coarse}");
    }

    #[test]
    fn product_of_lines_solved_by_hand() {
        // ∫_0^1 x · x dx = 1/3 and ∫_0^1 x·x·x·(1-x) dx = 1/20.
        let x = Curve::new("x", vec![1.0, 2.0], vec![0.0, 1.0]).unwrap();
        let one_minus = Curve::new("1-x", vec![1.0, 2.0], vec![1.0, 0.0]).unwrap();
        let v2 = integrate_product(&[&x, &x]).unwrap();
        assert!((v2 - 1.0 / 3.0).abs() < 1e-14);
        let v4 = integrate_product(&[&x, &x, &x, &one_minus]).unwrap();
        assert!((v4 - 1.0 / 20.0).abs() < 1e-14);
        let x6 = integrate_product(&[&x, &x, &x, &x, &x, &x, &x]).unwrap();
        assert!((x6 - 1.0 / 8.0).abs() < 1e-14);
    }

    #[test]
    fn disjoint_supports_integrate_to_zero() {
        let a = Curve::constant("a", 400.0, 500.0, 1.0).unwrap();
        let b = Curve::constant("b", 600.0, 700.0, 1.0).unwrap();
        assert_eq!(integrate_product(&[&a, &b]).unwrap(), 0.0);
    }

    #[test]
    fn hats_partition_unity() {
        let g = Grid::VISIBLE;
        let flat = Curve::constant("one", 300.0, 800.0, 1.0).unwrap();
        let total: f64 = (0..g.count)
            .map(|k| integrate_product(&[&Curve::hat(&g, k), &flat]).unwrap())
            .sum();
        assert!((total - (g.end_nm() - g.start_nm)).abs() < 1e-9);
    }

    #[test]
    fn bad_curves_are_refused() {
        assert!(Curve::new("n", vec![400.0, 410.0], vec![1.0, f64::NAN]).is_err());
        assert!(Curve::new("d", vec![410.0, 400.0], vec![1.0, 1.0]).is_err());
        assert!(Curve::new("neg", vec![-1.0, 400.0], vec![1.0, 1.0]).is_err());
    }

    #[test]
    fn eval_interpolates_and_is_zero_outside() {
        let c = Curve::new("c", vec![400.0, 500.0], vec![1.0, 3.0]).unwrap();
        assert_eq!(c.eval(450.0), 2.0);
        assert_eq!(c.eval(399.0), 0.0);
        assert_eq!(c.eval(500.0), 3.0);
    }
}
