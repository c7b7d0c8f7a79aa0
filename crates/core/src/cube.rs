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
                "{what}: {}×{}×{} against {}×{}×{}",
                self.width, self.height, self.planes, other.width, other.height, other.planes
            )));
        }
        Ok(())
    }

    /// Largest value (f32::MIN for an empty cube).
    pub fn max(&self) -> f32 {
        self.data.iter().cloned().fold(f32::MIN, f32::max)
    }

    /// True when every value is finite.
    pub fn all_finite(&self) -> bool {
        self.data.iter().all(|v| v.is_finite())
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
        let mut out = Cube::zeros(self.width, self.height, m.len());
        self.mix_into(m, &mut out)?;
        Ok(out)
    }

    /// [`Cube::mix`] into a cube of the right size that the caller keeps (its values are
    /// overwritten, not added to).
    pub fn mix_into(&self, m: &[Vec<f64>], out: &mut Cube) -> Result<()> {
        if m.iter().any(|row| row.len() != self.planes) {
            return Err(Error::Shape(format!(
                "mixing matrix rows must have {} entries",
                self.planes
            )));
        }
        if (out.width, out.height, out.planes) != (self.width, self.height, m.len()) {
            return Err(Error::Shape(format!(
                "mixing {}×{} into a {}×{}×{} cube; {} planes expected",
                self.width,
                self.height,
                out.width,
                out.height,
                out.planes,
                m.len()
            )));
        }
        use rayon::prelude::*;
        out.data
            .par_chunks_mut(self.pixels().max(1))
            .zip(m.par_iter())
            .for_each(|(dst, row)| {
                let mut terms = row.iter().enumerate().filter(|(_, &w)| w != 0.0);
                // The first term is written, not added: it overwrites what the cube held, and a
                // fresh page read before its first write is mapped twice, the second time with
                // a TLB shootdown of every core (0.0 + w·s keeps the sum's bits).
                match terms.next() {
                    Some((j, &w)) => {
                        let w = w as f32;
                        let src = dst.iter_mut().zip(self.plane(j));
                        src.for_each(|(d, s)| *d = 0.0 + w * s);
                    }
                    None => dst.fill(0.0),
                }
                for (j, &w) in terms {
                    let w = w as f32;
                    let src = dst.iter_mut().zip(self.plane(j));
                    src.for_each(|(d, s)| *d += w * s);
                }
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn mix_into_overwrites_what_the_cube_held() {
        let c = Cube::from_vec(1, 1, 2, vec![1.0, 2.0]).unwrap();
        let mut out = Cube::from_vec(1, 1, 3, vec![f32::NAN; 3]).unwrap();
        c.mix_into(&[vec![1.0, 1.0], vec![0.0, 0.0], vec![0.0, 3.0]], &mut out)
            .unwrap();
        assert_eq!(out.data, vec![3.0, 0.0, 6.0]);
        let mut wrong = Cube::zeros(1, 1, 2);
        assert!(c.mix_into(&vec![vec![1.0, 1.0]; 3], &mut wrong).is_err());
    }
}
