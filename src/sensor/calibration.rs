//! Dark and flat-field correction of raw frames, as on the real rig: the dark frame removes the
//! black offset, dark current and DSNU, the flat removes PRNU (and any vignetting), and the
//! result keeps the flat's mean response so that it stays in DN above dark.

use crate::error::{Error, Result};
use crate::scene::Cube;

/// (raw − dark) / (flat − dark) × mean(flat − dark), plane by plane. Refuses a flat that is not
/// brighter than the dark frame at some pixel instead of dividing by zero or by a negative.
pub fn calibrate(raw: &Cube, dark: &Cube, flat: &Cube) -> Result<Cube> {
    raw.check_same_shape(dark, "calibrate: raw frame against dark frame")?;
    raw.check_same_shape(flat, "calibrate: raw frame against flat frame")?;
    for (what, c) in [("raw", raw), ("dark", dark), ("flat", flat)] {
        if let Some(i) = c.data.iter().position(|v| !v.is_finite()) {
            return Err(Error::Numerical(format!(
                "calibrate: {what} frame holds {} at index {i}",
                c.data[i]
            )));
        }
    }
    let n = raw.pixels();
    let mut out = Cube::zeros(raw.width, raw.height, raw.planes);
    for k in 0..raw.planes {
        let (r, d, f) = (raw.plane(k), dark.plane(k), flat.plane(k));
        if let Some(i) = (0..n).find(|&i| f[i] <= d[i]) {
            return Err(Error::Numerical(format!(
                "calibrate: flat − dark = {} DN at pixel ({}, {}) of plane {k}; the flat must be \
                 brighter than the dark frame at every pixel (take the flat with more light)",
                f[i] - d[i],
                i % raw.width,
                i / raw.width
            )));
        }
        let mean_response = f
            .iter()
            .zip(d)
            .map(|(&f, &d)| f as f64 - d as f64)
            .sum::<f64>()
            / n as f64;
        for (i, o) in out.plane_mut(k).iter_mut().enumerate() {
            let response = f[i] as f64 - d[i] as f64;
            *o = ((r[i] as f64 - d[i] as f64) / response * mean_response) as f32;
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_case() {
        // Two pixels: dark 10 and 12 DN, flat response 100 and 50 DN above dark (gain 2:1).
        let dark = Cube::from_vec(2, 1, 1, vec![10.0, 12.0]).unwrap();
        let flat = Cube::from_vec(2, 1, 1, vec![110.0, 62.0]).unwrap();
        let raw = Cube::from_vec(2, 1, 1, vec![60.0, 37.0]).unwrap();
        let out = calibrate(&raw, &dark, &flat).unwrap();
        // (60−10)/100·75 = 37.5 and (37−12)/50·75 = 37.5.
        assert_eq!(out.data, vec![37.5, 37.5]);
        // The flat itself becomes its mean response everywhere.
        let flat_out = calibrate(&flat, &dark, &flat).unwrap();
        assert_eq!(flat_out.data, vec![75.0, 75.0]);
    }

    #[test]
    fn is_linear_in_the_raw_signal_above_dark() {
        let dark = Cube::from_vec(3, 1, 1, vec![5.0, 6.0, 7.0]).unwrap();
        let flat = Cube::from_vec(3, 1, 1, vec![105.0, 86.0, 207.0]).unwrap();
        let a = Cube::from_vec(3, 1, 1, vec![15.0, 26.0, 47.0]).unwrap();
        let mut b = a.clone();
        for (v, d) in b.data.iter_mut().zip(&dark.data) {
            *v = 3.0 * (*v - d) + d;
        }
        let (ca, cb) = (
            calibrate(&a, &dark, &flat).unwrap(),
            calibrate(&b, &dark, &flat).unwrap(),
        );
        for (x, y) in ca.data.iter().zip(&cb.data) {
            assert!((3.0 * x - y).abs() < 1e-4 * y.abs(), "{x} {y}");
        }
    }

    #[test]
    fn refuses_a_dark_flat_pixel() {
        let dark = Cube::from_vec(2, 2, 1, vec![10.0; 4]).unwrap();
        let flat = Cube::from_vec(2, 2, 1, vec![50.0, 50.0, 10.0, 50.0]).unwrap();
        let raw = flat.clone();
        let msg = calibrate(&raw, &dark, &flat).unwrap_err().to_string();
        assert!(msg.contains("pixel (0, 1)"), "{msg}");
        let bad_shape = Cube::zeros(2, 1, 1);
        assert!(calibrate(&bad_shape, &dark, &flat).is_err());
    }
}
