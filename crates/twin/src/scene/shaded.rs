//! A scene of the CAVE kind: smoothly shaded matte spheres, each of one measured reflectance, on a
//! dark background. Lambertian shading under one distant light plus ambient; silhouettes are
//! anti-aliased by the disc coverage of each pixel.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Per pixel: up to two (material, weight) pairs (a sphere edge mixes a sphere and what lies
/// behind); material `None` is the background.
pub struct Shading {
    pub width: usize,
    pub height: usize,
    /// (front material, front weight, back material, back weight) per pixel; weights include shading.
    pub layers: Vec<(Option<u32>, f32, Option<u32>, f32)>,
}

/// Draw 6–9 spheres of random size and material; the light comes from the upper left.
pub fn spheres(width: usize, height: usize, materials: usize, seed: u64) -> Shading {
    spheres_at(width, height, materials, seed, [0.0, 0.0])
}

/// The same spheres moved by `shift` pixels (the background stays): a moving scene.
pub fn spheres_at(
    width: usize,
    height: usize,
    materials: usize,
    seed: u64,
    shift: [f64; 2],
) -> Shading {
    let mut rng = Pcg64::seed_from_u64(seed);
    let s = width.min(height) as f64;
    let n = rng.gen_range(6..=9);
    let mut balls: Vec<(f64, f64, f64, u32)> = (0..n)
        .map(|_| {
            let r = rng.gen_range(0.07..0.2) * s;
            (
                rng.gen_range(r..width as f64 - r),
                rng.gen_range(r..height as f64 - r),
                r,
                rng.gen_range(0..materials) as u32,
            )
        })
        .collect();
    // Larger spheres are nearer the camera (painter's order: far first).
    balls.sort_by(|a, b| a.2.total_cmp(&b.2));
    let l = {
        let v = [-0.45f64, -0.55, 0.70];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        [v[0] / n, v[1] / n, v[2] / n]
    };
    let mut layers = vec![(None, 1.0f32, None, 0.0f32); width * height];
    for &(cx, cy, r, m) in &balls {
        let (cx, cy) = (cx + shift[0], cy + shift[1]);
        let y0 = (cy - r - 1.0).max(0.0) as usize;
        let y1 = (cy + r + 1.0).clamp(0.0, height as f64) as usize;
        let x0 = (cx - r - 1.0).max(0.0) as usize;
        let x1 = (cx + r + 1.0).clamp(0.0, width as f64) as usize;
        for y in y0..y1 {
            for x in x0..x1 {
                let (dx, dy) = ((x as f64 + 0.5 - cx) / r, (y as f64 + 0.5 - cy) / r);
                let d2 = dx * dx + dy * dy;
                // Coverage of the pixel by the disc edge, linear over one pixel.
                let cover = (r * (1.0 - d2.sqrt()) + 0.5).clamp(0.0, 1.0);
                if cover <= 0.0 {
                    continue;
                }
                let nz = (1.0 - d2.min(1.0)).sqrt();
                let shade = 0.12 + 0.88 * (dx * l[0] + dy * l[1] + nz * l[2]).max(0.0);
                let px = &mut layers[y * width + x];
                let (front_m, front_w) = (px.0, px.1);
                *px = (
                    Some(m),
                    (cover * shade) as f32,
                    front_m,
                    front_w * (1.0 - cover) as f32,
                );
            }
        }
    }
    Shading {
        width,
        height,
        layers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_bounded_and_spheres_are_shaded() {
        let s = spheres(96, 80, 10, 1);
        let mut lit = 0;
        for &(m, w, _, w2) in &s.layers {
            assert!((0.0..=1.0).contains(&w) && (0.0..=1.0).contains(&w2));
            if m.is_some() {
                lit += 1;
            }
        }
        assert!(lit > 96 * 80 / 10, "{lit}");
    }

    #[test]
    fn moved_spheres_are_the_same_spheres_shifted() {
        let (a, b) = (
            spheres(64, 64, 10, 3),
            spheres_at(64, 64, 10, 3, [5.0, -2.0]),
        );
        // A pixel of the still scene reappears 5 px right and 2 px up, away from the edges.
        let mut same = 0;
        for y in 10..50 {
            for x in 10..50 {
                let (p, q) = (a.layers[y * 64 + x], b.layers[(y - 2) * 64 + x + 5]);
                same += usize::from(p.0 == q.0 && (p.1 - q.1).abs() < 1e-6);
            }
        }
        assert_eq!(same, 40 * 40);
        // Moved entirely out of the frame: only background.
        let gone = spheres_at(64, 64, 10, 3, [1e4, 0.0]);
        assert!(gone.layers.iter().all(|l| l.0.is_none()));
    }
}
