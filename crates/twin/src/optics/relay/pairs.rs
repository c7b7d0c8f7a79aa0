//! Passed bins and their pair sums: the bins' pass intervals over wavelength, the sums' storage
//! on a lattice map, and the pair loop that the sums by slices also use for what they leave.

use super::shear::Shear;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;

/// One wavelength interval (nm) in which a bin passes, with the cumulative pair weights
/// (weight, first moment) below its lower end and through its upper end.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Interval {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) c_lo: [f64; 2],
    pub(super) c_hi: [f64; 2],
}

/// A frequency bin some wavelength of the light carries through the mask.
#[derive(Clone, Debug)]
pub struct PassedBin {
    /// Bin indices on the (padded) mirror grid: f = (kx/wc, ky/hc) cycles per mirror.
    pub kx: i64,
    pub ky: i64,
    /// The source spectrum there (coherent: the field; incoherent: 1).
    pub value: Complex64,
    /// Fraction of the light for which the bin passes.
    pub weight: f64,
    pub(super) ivs: [Interval; 3],
    pub(super) n: usize,
}

/// ∫ of the pair weights over the wavelengths for which both bins pass.
#[inline]
pub(super) fn overlap(a: &PassedBin, b: &PassedBin) -> [f64; 2] {
    let mut g = [0.0; 2];
    for x in &a.ivs[..a.n] {
        for y in &b.ivs[..b.n] {
            let (lo, c_lo) = if x.lo >= y.lo {
                (x.lo, x.c_lo)
            } else {
                (y.lo, y.c_lo)
            };
            let (hi, c_hi) = if x.hi <= y.hi {
                (x.hi, x.c_hi)
            } else {
                (y.hi, y.c_hi)
            };
            if hi >= lo {
                g[0] += c_hi[0] - c_lo[0];
                g[1] += c_hi[1] - c_lo[1];
            }
        }
    }
    g
}

/// The pair sums Σ value_a·conj(value_b)·∫(pair weights) at q = k_a − k_b: component 0 with the
/// weight, 1 with its first moment about the centroid; stored for half the differences (those
/// with s·q ≥ 0 for the first row s of a lattice map: kx ≥ 0 unsheared), the rest following by
/// Hermitian symmetry.
pub struct PairSums {
    pub(super) map: Shear,
    pub(super) s: [Vec<Complex64>; 2],
}

impl PairSums {
    /// Zero sums over the map's box.
    fn zeros(map: Shear) -> PairSums {
        let n = map.cells() as usize;
        PairSums {
            map,
            s: [vec![Complex64::default(); n], vec![Complex64::default(); n]],
        }
    }

    /// The cells of the half box the sums are stored on (each holds both components).
    pub fn cells(&self) -> usize {
        self.s[0].len()
    }

    /// Both components at (qx, qy), zero outside the pairs' reach.
    pub fn at(&self, qx: i64, qy: i64) -> [Complex64; 2] {
        let value = |i: usize| [self.s[0][i], self.s[1][i]];
        match (self.map.cell(qx, qy), self.map.cell(-qx, -qy)) {
            (Some(i), _) => value(i),
            (None, Some(i)) => value(i).map(|v| v.conj()),
            (None, None) => [Complex64::default(); 2],
        }
    }

    /// Every stored cell with some sum not zero, in parallel: (qx, qy), the sums, and whether −q
    /// is a cell not stored (its sums are their conjugates).
    pub fn half_plane(
        &self,
    ) -> impl ParallelIterator<Item = ((i64, i64), [Complex64; 2], bool)> + '_ {
        (self.s[0].par_iter().zip(&self.s[1]).enumerate()).filter_map(|(i, (&a, &b))| {
            let zero = a == Complex64::default() && b == Complex64::default();
            let c = self.map.image_of_cell(i);
            // s·q > 0: −q has s·q < 0, the half not stored.
            (!zero).then(|| (self.map.unshear(c.x, c.y), [a, b], c.x > 0))
        })
    }
}

/// The pair sums of `bins` pair by pair: O(N²) in the number of bins.
pub fn direct_pair_sums(bins: &[PassedBin]) -> PairSums {
    let (kx0, kx1) = match (bins.first(), bins.last()) {
        (Some(a), Some(b)) => (a.kx, b.kx),
        _ => (0, 0),
    };
    // No bins (the openings pass nothing): one zero cell.
    let ky = bins.first().map_or(0, |b| b.ky);
    let (ky0, ky1) = bins
        .iter()
        .fold((ky, ky), |(a, b), x| (a.min(x.ky), b.max(x.ky)));
    let mut sums = PairSums::zeros(Shear::half_box(kx1 - kx0, ky1 - ky0));
    add_pairs(bins, &mut sums);
    sums
}

/// Adds the pairs of `bins` whose q falls in the box of `sums` to it, the bins sorted by the
/// first coordinate of its map (kx for the half plane's box); parallel over rows of the box so
/// that every row has one writer.
pub(super) fn add_pairs(bins: &[PassedBin], sums: &mut PairSums) {
    let map = sums.map;
    let h = map.len.y as usize;
    let at: Vec<_> = bins.iter().map(|b| map.image(b.kx, b.ky)).collect();
    // Four tasks a thread balance the load; more only repeat the searches below per task (the
    // sums by slices call this once per slice on a few thousand bins). A cell's pairs are added
    // in the order of a whatever the split, so the sums do not depend on it.
    let tasks = (4 * rayon::current_num_threads()).clamp(1, 64);
    let per_task = (map.len.x as usize).div_ceil(tasks).max(1);
    let [s0, s1] = &mut sums.s;
    s0.par_chunks_mut(per_task * h)
        .zip(s1.par_chunks_mut(per_task * h))
        .enumerate()
        .for_each(|(t, (c0, c1))| {
            let d0 = map.lo.x + (t * per_task) as i64;
            let d1 = d0 + (c0.len() / h) as i64;
            for (a, pa) in bins.iter().zip(&at) {
                // b with d0 ≤ s_a − s_b < d1.
                let lo = at.partition_point(|p| p.x <= pa.x - d1);
                let hi = at.partition_point(|p| p.x <= pa.x - d0);
                for (b, pb) in bins[lo..hi].iter().zip(&at[lo..hi]) {
                    let g = overlap(a, b);
                    if g == [0.0; 2] {
                        continue;
                    }
                    let p = a.value * b.value.conj();
                    let d = *pa - *pb - map.lo;
                    let i = ((d.x - (d0 - map.lo.x)) * h as i64 + d.y) as usize;
                    c0[i] += p * g[0];
                    c1[i] += p * g[1];
                }
            }
        });
}

/// Per component, the largest |a − b| over the cells either holds relative to b's
/// largest |sum| (absolute where that is 0): sums on different maps compared cell by cell
/// (the tests' and `benches/relay.rs`' measure of the GPU kernel against the CPU).
pub fn relative_difference(a: &PairSums, b: &PairSums) -> [f64; 2] {
    let worst = |x: &PairSums, y: &PairSums, c: usize| {
        (x.half_plane())
            .map(|((qx, qy), v, _)| (v[c] - y.at(qx, qy)[c]).norm())
            .reduce(|| 0.0, f64::max)
    };
    [0, 1].map(|c| {
        let scale = b
            .half_plane()
            .map(|(_, v, _)| v[c].norm())
            .reduce(|| 0.0, f64::max);
        let diff = worst(a, b, c).max(worst(b, a, c));
        diff / if scale > 0.0 { scale } else { 1.0 }
    })
}
