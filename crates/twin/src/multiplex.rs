//! The monochrome camera sums the modulated images: y = Σ_k z_k ⊙ s̃_k. Used by the forward
//! model for the scene's frame and by the calibration captures for the white target's.

use rayon::prelude::*;
use specmux_core::{Cube, Result};

/// y = Σ_k z_k ⊙ s̃_k, in parallel over pixel chunks.
pub fn multiplex(z: &Cube, s: &Cube) -> Result<Cube> {
    z.check_same_shape(s, "channels against patterns")?;
    let mut y = Cube::zeros(z.width, z.height, 1);
    y.data
        .par_chunks_mut(4096)
        .enumerate()
        .for_each(|(c, out)| {
            let off = c * 4096;
            for k in 0..z.planes {
                let (zs, ss) = (
                    &z.plane(k)[off..off + out.len()],
                    &s.plane(k)[off..off + out.len()],
                );
                for ((o, a), b) in out.iter_mut().zip(zs).zip(ss) {
                    *o += a * b;
                }
            }
        });
    Ok(y)
}
