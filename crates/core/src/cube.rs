//! The one array type of the crate: `planes` images of `width × height` f32 pixels, row-major,
//! one contiguous plane per channel. A frame is a cube with one plane.

use crate::error::Error;
use crate::error::Result;

#[derive(Clone, Debug, PartialEq)]
pub struct Cube {
    pub width: usize,
    pub height: usize,
    pub planes: usize,
    pub data: Vec<f32>,
}

/// The largest |v| over `x`, None when some value is not finite: running maxima and sums of
/// v − v (0 for finite values, NaN otherwise) in eight lanes, which the compiler vectorises.
#[allow(clippy::eq_op)]
fn largest_magnitude(x: &[f32]) -> Option<f32> {
    let (mut top, mut nan) = ([0.0f32; 8], [0.0f32; 8]);
    let chunks = x.chunks_exact(8);
    let rest = chunks.remainder();
    for ch in chunks {
        for ((t, s), &v) in top.iter_mut().zip(&mut nan).zip(ch) {
            *t = t.max(v.abs());
            *s += v - v;
        }
    }
    let finite = nan.iter().all(|&s| s == 0.0) && rest.iter().all(|v| v.is_finite());
    let m = rest.iter().chain(&top).fold(0.0f32, |m, v| m.max(v.abs()));
    finite.then_some(m)
}

/// True when every value of `x` is finite ([`largest_magnitude`]'s vectorised pass).
pub(crate) fn all_finite(x: &[f32]) -> bool {
    largest_magnitude(x).is_some()
}

/// `v` as written when it is a plain size, in exponent form when it is large or small.
fn plain_or_exponent(v: f32) -> String {
    match v.abs() {
        a if a >= 1e6 || (a > 0.0 && a < 1e-4) => format!("{v:e}"),
        _ => format!("{v}"),
    }
}

/// Largest |value| × pixels of a frame (a plane): its Fourier transform sums the pixels, and
/// f32 ends at 3.4·10³⁸, so this leaves a margin of 340 for the windows' and patterns' gains.
/// Measured: every method runs to a finite cube up to 5·10³² at 64² and 5·10³⁰ at 256², and
/// fails at 5·10³⁶ and 5·10³⁴ (docs/stability.md).
pub const FRAME_SUM_MAX: f32 = 1e36;
/// Smallest largest |value| of a frame that is not all zero: GAP-TV's products leave f32's
/// normal range (1.2·10⁻³⁸) at 5·10⁻³⁸; every method runs at 5·10⁻³⁶ (docs/stability.md).
pub const FRAME_MIN: f32 = 1e-30;

impl Cube {
    /// A cube of zeros.
    pub fn zeros(width: usize, height: usize, planes: usize) -> Cube {
        Cube {
            width,
            height,
            planes,
            data: vec![0.0; width * height * planes],
        }
    }

    /// A cube of zeros on memory advised onto huge pages ([`crate::pages`]), for a large output
    /// written whole at once (the unmixed cube of a frame).
    pub fn zeros_on_huge_pages(width: usize, height: usize, planes: usize) -> Cube {
        Cube {
            width,
            height,
            planes,
            data: crate::pages::zeroed(width * height * planes),
        }
    }

    /// A cube from its data, checked for size.
    pub fn from_vec(width: usize, height: usize, planes: usize, data: Vec<f32>) -> Result<Cube> {
        if data.len() != width * height * planes {
            return Err(Error::Shape(format!(
                "{} values for {width}×{height}×{planes}",
                data.len()
            )));
        }
        Ok(Cube {
            width,
            height,
            planes,
            data,
        })
    }

    /// Pixels per plane.
    pub fn pixels(&self) -> usize {
        self.width * self.height
    }

    /// The size for a message, its axes named, since numpy users read (planes, height, width):
    /// "256 wide × 128 high × 31 planes".
    pub fn size_text(&self) -> String {
        format!(
            "{} wide × {} high × {} planes",
            self.width, self.height, self.planes
        )
    }

    pub fn plane(&self, k: usize) -> &[f32] {
        let n = self.pixels();
        &self.data[k * n..(k + 1) * n]
    }

