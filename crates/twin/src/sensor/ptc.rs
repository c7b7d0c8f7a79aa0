//! The EMVA 1288 photon-transfer measurement, run on the simulated camera as a lab would run it
//! on the real one: pairs of flat frames at increasing light, a dark pair, and averaged frames
//! for the spatial non-uniformities. Model (EMVA 1288 release 3.1, section 2):
//! μ_y = μ_y.dark + K·μ_e and σ_y² = K²σ_d² + σ_q² + K(μ_y − μ_y.dark), σ_q² = 1/12 DN².

use crate::sensor::Sensor;
use crate::sensor::Stream;
use serde::Serialize;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::Cube;

/// Frames averaged for the DSNU and PRNU measurement (EMVA 1288 asks for a sequence of L frames
/// so that the temporal noise left in the average, σ_y²/L, is small next to the spatial one).
pub const NONUNIFORMITY_FRAMES: usize = 16;

/// Quantisation noise of a uniform rounding ADC (DN²).
const QUANTISATION_VARIANCE_DN2: f64 = 1.0 / 12.0;

/// Below this dark variance (DN²) the read noise is not resolved by the ADC (EMVA 1288 3.1:
/// σ_y.dark² < 0.24 DN²); the read noise reported is then only indicative.
const QUANTISATION_LIMIT_DN2: f64 = 0.24;

/// Upper end of the linear fit range as a fraction of the saturation signal above dark (EMVA
/// 1288 3.1: 0 … 70 % of μ_y.sat − μ_y.dark).
const FIT_RANGE_FRACTION: f64 = 0.7;

/// One level of the photon-transfer curve.
#[derive(Clone, Debug, Serialize)]
pub struct PtcPoint {
    /// Mean photo-electrons asked of the light source (before PRNU).
    pub level_e: f64,
    /// μ_y: mean of the pair (DN).
    pub mean_dn: f64,
    /// σ_y²: temporal variance, var(A − B)/2 (DN²).
    pub variance_dn2: f64,
}

/// What the photon-transfer measurement finds.
#[derive(Clone, Debug, Serialize)]
pub struct PtcResult {
    /// Overall system gain K (DN/e⁻): slope of σ_y² − σ_y.dark² against μ_y − μ_y.dark.
    pub k_dn_per_e: f64,
    /// Standard error of K from the sampling variance of each σ_y², 2σ_y⁴/(N − 1).
    pub k_stderr_dn_per_e: f64,
    /// Intercept of the fitted line (DN²); near zero when the model holds.
    pub fit_offset_dn2: f64,
    /// Upper end of the fit range, μ_y − μ_y.dark (DN).
    pub fit_max_signal_dn: f64,
    /// Temporal dark noise σ_d = √(σ_y.dark² − σ_q²)/K (e⁻): read noise and dark-current shot
    /// noise together, as EMVA 1288 defines it.
    pub read_noise_e: f64,
    /// True when σ_y.dark² < 0.24 DN²: the ADC does not resolve the dark noise.
    pub quantisation_limited: bool,
    /// Saturation capacity μ_e.sat = (μ_y.sat − μ_y.dark)/K (e⁻), μ_y.sat at the maximum of the
    /// variance curve.
    pub full_well_e: f64,
    /// μ_y.sat (DN).
    pub saturation_mean_dn: f64,
    /// μ_y.dark and σ_y.dark² of the dark pair.
    pub dark_mean_dn: f64,
    pub dark_variance_dn2: f64,
    /// PRNU1288: √(s_y.50² − s_y.dark²)/(μ_y.50 − μ_y.dark), at the level nearest 50 % saturation.
    pub prnu_fraction: f64,
    /// DSNU1288: s_y.dark/K (e⁻).
    pub dsnu_e: f64,
    /// Level (e⁻) used for the PRNU.
    pub prnu_level_e: f64,
    /// Frames averaged for DSNU and PRNU.
    pub nonuniformity_frames: usize,
    /// Pixels per frame.
    pub pixels: usize,
    /// The curve, dark pair excluded, in increasing level.
    pub points: Vec<PtcPoint>,
}

