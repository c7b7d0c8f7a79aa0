//! The camera's temporal noise as its EMVA 1288 photon-transfer measurement gives it (gain K and
//! dark noise σ_y.dark), and the per-pixel inverse variances ω of a dark/flat-corrected frame
//! that the joint reconstruction weighs its data term by (docs/joint.md, "Noise-aware weights").

use crate::calibration::DarkFlat;
use crate::error::{Error, Result};
use crate::Cube;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The joint method's per-pixel data weights ω and the pixels whose raw value reads the camera's
/// saturation: their measurement is only a lower bound, so the data term there is one-sided
/// (ω/2·max(0, y − aᵀα)², a censored observation).
#[derive(Clone, Debug, PartialEq)]
pub struct DataWeights {
    pub omega: Cube,
    pub saturated: Vec<bool>,
}

impl DataWeights {
    /// Weights ω with no pixel saturated.
    pub fn new(omega: Cube) -> DataWeights {
        let saturated = vec![false; omega.pixels()];
        DataWeights { omega, saturated }
    }
}

/// The warning for a frame whose mean signal is under its noise ([`NoiseModel::mean_snr`]
/// below 1): shown by the twin's reports and by `specmux reconstruct`.
pub fn snr_warning(mean_snr: f64) -> Option<String> {
    (mean_snr < 1.0).then(|| {
        format!(
            "the frame's mean signal is {:.2} times its noise: one frame says little beyond the reconstruction's prior, so its figures are mostly the prior's; raise the light or the exposure",
            mean_snr.max(0.0)
        )
    })
}

/// EMVA 1288 linear camera model: σ_y² = σ_y.dark² + K·(μ_y − μ_y.dark) in DN².
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseModel {
    /// Overall system gain K (DN per electron).
    pub gain_dn_per_e: f64,
    /// Temporal dark noise σ_y.dark (DN rms) at the rig's exposure: read noise, dark-current
    /// shot noise and quantisation together, as the photon-transfer dark point measures it.
    pub dark_noise_dn: f64,
    /// The raw value (DN) of a saturated pixel: round(K·μ_e.sat + black offset), or the ADC's top
    /// when that comes first (EMVA 1288 saturation). A pixel at or above it holds only a lower
    /// bound of its signal (a censored observation, [`DataWeights`]). None: not known.
    #[serde(default)]
    pub saturation_dn: Option<f64>,
}

/// Whether a raw value reads the saturation level `level_dn` once rounded to the DN: the one
/// test of saturation, shared by the weights here and the twin's frame statistics.
pub fn reads_saturation(raw: f32, level_dn: f64) -> bool {
    raw as f64 >= level_dn - 0.5
}

