//! The binary pictures the controller uploads to the DMD, made from the design alone: each
//! carrier's sinusoid s_k = 1 + cos(2π ω_k·p + φ_k), halved into [0, 1] and error-diffused
//! (Floyd–Steinberg) into one bit plane, since the rig's 1 kHz wheel leaves a sixth of a turn
//! per pattern — far too short for grey levels, which a DMD shows as bit-plane sequences. The
//! calibration also needs an all-dark and an all-bright picture.

use crate::devices::BitPlane;
use specmux_core::Carrier;

/// One bit plane per carrier, in carrier (= wheel segment) order.
pub fn carrier_pictures(carriers: &[Carrier], width: usize, height: usize) -> Vec<BitPlane> {
    carriers
        .iter()
        .map(|c| dither(&c.ideal_pattern(width, height), width, height))
        .collect()
}

/// Floyd–Steinberg error diffusion of a pattern in [0, 2] (threshold at 1, weights 7/16, 3/16,
/// 5/16, 1/16), row by row left to right.
fn dither(pattern: &[f32], width: usize, height: usize) -> BitPlane {
    let mut v: Vec<f32> = pattern.iter().map(|s| 0.5 * s).collect();
    let mut out = BitPlane::uniform(width, height, false);
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let on = v[i] >= 0.5;
            if on {
                out.set(i);
            }
            let err = v[i] - if on { 1.0 } else { 0.0 };
            let mut spread = |dx: isize, dy: usize, w: f32| {
                let xx = x as isize + dx;
                if xx >= 0 && (xx as usize) < width && y + dy < height {
                    v[(y + dy) * width + xx as usize] += err * w;
                }
            };
            spread(1, 0, 7.0 / 16.0);
            spread(-1, 1, 3.0 / 16.0);
            spread(0, 1, 5.0 / 16.0);
            spread(1, 1, 1.0 / 16.0);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dithered_pictures_keep_the_mean_and_differ_per_carrier() {
        let carriers = specmux_core::carriers::default_layout();
        let pics = carrier_pictures(&carriers, 64, 64);
        assert_eq!(pics.len(), 6);
        for p in &pics {
            let on = (0..64 * 64).filter(|&i| p.get(i)).count() as f64 / 4096.0;
            // The sinusoid's mean is ½: error diffusion keeps it to a fraction of a percent.
            assert!((on - 0.5).abs() < 0.01, "{on}");
        }
        for a in 0..6 {
            for b in a + 1..6 {
                assert_ne!(pics[a], pics[b], "{a} {b}");
            }
        }
    }

    #[test]
    fn uniform_pictures() {
        let dark = BitPlane::uniform(5, 3, false);
        let bright = BitPlane::uniform(5, 3, true);
        assert!((0..15).all(|i| !dark.get(i) && bright.get(i)));
        assert_eq!(bright.bits.len(), 2);
    }
}
