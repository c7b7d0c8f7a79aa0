//! The pair sums by slices of wavelength, exact like the pair loop but O(K FFTs + E²/K) for E
//! interval ends instead of O(N²). Within a slice the bins that pass all of it (F) and those with
//! an end inside it (P) make
//!   Σ_pairs = ΔW·(F ⋆ F) + F ⋆ (w·P) + (w·P) ⋆ F + (P × P pair by pair),
//! with ΔW the slice's pair weights and w a P bin's own weight in it; the correlations are one
//! FFT each on a lattice sheared so that the streaks of passed bins lie along an axis (their box
//! is then mostly full, not mostly empty), accumulated in the transform domain over the slices.

use super::pairs::add_pairs;
use super::pairs::Interval;
use super::pairs::PairSums;
use super::pairs::PassedBin;
use super::shear::Shear;
use glam::I64Vec2;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use rustfft::Fft;
use rustfft::FftPlanner;
use std::sync::Arc;

/// Fewest bins for which slicing is considered: below it the pair loop (1.3·10⁸ pairs) takes
/// about 0.2 s on two cores, and the small rigs of the tests keep its bits.
pub const SLICED_FROM_BINS: usize = 16_384;

/// Cost of one FFT point per factor log₂(size), in pair-loop pairs (measured, docs/speed.md).
const FFT_COST: f64 = 0.25;

/// Largest FFT grid, in points (128 MB a complex grid, four in flight per thread): bins spread
/// too widely for the shear to gather are summed pair by pair.
const MAX_GRID_POINTS: usize = 1 << 23;

/// A boundary between slices: the wavelength and the cumulative pair weights through it.
#[derive(Clone, Copy, Debug)]
struct Cut {
    at: f64,
    c: [f64; 2],
}

/// A bin with an interval end inside a slice: its intervals clipped to the slice, and its pair
/// weights there (those it has with a bin that passes all of the slice).
struct Clipped {
    bin: PassedBin,
    w: [f64; 2],
}

/// The slice (lo, hi] of the band between two cuts (the first one closed below: [lo, hi]).
#[derive(Clone, Copy, Debug)]
struct Slice {
    lo: Cut,
    hi: Cut,
    first: bool,
}

impl Slice {
    /// The slice's own pair weights (those of two bins passing all of it).
    fn weight(&self) -> [f64; 2] {
        [self.hi.c[0] - self.lo.c[0], self.hi.c[1] - self.lo.c[1]]
    }

    /// Whether one of the bin's intervals covers the slice.
    fn covered_by(&self, b: &PassedBin) -> bool {
        (b.ivs[..b.n].iter()).any(|iv| iv.lo <= self.lo.at && iv.hi >= self.hi.at)
    }

    /// For a bin no interval of which covers the slice: its intervals clipped to the slice and
    /// its weights there, None when none meets it.
    fn clip(&self, b: &PassedBin) -> Option<Clipped> {
        let mut ivs = [Interval::default(); 3];
        let mut n = 0;
        for iv in &b.ivs[..b.n] {
            if iv.lo > self.hi.at || (!self.first && iv.hi <= self.lo.at) {
                continue;
            }
            let (from_below, past) = (iv.lo <= self.lo.at, iv.hi >= self.hi.at);
            ivs[n] = Interval {
                lo: iv.lo.max(self.lo.at),
                hi: iv.hi.min(self.hi.at),
                c_lo: if from_below { self.lo.c } else { iv.c_lo },
                c_hi: if past { self.hi.c } else { iv.c_hi },
            };
            n += 1;
        }
        let w = ivs[..n].iter().fold([0.0; 2], |w, iv| {
            [
                w[0] + iv.c_hi[0] - iv.c_lo[0],
                w[1] + iv.c_hi[1] - iv.c_lo[1],
            ]
        });
        (n > 0).then(|| Clipped {
            bin: PassedBin {
                ivs,
                n,
                ..b.clone()
            },
            w,
        })
    }

    /// The bins that pass all of the slice, and those with an end inside it (bins with
    /// disjoint intervals, as `passed_bins` makes them), in the order of `bins`.
    fn split<'a>(&self, bins: &'a [PassedBin]) -> (Vec<&'a PassedBin>, Vec<Clipped>) {
        let (mut whole, mut part) = (Vec::new(), Vec::new());
        for b in bins {
            if self.covered_by(b) {
                whole.push(b);
            } else if let Some(c) = self.clip(b) {
                part.push(c);
            }
        }
        (whole, part)
    }
}

