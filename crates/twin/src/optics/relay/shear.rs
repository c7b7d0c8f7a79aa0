//! Unimodular shears of the frequency lattice: the relay's passed bins lie along streaks through
//! the origin, mostly diagonal, whose bounding box is mostly empty; an integer map of determinant
//! ±1 that lines a streak up with an axis keeps every correlation (it relabels the lattice) and
//! makes the box of the bins, and of their differences, nearly full.

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
    /// `points` need only hold the extremes of every linear function over the set (the lowest
    /// and highest point of every column do).
    pub(super) fn fit(points: &[I64Vec2]) -> Shear {
        let rows = (0..=12i64).flat_map(|x| (-12..=12i64).map(move |y| I64Vec2::new(x, y)));
        rows.filter(|t| gcd(t.x, t.y) == 1 && (t.x != 0 || t.y == 1))
            .flat_map(|t| {
                let s0 = completion(t);
                let m = -(s0.dot(t) as f64 / t.length_squared() as f64).round() as i64;
                [m - 1, m, m + 1].map(|m| Shear::over(s0 + m * t, t, points))
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

    /// The number of cells in the box.
    pub(super) fn cells(&self) -> i64 {
        self.len.x * self.len.y
    }

    /// The image (s·k, t·k) of lattice point k, before the offset.
    pub(super) fn image(&self, kx: i64, ky: i64) -> I64Vec2 {
        let k = I64Vec2::new(kx, ky);
        I64Vec2::new(self.s.dot(k), self.t.dot(k))
    }

    /// The place of lattice point k in the box.
    pub(super) fn place(&self, kx: i64, ky: i64) -> (usize, usize) {
        let q = self.image(kx, ky) - self.lo;
        (q.x as usize, q.y as usize)
    }

    /// The row-major cell of lattice point k in the box, None outside it.
    pub(super) fn cell(&self, kx: i64, ky: i64) -> Option<usize> {
        let c = self.image(kx, ky) - self.lo;
        (c.cmpge(I64Vec2::ZERO).all() && c.cmplt(self.len).all())
            .then(|| (c.x * self.len.y + c.y) as usize)
    }

    /// The image (s·k, t·k) of the lattice point in row-major cell i.
    pub(super) fn image_of_cell(&self, i: usize) -> I64Vec2 {
        I64Vec2::new(i as i64 / self.len.y, i as i64 % self.len.y) + self.lo
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every lattice point of a band along direction (2, 1) through the origin: |x − 2y| ≤ 5.
    fn band() -> Vec<I64Vec2> {
        (-600..600i64)
            .flat_map(|x| {
                ((x - 5).div_euclid(2)..=(x + 5).div_euclid(2)).map(move |y| I64Vec2::new(x, y))
            })
            .filter(|p| (p.x - 2 * p.y).abs() <= 5)
            .collect()
    }

    #[test]
    fn the_shear_lines_a_diagonal_streak_up_with_an_axis() {
        let points = band();
        let shear = Shear::fit(&points);
        let (lo, hi) = (points.iter()).fold((I64Vec2::MAX, I64Vec2::MIN), |(l, h), p| {
            (l.min(*p), h.max(*p))
        });
        let boxed = (hi - lo + I64Vec2::ONE).element_product();
        // 6 600 points in a box of 1 200 × 605 cells; sheared, at most two cells a point.
        assert!(
            shear.cells() <= 2 * points.len() as i64,
            "{} of {boxed} cells",
            shear.cells()
        );
        // Differences map back: unshear(place(a) − place(b)) = a − b, and places fit the box.
        for (a, b) in points.iter().zip(points.iter().rev()) {
            let ((sa, ta), (sb, tb)) = (shear.place(a.x, a.y), shear.place(b.x, b.y));
            let q = shear.unshear(sa as i64 - sb as i64, ta as i64 - tb as i64);
            assert_eq!(q, (a.x - b.x, a.y - b.y));
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
        let shear = Shear::fit(&band()).half_differences();
        for i in [0, 1, 17, shear.cells() as usize - 1] {
            let c = shear.image_of_cell(i);
            let (qx, qy) = shear.unshear(c.x, c.y);
            assert_eq!(shear.cell(qx, qy), Some(i));
        }
        // The half with s·q < 0 is not stored.
        let below = shear.unshear(-1, 0);
        assert_eq!(shear.cell(below.0, below.1), None);
    }
}
