//! How good the imaged patterns are: per channel the error against the ideal sinusoid, the
//! carrier gain, the energy at 2ω_i and in every other channel's crop window, the mask's
//! throughput; PNGs of the patterns and their spectra; and the dithering study.

use serde::Serialize;
use specmux_core::carriers::window_bins;
use specmux_core::carriers::Carrier;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::fft::dft_at;
use specmux_core::fft::Fft2;
use specmux_core::fft::HalfSpectrum;
use specmux_core::Complex64;
use specmux_twin::optics::dither::in_band_error;
use specmux_twin::optics::dither::DitherMethod;
use specmux_twin::optics::fourier_filter::FourierFilterConfig;
use specmux_twin::optics::fourier_filter::Illumination;
use specmux_twin::optics::imaging::simulate_patterns;
use specmux_twin::optics::imaging::stage_names;
use specmux_twin::optics::imaging::OpticsConfig;
use specmux_twin::optics::imaging::PatternSet;
use specmux_twin::optics::light::PatternLight;
use std::path::Path;

/// One channel's figures.
#[derive(Clone, Debug, Serialize)]
pub struct ChannelReport {
    pub fx: f64,
    pub fy: f64,
    /// rms(s̃ − s) / rms(s − 1): the error relative to the carrier's own rms.
    pub rel_rms_error: f64,
    /// rms(s̃ − fit) / rms(s − 1) with fit = DC + 2 Re(ĝ e^{iω·p}): what is left once the
    /// demultiplexer uses the measured gain ĝ (dither noise, 2ω harmonic).
    pub residual_error: f64,
    /// |ĝ| / ½: carrier amplitude of s̃ against the ideal pattern's.
    pub gain: f64,
    /// arg ĝ − φ, radians.
    pub gain_phase_rad: f64,
    /// Energy in a crop window centred on 2ω_i, relative to the energy in the carrier's window.
    pub harmonic_2w: f64,
    /// Energy in each channel's crop window relative to this channel's own (1 on the diagonal).
    pub crosstalk: Vec<f64>,
    /// Light passed by the Fourier mask (see `PatternSet::throughput`).
    pub throughput: f64,
    /// In-band error of the displayed pattern against the grey target, on the mirror grid.
    pub in_band_error: Option<f64>,
}

/// The report for one rig and carrier set.
#[derive(Clone, Debug, Serialize)]
pub struct PatternReport {
    pub stages: Vec<String>,
    pub width: usize,
    pub height: usize,
    pub crop: f64,
    pub channels: Vec<ChannelReport>,
    /// Largest off-diagonal crosstalk.
    pub worst_crosstalk: f64,
}

/// Σ|Y|² over the window of `wx × wy` bins centred on (cx, cy).
fn window_energy(spec: &HalfSpectrum, cx: i64, cy: i64, wx: usize, wy: usize) -> f64 {
    let (x0, y0) = (cx - (wx / 2) as i64, cy - (wy / 2) as i64);
    let mut e = 0.0;
    for dx in 0..wx as i64 {
        for dy in 0..wy as i64 {
            e += spec.at(x0 + dx, y0 + dy).norm_sqr() as f64;
        }
    }
    e
}