/// Mean of a pair and its temporal variance var(A − B)/2, free of fixed-pattern noise.
pub(super) fn pair_statistics(a: &Cube, b: &Cube) -> (f64, f64) {
    let n = a.data.len() as f64;
    let (mut sum, mut sum_d, mut sum_d2) = (0f64, 0f64, 0f64);
    for (&x, &y) in a.data.iter().zip(&b.data) {
        let d = x as f64 - y as f64;
        sum += x as f64 + y as f64;
        sum_d += d;
        sum_d2 += d * d;
    }
    let var_d = (sum_d2 - sum_d * sum_d / n) / (n - 1.0);
    (sum / (2.0 * n), var_d / 2.0)
}

/// Mean and spatial variance (N − 1 normalised) of a frame.
fn spatial_statistics(c: &Cube) -> (f64, f64) {
    let n = c.data.len() as f64;
    let mean = c.data.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = c
        .data
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0);
    (mean, var)
}

/// Levels for a photon-transfer curve of a camera with this full well: 27 even steps up to 90 %
/// of it, then 26 steps of 1/150 of it past saturation, where the variance curve turns over.
pub fn default_levels(full_well_e: f64) -> Vec<f64> {
    let coarse = full_well_e / 30.0;
    let fine = full_well_e / 150.0;
    let mut levels: Vec<f64> = (1..=27).map(|i| i as f64 * coarse).collect();
    levels.extend((1..=26).map(|i| 27.0 * coarse + i as f64 * fine));
    levels
}

/// Run the EMVA 1288 photon-transfer measurement at mean photo-electron `levels` (before PRNU).
/// The levels must climb past saturation so that the variance curve has its maximum inside.
pub fn photon_transfer(sensor: &Sensor, levels: &[f64]) -> Result<PtcResult> {
    let levels = checked_levels(levels)?;
    let pixels = sensor.width * sensor.height;
    if pixels < 2 {
        return Err(Error::Shape(
            "photon transfer needs at least two pixels".into(),
        ));
    }
    let (dark, points) = curve(sensor, &levels);
    let sat = saturation(&points)?;
    let sat_signal = points[sat].mean_dn - dark.mean_dn;
    let fit = fit_gain(&points, &dark, sat_signal, pixels)?;
    let k = fit.k;
    let nu = nonuniformities(sensor, &points, &dark, sat, sat_signal)?;
    let (dark_mean, dark_var) = (dark.mean_dn, dark.variance_dn2);
    Ok(PtcResult {
        k_dn_per_e: k,
        k_stderr_dn_per_e: fit.var_k.sqrt(),
        fit_offset_dn2: fit.offset_dn2,
        fit_max_signal_dn: fit.max_signal_dn,
        read_noise_e: (dark_var - QUANTISATION_VARIANCE_DN2).max(0.0).sqrt() / k,
        quantisation_limited: dark_var < QUANTISATION_LIMIT_DN2,
        full_well_e: sat_signal / k,
        saturation_mean_dn: points[sat].mean_dn,
        dark_mean_dn: dark_mean,
        dark_variance_dn2: dark_var,
        prnu_fraction: (nu.s2_half - nu.s2_dark).max(0.0).sqrt()
            / (nu.flat_mean - nu.dark_avg_mean),
        dsnu_e: nu.s2_dark.max(0.0).sqrt() / k,
        prnu_level_e: points[nu.half].level_e,
        nonuniformity_frames: NONUNIFORMITY_FRAMES,
        pixels,
        points,
    })
}