    pub fn plane_mut(&mut self, k: usize) -> &mut [f32] {
        let n = self.pixels();
        &mut self.data[k * n..(k + 1) * n]
    }

    /// Mutable views of all planes at once (for filling planes in parallel).
    pub fn planes_mut(&mut self) -> std::slice::ChunksExactMut<'_, f32> {
        let n = self.pixels();
        self.data.chunks_exact_mut(n.max(1))
    }

    /// A one-plane cube holding plane `k`.
    pub fn extract(&self, k: usize) -> Cube {
        Cube {
            width: self.width,
            height: self.height,
            planes: 1,
            data: self.plane(k).to_vec(),
        }
    }

    /// The spectrum (one value per plane) at pixel `(x, y)`.
    pub fn spectrum(&self, x: usize, y: usize) -> Vec<f32> {
        let p = y * self.width + x;
        (0..self.planes).map(|k| self.plane(k)[p]).collect()
    }

    /// Same width, height and plane count.
    pub fn check_same_shape(&self, other: &Cube, what: &str) -> Result<()> {
        if (self.width, self.height, self.planes) != (other.width, other.height, other.planes) {
            return Err(Error::Shape(format!(
                "{what}: {} against {}",
                self.size_text(),
                other.size_text()
            )));
        }
        Ok(())
    }

    /// Largest value (f32::MIN for an empty cube).
    pub fn max(&self) -> f32 {
        self.data.iter().cloned().fold(f32::MIN, f32::max)
    }

    /// (plane, x, y) of the value at index `i` of `data`.
    pub fn place(&self, i: usize) -> (usize, usize, usize) {
        let n = (self.width * self.height).max(1);
        (i / n, i % self.width.max(1), (i % n) / self.width.max(1))
    }

    /// True when every value is finite.
    pub fn all_finite(&self) -> bool {
        all_finite(&self.data)
    }

    /// Why this cube cannot be a frame (or a calibration frame) that the reconstruction takes
    /// in: a value that is not finite, or beyond ±[`FRAME_SUM_MAX`] / (width·height), or, not
    /// all zero, a largest |value| under [`FRAME_MIN`]; "`what`: pixel (x, y) …" ("`what`[k]:
    /// pixel …" when it has planes; without `what`: and the colon when it is empty). One pass
    /// over the values when there is none.
    pub fn frame_problem(&self, what: &str) -> Option<String> {
        let n = (self.width * self.height).max(1);
        let limit = FRAME_SUM_MAX / n as f32;
        let largest = largest_magnitude(&self.data);
        if largest.is_some_and(|m| m <= limit && (m == 0.0 || m >= FRAME_MIN)) {
            return None;
        }
        let named = |plane: Option<usize>| match (what, plane) {
            ("", None) => String::new(),
            (_, None) => format!("{what}: "),
            (_, Some(k)) => format!("{what}[{k}]: "),
        };
        let at = |p: usize| {
            let (k, x, y) = self.place(p);
            let name = named((self.planes > 1).then_some(k));
            format!(
                "{name}pixel ({x}, {y}) is {}",
                plain_or_exponent(self.data[p])
            )
        };
        let scale = "scale the frame, the cube scales with it";
        if let Some(p) = self.data.iter().position(|v| !v.is_finite()) {
            return Some(format!("{}: a frame must be finite", at(p)));
        }
        if let Some(p) = self.data.iter().position(|v| v.abs() > limit) {
            let (w, h) = (self.width, self.height);
            return Some(format!("{}: a {w}×{h} frame's values must lie within ±{limit:.1e} (its Fourier transform sums them, and f32 ends at 3.4e38); {scale}", at(p)));
        }
        let m = largest.unwrap_or(0.0);
        Some(format!("{}its largest |value| is {m:e}, under {FRAME_MIN:e} (the reconstruction's f32 products would leave the normal range); {scale}", named(None)))
    }

    /// Plane k multiplied by `k_per_plane[k]`.
    pub fn scaled_planes(&self, k_per_plane: &[f64]) -> Result<Cube> {
        if k_per_plane.len() != self.planes {
            return Err(Error::Shape(format!(
                "{} scale factors for {} planes",
                k_per_plane.len(),
                self.planes
            )));
        }
        let mut out = self.clone();
        for (plane, &k) in out.planes_mut().zip(k_per_plane) {
            plane.iter_mut().for_each(|v| *v = (*v as f64 * k) as f32);
        }
        Ok(out)
    }

    /// Linear map across planes: out_k = Σ_j m[k][j] · in_j, pixel by pixel (m is planes_out × planes_in).
    pub fn mix(&self, m: &[Vec<f64>]) -> Result<Cube> {
        if m.iter().any(|row| row.len() != self.planes) {
            return Err(Error::Shape(format!(
                "mixing matrix rows must have {} entries",
                self.planes
            )));
        }
        let mut out = Cube::zeros(self.width, self.height, m.len());
        use rayon::prelude::*;
        let n = self.pixels();
        out.data
            .par_chunks_mut(n.max(1))
            .zip(m.par_iter())
            .for_each(|(dst, row)| mix_row(row, &self.data, n, dst));
        Ok(out)
    }

    /// [`Cube::mix`] with a square m, in place: each pixel block's planes are copied aside
    /// and mixed back, so a camera loop needs no second cube (the same bits as `mix`).
    pub fn mix_in_place(&mut self, m: &[Vec<f64>]) -> Result<()> {
        if m.len() != self.planes || m.iter().any(|row| row.len() != self.planes) {
            return Err(Error::Shape(format!(
                "mixing a {}-plane cube in place needs a {0} × {0} matrix",
                self.planes
            )));
        }
        use rayon::prelude::*;
        let (n, p) = (self.pixels(), self.planes);
        let mut ranges: Vec<Vec<&mut [f32]>> = (0..n.div_ceil(MIX_RANGE))
            .map(|_| Vec::with_capacity(p))
            .collect();
        for plane in self.data.chunks_exact_mut(n.max(1)) {
            for (range, part) in ranges.iter_mut().zip(plane.chunks_mut(MIX_RANGE)) {
                range.push(part);
            }
        }
        ranges.into_par_iter().for_each(|mut planes| {
            let mut aside = vec![0.0f32; p * MIX_BLOCK];
            let len = planes.first().map_or(0, |s| s.len());
            for at in (0..len).step_by(MIX_BLOCK) {
                let b = MIX_BLOCK.min(len - at);
                for (copy, plane) in aside.chunks_exact_mut(MIX_BLOCK).zip(&planes) {
                    copy[..b].copy_from_slice(&plane[at..at + b]);
                }
                for (plane, row) in planes.iter_mut().zip(m) {
                    mix_row(row, &aside, MIX_BLOCK, &mut plane[at..at + b]);
                }
            }
        });
        Ok(())
    }
}

