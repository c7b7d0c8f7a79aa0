//! The layout of the joint iteration's fields: row by row, and within a row each of the k
//! values a pixel holds as a run over the row's pixels, the width padded to whole lanes — so
//! one load takes value c of eight neighbouring pixels (`lane.rs`). The constraint dual (one
//! value a band, 31 or so a pixel) is in groups of eight pixels instead, each group's bands
//! together ([`Rows::band`]): a pass over a row then reads one stream, not one per band. The
//! padding pixels hold zeros, which the iteration keeps (their gradients, divergence and tables
//! are zero).

use super::lane::LANES;
use rayon::prelude::*;

/// The rows of a w × h field, each padded to `wp` pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Rows {
    pub w: usize,
    pub h: usize,
    /// w rounded up to whole lanes.
    pub wp: usize,
}

impl Rows {
    pub fn new(w: usize, h: usize) -> Rows {
        Rows {
            w,
            h,
            wp: w.div_ceil(LANES) * LANES,
        }
    }

    /// Values in one row of a field of k values a pixel.
    pub fn row_len(&self, k: usize) -> usize {
        k * self.wp
    }

    /// Values in a field of k values a pixel.
    pub fn len(&self, k: usize) -> usize {
        self.h * self.row_len(k)
    }

    /// The index of band k of pixel x in a row of a banded field (`nb` bands a pixel): the
    /// row's pixels in groups of `LANES`, a group's bands one after the other, `LANES` values
    /// (one a pixel) a band.
    pub fn band(nb: usize, k: usize, x: usize) -> usize {
        ((x / LANES) * nb + k) * LANES + x % LANES
    }

    /// A banded field (`nb` bands a pixel) → pixel-major, the padding dropped.
    pub fn bands_to_pixel_major(&self, v: &[f32], nb: usize) -> Vec<f32> {
        self.scatter(v, nb, |k, x| Rows::band(nb, k, x))
    }

    /// A field of k values a pixel from `get(c, p)`, value c of pixel p = y·w + x; zeros in
    /// the padding.
    fn gather(&self, k: usize, get: impl Fn(usize, usize) -> f32 + Sync) -> Vec<f32> {
        let (w, wp) = (self.w, self.wp);
        let mut out = vec![0.0f32; self.len(k)];
        out.par_chunks_mut(self.row_len(k).max(1))
            .enumerate()
            .for_each(|(y, row)| {
                for (c, run) in row.chunks_exact_mut(wp).enumerate() {
                    for (x, v) in run[..w].iter_mut().enumerate() {
                        *v = get(c, y * w + x);
                    }
                }
            });
        out
    }

    /// k planes of w·h values (a cube's data) → rows.
    pub fn planes_to_rows(&self, planes: &[f32], k: usize) -> Vec<f32> {
        let n = self.w * self.h;
        self.gather(k, |c, p| planes[c * n + p])
    }

    /// Pixel-major values (k per pixel) → rows.
    pub fn pixel_major_to_rows(&self, v: &[f32], k: usize) -> Vec<f32> {
        self.gather(k, |c, p| v[p * k + c])
    }

    /// Rows → pixel-major (k per pixel), the padding dropped.
    pub fn rows_to_pixel_major(&self, v: &[f32], k: usize) -> Vec<f32> {
        let wp = self.wp;
        self.scatter(v, k, |c, x| c * wp + x)
    }

    /// A field of k values a pixel, value c of pixel x at `at(c, x)` in its row → pixel-major,
    /// the padding dropped.
    fn scatter(&self, v: &[f32], k: usize, at: impl Fn(usize, usize) -> usize + Sync) -> Vec<f32> {
        let mut out = vec![0.0f32; self.w * self.h * k];
        out.par_chunks_mut((self.w * k).max(1))
            .zip(v.par_chunks(self.row_len(k).max(1)))
            .for_each(|(o, row)| {
                for (x, px) in o.chunks_exact_mut(k).enumerate() {
                    for (c, value) in px.iter_mut().enumerate() {
                        *value = row[at(c, x)];
                    }
                }
            });
        out
    }

    /// Rows → k planes of w·h values, the padding dropped.
    pub fn rows_to_planes(&self, v: &[f32], k: usize) -> Vec<f32> {
        let (w, h, wp) = (self.w, self.h, self.wp);
        let mut out = vec![0.0f32; w * h * k];
        out.par_chunks_mut(w.max(1)).enumerate().for_each(|(i, o)| {
            let (c, y) = (i / h.max(1), i % h.max(1));
            o.copy_from_slice(&v[(y * k + c) * wp..][..w]);
        });
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_field_goes_through_rows_and_back() {
        let rows = Rows::new(5, 3);
        assert_eq!(rows.wp, 8);
        let (k, n) = (2, 15);
        let planes: Vec<f32> = (0..k * n).map(|i| i as f32 + 1.0).collect();
        let r = rows.planes_to_rows(&planes, k);
        assert_eq!(r.len(), 3 * 2 * 8);
        // Row 1, value 1, pixel 2: plane 1 at p = 1·5 + 2.
        assert_eq!(r[(2 + 1) * 8 + 2], planes[n + 7]);
        // The padding holds zeros.
        assert!(r.chunks(8).all(|run| run[5..] == [0.0; 3]));
        assert_eq!(rows.rows_to_planes(&r, k), planes);
        let pm = rows.rows_to_pixel_major(&r, k);
        assert_eq!((pm[7 * 2], pm[7 * 2 + 1]), (planes[7], planes[n + 7]));
        assert_eq!(rows.pixel_major_to_rows(&pm, k), r);
    }

    #[test]
    fn bands_go_in_groups_of_eight_pixels() {
        // Band 2 of pixel 9 of a row with 3 bands: group 1 (pixels 8–15), after its bands 0
        // and 1 (8 values each), lane 1.
        assert_eq!(Rows::band(3, 2, 9), 24 + 16 + 1);
        let rows = Rows::new(10, 2);
        let nb = 3;
        let mut v = vec![0.0f32; rows.len(nb)];
        for (y, row) in v.chunks_mut(rows.row_len(nb)).enumerate() {
            for (x, k) in (0..10).flat_map(|x| (0..nb).map(move |k| (x, k))) {
                row[Rows::band(nb, k, x)] = (100 * y + 10 * x + k) as f32;
            }
        }
        let pm = rows.bands_to_pixel_major(&v, nb);
        assert_eq!(pm[(10 + 9) * nb + 2], 192.0);
        assert!(pm.iter().enumerate().all(|(i, &x)| {
            let (p, k) = (i / nb, i % nb);
            x == (100 * (p / 10) + 10 * (p % 10) + k) as f32
        }));
    }
}