/// How to slice one set of bins: the shear, the FFT grid and the cuts.
pub(super) struct Plan {
    shear: Shear,
    grid: (usize, usize),
    slices: Vec<Slice>,
}

impl Plan {
    /// The plan for `bins` (sorted by (kx, ky)), None when the pair loop is cheaper.
    pub(super) fn new(bins: &[PassedBin]) -> Option<Plan> {
        if bins.len() < SLICED_FROM_BINS {
            return None;
        }
        let (shear, grid) = layout(bins);
        if grid.0 * grid.1 > MAX_GRID_POINTS {
            return None;
        }
        let (first, his, last) = ends(bins);
        let interior = interior_ends(bins, first.at, last.at) as f64;
        let points = (grid.0 * grid.1) as f64;
        let per_slice = 3.0 * points * points.log2() * FFT_COST;
        let cost = |k: usize| k as f64 * per_slice + interior * interior / (2.0 * k as f64);
        let k = (1..=his.len() + 1).min_by(|&a, &b| cost(a).total_cmp(&cost(b)))?;
        let pairs = (bins.len() * bins.len()) as f64 / 2.0;
        (cost(k) <= pairs / 2.0).then(|| Plan {
            shear,
            grid,
            slices: slices(first, &his, last, k),
        })
    }

    /// The plan for `bins` with `k` slices (fewer where the upper ends are fewer), cheaper or not.
    #[cfg(test)]
    pub(super) fn with_slices(bins: &[PassedBin], k: usize) -> Plan {
        let (shear, grid) = layout(bins);
        let (first, his, last) = ends(bins);
        Plan {
            shear,
            grid,
            slices: slices(first, &his, last, k.min(his.len() + 1)),
        }
    }

    /// The pair sums of `bins`, the same cells as the pair loop's (to rounding).
    pub(super) fn sums(&self, bins: &[PassedBin]) -> PairSums {
        let ffts = Transforms::new(self.grid);
        let zero = || (Spectra::zeros(self.grid), Vec::new(), Workspace::default());
        let (spectra, parts, _) = (self.slices.par_iter())
            .filter(|slice| slice.weight()[0] != 0.0)
            .fold(zero, |(mut acc, mut parts, mut work), slice| {
                let (whole, part) = slice.split(bins);
                acc.add(&ffts, &mut work, &self.shear, slice.weight(), &whole, &part);
                parts.push(part.into_iter().map(|c| c.bin).collect::<Vec<_>>());
                (acc, parts, work)
            })
            .reduce(zero, |(a, mut pa, work), (b, pb, _)| {
                pa.extend(pb);
                (a.plus(b), pa, work)
            });
        let mut sums = spectra.sums(&ffts, &self.shear);
        for mut part in parts {
            part.sort_by_key(|b| sums.map.image(b.kx, b.ky).x);
            add_pairs(&part, &mut sums);
        }
        sums
    }
}

/// The shear of the bins and the grid that holds their correlations without wrapping round.
fn layout(bins: &[PassedBin]) -> (Shear, (usize, usize)) {
    let shear = Shear::fit(&column_ends(bins));
    let side = |len: i64| smooth(2 * len as usize - 1);
    (shear, (side(shear.len.x), side(shear.len.y)))
}

/// The lowest and highest bin of every column (bins sorted by (kx, ky)): the extremes of any
/// linear function of k over the bins are among them.
fn column_ends(bins: &[PassedBin]) -> Vec<I64Vec2> {
    bins.chunk_by(|a, b| a.kx == b.kx)
        .flat_map(|c| [&c[0], &c[c.len() - 1]])
        .map(|b| I64Vec2::new(b.kx, b.ky))
        .collect()
}

/// Interval ends strictly inside the band [first, last].
fn interior_ends(bins: &[PassedBin], first: f64, last: f64) -> usize {
    bins.iter()
        .flat_map(|b| &b.ivs[..b.n])
        .map(|iv| usize::from(iv.lo > first) + usize::from(iv.hi < last))
        .sum()
}

