//! The camera: the EMVA 1288 linear model of a CMOS sensor, from mean photo-electrons per pixel
//! to a raw frame in DN, in the order of the photon-transfer chain:
//!
//! 1. photo-electrons μ_e (from radiometry, [`Sensor::electrons_from_irradiance`], or the
//!    shortcut [`Sensor::electrons_from_relative`]), times the PRNU gain map (1 + p_i);
//! 2. Poisson shot noise of light and dark current together (a sum of independent Poisson
//!    variables is Poisson with the summed mean; dark current doubles every `dark_doubling_c`);
//! 3. Gaussian read noise σ_d and the DSNU offset map d_i, in electrons;
//! 4. clip at the full well μ_e.sat;
//! 5. gain K, black offset, ADC: round to the nearest DN and clip to [0, 2^bits − 1].
//!
//! The forward model builds a `Sensor` only when the experiment has a `[rig.sensor]` section;
//! without it the frame stays noiseless and unquantised. Inside the sensor a zero PRNU, DSNU or
//! read noise draws nothing. Dark and flat frames come from the same model, and
//! [`calibrate`] uses them the way the real rig's raw frames are corrected.

mod config;
mod poisson;
mod ptc;
mod radiometry;

pub use config::{CameraConfig, SensorConfig, MAX_PRNU_FRACTION};
pub use ptc::{
    default_levels, photon_transfer, ptc_frames, PtcFrames, PtcPoint, PtcResult,
    NONUNIFORMITY_FRAMES,
};
pub use radiometry::{photo_electrons, SpectralIrradiance};

use poisson::Poisson;
use rand::Rng;
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::Cube;

/// Independent noise streams: the same frame index in two streams gives unrelated noise.
#[derive(Clone, Copy, Debug)]
enum Stream {
    Scene = 0,
    Dark = 1,
    Flat = 2,
    PhotonTransfer = 3,
    PrnuMap = 4,
    DsnuMap = 5,
    Calibration = 6,
}

/// The noise key of flat exposure `k` at `level_e`: unrelated across levels and exposures.
fn flat_key(level_e: f64, k: usize) -> u64 {
    splitmix64(level_e.to_bits()) ^ k as u64
}

/// SplitMix64 finaliser: a bijective mix of 64 bits, used to derive seeds.
fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator of one image row of one frame of one stream: a function of
/// (seed, stream, frame, row) only, so frames are reproducible whatever the thread count.
fn row_rng(seed: u64, stream: Stream, frame: u64, row: usize) -> Pcg64Mcg {
    let hi =
        splitmix64(seed ^ splitmix64((stream as u64) ^ splitmix64(frame ^ splitmix64(row as u64))));
    let lo = splitmix64(hi ^ 0x6A09_E667_F3BC_C909);
    Pcg64Mcg::new(((hi as u128) << 64) | lo as u128)
}

/// A camera with its fixed-pattern maps drawn once from its seed.
#[derive(Clone, Debug)]
pub struct Sensor {
    cfg: SensorConfig,
    width: usize,
    height: usize,
    /// Per-pixel gain 1 + p_i, p_i ~ N(0, prnu_fraction); None when PRNU is zero.
    prnu: Option<Vec<f32>>,
    /// Per-pixel dark offset d_i ~ N(0, dsnu_e) in e⁻; None when DSNU is zero.
    dsnu: Option<Vec<f32>>,
    /// Mean dark-current electrons per frame at the set temperature and exposure.
    dark_e: f64,
}

impl Sensor {
    /// A camera of `width × height` pixels; validates `cfg` and draws the PRNU and DSNU maps.
    pub fn new(cfg: &SensorConfig, width: usize, height: usize) -> Result<Sensor> {
        cfg.validate("sensor configuration")?;
        if width == 0 || height == 0 {
            return Err(Error::Shape(format!("a sensor of {width}×{height} pixels")));
        }
        let map = |stream: Stream, sigma: f64, mean: f64| -> Option<Vec<f32>> {
            (sigma > 0.0).then(|| {
                let mut m = vec![0f32; width * height];
                m.par_chunks_mut(width).enumerate().for_each(|(y, row)| {
                    let mut rng = row_rng(cfg.seed, stream, 0, y);
                    for v in row {
                        *v = (mean + sigma * rng.sample::<f64, _>(StandardNormal)) as f32;
                    }
                });
                m
            })
        };
        Ok(Sensor {
            prnu: map(Stream::PrnuMap, cfg.prnu_fraction, 1.0),
            dsnu: map(Stream::DsnuMap, cfg.dsnu_e, 0.0),
            dark_e: cfg.dark_electrons(),
            cfg: cfg.clone(),
            width,
            height,
        })
    }