/// The levels sorted and deduplicated; refuses a level that is not finite and positive, and
/// fewer than 5 distinct levels (a line through the linear range needs them).
fn checked_levels(levels: &[f64]) -> Result<Vec<f64>> {
    if let Some(v) = levels.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
        return Err(Error::Numerical(format!(
            "photon transfer: level {v} e⁻; levels must be finite and > 0 (the dark pair is taken anyway)"
        )));
    }
    let mut levels = levels.to_vec();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    if levels.len() < 5 {
        return Err(Error::Numerical(format!(
            "photon transfer needs at least 5 distinct light levels, got {}",
            levels.len()
        )));
    }
    Ok(levels)
}

/// The dark pair and one pair of flat frames per level, each reduced to its mean and temporal
/// variance (pair i on its own noise stream, so the draws do not depend on the other levels).
fn curve(sensor: &Sensor, levels: &[f64]) -> (PtcPoint, Vec<PtcPoint>) {
    let point = |index: usize, level_e: f64| {
        let [a, b] = pair(sensor, index, level_e);
        let (mean_dn, variance_dn2) = pair_statistics(&a, &b);
        PtcPoint {
            level_e,
            mean_dn,
            variance_dn2,
        }
    };
    let dark = point(0, 0.0);
    let points = (levels.iter().enumerate())
        .map(|(i, &level)| point(i + 1, level))
        .collect();
    (dark, points)
}

/// Pair `index` of the curve (0: the dark pair) at `level_e` mean photo-electrons (DN).
fn pair(sensor: &Sensor, index: usize, level_e: f64) -> [Cube; 2] {
    let mean_e = vec![level_e as f32; sensor.width * sensor.height];
    let index = index as u64;
    [0, 1].map(|k| sensor.expose(&mean_e, Stream::PhotonTransfer, 2 * index + k))
}

/// The raw frames of a photon-transfer measurement, for an outside analysis (the EMVA 1288
/// reference code): the same frames [`photon_transfer`] reduces.
pub struct PtcFrames {
    /// (level e⁻, pair) in increasing level, the dark pair first at level 0.
    pub pairs: Vec<(f64, [Cube; 2])>,
    /// The dark frames [`Sensor::dark_frame`] averages for the DSNU.
    pub dark_sequence: Vec<Cube>,
    /// The level nearest 50 % saturation and the flat frames averaged there for the PRNU.
    pub flat_sequence: (f64, Vec<Cube>),
}

/// The frames behind `result` (measured at `levels` on `sensor`), for an outside referee.
pub fn ptc_frames(sensor: &Sensor, levels: &[f64], result: &PtcResult) -> Result<PtcFrames> {
    let levels = checked_levels(levels)?;
    let l = result.nonuniformity_frames;
    let half = result.prnu_level_e;
    Ok(PtcFrames {
        pairs: std::iter::once(0.0)
            .chain(levels)
            .enumerate()
            .map(|(i, level)| (level, pair(sensor, i, level)))
            .collect(),
        dark_sequence: (0..l).map(|k| sensor.dark_exposure(k)).collect(),
        flat_sequence: (
            half,
            (0..l)
                .map(|k| sensor.flat_exposure(half, k))
                .collect::<Result<_>>()?,
        ),
    })
}

/// Saturation: the index of the variance curve's maximum, which must lie inside the series.
fn saturation(points: &[PtcPoint]) -> Result<usize> {
    let sat = (0..points.len())
        .max_by(|&i, &j| points[i].variance_dn2.total_cmp(&points[j].variance_dn2))
        .ok_or_else(|| Error::Numerical("photon transfer: no light level".into()))?;
    if sat + 1 == points.len() {
        return Err(Error::Numerical(format!(
            "photon transfer: the variance still rises at the brightest level ({} e⁻); add levels \
             beyond the full well",
            points[sat].level_e
        )));
    }
    Ok(sat)
}

/// The fitted line σ_y² − σ_y.dark² = K·(μ_y − μ_y.dark) + offset.
struct GainFit {
    k: f64,
    /// Sampling variance of K.
    var_k: f64,
    offset_dn2: f64,
    /// Upper end of the fit range, μ_y − μ_y.dark (DN).
    max_signal_dn: f64,
}

