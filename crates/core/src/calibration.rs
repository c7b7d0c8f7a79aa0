//! Calibration from captured frames, as on the real rig: dark and flat frames correct the
//! raw frames (dark removes black offset, dark current and DSNU; flat removes PRNU and
//! vignetting), and a capture of each pattern on a uniform white target gives the carrier's
//! frequency, phase and complex amplitude and the pattern as imaged (for GAP). Nothing here
//! knows how the frames were made: the twin simulates the same captures (twin::captures).

use crate::carriers::Carrier;
use crate::error::Error;
use crate::error::Result;
use crate::fft::{dtft_at, Fft2, HalfSpectrum};
use crate::Cube;
use rayon::prelude::*;
use rustfft::num_complex::{Complex32, Complex64};
use serde::Serialize;
use std::borrow::Cow;

/// The frames a calibration captures, each the mean of `frames_averaged` exposures.
#[derive(Clone, Debug)]
pub struct CalibrationFrames {
    /// Dark frame (no light); None for a frame already in linear units (no camera modelled).
    pub dark: Option<Cube>,
    /// Flat frame (uniform target, every mirror on); None with `dark`.
    pub flat: Option<Cube>,
    /// One plane per pattern k: the white target while the DMD shows pattern k in its own
    /// wheel segment's slot and is dark in the others.
    pub patterns: Cube,
    /// True when `patterns` are already in linear units (the oracle), so the dark/flat
    /// correction is not applied to them again.
    pub patterns_linear: bool,
    pub frames_averaged: usize,
    /// What made the frames: "captures" (simulated or real) or "oracle" (the simulator's exact
    /// patterns and weights, noiseless — for comparison only).
    pub source: String,
}

impl CalibrationFrames {
    /// Single captures handed in from outside (files, arrays): raw when a dark frame comes with
    /// them, already linear when none does.
    pub fn single(
        dark: Option<Cube>,
        flat: Option<Cube>,
        patterns: Cube,
        source: String,
    ) -> CalibrationFrames {
        CalibrationFrames {
            patterns_linear: dark.is_none(),
            dark,
            flat,
            patterns,
            frames_averaged: 1,
            source,
        }
    }
}

/// One carrier as the calibration measured it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct MeasuredCarrier {
    /// Frequency (cycles/px) and phase at pixel (0, 0) of the e^{+iω·p} term.
    pub carrier: Carrier,
    /// Complex amplitude of that term in the white-target capture (frame units).
    pub amplitude: [f64; 2],
    /// Mean of the white-target capture under the Hann taper `amplitude` is measured with: the
    /// white level of this pattern's slot where its carrier is measured.
    pub white_level: f64,
    /// Shift from the design carrier, in cycles/px.
    pub shift: [f64; 2],
    /// How far the carrier's peak stands above the capture's spectrum around it (its magnitude
    /// over their median; [`PROMINENT`] and more for a carrier, about 3 for noise alone; at most
    /// 10¹⁵, which noiseless captures reach); None where the frame is too small to have bins
    /// around it.
    pub prominence: Option<f64>,
}

/// The least prominence of a carrier found: the largest of the ~80 noise bins a search sees
/// stands about 2.5 times their median (Rayleigh magnitudes), and one beyond 5 times has a
/// chance of about 2·10⁻⁶; the rigs' carriers stand 260–3 000 times (docs/stability.md).
pub const PROMINENT: f64 = 5.0;

impl MeasuredCarrier {
    pub fn amplitude(&self) -> Complex64 {
        Complex64::new(self.amplitude[0], self.amplitude[1])
    }

    /// The same carrier with its amplitude and white level in units `k` times larger.
    pub fn scaled(&self, k: f64) -> MeasuredCarrier {
        MeasuredCarrier {
            amplitude: [self.amplitude[0] * k, self.amplitude[1] * k],
            white_level: self.white_level * k,
            ..*self
        }
    }
}

/// Dark and flat frames that turn raw DN into linear frame units.
#[derive(Clone, Debug)]
pub struct DarkFlat {
    pub dark: Cube,
    pub flat: Cube,
    /// Exposures each of the two frames is the mean of (their own noise is 1/N of one frame's;
    /// 0 is read as 1 by the noise weights).
    pub frames_averaged: usize,
}