/// Simulate the patterns and measure them.
pub fn pattern_report(
    cfg: &OpticsConfig,
    carriers: &[Carrier],
    lights: &[PatternLight],
    w: usize,
    h: usize,
    crop: f64,
) -> Result<(PatternReport, PatternSet)> {
    if !(crop > 0.0 && crop <= 0.5) {
        return Err(Error::config(
            specmux_core::error::UNNAMED_FILE,
            "reconstruct.crop",
            crop,
            "must lie in (0, 0.5]",
        ));
    }
    let set = simulate_patterns(cfg, carriers, lights, w, h)?;
    let fft = Fft2::new(w, h);
    let (wx, wy) = (window_bins(crop, w).max(1), window_bins(crop, h).max(1));
    let bins: Vec<(i64, i64)> = carriers
        .iter()
        .map(|c| (Carrier::bin(c.fx, w), Carrier::bin(c.fy, h)))
        .collect();
    let mut channels = Vec::new();
    for (i, c) in carriers.iter().enumerate() {
        let s = set.imaged.plane(i);
        let ideal = c.ideal_pattern(w, h);
        let (mut num, mut den) = (0.0, 0.0);
        for (a, b) in s.iter().zip(&ideal) {
            num += ((a - b) as f64).powi(2);
            den += ((b - 1.0) as f64).powi(2);
        }
        let g = dft_at(s, w, h, bins[i].0, bins[i].1);
        let dc = dft_at(s, w, h, 0, 0).re;
        let tau = std::f64::consts::TAU;
        let mut res = 0.0;
        for (p, &v) in s.iter().enumerate() {
            let (x, y) = ((p % w) as f64, (p / w) as f64);
            let e = Complex64::from_polar(
                1.0,
                tau * (bins[i].0 as f64 * x / w as f64 + bins[i].1 as f64 * y / h as f64),
            );
            res += (v as f64 - dc - 2.0 * (g * e).re).powi(2);
        }
        let spec = fft.forward(s);
        let own = window_energy(&spec, bins[i].0, bins[i].1, wx, wy).max(f64::MIN_POSITIVE);
        let crosstalk = bins
            .iter()
            .map(|&(bx, by)| window_energy(&spec, bx, by, wx, wy) / own)
            .collect();
        let harmonic_2w = window_energy(&spec, 2 * bins[i].0, 2 * bins[i].1, wx, wy) / own;
        let in_band = match (&set.masks[i], &cfg.dmd) {
            (Some(mk), Some(d)) => Some(in_band_error(
                set.display.plane(i),
                set.targets.plane(i),
                d.width,
                d.height,
                &|fx, fy| mk.at_periodic(fx, fy),
            )),
            _ => None,
        };
        channels.push(ChannelReport {
            fx: c.fx,
            fy: c.fy,
            rel_rms_error: (num / den.max(f64::MIN_POSITIVE)).sqrt(),
            residual_error: (res / den.max(f64::MIN_POSITIVE)).sqrt(),
            gain: g.norm() / 0.5,
            gain_phase_rad: (g.arg() - c.phase_rad + std::f64::consts::PI)
                .rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI,
            harmonic_2w,
            crosstalk,
            throughput: set.throughput[i],
            in_band_error: in_band,
        });
    }
    let worst_crosstalk = channels
        .iter()
        .enumerate()
        .flat_map(|(i, c)| {
            c.crosstalk
                .iter()
                .enumerate()
                .filter(move |(j, _)| *j != i)
                .map(|(_, v)| *v)
        })
        .fold(0.0, f64::max);
    Ok((
        PatternReport {
            stages: stage_names(cfg, w, h),
            width: w,
            height: h,
            crop,
            channels,
            worst_crosstalk,
        },
        set,
    ))
}

/// pattern_{i}.png for every channel: the displayed and the imaged pattern with their Fourier
/// planes, on axes, with colour bars (`panel::pattern_png`).
pub fn write_pattern_pngs(set: &PatternSet, carriers: &[Carrier], dir: &Path) -> Result<()> {
    let (dw, dh) = (set.display.width, set.display.height);
    let (w, h) = (set.imaged.width, set.imaged.height);
    for (i, c) in carriers.iter().enumerate().take(set.imaged.planes) {
        crate::panel::pattern_png(
            &dir.join(format!("pattern_{i}.png")),
            &format!(
                "Pattern {i}: carrier ({:.4}, {:.4}) cycles/pixel on the sensor",
                c.fx, c.fy
            ),
            (set.display.plane(i), dw, dh),
            (set.imaged.plane(i), w, h),
        )?;
    }
    Ok(())
}

/// One row of the dithering study.
#[derive(Clone, Debug, Serialize)]
pub struct StudyRow {
    pub dither: &'static str,
    pub pinhole_radius_um: f64,
    pub illumination: Illumination,
    /// Mean over channels of the in-band error on the mirror grid.
    pub in_band_error: f64,
    /// Mean over channels of rms(s̃ − s)/rms(s − 1).
    pub pattern_error: f64,
    /// Mean over channels of the residual after the measured gain (see `ChannelReport`).
    pub residual_error: f64,
    /// Carrier gains (min, max) over channels.
    pub gain_min: f64,
    pub gain_max: f64,
    /// Largest energy in another channel's window relative to the channel's own.
    pub worst_crosstalk: f64,
}

/// Every dithering method × pinhole radius × illumination on `base` (its DMD, lens and 4f
/// settings other than radius and illumination), for `carriers` on a `w × h` sensor.
pub fn dither_study(
    base: &OpticsConfig,
    carriers: &[Carrier],
    lights: &[PatternLight],
    w: usize,
    h: usize,
    crop: f64,
    radii_um: &[f64],
) -> Result<Vec<StudyRow>> {
    let mut rows = Vec::new();
    for &r in radii_um {
        for ill in [Illumination::Coherent, Illumination::Incoherent] {
            for m in DitherMethod::ALL {
                let mut cfg = base.clone();
                let mut d = cfg.dmd.clone().unwrap_or_default();
                d.dither = m;
                cfg.dmd = Some(d);
                let f = cfg.fourier_filter.clone().unwrap_or_default();
                cfg.fourier_filter = Some(FourierFilterConfig {
                    pinhole_radius_um: r,
                    illumination: ill,
                    ..f
                });
                let (rep, _) = pattern_report(&cfg, carriers, lights, w, h, crop)?;
                let n = rep.channels.len().max(1) as f64;
                rows.push(StudyRow {
                    dither: m.name(),
                    pinhole_radius_um: r,
                    illumination: ill,
                    in_band_error: rep
                        .channels
                        .iter()
                        .filter_map(|c| c.in_band_error)
                        .sum::<f64>()
                        / n,
                    pattern_error: rep.channels.iter().map(|c| c.rel_rms_error).sum::<f64>() / n,
                    residual_error: rep.channels.iter().map(|c| c.residual_error).sum::<f64>() / n,
                    gain_min: rep.channels.iter().map(|c| c.gain).fold(f64::MAX, f64::min),
                    gain_max: rep.channels.iter().map(|c| c.gain).fold(0.0, f64::max),
                    worst_crosstalk: rep.worst_crosstalk,
                });
            }
        }
    }
    Ok(rows)
}