/// The band's lower end (with the weights below it), the interior upper ends (sorted, with the
/// weights through them) and the upper end.
fn ends(bins: &[PassedBin]) -> (Cut, Vec<Cut>, Cut) {
    let ivs = || bins.iter().flat_map(|b| &b.ivs[..b.n]);
    let first = ivs().min_by(|a, b| a.lo.total_cmp(&b.lo)).map(|iv| Cut {
        at: iv.lo,
        c: iv.c_lo,
    });
    let mut his: Vec<Cut> = ivs()
        .map(|iv| Cut {
            at: iv.hi,
            c: iv.c_hi,
        })
        .collect();
    his.sort_by(|a, b| a.at.total_cmp(&b.at));
    let last = *his.last().expect("slicing is planned for some bins");
    his.retain(|c| c.at < last.at);
    (first.expect("some bins"), his, last)
}

/// `k` slices cut at quantiles of the interior upper ends.
fn slices(first: Cut, his: &[Cut], last: Cut, k: usize) -> Vec<Slice> {
    let mut cuts = vec![first];
    for j in 1..k {
        let c = his[j * his.len() / k];
        if c.at > cuts[cuts.len() - 1].at {
            cuts.push(c);
        }
    }
    cuts.push(last);
    cuts.windows(2)
        .enumerate()
        .map(|(i, w)| Slice {
            lo: w[0],
            hi: w[1],
            first: i == 0,
        })
        .collect()
}

/// The smallest size ≥ n with no prime factor above 7 (fast for rustfft).
fn smooth(n: usize) -> usize {
    (n.max(1)..)
        .find(|&m| {
            let mut r = m;
            for p in [2, 3, 5, 7] {
                while r % p == 0 {
                    r /= p;
                }
            }
            r == 1
        })
        .expect("smooth numbers are unbounded")
}

/// One thread's buffers, kept across its slices (fresh buffers of a few MB each cost their page
/// faults every slice): [`Transforms::forward`]'s own, and the slice's two transforms.
#[derive(Default)]
struct Workspace {
    scratch: Scratch,
    f: Vec<Complex64>,
    g: Vec<Complex64>,
}

/// The grid and the FFT scratch of [`Transforms::forward`].
#[derive(Default)]
struct Scratch {
    grid: Vec<Complex64>,
    fft: Vec<Complex64>,
}

/// Planned 2-D transforms of the sheared grid: rows s (gs of them), columns t (gt).
struct Transforms {
    gs: usize,
    gt: usize,
    t_fwd: Arc<dyn Fft<f64>>,
    s_fwd: Arc<dyn Fft<f64>>,
    t_inv: Arc<dyn Fft<f64>>,
    s_inv: Arc<dyn Fft<f64>>,
}

impl Transforms {
    fn new((gs, gt): (usize, usize)) -> Transforms {
        let mut p = FftPlanner::new();
        Transforms {
            gs,
            gt,
            t_fwd: p.plan_fft_forward(gt),
            s_fwd: p.plan_fft_forward(gs),
            t_inv: p.plan_fft_inverse(gt),
            s_inv: p.plan_fft_inverse(gs),
        }
    }

    /// The transform of `values` placed on the grid's first `rows` rows, transposed into `out`:
    /// (xt, xs) at xt·gs + xs. Only the filled rows are transformed along t.
    fn forward(
        &self,
        scratch: &mut Scratch,
        rows: usize,
        values: impl Iterator<Item = ((usize, usize), Complex64)>,
        out: &mut Vec<Complex64>,
    ) {
        let (gs, gt) = (self.gs, self.gt);
        let grid = &mut scratch.grid;
        grid.clear();
        grid.resize(rows * gt, Complex64::default());
        for ((s, t), v) in values {
            grid[s * gt + t] = v;
        }
        let scratch_len =
            (self.t_fwd.get_inplace_scratch_len()).max(self.s_fwd.get_inplace_scratch_len());
        scratch.fft.resize(scratch_len, Complex64::default());
        for row in grid.chunks_exact_mut(gt) {
            self.t_fwd.process_with_scratch(row, &mut scratch.fft);
        }
        grid.resize(gs * gt, Complex64::default());
        out.resize(gs * gt, Complex64::default());
        transpose::transpose(grid, out, gt, gs);
        for row in out.chunks_exact_mut(gs) {
            self.s_fwd.process_with_scratch(row, &mut scratch.fft);
        }
    }

