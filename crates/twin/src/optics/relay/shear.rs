//! Unimodular shears of the frequency lattice: the relay's passed bins lie along streaks through
//! the origin, mostly diagonal, whose bounding box is mostly empty; an integer map of determinant
//! ±1 that lines a streak up with an axis keeps every correlation (it relabels the lattice) and
//! makes the box of the bins, and of their differences, nearly full.

use super::PassedBin;
use glam::I64Vec2;

/// A unimodular map of the bin lattice, k ↦ (s·k − lo.x, t·k − lo.y), under which the bins fill
/// the box [0, len.x) × [0, len.y); correlations on it are those of the bins, relabelled.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Shear {
    s: I64Vec2,
    t: I64Vec2,
    pub(super) lo: I64Vec2,
    pub(super) len: I64Vec2,
}

impl Shear {
    /// The shear with the smallest box over the bins, among rows t of entries up to 12 (the
    /// streaks' directions) and rows s completing them to a unimodular map.
    pub(super) fn fit(bins: &[PassedBin]) -> Shear {
        let edge = column_ends(bins);
        let rows = (0..=12i64).flat_map(|x| (-12..=12i64).map(move |y| I64Vec2::new(x, y)));
        rows.filter(|t| gcd(t.x, t.y) == 1 && (t.x != 0 || t.y == 1))
            .flat_map(|t| {
                let s0 = completion(t);
                let m = -(s0.dot(t) as f64 / t.length_squared() as f64).round() as i64;
                [m - 1, m, m + 1].map(|m| Shear::over(s0 + m * t, t, &edge))
            })
            .min_by_key(|c| c.cells())
            .expect("t = (0, 1) is always a candidate")
    }

    /// The map with rows s, t, offset to the points' box.
    fn over(s: I64Vec2, t: I64Vec2, points: &[I64Vec2]) -> Shear {
        let (mut lo, mut hi) = (I64Vec2::MAX, I64Vec2::MIN);
        for p in points {
            let q = I64Vec2::new(s.dot(*p), t.dot(*p));
            (lo, hi) = (lo.min(q), hi.max(q));
        }
        Shear {
            s,
            t,
            lo,
            len: hi - lo + I64Vec2::ONE,
        }
    }

    /// The unsheared box qx in 0..=qx_max, |qy| ≤ qy_max: the half differences of the pair loop.
    pub(super) fn half_box(qx_max: i64, qy_max: i64) -> Shear {
        Shear {
            s: I64Vec2::X,
            t: I64Vec2::Y,
            lo: I64Vec2::new(0, -qy_max),
            len: I64Vec2::new(qx_max + 1, 2 * qy_max + 1),
        }
    }

    /// The same map over the differences of the points of this box with s·q ≥ 0: the other half
    /// of the differences follows by Hermitian symmetry.
    pub(super) fn half_differences(&self) -> Shear {
        Shear {
            lo: I64Vec2::new(0, 1 - self.len.y),
            len: I64Vec2::new(self.len.x, 2 * self.len.y - 1),
            ..*self
        }
    }

    pub(super) fn cells(&self) -> i64 {
        self.len.x * self.len.y
    }

    /// The image (s·k, t·k) of lattice point k, before the offset.
    pub(super) fn image(&self, kx: i64, ky: i64) -> I64Vec2 {
        let k = I64Vec2::new(kx, ky);
        I64Vec2::new(self.s.dot(k), self.t.dot(k))
    }

    /// The bin's place in the box.
    pub(super) fn place(&self, b: &PassedBin) -> (usize, usize) {
        let q = self.image(b.kx, b.ky) - self.lo;
        (q.x as usize, q.y as usize)
    }

    /// The row-major cell of lattice point k in the box, None outside it.
    pub(super) fn cell(&self, kx: i64, ky: i64) -> Option<usize> {
        let c = self.image(kx, ky) - self.lo;
        (c.cmpge(I64Vec2::ZERO).all() && c.cmplt(self.len).all())
            .then(|| (c.x * self.len.y + c.y) as usize)
    }