impl DarkFlat {
    pub fn apply(&self, raw: &Cube) -> Result<Cube> {
        if raw.planes == 1 {
            return calibrate(raw, &self.dark, &self.flat);
        }
        // A stack of planes (the pattern captures): each plane against the same frames.
        let mut out = Cube::zeros(raw.width, raw.height, raw.planes);
        for k in 0..raw.planes {
            let c = calibrate(&raw.extract(k), &self.dark, &self.flat)?;
            out.plane_mut(k).copy_from_slice(&c.data);
        }
        Ok(out)
    }
}

/// What the reconstruction knows of the rig beyond its design: measured carriers, the white-
/// target captures (linear units) and the dark/flat correction.
#[derive(Clone, Debug)]
pub struct Calibration {
    pub dark_flat: Option<DarkFlat>,
    pub carriers: Vec<MeasuredCarrier>,
    /// P_k: the white-target capture of each pattern, dark/flat corrected.
    pub patterns: Cube,
    pub source: String,
}

/// Sub-bin search for a carrier's frequency: the white-target capture's DTFT magnitude is
/// maximised within ± this many bins of the strongest bin near the design carrier.
const SEARCH_BINS: i64 = 2;

/// The `source` of an oracle calibration (the simulator's exact patterns), as reports write it.
pub const ORACLE: &str = "oracle";

/// What every figure made with an oracle calibration carries (`[calibration] source =
/// "oracle"`): it used what no rig can know.
pub const ORACLE_LABEL: &str = "ORACLE calibration ([calibration] source = \"oracle\"): the simulator's exact patterns and weights, which no rig knows; these are not a rig's figures";

impl Calibration {
    /// True when the calibration is the simulator's oracle, not captures.
    pub fn is_oracle(&self) -> bool {
        self.source == ORACLE
    }

    /// What a report says of this calibration: [`ORACLE_LABEL`] for the oracle, then
    /// [`Calibration::warning`].
    pub fn notes(&self) -> impl Iterator<Item = String> {
        let oracle = self.is_oracle().then(|| ORACLE_LABEL.to_string());
        oracle.into_iter().chain(self.warning())
    }

    /// A warning naming the carriers that do not stand out of their captures' spectra, whose
    /// channels would be demultiplexed from noise; None when every carrier does.
    pub fn warning(&self) -> Option<String> {
        let weak = |(k, m): (usize, &MeasuredCarrier)| {
            let p = m.prominence.filter(|&p| p < PROMINENT)?;
            let (fx, fy) = (m.carrier.fx, m.carrier.fy);
            Some(format!(
                "pattern {k} at ({fx:.4}, {fy:.4}) cycles/px {p:.1}×"
            ))
        };
        let weak: Vec<String> = self.carriers.iter().enumerate().filter_map(weak).collect();
        (!weak.is_empty()).then(|| format!(
            "calibration: carriers that do not stand out of their captures: {} the median of the bins around them (noise alone reaches about 3×, a carrier {PROMINENT}× and more); those channels are demultiplexed from noise: check that the patterns reach the camera (lens NA, Fourier filter) and the light level",
            weak.join(", ")
        ))
    }

    /// Estimate every carrier from the captures. `design` gives where to look: the strongest
    /// bin within `radius_bins` of each design carrier (never the DC bin), then sub-bin refined.
    pub fn from_frames(
        design: &[Carrier],
        frames: &CalibrationFrames,
        radius_bins: usize,
    ) -> Result<Calibration> {
        let p = &frames.patterns;
        if p.planes != design.len() {
            return Err(Error::Shape(format!(
                "{} pattern captures for {} carriers",
                p.planes,
                design.len()
            )));
        }
        let dark_flat = match (&frames.dark, &frames.flat) {
            (Some(d), Some(f)) => Some(DarkFlat {
                dark: d.clone(),
                flat: f.clone(),
                frames_averaged: frames.frames_averaged,
            }),
            (None, None) => None,
            _ => {
                return Err(Error::Shape(
                    "calibration: a dark frame needs a flat frame and the reverse".into(),
                ))
            }
        };
        let patterns = match (&dark_flat, frames.patterns_linear) {
            (Some(df), false) => df.apply(p)?,
            _ => p.clone(),
        };
        if !patterns.all_finite() {
            return Err(Error::Numerical(
                "calibration: the pattern captures contain NaN or infinite values".into(),
            ));
        }
        let fft = Fft2::new(p.width, p.height);
        let carriers = design
            .par_iter()
            .enumerate()
            .map(|(k, c)| measure_carrier(&fft, &patterns, k, c, radius_bins))
            .collect::<Result<Vec<_>>>()?;
        Ok(Calibration {
            dark_flat,
            carriers,
            patterns,
            source: frames.source.clone(),
        })
    }