impl NoiseModel {
    /// Both figures finite and > 0 (quantisation alone gives σ_y.dark ≥ 1/√12 DN); the error
    /// names `what` (where the model came from) and the value.
    pub fn validate(&self, what: &str) -> Result<()> {
        for (key, v) in [
            ("gain_dn_per_e", self.gain_dn_per_e),
            ("dark_noise_dn", self.dark_noise_dn),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::Numerical(format!(
                    "{what}: noise model {key} = {v} must be finite and > 0"
                )));
            }
        }
        match self.saturation_dn {
            Some(v) if !(v.is_finite() && v > 0.0) => Err(Error::Numerical(format!(
                "{what}: noise model saturation_dn = {v} must be finite and > 0"
            ))),
            _ => Ok(()),
        }
    }

    /// Whether a raw value reads the saturation level (rounded to the DN).
    fn saturated(&self, raw: f32) -> bool {
        self.saturation_dn.is_some_and(|s| reads_saturation(raw, s))
    }

    /// ω_p = 1/var(y_p) of a linearised frame y = g⊙(raw − dark), g_p the flat-field gain
    /// m/(flat_p − dark_p), m = mean(flat − dark): the frame's own variance
    /// g_p²σ_y.dark² + g_p·K·max(y_p, 0) plus that of the dark and flat frames, each the mean of
    /// N exposures, carried through the correction to first order ([`NoiseModel::variance`]);
    /// and the pixels where the `raw` frame reads the saturation level. Without a dark/flat
    /// correction g = 1 (the frame is taken as raw DN above dark). A frame saturated everywhere
    /// is refused: it bounds the light from below and says nothing else.
    pub fn weights(
        &self,
        raw: &Cube,
        y: &Cube,
        dark_flat: Option<&DarkFlat>,
    ) -> Result<DataWeights> {
        self.validate("noise weights")?;
        y.check_same_shape(raw, "noise weights: linearised frame against raw frame")?;
        let (gains, calibration) = match dark_flat {
            Some(df) => {
                let (gains, mean) = flat_gains(df, y)?;
                (gains, Some((mean, df.frames_averaged.max(1) as f64)))
            }
            None => (vec![1.0; y.pixels()], None),
        };
        let data: Vec<f32> = y
            .data
            .par_iter()
            .zip(&gains)
            .map(|(&v, &g)| (1.0 / self.variance(v as f64, g, calibration)) as f32)
            .collect();
        let saturated: Vec<bool> = raw.data.iter().map(|&r| self.saturated(r)).collect();
        let everywhere = !saturated.is_empty() && saturated.iter().all(|&s| s);
        if let Some(level) = self.saturation_dn.filter(|_| everywhere) {
            return Err(Error::Numerical(format!(
                "noise weights: every pixel of the frame reads the camera's saturation level ({level} DN): no measurement is left to reconstruct from; shorten the exposure"
            )));
        }
        Ok(DataWeights {
            omega: Cube::from_vec(y.width, y.height, 1, data)?,
            saturated,
        })
    }

    /// The raw frame's mean signal above `dark` over the noise of a pixel at that signal,
    /// mean(raw − dark)/√(σ_y.dark² + K·max(mean, 0)): below about 1 a single frame says little
    /// more than the prior does, and a reconstruction of it should say so.
    pub fn mean_snr(&self, raw: &Cube, dark: &Cube) -> Result<f64> {
        self.validate("frame SNR")?;
        raw.check_same_shape(dark, "frame SNR: frame against dark frame")?;
        let n = raw.data.len().max(1) as f64;
        let signal = raw
            .data
            .iter()
            .zip(&dark.data)
            .map(|(&r, &d)| r as f64 - d as f64)
            .sum::<f64>()
            / n;
        Ok(signal / self.variance(signal, 1.0, None).sqrt())
    }

    /// var(y) of one pixel of y = m(raw − d)/(f − d), g = m/(f − d): g²·var(raw) from the frame,
    /// and with `calibration` = (m, N) the dark and flat frames' var(d) = σ²/N and
    /// var(f) = (σ² + K(f − d))/N times the squares of ∂y/∂d = g(y/m − 1) and ∂y/∂f = −g·y/m
    /// (m, the mean over the whole frame, taken as exact).
    fn variance(&self, y: f64, g: f64, calibration: Option<(f64, f64)>) -> f64 {
        let (s2, k) = (self.dark_noise_dn.powi(2), self.gain_dn_per_e);
        let frame = g * g * s2 + g * k * y.max(0.0);
        let Some((m, n)) = calibration else {
            return frame;
        };
        let dark = (g * (y / m - 1.0)).powi(2) * s2;
        let flat = (g * y / m).powi(2) * (s2 + k * m / g);
        frame + (dark + flat) / n
    }
}

