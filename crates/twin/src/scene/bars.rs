//! A bar chart: the plane cut into columns and rows of random widths by straight lines that run
//! the whole width or height, each cell one measured reflectance. Its edges are long and exactly
//! along both axes, so their energy lies on the fx and fy axes of the Fourier plane — the case
//! the paper's strip test objects put into the carriers nearest DC.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Cut `n` pixels into runs of 4–16 % of `n` (the last run takes the rest): run index per pixel.
fn runs(n: usize, rng: &mut Pcg64) -> Vec<u32> {
    let (lo, hi) = ((n / 25).max(1), (n * 4 / 25).max(2));
    let mut out = Vec::with_capacity(n);
    let mut run = 0u32;
    while out.len() < n {
        let len = rng.gen_range(lo..hi).min(n - out.len());
        out.extend(std::iter::repeat(run).take(len));
        run += 1;
    }
    out
}

/// Material label per pixel (`width × height`, row-major): cell (column run, row run) takes a
/// material drawn once for it, so every column and row boundary is a straight line across the
/// whole frame (where the two materials beside it differ).
pub fn labels(width: usize, height: usize, materials: usize, seed: u64) -> Vec<u32> {
    let mut rng = Pcg64::seed_from_u64(seed);
    let cols = runs(width, &mut rng);
    let rows = runs(height, &mut rng);
    let ncols = cols.last().map_or(0, |c| *c as usize + 1);
    let nrows = rows.last().map_or(0, |r| *r as usize + 1);
    let cell: Vec<u32> = (0..ncols * nrows)
        .map(|_| rng.gen_range(0..materials) as u32)
        .collect();
    let mut out = Vec::with_capacity(width * height);
    for &r in &rows {
        out.extend(cols.iter().map(|&c| cell[r as usize * ncols + c as usize]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_edge_is_a_straight_line_across_the_whole_frame_along_both_axes() {
        // With a million materials two neighbouring cells practically never share one, so a
        // boundary between column runs changes the label on every row, and inside a run on none.
        let (w, h) = (200, 120);
        let l = labels(w, h, 1_000_000, 5);
        assert_eq!(l, labels(w, h, 1_000_000, 5));
        let differs = |a: usize, b: usize| l[a] != l[b];
        let mut edges = [0, 0];
        for x in 1..w {
            let n = (0..h)
                .filter(|&y| differs(y * w + x, y * w + x - 1))
                .count();
            assert!(n == 0 || n == h, "column {x}: {n} of {h} rows change");
            edges[0] += (n == h) as usize;
        }
        for y in 1..h {
            let n = (0..w)
                .filter(|&x| differs(y * w + x, (y - 1) * w + x))
                .count();
            assert!(n == 0 || n == w, "row {y}: {n} of {w} columns change");
            edges[1] += (n == w) as usize;
        }
        // Runs are 4–16 % of the side: at least 6 of them, so at least 5 edges per axis.
        assert!(edges[0] >= 5 && edges[1] >= 5, "{edges:?}");
    }
}
