//! The binary pictures the controller uploads to the DMD, made from the design alone: each
//! carrier's sinusoid s_k = 1 + cos(2π ω_k·p + φ_k), halved into [0, 1] and error-diffused
//! (Floyd–Steinberg) into one bit plane, since the rig's 1 kHz wheel leaves a sixth of a turn
//! per pattern — far too short for grey levels, which a DMD shows as bit-plane sequences. A
//! picture covers all the DMD's mirrors, the sinusoid laid out as the camera sees them through the
//! lens. The calibration also needs an all-dark and an all-bright picture.

use crate::devices::BitPlane;
use crate::error::Result;
use serde::Serialize;
use specmux_core::Carrier;
use specmux_twin::optics::dmd::DmdConfig;
use specmux_twin::optics::imaging::mirror_target;
use specmux_twin::optics::psf::LensConfig;
use specmux_twin::Experiment;

/// How the camera sees the DMD: its mirrors (the device's count, the experiment's pitch) and the
/// lens between them (none: one pixel per mirror, upright). A DMD takes whole pictures, so each
/// picture covers every mirror, its pattern laid out as the camera's pixels see it.
#[derive(Clone, Debug, Serialize)]
pub struct PictureOptics {
    pub dmd: DmdConfig,
    pub lens: Option<LensConfig>,
}

impl PictureOptics {
    /// The experiment's lens and DMD pitch, on a DMD of `width × height` mirrors.
    pub fn of(exp: &Experiment, width: usize, height: usize) -> PictureOptics {
        PictureOptics {
            dmd: DmdConfig {
                width,
                height,
                ..exp.rig.dmd.clone().unwrap_or_default()
            },
            lens: exp.rig.lens.clone(),
        }
    }

    /// Camera pixels per mirror (1 without a lens).
    pub fn pixels_per_mirror(&self) -> f64 {
        self.lens
            .as_ref()
            .map_or(1.0, |l| l.sensor_pixels_per_mirror(self.dmd.pitch_um))
    }
}

/// One bit plane per carrier, in carrier (= wheel segment) order: the DMD's whole picture for a
/// `width × height` camera looking through `optics`.
pub fn carrier_pictures(
    carriers: &[Carrier],
    optics: &PictureOptics,
    width: usize,
    height: usize,
) -> Result<Vec<BitPlane>> {
    let (wd, hd) = (optics.dmd.width, optics.dmd.height);
    carriers
        .iter()
        .map(|c| {
            let target = mirror_target(optics.lens.as_ref(), &optics.dmd, c, width, height)?;
            Ok(dither(&target, wd, hd))
        })
        .collect()
}

/// Floyd–Steinberg error diffusion of a grey target in [0, 1] (threshold at ½, weights 7/16,
/// 3/16, 5/16, 1/16), row by row left to right.
fn dither(target: &[f32], width: usize, height: usize) -> BitPlane {
    let mut v = target.to_vec();
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

    /// A DMD of `w × h` mirrors of the default pitch behind `lens`.
    fn optics(w: usize, h: usize, lens: Option<LensConfig>) -> PictureOptics {
        let dmd = DmdConfig {
            width: w,
            height: h,
            ..DmdConfig::default()
        };
        PictureOptics { dmd, lens }
    }

    #[test]
    fn dithered_pictures_keep_the_mean_and_differ_per_carrier() {
        let carriers = specmux_core::carriers::default_layout();
        let pics = carrier_pictures(&carriers, &optics(64, 64, None), 64, 64).unwrap();
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

    /// By hand: without a lens a 64 × 64 camera sees the middle of an 80 × 72 DMD, mirror (u, v)
    /// on pixel (u − 8, v − 4), so the picture's target there is the camera's sinusoid; through
    /// an inverting lens of 2 pixels per mirror, mirror (u, v) lies on pixel
    /// (31.5 − 2(u − 39.5), 31.5 − 2(v − 35.5)). A DMD smaller than the camera's field is refused.
    #[test]
    fn a_picture_covers_the_dmd_as_the_camera_sees_it() {
        let c = Carrier {
            fx: 0.25,
            fy: -0.125,
            phase_rad: 0.7,
        };
        let half = |x: f64, y: f64| {
            0.5 + 0.5 * (std::f64::consts::TAU * (c.fx * x + c.fy * y) + c.phase_rad).cos()
        };
        let upright = optics(80, 72, None);
        let t = mirror_target(None, &upright.dmd, &c, 64, 64).unwrap();
        let two = LensConfig {
            magnification: -1.0,
            camera_magnification: 2.0 * 5.0 / upright.dmd.pitch_um,
            sensor_pitch_um: 5.0,
            ..LensConfig::default()
        };
        let inverted = optics(80, 72, Some(two));
        assert!((inverted.pixels_per_mirror() - 2.0).abs() < 1e-12);
        let ti = mirror_target(inverted.lens.as_ref(), &inverted.dmd, &c, 64, 64).unwrap();
        for (u, v) in [(0, 0), (8, 4), (40, 30), (79, 71)] {
            let p = v * 80 + u;
            let upright_px = half(u as f64 - 8.0, v as f64 - 4.0);
            assert!((t[p] as f64 - upright_px).abs() < 1e-6, "({u}, {v})");
            let (x, y) = (
                31.5 - 2.0 * (u as f64 - 39.5),
                31.5 - 2.0 * (v as f64 - 35.5),
            );
            assert!((ti[p] as f64 - half(x, y)).abs() < 1e-6, "({u}, {v})");
        }
        let pics = carrier_pictures(&[c], &inverted, 64, 64).unwrap();
        assert_eq!((pics[0].width, pics[0].height), (80, 72));
        let small = carrier_pictures(&[c], &optics(60, 64, None), 64, 64).unwrap_err();
        assert!(small.to_string().contains("rig.dmd.width"), "{small}");
    }

    #[test]
    fn uniform_pictures() {
        let dark = BitPlane::uniform(5, 3, false);
        let bright = BitPlane::uniform(5, 3, true);
        assert!((0..15).all(|i| !dark.get(i) && bright.get(i)));
        assert_eq!(bright.bits.len(), 2);
    }
}