    /// A raw frame in linear units (dark/flat corrected when the rig has a camera; the frame
    /// itself, not a copy, when it has none).
    pub fn linearise<'a>(&self, raw: &'a Cube) -> Result<Cow<'a, Cube>> {
        match &self.dark_flat {
            Some(df) => Ok(Cow::Owned(df.apply(raw)?)),
            None => Ok(Cow::Borrowed(raw)),
        }
    }
}

/// Frequency, phase and amplitude of pattern `k`'s carrier in its white-target capture.
fn measure_carrier(
    fft: &Fft2,
    patterns: &Cube,
    k: usize,
    design: &Carrier,
    radius_bins: usize,
) -> Result<MeasuredCarrier> {
    let (w, h) = (patterns.width, patterns.height);
    let plane = patterns.plane(k);
    let spec = fft.forward(plane);
    let (bx, by) = (Carrier::bin(design.fx, w), Carrier::bin(design.fy, h));
    let r = radius_bins as i64;
    let mut best = (bx, by, -1.0f32);
    for dy in -r..=r {
        for dx in -r..=r {
            let (kx, ky) = (bx + dx, by + dy);
            if (kx.rem_euclid(w as i64), ky.rem_euclid(h as i64)) == (0, 0) {
                continue;
            }
            let m = spec.at(kx, ky).norm();
            if m > best.2 {
                best = (kx, ky, m);
            }
        }
    }
    let (fx0, fy0) = (best.0 as f64 / w as f64, best.1 as f64 / h as f64);
    // A Hann taper keeps the DC term and the mirror carrier from leaking into the estimate of
    // an off-grid tone; on the grid its transform is zero two bins away, so nothing changes.
    let tapered = hann(plane, w, h);
    // The white level under the same taper as the amplitude, so that their ratio is the
    // modulation depth where the amplitude is measured: a plain mean counts the dim border of an
    // imaged DMD that the taper leaves out (it read the full rig's gains 5–7 % high).
    let white_level = tapered.iter().map(|&v| v as f64).sum::<f64>() / plane.len() as f64 * 4.0;
    let (fx, fy) = if off_grid(&spec, best.0, best.1) {
        refine_peak(&tapered, w, h, fx0, fy0)
    } else {
        (fx0, fy0)
    };
    // The periodic Hann window's mean is ¼: dividing by it gives the tone's amplitude.
    let a = dtft_at(&tapered, w, h, fx, fy) * 4.0;
    let floor = 1e-6 * white_level.abs().max(f64::MIN_POSITIVE);
    if a.norm().is_nan() || a.norm() <= floor {
        return Err(Error::Numerical(format!(
            "calibration: pattern {k}'s capture carries no carrier near ({}, {}) cycles/px (amplitude {:.3e} against a white level {white_level:.3e}); it cannot be demultiplexed",
            design.fx,
            design.fy,
            a.norm()
        )));
    }
    Ok(MeasuredCarrier {
        carrier: Carrier {
            fx,
            fy,
            phase_rad: a.arg(),
        },
        amplitude: [a.re, a.im],
        white_level,
        shift: [fx - design.fx, fy - design.fy],
        prominence: prominence(&spec, best.0, best.1, best.2),
    })
}