/// g_p = mean(flat − dark)/(flat_p − dark_p), the factor `calibration::calibrate` multiplies
/// pixel p's raw signal by, and that mean.
fn flat_gains(df: &DarkFlat, y: &Cube) -> Result<(Vec<f64>, f64)> {
    y.check_same_shape(&df.dark, "noise weights: frame against dark frame")?;
    y.check_same_shape(&df.flat, "noise weights: frame against flat frame")?;
    let resp: Vec<f64> = df
        .flat
        .data
        .iter()
        .zip(&df.dark.data)
        .map(|(&f, &d)| f as f64 - d as f64)
        .collect();
    if let Some(i) = resp.iter().position(|&r| r.is_nan() || r <= 0.0) {
        return Err(Error::Numerical(format!(
            "noise weights: flat − dark = {} DN at pixel {i}; the flat must be brighter",
            resp[i]
        )));
    }
    let mean = resp.iter().sum::<f64>() / resp.len() as f64;
    Ok((resp.iter().map(|r| mean / r).collect(), mean))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two pixels by hand: K = 0.5 DN/e⁻, σ = 2 DN, dark (10, 10), flat (110, 60) → responses
    /// (100, 50), mean m = 75, gains (0.75, 1.5). y = (30, −4): the frame's var = 0.75²·4 +
    /// 0.75·0.5·30 = 2.25 + 11.25 = 13.5 and 1.5²·4 + 0 = 9 (a negative signal adds no shot
    /// noise). Dark and flat of N = 4 exposures add [(g(y/m − 1))²σ² + (gy/m)²(σ² + Km/g)]/N:
    /// (0.81 + 4.86)/4 = 1.4175 and (9.9856 + 0.1856)/4 = 2.5428.
    #[test]
    fn weights_of_a_case_computed_by_hand() {
        let m = NoiseModel {
            gain_dn_per_e: 0.5,
            dark_noise_dn: 2.0,
            saturation_dn: None,
        };
        let df = DarkFlat {
            dark: Cube::from_vec(2, 1, 1, vec![10.0, 10.0]).unwrap(),
            flat: Cube::from_vec(2, 1, 1, vec![110.0, 60.0]).unwrap(),
            frames_averaged: 4,
        };
        let y = Cube::from_vec(2, 1, 1, vec![30.0, -4.0]).unwrap();
        let w = m.weights(&y, &y, Some(&df)).unwrap().omega;
        assert!((w.data[0] - 1.0 / 14.9175).abs() < 1e-7, "{:?}", w.data);
        assert!((w.data[1] - 1.0 / 11.5428).abs() < 1e-7, "{:?}", w.data);
        // Averaged without end, the dark and flat add nothing.
        let exact = DarkFlat {
            frames_averaged: 1 << 40,
            ..df
        };
        let w = m.weights(&y, &y, Some(&exact)).unwrap().omega;
        assert!((w.data[0] - 1.0 / 13.5).abs() < 1e-7, "{:?}", w.data);
        assert!((w.data[1] - 1.0 / 9.0).abs() < 1e-7, "{:?}", w.data);
        // Without dark/flat: var = σ² + K·y.
        let w = m.weights(&y, &y, None).unwrap().omega;
        assert!((w.data[0] - 1.0 / 19.0).abs() < 1e-7 && (w.data[1] - 0.25).abs() < 1e-7);
    }

    /// The weights match the sample variance of simulated Poisson + Gaussian frames pushed
    /// through the same dark/flat correction, with the dark and flat frames themselves drawn
    /// afresh (each the mean of N = 4 exposures) for every frame: a property of the
    /// derivation, not of the code.
    #[test]
    fn weights_match_the_sample_variance_of_corrected_frames() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal, Poisson};
        let (k, sd, frames) = (0.25, 0.9, 4usize);
        let (electrons, dark_dn, resp) = (4000.0, 100.0f64, [800.0f64, 400.0]);
        let df = DarkFlat {
            dark: Cube::from_vec(2, 1, 1, vec![dark_dn as f32; 2]).unwrap(),
            flat: Cube::from_vec(2, 1, 1, resp.iter().map(|r| (r + dark_dn) as f32).collect())
                .unwrap(),
            frames_averaged: frames,
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(7);
        let read = Normal::new(0.0, sd).unwrap();
        let n = 20000;
        let mean_resp = (resp[0] + resp[1]) / 2.0;
        for (p, r) in resp.iter().enumerate() {
            // The pixel's quantum efficiency × light scales with its flat response.
            let mu = electrons * r / mean_resp;
            let pois = Poisson::new(mu).unwrap();
            let flat_pois = Poisson::new(r / k).unwrap();
            type Rng = rand_pcg::Pcg64Mcg;
            let mean_of = |g: &mut Rng, signal: &dyn Fn(&mut Rng) -> f64| {
                (0..frames).map(|_| signal(g)).sum::<f64>() / frames as f64
            };
            let ys: Vec<f64> = (0..n)
                .map(|_| {
                    let g = &mut rng;
                    let dark = mean_of(g, &|g| read.sample(g) + dark_dn);
                    let flat = mean_of(g, &|g| k * flat_pois.sample(g) + read.sample(g) + dark_dn);
                    let raw = k * pois.sample(g) + read.sample(g) + dark_dn;
                    (raw - dark) / (flat - dark) * mean_resp
                })
                .collect();
            let mean = ys.iter().sum::<f64>() / n as f64;
            let var = ys.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            let mut y = Cube::zeros(2, 1, 1);
            y.data[p] = mean as f32;
            let w = NoiseModel {
                gain_dn_per_e: k,
                dark_noise_dn: sd,
                saturation_dn: None,
            }
            .weights(&y, &y, Some(&df))
            .unwrap()
            .omega;
            let predicted = 1.0 / w.data[p] as f64;
            // 20000 samples: the sample variance is within ±3 % (about 3 σ) of the truth.
            assert!(
                (var / predicted - 1.0).abs() < 0.03,
                "pixel {p}: sample {var:.3} against {predicted:.3}"
            );
        }
    }

    /// SNR by hand: K = 0.5, σ = 2; raw (110, 30) over dark (10, 10): mean signal 60 DN,
    /// noise √(4 + 30) = √34, SNR 60/√34 = 10.29; a frame at the dark level has SNR 0.
    #[test]
    fn the_mean_snr_by_hand() {
        let m = NoiseModel {
            gain_dn_per_e: 0.5,
            dark_noise_dn: 2.0,
            saturation_dn: None,
        };
        let dark = Cube::from_vec(2, 1, 1, vec![10.0, 10.0]).unwrap();
        let raw = Cube::from_vec(2, 1, 1, vec![110.0, 30.0]).unwrap();
        let snr = m.mean_snr(&raw, &dark).unwrap();
        assert!((snr - 60.0 / 34f64.sqrt()).abs() < 1e-12, "{snr}");
        assert_eq!(m.mean_snr(&dark, &dark).unwrap(), 0.0);
        assert!(m.mean_snr(&raw, &Cube::zeros(1, 1, 1)).is_err());
    }

    /// Saturation by hand: level 3882 DN; raw (3882, 3881.6, 3881.4, 4095) → the first, second
    /// (rounds to 3882) and last read it, the third does not; ω stays σ² + K·y = 4 + 0.5·100
    /// everywhere (the one-sided data term keeps the weight).
    #[test]
    fn saturated_pixels_are_flagged() {
        let m = NoiseModel {
            gain_dn_per_e: 0.5,
            dark_noise_dn: 2.0,
            saturation_dn: Some(3882.0),
        };
        let raw = Cube::from_vec(4, 1, 1, vec![3882.0, 3881.6, 3881.4, 4095.0]).unwrap();
        let y = Cube::from_vec(4, 1, 1, vec![100.0; 4]).unwrap();
        let w = m.weights(&raw, &y, None).unwrap();
        assert_eq!(w.saturated, [true, true, false, true]);
        assert!(
            w.omega.data.iter().all(|&v| (v - 1.0 / 54.0).abs() < 1e-7),
            "{w:?}"
        );
        // Every pixel saturated: nothing to reconstruct from, refused naming the level.
        let all = Cube::from_vec(4, 1, 1, vec![3900.0; 4]).unwrap();
        let e = m.weights(&all, &y, None).unwrap_err().to_string();
        assert!(e.contains("every pixel") && e.contains("3882 DN"), "{e}");
        // A raw frame of another size is a shape error, not a silent zip.
        let e = m.weights(&Cube::zeros(2, 1, 1), &y, None).unwrap_err();
        assert!(e.to_string().contains("raw frame"), "{e}");
    }

    #[test]
    fn bad_models_are_refused() {
        let mut m = NoiseModel {
            gain_dn_per_e: 0.5,
            dark_noise_dn: 0.0,
            saturation_dn: None,
        };
        let zeros = Cube::zeros(2, 1, 1);
        let e = m.weights(&zeros, &zeros, None).unwrap_err();
        assert!(e.to_string().contains("dark_noise_dn = 0"), "{e}");
        m.dark_noise_dn = 1.0;
        for bad in [0.0, -1.0, f64::NAN] {
            m.saturation_dn = Some(bad);
            let e = m.weights(&zeros, &zeros, None).unwrap_err();
            assert!(e.to_string().contains("saturation_dn"), "{e}");
        }
    }
}