/// K: least squares of y = σ_y² − σ_y.dark² on x = μ_y − μ_y.dark over 0 … 70 % of saturation,
/// with its standard error from the sampling variance of each σ_y².
fn fit_gain(
    points: &[PtcPoint],
    dark: &PtcPoint,
    sat_signal: f64,
    pixels: usize,
) -> Result<GainFit> {
    let fit_max = FIT_RANGE_FRACTION * sat_signal;
    let fit: Vec<(f64, f64, f64)> = points
        .iter()
        .map(|p| {
            (
                p.mean_dn - dark.mean_dn,
                p.variance_dn2 - dark.variance_dn2,
                p.variance_dn2,
            )
        })
        .filter(|&(x, _, _)| x > 0.0 && x <= fit_max)
        .collect();
    if fit.len() < 3 {
        return Err(Error::Numerical(format!(
            "photon transfer: {} levels fall in the linear range (0–70 % of saturation, ≤ {:.1} DN \
             above dark); at least 3 are needed",
            fit.len(),
            fit_max
        )));
    }
    let m = fit.len() as f64;
    let x_mean = fit.iter().map(|f| f.0).sum::<f64>() / m;
    let y_mean = fit.iter().map(|f| f.1).sum::<f64>() / m;
    let sxx: f64 = fit.iter().map(|f| (f.0 - x_mean).powi(2)).sum();
    let sxy: f64 = fit.iter().map(|f| (f.0 - x_mean) * (f.1 - y_mean)).sum();
    let k = sxy / sxx;
    if !(k.is_finite() && k > 0.0) {
        return Err(Error::Numerical(format!(
            "photon transfer: fitted gain K = {k} DN/e⁻ is not positive"
        )));
    }
    // Var(σ̂²) = 2σ⁴/(N − 1) for a sample variance of N near-Gaussian differences; the dark
    // variance is common to all points and moves only the intercept.
    let var_k: f64 = fit
        .iter()
        .map(|f| (f.0 - x_mean).powi(2) * 2.0 * f.2.powi(2) / (pixels as f64 - 1.0))
        .sum::<f64>()
        / (sxx * sxx);
    Ok(GainFit {
        k,
        var_k,
        offset_dn2: y_mean - k * x_mean,
        max_signal_dn: fit_max,
    })
}

/// Spatial statistics of averaged dark and flat frames, for DSNU and PRNU.
struct Nonuniformities {
    dark_avg_mean: f64,
    /// s_y.dark²: the dark frame's spatial variance, its temporal part σ_y²/L taken out.
    s2_dark: f64,
    /// The level nearest 50 % saturation, and the flat frame's mean and spatial variance there.
    half: usize,
    flat_mean: f64,
    s2_half: f64,
}

/// Non-uniformities from frames averaged over [`NONUNIFORMITY_FRAMES`], dark and at the level
/// nearest 50 % of saturation, the temporal part σ_y²/L taken out.
fn nonuniformities(
    sensor: &Sensor,
    points: &[PtcPoint],
    dark: &PtcPoint,
    sat: usize,
    sat_signal: f64,
) -> Result<Nonuniformities> {
    let l = NONUNIFORMITY_FRAMES;
    let (dark_avg_mean, dark_avg_var) = spatial_statistics(&sensor.dark_frame(l)?);
    let s2_dark = dark_avg_var - dark.variance_dn2 / l as f64;
    let half = (0..sat)
        .min_by(|&i, &j| {
            let d = |p: &PtcPoint| (p.mean_dn - dark.mean_dn - 0.5 * sat_signal).abs();
            d(&points[i]).total_cmp(&d(&points[j]))
        })
        .unwrap_or(0);
    let (flat_mean, flat_var) = spatial_statistics(&sensor.flat_frame(points[half].level_e, l)?);
    Ok(Nonuniformities {
        dark_avg_mean,
        s2_dark,
        half,
        flat_mean,
        s2_half: flat_var - points[half].variance_dn2 / l as f64,
    })
}