/// How far the peak at (kx, ky) of magnitude `peak` stands above the spectrum around it: peak
/// over the median magnitude of the bins 3 to 6 bins from it (Chebyshev distance; the DC bin
/// and bins within 2 of the peak, wrapped, left out), at most 10¹⁵ (a median of zero: noiseless
/// captures), so that it stays a finite number in the reports. None where fewer than 16 such
/// bins exist.
fn prominence(spec: &HalfSpectrum, kx: i64, ky: i64, peak: f32) -> Option<f64> {
    let (w, h) = (spec.w as i64, spec.h as i64);
    // Chebyshev distance to the peak on the periodic grid.
    let d = |a: i64, b: i64, n: i64| (a - b).rem_euclid(n).min((b - a).rem_euclid(n));
    let near = |x: i64, y: i64| d(x, kx, w).max(d(y, ky, h)) <= 2;
    let mut ring: Vec<f32> = (-6..=6i64)
        .flat_map(|dy| (-6..=6i64).map(move |dx| (kx + dx, ky + dy)))
        .filter(|&(x, y)| !near(x, y) && (x.rem_euclid(w), y.rem_euclid(h)) != (0, 0))
        .map(|(x, y)| spec.at(x, y).norm())
        .collect();
    if ring.len() < 16 {
        return None;
    }
    let mid = ring.len() / 2;
    let median = *ring.select_nth_unstable_by(mid, f32::total_cmp).1;
    Some(
        peak as f64
            / (median as f64)
                .max(1e-15 * peak as f64)
                .max(f64::MIN_POSITIVE),
    )
}

/// The plane times the separable periodic Hann window (½ − ½cos 2πx/w)(½ − ½cos 2πy/h).
fn hann(plane: &[f32], w: usize, h: usize) -> Vec<f32> {
    let tau = std::f64::consts::TAU;
    let taper = |i: usize, n: usize| 0.5 - 0.5 * (tau * i as f64 / n as f64).cos();
    let wx: Vec<f64> = (0..w).map(|x| taper(x, w)).collect();
    plane
        .chunks_exact(w)
        .enumerate()
        .flat_map(|(y, row)| {
            let wy = taper(y, h);
            row.iter()
                .zip(&wx)
                .map(move |(&v, &t)| (v as f64 * t * wy) as f32)
        })
        .collect()
}

/// True when the peak at bin (kx, ky) leaks into its neighbours as an off-grid tone does:
/// the three-bin interpolation (Jacobsen) puts the true peak over 1e-3 bins away on an axis.
fn off_grid(spec: &HalfSpectrum, kx: i64, ky: i64) -> bool {
    let offset = |m: Complex32, c: Complex32, p: Complex32| {
        let den = c * 2.0 - m - p;
        if den.norm() == 0.0 {
            0.0
        } else {
            ((m - p) / den).re.abs()
        }
    };
    let c = spec.at(kx, ky);
    let dx = offset(spec.at(kx - 1, ky), c, spec.at(kx + 1, ky));
    let dy = offset(spec.at(kx, ky - 1), c, spec.at(kx, ky + 1));
    dx > 1e-3 || dy > 1e-3
}

/// The frequency near (fx0, fy0) (cycles/px) where |DTFT| peaks, within ±`SEARCH_BINS`/2
/// bins, by golden-section search along x then y, twice. On-grid peaks stay exactly on the bin.
fn refine_peak(plane: &[f32], w: usize, h: usize, fx0: f64, fy0: f64) -> (f64, f64) {
    let mag = |fx: f64, fy: f64| dtft_at(plane, w, h, fx, fy).norm();
    let (mut fx, mut fy) = (fx0, fy0);
    let half = SEARCH_BINS as f64 / 2.0;
    for _ in 0..2 {
        fx = golden_max(|f| mag(f, fy), fx0 - half / w as f64, fx0 + half / w as f64);
        fy = golden_max(|f| mag(fx, f), fy0 - half / h as f64, fy0 + half / h as f64);
    }
    // Keep the exact bin when refinement gains nothing measurable (an on-grid carrier).
    if mag(fx0, fy0) >= mag(fx, fy) * (1.0 - 1e-9) {
        (fx0, fy0)
    } else {
        (fx, fy)
    }
}