    /// The inverse of [`Transforms::forward`] for a real spectrum, normalised: (ds, dt) at
    /// ds·gt + dt, indices modulo the grid.
    fn inverse(&self, spectrum: &[f64]) -> Vec<Complex64> {
        let (gs, gt) = (self.gs, self.gt);
        let norm = 1.0 / (gs * gt) as f64;
        let mut x: Vec<Complex64> = spectrum
            .iter()
            .map(|&v| Complex64::new(v * norm, 0.0))
            .collect();
        x.par_chunks_mut(gs).for_each_init(
            || vec![Complex64::default(); self.s_inv.get_inplace_scratch_len()],
            |scratch, row| self.s_inv.process_with_scratch(row, scratch),
        );
        let mut out = vec![Complex64::default(); gs * gt];
        transpose::transpose(&x, &mut out, gs, gt);
        out.par_chunks_mut(gt).for_each_init(
            || vec![Complex64::default(); self.t_inv.get_inplace_scratch_len()],
            |scratch, row| self.t_inv.process_with_scratch(row, scratch),
        );
        out
    }
}

/// The transform of Σ over slices of the correlations of their whole and part bins, per pair
/// weight component (real: the sums are Hermitian in q).
struct Spectra {
    a: [Vec<f64>; 2],
}

impl Spectra {
    fn zeros((gs, gt): (usize, usize)) -> Spectra {
        Spectra {
            a: [vec![0.0; gs * gt], vec![0.0; gs * gt]],
        }
    }

    fn plus(mut self, other: Spectra) -> Spectra {
        for (a, b) in self.a.iter_mut().zip(&other.a) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        self
    }

    /// Adds ΔW·|F̂|² + 2·Re(F̂·conj(Ĝ)) of one slice: F its whole bins, G its part bins times
    /// their weights in it.
    fn add(
        &mut self,
        ffts: &Transforms,
        work: &mut Workspace,
        shear: &Shear,
        dw: [f64; 2],
        whole: &[&PassedBin],
        part: &[Clipped],
    ) {
        if whole.is_empty() {
            return;
        }
        let rows = shear.len.x as usize;
        let Workspace { scratch, f, g } = work;
        let placed = |b: &PassedBin| shear.place(b.kx, b.ky);
        let whole = whole.iter().map(|b| (placed(b), b.value));
        ffts.forward(scratch, rows, whole, f);
        let crossed = !part.is_empty();
        for (c, a) in self.a.iter_mut().enumerate() {
            if crossed {
                let values = part.iter().map(|p| (placed(&p.bin), p.bin.value * p.w[c]));
                ffts.forward(scratch, rows, values, g);
            }
            for (i, (a, x)) in a.iter_mut().zip(f.iter()).enumerate() {
                let cross = if crossed { (x * g[i].conj()).re } else { 0.0 };
                *a += dw[c] * x.norm_sqr() + 2.0 * cross;
            }
        }
    }

    /// The sums these spectra hold, on the sheared lattice's half differences.
    fn sums(&self, ffts: &Transforms, shear: &Shear) -> PairSums {
        let map = shear.half_differences();
        let (gs, gt) = (ffts.gs as i64, ffts.gt as i64);
        let s = self.a.each_ref().map(|a| {
            let x = ffts.inverse(a);
            (0..map.cells() as usize)
                .map(|i| {
                    let d = map.image_of_cell(i);
                    x[(d.x.rem_euclid(gs) * gt + d.y.rem_euclid(gt)) as usize]
                })
                .collect()
        });
        PairSums { map, s }
    }
}

#[cfg(test)]
mod tests {
    use super::super::pairs::direct_pair_sums;
    use super::super::pairs::relative_difference;
    use super::*;
    use rand::Rng;
    use rand::SeedableRng;

    /// Cumulative pair weights (weight, first moment about 550 nm) below and through λ: flat
    /// light on 400–700 nm, or with `line` all of it at 550 nm (where below and through differ).
    fn cumulative(line: bool) -> impl Fn(f64, bool) -> [f64; 2] {
        move |l, through| {
            if line {
                let w = if l > 550.0 || (through && l == 550.0) {
                    1.0
                } else {
                    0.0
                };
                [w, 0.0]
            } else {
                let l = l.clamp(400.0, 700.0);
                [
                    (l - 400.0) / 300.0,
                    ((l - 550.0).powi(2) - 150.0f64.powi(2)) / 600.0,
                ]
            }
        }
    }