    pub fn config(&self) -> &SensorConfig {
        &self.cfg
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Largest output value 2^bits − 1 (DN).
    pub fn max_dn(&self) -> f64 {
        self.cfg.max_dn()
    }

    /// Mean dark-current electrons per frame.
    pub fn dark_electrons(&self) -> f64 {
        self.dark_e
    }

    /// The output of a pixel whose charge reached the full well (DN): round(K·μ_e.sat + offset),
    /// or the ADC's top rail when that comes first.
    pub fn saturation_dn(&self) -> f64 {
        self.cfg.saturation_dn()
    }

    /// The PRNU gain map (1 + p_i), if PRNU is modelled.
    pub fn prnu_map(&self) -> Option<&[f32]> {
        self.prnu.as_deref()
    }

    /// The DSNU offset map d_i (e⁻), if DSNU is modelled.
    pub fn dsnu_map(&self) -> Option<&[f32]> {
        self.dsnu.as_deref()
    }

    /// One raw frame in DN (f32 holding integers) from the mean photo-electrons per pixel
    /// (one plane, before PRNU). Frame `frame_index` always gets the same noise.
    pub fn capture(&self, mean_e: &Cube, frame_index: u64) -> Result<Cube> {
        self.check_frame(mean_e, "mean photo-electrons")?;
        Ok(self.expose(&mean_e.data, Stream::Scene, frame_index))
    }

    /// The shortcut without radiometry: electrons = frame × electrons_at_full_scale / full_scale.
    /// Values above `full_scale` are kept (they saturate in [`Sensor::capture`]).
    pub fn electrons_from_relative(&self, frame: &Cube, full_scale: f32) -> Result<Cube> {
        if !(full_scale.is_finite() && full_scale > 0.0) {
            return Err(Error::Numerical(format!(
                "full scale of the noiseless frame is {full_scale}; it must be finite and > 0"
            )));
        }
        self.check_frame(frame, "noiseless frame")?;
        let scale = (self.cfg.electrons_at_full_scale / full_scale as f64) as f32;
        let data = frame.data.iter().map(|v| v * scale).collect();
        Cube::from_vec(self.width, self.height, 1, data)
    }

    /// Average of `n_average` frames with no light (DN): the dark frame of the calibration.
    pub fn dark_frame(&self, n_average: usize) -> Result<Cube> {
        let zeros = vec![0f32; self.width * self.height];
        let keys: Vec<u64> = (0..n_average as u64).collect();
        self.averaged(&zeros, Stream::Dark, &keys)
    }

    /// Dark exposure number `k` (DN): the frames [`Sensor::dark_frame`] averages.
    pub fn dark_exposure(&self, k: usize) -> Cube {
        let zeros = vec![0f32; self.width * self.height];
        self.expose(&zeros, Stream::Dark, k as u64)
    }

    /// The mean of `n_average` exposures of `mean_e` (one plane of electrons), drawn from the
    /// calibration stream under `key`: a calibration capture, with its own noise.
    pub fn averaged_capture(&self, mean_e: &Cube, n_average: usize, key: u64) -> Result<Cube> {
        self.check_frame(mean_e, "mean photo-electrons")?;
        let key = splitmix64(key);
        let keys: Vec<u64> = (0..n_average as u64).map(|k| key ^ k).collect();
        self.averaged(&mean_e.data, Stream::Calibration, &keys)
    }

    /// Average of `n_average` frames of a uniform light of `level_e` mean photo-electrons (DN).
    /// Different levels use unrelated noise.
    pub fn flat_frame(&self, level_e: f64, n_average: usize) -> Result<Cube> {
        let flat = self.uniform_light(level_e)?;
        let keys: Vec<u64> = (0..n_average).map(|k| flat_key(level_e, k)).collect();
        self.averaged(&flat, Stream::Flat, &keys)
    }

    /// Flat exposure number `k` at `level_e` (DN): the frames [`Sensor::flat_frame`] averages.
    pub fn flat_exposure(&self, level_e: f64, k: usize) -> Result<Cube> {
        let flat = self.uniform_light(level_e)?;
        Ok(self.expose(&flat, Stream::Flat, flat_key(level_e, k)))
    }

    /// A uniform light of `level_e` photo-electrons per pixel; refuses a negative or NaN level.
    fn uniform_light(&self, level_e: f64) -> Result<Vec<f32>> {
        if !(level_e.is_finite() && level_e >= 0.0) {
            return Err(Error::Numerical(format!(
                "flat-field level {level_e} e⁻: it must be finite and ≥ 0"
            )));
        }
        Ok(vec![level_e as f32; self.width * self.height])
    }

    /// A one-plane frame of the sensor's size with finite values ≥ 0.
    fn check_frame(&self, frame: &Cube, what: &str) -> Result<()> {
        if (frame.width, frame.height, frame.planes) != (self.width, self.height, 1) {
            return Err(Error::Shape(format!(
                "{what}: {}×{}×{} for a {}×{} sensor (one plane expected)",
                frame.width, frame.height, frame.planes, self.width, self.height
            )));
        }
        // A branch-free pass first (it vectorises); the position only when something is wrong.
        let ok = |v: &f32| *v >= 0.0 && *v <= f32::MAX;
        if !frame.data.iter().fold(true, |all, v| all & ok(v)) {
            let i = frame.data.iter().position(|v| !ok(v)).unwrap_or(0);
            return Err(Error::Numerical(format!(
                "{what}: value {} at pixel ({}, {}); it must be finite and ≥ 0",
                frame.data[i],
                i % self.width,
                i / self.width
            )));
        }
        Ok(())
    }

    /// The photon-transfer chain for checked means, one generator per row.
    fn expose(&self, mean_e: &[f32], stream: Stream, frame: u64) -> Cube {
        self.exposures_averaged(mean_e, stream, &[frame])
    }

    /// The pixel-wise mean of the exposures of checked means under `keys` (at least one).
    fn averaged(&self, mean_e: &[f32], stream: Stream, keys: &[u64]) -> Result<Cube> {
        if keys.is_empty() {
            return Err(Error::Numerical(
                "averaging needs at least one frame (n_average = 0)".into(),
            ));
        }
        Ok(self.exposures_averaged(mean_e, stream, keys))
    }

    /// The mean of one exposure per key, each the frame [`Sensor::expose`] makes under its key
    /// (its own generator per row), summed in f64 in the order of `keys`. Pixel by pixel, so
    /// that a pixel's sampler is set up once for all its exposures and no frame is stored.
    fn exposures_averaged(&self, mean_e: &[f32], stream: Stream, keys: &[u64]) -> Cube {
        let mut out = Cube::zeros(self.width, self.height, 1);
        let w = self.width;
        out.data.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            let mut rngs: Vec<Pcg64Mcg> = (keys.iter())
                .map(|&k| row_rng(self.cfg.seed, stream, k, y))
                .collect();
            let span = y * w..(y + 1) * w;
            self.expose_row(
                &mut rngs,
                &mean_e[span.clone()],
                self.prnu.as_ref().map(|m| &m[span.clone()]),
                self.dsnu.as_ref().map(|m| &m[span]),
                row,
            );
        });
        out
    }

    /// One row: for each pixel, one exposure from each generator, averaged (a single generator
    /// is kept in registers: the one-frame capture of the scene).
    #[inline]
    fn expose_row(
        &self,
        rngs: &mut [Pcg64Mcg],
        mean_e: &[f32],
        prnu: Option<&[f32]>,
        dsnu: Option<&[f32]>,
        out: &mut [f32],
    ) {
        let pixel = |x: usize| {
            let light = mean_e[x] as f64 * prnu.map_or(1.0, |g| g[x] as f64);
            (
                Poisson::new(light + self.dark_e),
                dsnu.map_or(0.0, |d| d[x] as f64),
            )
        };
        if let [rng] = rngs {
            let mut rng = rng.clone();
            for (x, dst) in out.iter_mut().enumerate() {
                let (mut poisson, offset) = pixel(x);
                *dst = self.exposure_dn(&mut poisson, &mut rng, offset) as f32;
            }
            return;
        }
        let n = rngs.len() as f64;
        for (x, dst) in out.iter_mut().enumerate() {
            let (mut poisson, offset) = pixel(x);
            let sum = (rngs.iter_mut())
                .map(|rng| self.exposure_dn(&mut poisson, rng, offset) as f32 as f64)
                .fold(0.0, |s, v| s + v);
            *dst = (sum / n) as f32;
        }
    }

    /// One pixel's reading in DN: shot noise, read noise, the DSNU `offset` (e⁻), the full
    /// well, then the ADC, which clips to its rails and rounds half up (the rails are integers,
    /// so the order does not matter; fast_floor avoids a libm call per pixel).
    #[inline(always)]
    fn exposure_dn(&self, poisson: &mut Poisson, rng: &mut Pcg64Mcg, offset: f64) -> f64 {
        let c = &self.cfg;
        let mut e = poisson.sample(rng);
        if c.read_noise_e > 0.0 {
            e += c.read_noise_e * rng.sample::<f64, _>(StandardNormal);
        }
        e += offset;
        let dn = c.gain_dn_per_e * e.min(c.full_well_e) + c.black_offset_dn;
        poisson::fast_floor(dn.clamp(0.0, self.max_dn()) + 0.5)
    }
}

#[cfg(test)]
mod tests;
