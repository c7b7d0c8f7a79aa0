//! The dead-leaves model (Matheron; Lee, Mumford & Huang 2001): opaque discs with radii drawn from
//! a density ∝ r⁻³ between r_min and r_max, dropped until the plane is covered. Its images are
//! scale invariant with a power spectrum close to 1/f², the standard synthetic stand-in for natural
//! images; in the twin's scene each leaf carries one measured reflectance spectrum. The label
//! map lives in core so that core's own tests (GAP's) draw the very scene the twin does.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Leaf label per pixel (index into the material list), `width × height`, row-major.
pub fn labels(width: usize, height: usize, materials: usize, seed: u64) -> Vec<u32> {
    const UNSET: u32 = u32::MAX;
    let mut rng = Pcg64::seed_from_u64(seed);
    let scale = width.max(height) as f64;
    let (r_min, r_max) = (scale / 256.0, scale / 5.0);
    let (a, b) = (r_min.powi(-2), r_max.powi(-2));
    let mut out = vec![UNSET; width * height];
    let mut uncovered = width * height;
    // Front to back: each new disc fills only pixels no earlier (nearer) disc covers.
    let max_discs = 200 * width * height / (r_min * r_min).max(1.0) as usize + 1000;
    for _ in 0..max_discs {
        if uncovered == 0 {
            break;
        }
        // Inverse CDF of p(r) ∝ r⁻³ on [r_min, r_max].
        let u: f64 = rng.gen();
        let r = (a - u * (a - b)).powf(-0.5);
        let cx = rng.gen_range(-r..width as f64 + r);
        let cy = rng.gen_range(-r..height as f64 + r);
        let m = rng.gen_range(0..materials) as u32;
        let y0 = (cy - r).floor().max(0.0) as usize;
        let y1 = ((cy + r).ceil() as usize).min(height);
        let x0 = (cx - r).floor().max(0.0) as usize;
        let x1 = ((cx + r).ceil() as usize).min(width);
        for y in y0..y1 {
            let dy = y as f64 + 0.5 - cy;
            for x in x0..x1 {
                let dx = x as f64 + 0.5 - cx;
                let px = &mut out[y * width + x];
                if *px == UNSET && dx * dx + dy * dy <= r * r {
                    *px = m;
                    uncovered -= 1;
                }
            }
        }
    }
    // Pixels still uncovered after the cap (vanishingly rare) see the deepest leaf: material 0.
    for px in out.iter_mut().filter(|p| **p == UNSET) {
        *px = 0;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covers_the_plane_with_many_leaves_and_is_reproducible() {
        let l = labels(128, 96, 50, 3);
        assert_eq!(l, labels(128, 96, 50, 3));
        let distinct: std::collections::HashSet<u32> = l.iter().cloned().collect();
        assert!(distinct.len() > 20, "{}", distinct.len());
        assert!(l.iter().all(|&m| m < 50));
    }
}