/// Pixels of each plane that one task of [`Cube::mix_in_place`] mixes.
const MIX_RANGE: usize = 16384;
/// Pixels of each plane that the task copies aside at a time (6 planes: 6 kB, in L1).
const MIX_BLOCK: usize = 256;

/// dst = Σ_j row_j · src_j in f32, the terms in order, source plane j starting at j · `stride`
/// of `src` (a cube's planes, or a block of them copied aside). The first non-zero term is
/// written, not added: it overwrites what dst held, and a fresh page read before its first write
/// is mapped twice, the second time with a TLB shootdown of every core (0.0 + w·s keeps the
/// sum's bits).
fn mix_row(row: &[f64], src: &[f32], stride: usize, dst: &mut [f32]) {
    let len = dst.len();
    let plane = |j: usize| &src[j * stride..j * stride + len];
    let mut terms = row.iter().enumerate().filter(|(_, &w)| w != 0.0);
    match terms.next() {
        Some((j, &w)) => {
            let (w, s) = (w as f32, plane(j));
            dst.iter_mut().zip(s).for_each(|(d, s)| *d = 0.0 + w * s);
        }
        None => dst.fill(0.0),
    }
    for (j, &w) in terms {
        let (w, s) = (w as f32, plane(j));
        dst.iter_mut().zip(s).for_each(|(d, s)| *d += w * s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_must_be_finite_and_within_the_range_its_transform_holds() {
        let frame = |w: usize, v: &[f32]| Cube::from_vec(w, w, v.len() / (w * w), v.to_vec());
        let why = |w: usize, v: &[f32]| frame(w, v).unwrap().frame_problem("");
        // 2 × 2: values up to 1e36 / 4.
        assert_eq!(why(2, &[0.0; 4]), None);
        assert_eq!(why(2, &[2.5e35, -2.5e35, 1e-30, 0.0]), None);
        let refused = |w: usize, v: &[f32]| why(w, v).unwrap();
        assert_eq!(
            refused(2, &[1.0, 2.0, 3.0, f32::NAN]),
            "pixel (1, 1) is NaN: a frame must be finite"
        );
        assert!(refused(2, &[1.0, -3e35, 0.0, 0.0])
            .starts_with("pixel (1, 0) is -3e35: a 2×2 frame's values must lie within ±2.5e35"));
        assert!(
            refused(2, &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0])
                .starts_with("[1]: pixel (0, 1) is inf: a frame must be finite")
        );
        assert!(refused(2, &[0.0, 9e-31, 0.0, -1e-35])
            .starts_with("its largest |value| is 9e-31, under 1e-30"));
        // A name leads the message: "name: pixel …", "name[k]: pixel …", "name: its largest …".
        let named = |v: &[f32]| frame(2, v).unwrap().frame_problem("flat").unwrap();
        assert!(named(&[1.0, 2.0, 3.0, f32::NAN]).starts_with("flat: pixel (1, 1) is NaN"));
        assert!(named(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f32::INFINITY, 0.0])
            .starts_with("flat[1]: pixel (0, 1) is inf"));
        assert!(named(&[0.0, 9e-31, 0.0, 0.0]).starts_with("flat: its largest |value| is 9e-31"));
        // The ninth value lies past the eight lanes: still seen.
        let mut nine = [1.0f32; 9];
        nine[8] = f32::NAN;
        assert!(refused(3, &nine).starts_with("pixel (2, 2) is NaN"));
        nine[8] = 2e35;
        assert!(refused(3, &nine).starts_with("pixel (2, 2) is 2e35: a 3×3 frame's values"));
    }

    #[test]
    fn planes_are_contiguous() {
        let mut c = Cube::zeros(3, 2, 2);
        c.plane_mut(1)[4] = 5.0;
        assert_eq!(c.data[6 + 4], 5.0);
        assert_eq!(c.spectrum(1, 1), vec![0.0, 5.0]);
    }

    #[test]
    fn mix_is_matrix_product() {
        let c = Cube::from_vec(1, 1, 2, vec![1.0, 2.0]).unwrap();
        let m = c
            .mix(&[vec![1.0, 1.0], vec![2.0, -1.0], vec![0.0, 3.0]])
            .unwrap();
        assert_eq!(m.data, vec![3.0, 0.0, 6.0]);
    }

    #[test]
    fn mixing_in_place_gives_the_bits_of_a_new_cube() {
        // Planes longer than a task's range, so ranges and blocks end mid-plane.
        let (w, h) = (150, 131);
        let data = (0..w * h * 3).map(|i| ((i * 7919) % 1013) as f32 / 97.0 - 5.0);
        let mut c = Cube::from_vec(w, h, 3, data.collect()).unwrap();
        let m = [
            vec![1.3, 0.0, -0.7],
            vec![0.0, 0.0, 0.0],
            vec![0.1, 2.9, 1e-3],
        ];
        let new = c.mix(&m).unwrap();
        c.mix_in_place(&m).unwrap();
        assert_eq!(new.data.len(), c.data.len());
        assert!(new
            .data
            .iter()
            .zip(&c.data)
            .all(|(a, b)| a.to_bits() == b.to_bits()));
        let err = c.mix_in_place(&[vec![1.0; 3], vec![1.0; 3]]).unwrap_err();
        assert!(err.to_string().contains("3 × 3"), "{err}");
    }
}