    /// The lattice point of row-major cell i.
    pub(super) fn point(&self, i: usize) -> (i64, i64) {
        let c = I64Vec2::new(i as i64 / self.len.y, i as i64 % self.len.y) + self.lo;
        self.unshear(c.x, c.y)
    }

    /// The lattice point whose image is (ds, dt): the inverse map (determinant ±1).
    pub(super) fn unshear(&self, ds: i64, dt: i64) -> (i64, i64) {
        let det = self.s.x * self.t.y - self.s.y * self.t.x;
        (
            det * (self.t.y * ds - self.s.y * dt),
            det * (self.s.x * dt - self.t.x * ds),
        )
    }
}

/// Greatest common divisor of |a| and |b|.
fn gcd(a: i64, b: i64) -> i64 {
    if b == 0 {
        a.abs()
    } else {
        gcd(b, a % b)
    }
}

/// A row s with s.x·t.y − s.y·t.x = 1 for coprime t (extended Euclid).
fn completion(t: I64Vec2) -> I64Vec2 {
    // x·a + y·b = g for (a, b) = (t.y, −t.x).
    fn euclid(a: i64, b: i64) -> (i64, i64, i64) {
        if b == 0 {
            return (a, 1, 0);
        }
        let (g, x, y) = euclid(b, a.rem_euclid(b));
        (g, y, x - a.div_euclid(b) * y)
    }
    let (g, x, y) = euclid(t.y, -t.x);
    I64Vec2::new(x, y) * g.signum()
}

/// The lowest and highest bin of every column (bins sorted by (kx, ky)): the extremes of any
/// linear function of k over the bins are among them.
fn column_ends(bins: &[PassedBin]) -> Vec<I64Vec2> {
    bins.chunk_by(|a, b| a.kx == b.kx)
        .flat_map(|c| [&c[0], &c[c.len() - 1]])
        .map(|b| I64Vec2::new(b.kx, b.ky))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::sliced::tests::streak_bins;
    use super::*;

    #[test]
    fn the_shear_lines_a_diagonal_streak_up_with_an_axis() {
        let bins = streak_bins(5, (8, 4), false);
        let shear = Shear::fit(&bins);
        let (x0, x1) = (bins[0].kx, bins[bins.len() - 1].kx);
        let (y0, y1) = bins
            .iter()
            .fold((i64::MAX, i64::MIN), |(a, b), x| (a.min(x.ky), b.max(x.ky)));
        let boxed = (x1 - x0 + 1) * (y1 - y0 + 1);
        assert!(
            shear.cells() * 5 < boxed,
            "{} of {boxed} cells",
            shear.cells()
        );
        // Differences map back: unshear(place(a) − place(b)) = k_a − k_b.
        for (a, b) in bins.iter().zip(bins.iter().rev()) {
            let ((sa, ta), (sb, tb)) = (shear.place(a), shear.place(b));
            let q = shear.unshear(sa as i64 - sb as i64, ta as i64 - tb as i64);
            assert_eq!(q, (a.kx - b.kx, a.ky - b.ky));
            assert!(sa < shear.len.x as usize && ta < shear.len.y as usize);
        }
    }

    #[test]
    fn completion_is_unimodular() {
        for t in [(1, 0), (0, 1), (2, 1), (3, -7), (12, 5), (5, -12)] {
            let t = I64Vec2::new(t.0, t.1);
            let s = completion(t);
            assert_eq!(s.x * t.y - s.y * t.x, 1, "{t:?}: {s:?}");
        }
    }

    #[test]
    fn cells_and_points_are_inverse() {
        let shear = Shear::fit(&streak_bins(6, (-4, 12), false)).half_differences();
        for i in [0, 1, 17, shear.cells() as usize - 1] {
            let (qx, qy) = shear.point(i);
            assert_eq!(shear.cell(qx, qy), Some(i));
        }
        let (qx, qy) = shear.point(0);
        let past = shear.unshear(-1, 0);
        assert_eq!(shear.cell(past.0, past.1), None, "{qx}, {qy}");
    }
}