/// The study as a Markdown table.
pub fn study_table(rows: &[StudyRow]) -> String {
    let mut s = String::from("| dither | pinhole µm | light | in-band error | pattern error | residual after gain | gain min–max | worst crosstalk |\n|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        s += &format!(
            "| {} | {:.1} | {:?} | {:.4} | {:.4} | {:.4} | {:.3}–{:.3} | {:.2e} |\n",
            r.dither,
            r.pinhole_radius_um,
            r.illumination,
            r.in_band_error,
            r.pattern_error,
            r.residual_error,
            r.gain_min,
            r.gain_max,
            r.worst_crosstalk
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use specmux_core::carriers::default_layout;
    use specmux_twin::optics::dmd::DmdConfig;
    use specmux_twin::optics::psf::LensConfig;

    /// The 532 nm line for `n` patterns.
    fn line(n: usize) -> Vec<PatternLight> {
        vec![PatternLight::Line(532.0); n]
    }

    fn small_rig() -> OpticsConfig {
        OpticsConfig {
            dmd: Some(DmdConfig {
                width: 128,
                height: 128,
                ..Default::default()
            }),
            fourier_filter: Some(FourierFilterConfig {
                pinhole_radius_um: 6.0 / 128.0 * 53_200.0 / 13.68,
                ..Default::default()
            }),
            lens: Some(LensConfig::default()),
        }
    }

    #[test]
    fn ideal_patterns_report_no_error_and_no_crosstalk() {
        let (rep, _) = pattern_report(
            &OpticsConfig::default(),
            &default_layout(),
            &line(6),
            64,
            64,
            0.25,
        )
        .unwrap();
        for (i, c) in rep.channels.iter().enumerate() {
            assert!(
                c.rel_rms_error < 1e-6 && (c.gain - 1.0).abs() < 1e-6,
                "{c:?}"
            );
            assert!((c.crosstalk[i] - 1.0).abs() < 1e-12);
            assert!(c.harmonic_2w < 1e-10);
        }
        assert!(rep.worst_crosstalk < 1e-10, "{}", rep.worst_crosstalk);
    }

    #[test]
    fn study_shows_in_band_feedback_ahead_of_floyd_steinberg() {
        let radius = 6.0 / 128.0 * 53_200.0 / 13.68;
        let rows = dither_study(
            &small_rig(),
            &default_layout(),
            &line(6),
            128,
            128,
            0.25,
            &[radius],
        )
        .unwrap();
        assert_eq!(rows.len(), 2 * DitherMethod::ALL.len());
        eprintln!("{}", study_table(&rows));
        for ill in [Illumination::Coherent, Illumination::Incoherent] {
            let get = |m: &str| {
                rows.iter()
                    .find(|r| r.dither == m && r.illumination == ill)
                    .unwrap()
                    .clone()
            };
            let (fs, ours) = (get("floyd-steinberg"), get("in-band-feedback"));
            assert!(
                ours.in_band_error < 0.5 * fs.in_band_error,
                "{ours:?} vs {fs:?}"
            );
            // The residual also holds the 2ω harmonic (coherent) that no dither removes.
            assert!(
                ours.residual_error < fs.residual_error,
                "{ours:?} vs {fs:?}"
            );
        }
    }

    #[test]
    fn pngs_are_written() {
        let scratch = tempfile::Builder::new()
            .prefix("specmux-patterns-")
            .tempdir()
            .unwrap();
        let dir = scratch.path();
        let (_, set) =
            pattern_report(&small_rig(), &default_layout()[..2], &line(2), 64, 64, 0.25).unwrap();
        write_pattern_pngs(&set, &default_layout()[..2], dir).unwrap();
        let img = image::open(dir.join("pattern_1.png")).unwrap();
        // Four panels with axes and colour bars, each wider than the 128-mirror pattern.
        assert!(img.width() > 4 * 128 && img.height() > 2 * 128, "{img:?}");
        assert!(!dir.join("pattern_2.png").exists());
    }
}