/// Maximiser of a unimodal `f` on [a, b] to 1e-6 of the interval.
fn golden_max(f: impl Fn(f64) -> f64, mut a: f64, mut b: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (b - g * (b - a), a + g * (b - a));
    let (mut fc, mut fd) = (f(c), f(d));
    let tol = 1e-6 * (b - a);
    while b - a > tol {
        if fc > fd {
            b = d;
            (d, fd) = (c, fc);
            c = b - g * (b - a);
            fc = f(c);
        } else {
            a = c;
            (c, fc) = (d, fd);
            d = a + g * (b - a);
            fd = f(d);
        }
    }
    0.5 * (a + b)
}

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

    /// Captures of 64 × 64 pixels, white level 1 with Gaussian noise of σ = 0.05, plus the carrier
    /// 0.5·cos(2π·0.25x) where `carrier` is set.
    fn capture(carrier: bool, scale: f32) -> CalibrationFrames {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let noise = Normal::new(0.0f32, 0.05).unwrap();
        let plane = (0..64 * 64)
            .map(|i| {
                let x = (i % 64) as f32;
                let tone = if carrier {
                    0.5 * (std::f32::consts::TAU * 0.25 * x).cos()
                } else {
                    0.0
                };
                scale * (1.0 + tone + noise.sample(&mut rng))
            })
            .collect();
        let patterns = Cube::from_vec(64, 64, 1, plane).unwrap();
        CalibrationFrames::single(None, None, patterns, "test".into())
    }

    /// A carrier under noise stands far above the spectrum around it (by hand: its bin holds
    /// 0.25·4096 = 1024 against the noise bins' median 1.18·0.05·64/√2 ≈ 2.7, about 380×) and gives
    /// no warning; noise alone stands under PROMINENT and is named in a warning; the measure
    /// does not depend on the frame's units.
    #[test]
    fn a_carrier_stands_out_of_its_capture_and_noise_does_not() {
        let design = [Carrier {
            fx: 0.25,
            fy: 0.0,
            phase_rad: 0.0,
        }];
        let measure = |carrier, scale| {
            Calibration::from_frames(&design, &capture(carrier, scale), 4).unwrap()
        };
        let tone = measure(true, 1.0);
        let p = tone.carriers[0].prominence.unwrap();
        assert!((150.0..500.0).contains(&p), "{p}");
        assert_eq!(tone.warning(), None);
        let noise = measure(false, 1.0);
        let q = noise.carriers[0].prominence.unwrap();
        assert!((1.0..PROMINENT).contains(&q), "{q}");
        let w = noise.warning().unwrap();
        assert!(
            w.contains("do not stand out") && w.contains("pattern 0 at ("),
            "{w}"
        );
        let scaled = measure(true, 1000.0).carriers[0].prominence.unwrap();
        assert!((scaled / p - 1.0).abs() < 1e-3, "{scaled} against {p}");
    }

    /// By hand: the capture 1 + ½cos(2π·¼x) inside a 32 × 32 square, dark outside it (an imaged
    /// DMD's border), on a 64 × 64 frame. Wherever there is light the e^{iω·x} term is ¼ of the
    /// white level, so |a| / white = ¼ under one taper for both, up to the taper's leak of the
    /// lit square's DC into the carrier's bin (0.75 %, numpy). Over the plain mean it read 0.66.
    #[test]
    fn the_white_level_is_measured_where_the_amplitude_is() {
        let plane = (0..64 * 64)
            .map(|i| {
                let (x, y) = (i % 64, i / 64);
                let lit = (16..48).contains(&x) && (16..48).contains(&y);
                let tone = 0.5 * (std::f32::consts::TAU * 0.25 * x as f32).cos();
                if lit {
                    1.0 + tone
                } else {
                    0.0
                }
            })
            .collect();
        let patterns = Cube::from_vec(64, 64, 1, plane).unwrap();
        let frames = CalibrationFrames::single(None, None, patterns, "test".into());
        let design = [Carrier {
            fx: 0.25,
            fy: 0.0,
            phase_rad: 0.0,
        }];
        let m = Calibration::from_frames(&design, &frames, 4)
            .unwrap()
            .carriers[0];
        let depth = m.amplitude().norm() / m.white_level;
        assert!((depth / 0.25 - 1.0).abs() < 0.01, "{depth}");
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