    /// Random bins along a streak of direction `dir` (a band some bins wide, filled at random),
    /// complex values, 1–3 disjoint intervals each with ends on a 5 nm grid (so ends of
    /// different bins tie, 550 nm among them), sorted by (kx, ky) as `passed_bins` returns them.
    fn streak_bins(seed: u64, dir: (i64, i64), line: bool) -> Vec<PassedBin> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let c = cumulative(line);
        let mut bins = Vec::new();
        for along in -60..60i64 {
            for across in -3..=3i64 {
                if !rng.gen_bool(0.7) {
                    continue;
                }
                let n = rng.gen_range(1..=3);
                let mut ends: Vec<i64> = Vec::new();
                while ends.len() < 2 * n {
                    let e = rng.gen_range(76..=144) * 5;
                    if !ends.contains(&e) {
                        ends.push(e);
                    }
                }
                ends.sort();
                let mut ivs = [Interval::default(); 3];
                for (iv, e) in ivs.iter_mut().zip(ends.chunks(2)) {
                    let (lo, hi) = (e[0] as f64, e[1] as f64);
                    *iv = Interval {
                        lo,
                        hi,
                        c_lo: c(lo, false),
                        c_hi: c(hi, true),
                    };
                }
                bins.push(PassedBin {
                    kx: along * dir.0 / 4 + across * dir.1.signum(),
                    ky: along * dir.1 / 4 - across * dir.0.signum(),
                    value: Complex64::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0)),
                    weight: 0.0,
                    ivs,
                    n,
                });
            }
        }
        bins.sort_by_key(|b| (b.kx, b.ky));
        bins.dedup_by_key(|b| (b.kx, b.ky));
        bins
    }

    #[test]
    fn sliced_sums_are_the_pair_loops_for_any_slicing() {
        for (seed, dir, line) in [
            (1, (4, 0), false),
            (2, (8, 4), false),
            (3, (-4, 12), false),
            (4, (8, 4), true),
        ] {
            let bins = streak_bins(seed, dir, line);
            let direct = direct_pair_sums(&bins);
            for k in [1, 2, 7, 40, 1000] {
                let plan = Plan::with_slices(&bins, k);
                let e = relative_difference(&plan.sums(&bins), &direct);
                assert!(
                    e[0] < 1e-12 && e[1] < 1e-12,
                    "seed {seed}, {k} slices: {e:?}"
                );
            }
        }
    }

    #[test]
    fn bins_that_all_pass_the_whole_band_are_one_slice_of_ffts() {
        // No interval end inside the band: one slice, every bin whole, no pair summed by pairs.
        let c = cumulative(false);
        let mut bins = streak_bins(9, (8, 4), false);
        for b in &mut bins {
            b.n = 1;
            b.ivs[0] = Interval {
                lo: 400.0,
                hi: 700.0,
                c_lo: c(400.0, false),
                c_hi: c(700.0, true),
            };
        }
        let plan = Plan::with_slices(&bins, 5);
        assert_eq!(plan.slices.len(), 1);
        let e = relative_difference(&plan.sums(&bins), &direct_pair_sums(&bins));
        assert!(e[0] < 1e-12 && e[1] < 1e-12, "{e:?}");
    }

    #[test]
    fn bins_spread_over_a_wide_box_are_summed_pair_by_pair() {
        // 20 000 bins at random over 3 000 × 3 000 cells: no shear gathers them, and their
        // correlations would need a 6 000² grid.
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let template = streak_bins(8, (4, 0), false).swap_remove(0);
        let mut bins: Vec<PassedBin> = (0..20_000)
            .map(|_| PassedBin {
                kx: rng.gen_range(0..3000),
                ky: rng.gen_range(0..3000),
                ..template.clone()
            })
            .collect();
        bins.sort_by_key(|b| (b.kx, b.ky));
        bins.dedup_by_key(|b| (b.kx, b.ky));
        assert!(bins.len() > SLICED_FROM_BINS);
        assert!(Plan::new(&bins).is_none());
    }

    #[test]
    fn smooth_sizes_have_no_prime_above_seven() {
        assert_eq!(
            [1, 11, 13, 97, 121, 2733].map(smooth),
            [1, 12, 14, 98, 125, 2744]
        );
    }
}
