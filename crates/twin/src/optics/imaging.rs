//! The pattern as really imaged, s̃_i: the grey target s_i/2 on the mirror grid, dithered by the
//! DMD, filtered by the 4f pinhole mask (coherent or incoherent), imaged onto the sample by the
//! projection lens and integrated by the sensor pixels, resampled onto the sensor grid, and
//! normalised by its mean so that an ideal path returns exactly 1 + cos(ω_i·p + φ_i).
//!
//! Sampling. The mirror grid's spectrum is periodic (B(f mod 1) times the mirror envelope), so
//! the light past the mask is computed on a grid `oversample` times finer than the mirrors,
//! fine enough that the intensity (whose band is twice the mask's extent: the 2ω_i term) does
//! not alias. When an opening spans fewer than `MIN_PINHOLE_BINS` frequency bins the pattern
//! is zero-padded `pad` times (a dark frame around the DMD) to refine the Fourier plane; when
//! the grid this needs is too large the call is refused naming `pinhole_radius_um`.

use crate::optics::dither::signed_bin;
use crate::optics::dmd::DmdConfig;
use crate::optics::fourier_filter::Aperture;
use crate::optics::fourier_filter::FourierFilterConfig;
use crate::optics::fourier_filter::Illumination;
use crate::optics::fourier_filter::Light;
use crate::optics::fourier_filter::Mask;
use crate::optics::light::PatternLight;
use crate::optics::psf::LensConfig;
use crate::optics::relay::passed_bins;
use crate::optics::relay::CpuPairSums;
use crate::optics::relay::PairSummer;
use crate::optics::relay::PairSums;
use crate::optics::relay::PassedBin;
use rayon::prelude::*;
use rustfft::num_complex::{Complex32, Complex64};
use serde::{Deserialize, Serialize};
use specmux_core::carriers::Carrier;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::error::UNNAMED_FILE;
use specmux_core::fft::{Fft2, HalfSpectrum};
use specmux_core::spectral::Curve;
use specmux_core::Cube;
use std::sync::Arc;

/// An opening must span at least this many frequency bins in radius, else the grid is refined.
pub const MIN_PINHOLE_BINS: f64 = 4.0;
/// Largest fine simulation grid side (8192² f32 pixels ≈ 270 MB per buffer).
pub const MAX_GRID: usize = 8192;
/// The version of the patterns' physics: part of every pattern-cache key, so a change that is
/// meant to change the imaged patterns (and the checksums of `tests/imaged_reference.rs`,
/// which record it) makes every cached pattern set a miss.
pub const MODEL: u32 = 1;

/// The optical stages between the carriers and the sensor; an absent one is not simulated.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OpticsConfig {
    pub dmd: Option<DmdConfig>,
    pub fourier_filter: Option<FourierFilterConfig>,
    pub lens: Option<LensConfig>,
}

impl OpticsConfig {
    /// The 2019 prototype: every stage present with its defaults.
    pub fn prototype() -> OpticsConfig {
        OpticsConfig {
            dmd: Some(DmdConfig::default()),
            fourier_filter: Some(FourierFilterConfig::default()),
            lens: Some(LensConfig::default()),
        }
    }

    pub fn validate(&self, file: &str) -> Result<()> {
        if let Some(d) = &self.dmd {
            d.validate(file)?;
            if d.dither == super::dither::DitherMethod::InBandFeedback
                && self.fourier_filter.is_none()
            {
                return Err(Error::config(file, "rig.dmd.dither", "\"in-band-feedback\"", "needs a [rig.fourier_filter] section: its passband is what the method optimises"));
            }
        }
        if let Some(f) = &self.fourier_filter {
            f.validate(file)?;
        }
        if let Some(l) = &self.lens {
            l.validate(file)?;
        }
        Ok(())
    }

    /// The light of each pattern: a line for every pattern with `light = "line"`, else the
    /// pattern's own band, `spectra[i]` (T_i·L·QE of its wheel segment).
    pub fn pattern_lights(&self, spectra: &[Curve]) -> Result<Vec<PatternLight>> {
        match &self.fourier_filter {
            Some(f) if f.light == Light::Line => {
                Ok(vec![PatternLight::Line(f.wavelength_nm); spectra.len()])
            }
            _ => spectra.iter().map(PatternLight::band).collect(),
        }
    }

    /// The DMD, or without one an ideal grey modulator (fill 1) covering the sensor's field.
    fn modulator(&self, w: usize, h: usize) -> DmdConfig {
        self.dmd.clone().unwrap_or_else(|| {
            let d = DmdConfig::default();
            let s = self
                .lens
                .as_ref()
                .map_or(1.0, |l| l.sensor_pixels_per_mirror(d.pitch_um));
            DmdConfig {
                width: (w as f64 / s).ceil() as usize,
                height: (h as f64 / s).ceil() as usize,
                fill_factor: 1.0,
                ..d
            }
        })
    }
}

/// One line per optical stage that will run (for the pattern report).
pub fn stage_names(cfg: &OpticsConfig, sensor_w: usize, sensor_h: usize) -> Vec<String> {
    let m = cfg.modulator(sensor_w, sensor_h);
    let mut out = Vec::new();
    match &cfg.dmd {
        Some(d) => out.push(format!("dmd: {}", describe_dmd(d))),
        None if cfg.fourier_filter.is_some() || cfg.lens.is_some() => {
            out.push(format!("modulator: {}", describe_grey_modulator(&m)))
        }
        None => out.push("patterns: ideal grey sinusoids 1 + cos(ω·p + φ)".into()),
    }
    if let Some(f) = &cfg.fourier_filter {
        out.push(format!("fourier-filter: {}", describe_filter(f, &m)));
    }
    if let Some(l) = &cfg.lens {
        out.push(format!("lens: {}", describe_lens(l, &m)));
    }
    out
}

/// What the DMD shows, in one line.
pub fn describe_dmd(d: &DmdConfig) -> String {
    format!(
        "{}×{} mirrors, {} µm pitch, fill {}, dither {}",
        d.width,
        d.height,
        d.pitch_um,
        d.fill_factor,
        d.dither.name()
    )
}

/// The ideal grey modulator that stands in for a DMD, in one line.
pub fn describe_grey_modulator(m: &DmdConfig) -> String {
    format!(
        "ideal grey, {}×{} pixels of {} µm",
        m.width, m.height, m.pitch_um
    )
}

/// The 4f relay's Fourier filter on modulator `m`, in one line.
pub fn describe_filter(f: &FourierFilterConfig, m: &DmdConfig) -> String {
    let light = match f.light {
        Light::Channel => "each pattern's wheel band, exact over λ".to_string(),
        Light::Line => format!("a {} nm line", f.wavelength_nm),
    };
    format!(
        "{:?} light, {light}, f = {} mm, {:?} openings of {} µm ({:.4} cycles/mirror at 550 nm) at 0, ±ω",
        f.illumination, f.focal_length_mm, f.shape, f.pinhole_radius_um,
        f.cycles_per_mirror(f.pinhole_radius_um, m.pitch_um, 550.0)
    )
}

/// The projection lens and pixel integration on modulator `m`, in one line.
pub fn describe_lens(l: &LensConfig, m: &DmdConfig) -> String {
    format!(
        "NA {} Airy OTF over each pattern's light, magnification {}, {:.3} sensor pixels per mirror, pixel integration",
        l.na, l.magnification, l.sensor_pixels_per_mirror(m.pitch_um)
    )
}

/// Everything computed for a set of patterns, for the report and the PNGs.
#[derive(Clone, Debug)]
pub struct PatternSet {
    /// What the modulator shows (binary with a DMD, the grey target without), one plane each.
    pub display: Cube,
    /// The grey targets s_i/2 on the modulator grid.
    pub targets: Cube,
    /// s̃_i at sensor resolution, normalised (see the module doc).
    pub imaged: Cube,
    /// Light passed by the mask (1 without a filter): coherent, the fraction of the field's
    /// energy; incoherent, the open fraction of the mirror grid's frequency band.
    pub throughput: Vec<f64>,
    /// The mask's passband on the mirror grid for each pattern (None without a filter).
    pub masks: Vec<Option<Mask>>,
    /// Zero-padding and oversampling factors used for each pattern.
    pub grid: Vec<(usize, usize)>,
}

/// s̃_i, one plane per carrier at `sensor_w × sensor_h`, pattern i formed by `lights[i]`. With
/// every stage absent this is exactly `Carrier::ideal_pattern`.
pub fn imaged_patterns(
    cfg: &OpticsConfig,
    carriers: &[Carrier],
    lights: &[PatternLight],
    sensor_w: usize,
    sensor_h: usize,
) -> Result<Cube> {
    Ok(simulate_patterns(cfg, carriers, lights, sensor_w, sensor_h)?.imaged)
}

/// The whole computation behind [`imaged_patterns`]: the steps of [`Chain`], pattern by pattern.
pub fn simulate_patterns(
    cfg: &OpticsConfig,
    carriers: &[Carrier],
    lights: &[PatternLight],
    w: usize,
    h: usize,
) -> Result<PatternSet> {
    let chain = Chain::new(cfg, carriers, lights, w, h)?;
    let n = carriers.len();
    if cfg.dmd.is_none() && cfg.fourier_filter.is_none() && cfg.lens.is_none() {
        let imaged = Carrier::ideal_patterns(carriers, w, h);
        let display: Vec<f32> = imaged.data.iter().map(|v| v / 2.0).collect();
        return Ok(PatternSet {
            targets: Cube::from_vec(w, h, n, display.clone())?,
            display: Cube::from_vec(w, h, n, display)?,
            imaged,
            throughput: vec![1.0; n],
            masks: vec![None; n],
            grid: vec![(1, 1); n],
        });
    }
    let (wd, hd) = (chain.modulator.width, chain.modulator.height);
    let mut display = Cube::zeros(wd, hd, n);
    let mut targets = Cube::zeros(wd, hd, n);
    let mut imaged = Cube::zeros(w, h, n);
    let (mut throughput, mut masks, mut grid) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let p = chain.image_one(i)?;
        display.plane_mut(i).copy_from_slice(&p.display);
        targets.plane_mut(i).copy_from_slice(&p.target);
        imaged.plane_mut(i).copy_from_slice(&p.imaged);
        throughput.push(p.throughput);
        masks.push(p.mask);
        grid.push((p.pad, p.oversample));
    }
    Ok(PatternSet {
        display,
        targets,
        imaged,
        throughput,
        masks,
        grid,
    })
}

/// The optical chain of a set of patterns, one physical step at a time: the forward pipeline
/// runs each step over every pattern as one stage, [`simulate_patterns`] runs the same steps
/// pattern by pattern, so there is one way to compute a pattern.
pub struct Chain {
    cfg: OpticsConfig,
    /// The DMD, or the ideal grey modulator that stands in for it.
    modulator: DmdConfig,
    carriers: Vec<Carrier>,
    lights: Vec<PatternLight>,
    width: usize,
    height: usize,
    /// Where the relay's pair sums run (the CPU unless [`Chain::with_pair_summer`]).
    pairs: Arc<dyn PairSummer>,
}

impl Chain {
    /// The chain for `carriers` seen by a `w × h` sensor, pattern i formed by `lights[i]`.
    pub fn new(
        cfg: &OpticsConfig,
        carriers: &[Carrier],
        lights: &[PatternLight],
        w: usize,
        h: usize,
    ) -> Result<Chain> {
        cfg.validate(UNNAMED_FILE)?;
        if w < 2 || h < 2 {
            return Err(Error::Shape(format!("sensor {w}×{h}: at least 2×2 pixels")));
        }
        if lights.len() != carriers.len() {
            return Err(Error::Shape(format!(
                "{} pattern lights for {} carriers",
                lights.len(),
                carriers.len()
            )));
        }
        Ok(Chain {
            cfg: cfg.clone(),
            modulator: cfg.modulator(w, h),
            carriers: carriers.to_vec(),
            lights: lights.to_vec(),
            width: w,
            height: h,
            pairs: Arc::new(CpuPairSums),
        })
    }

    /// The chain with its relay's pair sums on `pairs` (`relay::pair_summer_for`).
    pub fn with_pair_summer(self, pairs: Arc<dyn PairSummer>) -> Chain {
        Chain { pairs, ..self }
    }

    /// Where the relay's pair sums run, in words.
    pub fn describe_pairs(&self) -> String {
        self.pairs.describe()
    }

    pub fn config(&self) -> &OpticsConfig {
        &self.cfg
    }

    /// The DMD, or the ideal grey modulator that stands in for it.
    pub fn modulator(&self) -> &DmdConfig {
        &self.modulator
    }

    /// The sensor's size in pixels.
    pub fn sensor_size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Everything the imaged patterns depend on, as text: the crate's version, [`MODEL`], the
    /// optics, the modulator, carriers and lights (f64 in Rust's round-trip form), the sensor's
    /// size and where the pair sums run. Equal keys give bit-identical patterns.
    pub fn cache_key(&self) -> String {
        format!(
            "specmux {} imaging model {MODEL}\n{:?}\n{:?}\n{:?}\n{:?}\nsensor {}x{}, pair sums on the {}",
            env!("CARGO_PKG_VERSION"),
            self.cfg,
            self.modulator,
            self.carriers,
            self.lights,
            self.width,
            self.height,
            self.pairs.device()
        )
    }

    /// Pattern `i` through every step.
    fn image_one(&self, i: usize) -> Result<Imaged> {
        let display = self.dither_one(i)?;
        let pairs = self.pairs.as_ref();
        let relayed = relay(&self.cfg, &self.modulator, &display, &self.lights[i], pairs)?;
        let image = lens(
            self.cfg.lens.as_ref(),
            &self.modulator,
            &relayed,
            &self.lights[i],
        );
        let imaged = pixel_sampling(&image, &self.carriers[i], self.width, self.height)?;
        Ok(Imaged {
            target: display.target,
            display: display.shown,
            imaged,
            throughput: relayed.throughput,
            mask: display.mask,
            pad: relayed.grid.pad,
            oversample: relayed.grid.oversample,
        })
    }

    fn dither_one(&self, i: usize) -> Result<Display> {
        let (c, light) = (&self.carriers[i], &self.lights[i]);
        dither(
            &self.cfg,
            &self.modulator,
            c,
            light,
            self.width,
            self.height,
        )
    }

    /// The patterns whose relay runs on the unpadded grid, each with the blur of its openings
    /// in mirrors (0.61 / their radius at the longest wavelength): that grid treats the
    /// modulator as one period of a periodic pattern, so within the blur of its edges the
    /// pattern is not a finite DMD's (docs/optics.md, "Known defect"). Empty without a filter.
    pub fn periodic_patterns(&self) -> Result<Vec<(usize, f64)>> {
        let Some(f) = &self.cfg.fourier_filter else {
            return Ok(Vec::new());
        };
        let m = &self.modulator;
        let mut out = Vec::new();
        for (i, (c, light)) in self.carriers.iter().zip(&self.lights).enumerate() {
            let g = geometry(self.cfg.lens.as_ref(), m, c, self.width, self.height)?;
            let (ap, grid) = filtered_grid(self.cfg.dmd.is_some(), f, m, &g, light)?;
            if grid.pad == 1 {
                out.push((i, 0.61 / ap.at_wavelength(light.support_nm().1).radius));
            }
        }
        Ok(out)
    }

    /// [`dither`] for every pattern.
    pub fn dither(&self) -> Result<Vec<Display>> {
        // In parallel over the patterns: error diffusion is sequential within one.
        (0..self.carriers.len())
            .into_par_iter()
            .map(|i| self.dither_one(i))
            .collect()
    }

    /// [`relay_filtered`] for every pattern, in parallel over the patterns as well as within each
    /// (its serial parts — the pattern's FFT, sorting the passed bins — then overlap).
    pub fn relay_filtered(
        &self,
        f: &FourierFilterConfig,
        displays: &[Display],
    ) -> Result<Vec<IntensitySpectrum>> {
        let dmd = self.cfg.dmd.as_ref();
        (displays.par_iter().zip(&self.lights))
            .map(|(d, light)| {
                relay_filtered(dmd, f, &self.modulator, d, light, self.pairs.as_ref())
            })
            .collect()
    }

    /// [`relay_open`] for every pattern.
    pub fn relay_open(&self, displays: &[Display]) -> Vec<IntensitySpectrum> {
        let dmd = self.cfg.dmd.as_ref();
        (displays.iter())
            .map(|d| relay_open(dmd, &self.modulator, d))
            .collect()
    }

    /// [`lens`] for every pattern (`None`: no lens, the relay's image unblurred).
    pub fn lens(
        &self,
        lens_cfg: Option<&LensConfig>,
        spectra: &[IntensitySpectrum],
    ) -> Vec<ImageSpectrum> {
        // In parallel over the patterns: folding a spectrum onto the torus is sequential.
        (spectra.par_iter().zip(&self.lights))
            .map(|(s, light)| lens(lens_cfg, &self.modulator, s, light))
            .collect()
    }

    /// [`pixel_sampling`] for every pattern, in parallel: s̃, one plane per carrier.
    pub fn pixel_sampling(&self, images: &[ImageSpectrum]) -> Result<Cube> {
        let (w, h) = (self.width, self.height);
        let planes: Vec<Vec<f32>> = (images.par_iter().zip(&self.carriers))
            .map(|(image, c)| pixel_sampling(image, c, w, h))
            .collect::<Result<_>>()?;
        let mut out = Cube::zeros(w, h, planes.len());
        for (i, plane) in planes.iter().enumerate() {
            out.plane_mut(i).copy_from_slice(plane);
        }
        Ok(out)
    }
}

/// Everything one pattern's chain produced (for [`PatternSet`]).
struct Imaged {
    target: Vec<f32>,
    display: Vec<f32>,
    imaged: Vec<f32>,
    throughput: f64,
    mask: Option<Mask>,
    pad: usize,
    oversample: usize,
}

/// Sensor ↔ mirror coordinates: the sensor's centre sits on the DMD's centre; sensor pixel x
/// lies at mirror u = u_c + σ(x − x_c)/s (σ = −1 for an inverted image, s pixels per mirror).
/// (fxd, fyd) is the carrier in cycles per mirror.
#[derive(Clone, Copy, Debug)]
struct Geometry {
    s: f64,
    sigma: f64,
    uc: f64,
    vc: f64,
    xc: f64,
    yc: f64,
    fxd: f64,
    fyd: f64,
}

impl Geometry {
    fn mirror_of(&self, x: f64, y: f64) -> (f64, f64) {
        (
            self.uc + self.sigma * (x - self.xc) / self.s,
            self.vc + self.sigma * (y - self.yc) / self.s,
        )
    }
    fn sensor_of(&self, u: f64, v: f64) -> (f64, f64) {
        (
            self.xc + self.sigma * (u - self.uc) * self.s,
            self.yc + self.sigma * (v - self.vc) * self.s,
        )
    }
}

/// Where the `w × h` sensor's pixels fall on the modulator `m`, and carrier `c` in cycles per
/// mirror; refuses a modulator that does not cover the sensor or a carrier past its Nyquist.
fn geometry(
    lens: Option<&LensConfig>,
    m: &DmdConfig,
    c: &Carrier,
    w: usize,
    h: usize,
) -> Result<Geometry> {
    let (wd, hd) = (m.width, m.height);
    let (s, sigma) = lens.map_or((1.0, 1.0), |l| {
        (
            l.sensor_pixels_per_mirror(m.pitch_um),
            if l.inverted() { -1.0 } else { 1.0 },
        )
    });
    if w as f64 / s > wd as f64 + 1e-9 || h as f64 / s > hd as f64 + 1e-9 {
        return Err(Error::config(
            UNNAMED_FILE,
            "rig.dmd.width",
            format!("{wd}×{hd} mirrors"),
            &format!("the {w}×{h} sensor sees {:.1}×{:.1} mirrors at {s:.4} pixels per mirror; the DMD must cover it", w as f64 / s, h as f64 / s),
        ));
    }
    let (fxd, fyd) = (sigma * c.fx * s, sigma * c.fy * s);
    if fxd.abs() > 0.5 + 1e-12 || fyd.abs() > 0.5 + 1e-12 {
        return Err(Error::config(
            UNNAMED_FILE,
            "rig.lens.camera_magnification",
            format!("{s:.4} pixels per mirror"),
            &format!("carrier ({}, {}) cycles/pixel is ({fxd:.3}, {fyd:.3}) cycles/mirror, past the DMD's Nyquist limit", c.fx, c.fy),
        ));
    }
    Ok(Geometry {
        s,
        sigma,
        uc: (wd as f64 - 1.0) / 2.0,
        vc: (hd as f64 - 1.0) / 2.0,
        xc: (w as f64 - 1.0) / 2.0,
        yc: (h as f64 - 1.0) / 2.0,
        fxd,
        fyd,
    })
}

/// One pattern on the modulator: the grey target, what the mirrors show, and where they sit.
pub struct Display {
    /// The grey target s_i/2 on the mirror grid.
    pub target: Vec<f32>,
    /// What the modulator shows: the dithered binary pattern with a DMD, the target without.
    pub shown: Vec<f32>,
    /// The Fourier mask at the light's centroid, the passband the dither saw (None: no filter).
    pub mask: Option<Mask>,
    geometry: Geometry,
}

/// The grey target s/2 of carrier `c` on the mirrors of `m`, as a `w × h` sensor sees them through
/// `lens` (none: one pixel per mirror, upright): what a controller dithers into the DMD's picture.
/// Refuses a DMD that does not cover the sensor, or a carrier past the mirrors' Nyquist limit.
pub fn mirror_target(
    lens: Option<&LensConfig>,
    m: &DmdConfig,
    c: &Carrier,
    w: usize,
    h: usize,
) -> Result<Vec<f32>> {
    Ok(grey_target(m, &geometry(lens, m, c, w, h)?, c))
}

/// The grey target s_i/2 on the mirrors, phase referenced to the sensor grid.
fn grey_target(m: &DmdConfig, g: &Geometry, c: &Carrier) -> Vec<f32> {
    let (wd, hd) = (m.width, m.height);
    let tau = std::f64::consts::TAU;
    (0..wd * hd)
        .into_par_iter()
        .map(|p| {
            let (x, y) = g.sensor_of((p % wd) as f64, (p / wd) as f64);
            (0.5 + 0.5 * (tau * (c.fx * x + c.fy * y) + c.phase_rad).cos()) as f32
        })
        .collect()
}

/// Target → what the modulator shows: the DMD dithers the grey target for the mask's passband
/// at the light's centroid (the band the dither can shape); a grey modulator shows it as is.
pub fn dither(
    cfg: &OpticsConfig,
    m: &DmdConfig,
    c: &Carrier,
    light: &PatternLight,
    w: usize,
    h: usize,
) -> Result<Display> {
    let geometry = geometry(cfg.lens.as_ref(), m, c, w, h)?;
    let target = grey_target(m, &geometry, c);
    let mask = cfg.fourier_filter.as_ref().map(|f| {
        f.aperture(m.pitch_um, geometry.fxd, geometry.fyd, light)
            .at_wavelength(light.centroid_nm())
    });
    let passband = |fx: f64, fy: f64| mask.as_ref().map_or(1.0, |mk| mk.at_periodic(fx, fy));
    let shown = match &cfg.dmd {
        Some(d) => d.display(&target, &passband),
        None => target.clone(),
    };
    Ok(Display {
        target,
        shown,
        mask,
        geometry,
    })
}

/// The simulation grid of one pattern: the `wd × hd` mirror grid zero-padded `pad` times (to
/// resolve the openings) and sampled `oversample` times finer (to hold the intensity's band).
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    pub pad: usize,
    pub oversample: usize,
    /// How far the openings reach, cycles per mirror (½ without a filter).
    reach: f64,
    wd: usize,
    hd: usize,
}

impl Grid {
    /// The mirror grid itself: no filter, nothing to resolve.
    fn mirrors(m: &DmdConfig) -> Grid {
        Grid {
            pad: 1,
            oversample: 1,
            reach: 0.5,
            wd: m.width,
            hd: m.height,
        }
    }
    /// The padded mirror grid, on which the relay's spectra are computed.
    fn coarse(&self) -> (usize, usize) {
        (self.pad * self.wd, self.pad * self.hd)
    }
    /// The oversampled grid, on which the image is formed.
    fn fine(&self) -> (usize, usize) {
        let (wc, hc) = self.coarse();
        (self.oversample * wc, self.oversample * hc)
    }
}

/// The grid an aperture needs: padded to resolve the openings at the longest wavelength (the
/// smallest in frequency). The intensity is exact at the grid's nodes (its spectrum is folded
/// onto it); when the sensor pixels fall between mirror nodes the grid is made `oversample`
/// times finer, enough to hold the intensity's band (twice the openings' reach at the shortest
/// wavelength) for the interpolation. Refused past [`MAX_GRID`], naming the pinhole radius.
fn grid(
    dmd: bool,
    m: &DmdConfig,
    g: &Geometry,
    ap: &Aperture,
    light: &PatternLight,
) -> Result<Grid> {
    let (wd, hd) = (m.width, m.height);
    let (l_short, l_long) = light.support_nm();
    let on_node = g.s == 1.0
        && [g.mirror_of(0.0, 0.0), g.mirror_of(1.0, 1.0)]
            .iter()
            .all(|&(u, v)| u.fract() == 0.0 && v.fract() == 0.0);
    let bins = ap.at_wavelength(l_long).radius * wd.min(hd) as f64;
    let pad = (MIN_PINHOLE_BINS / bins).ceil().max(1.0);
    let (ex, ey) = ap.at_wavelength(l_short).extent();
    // A grey modulator has no replicas: nothing beyond its Nyquist band.
    let reach = if dmd { ex.max(ey) } else { ex.max(ey).min(0.5) };
    let os = if on_node {
        1.0
    } else {
        (4.0 * reach).floor() + 1.0
    };
    let side = pad * os * wd.max(hd) as f64;
    if !side.is_finite() || side > MAX_GRID as f64 {
        return Err(Error::config(
            UNNAMED_FILE,
            "rig.fourier_filter.pinhole_radius_um",
            ap.radius_um,
            &format!(
                "an opening of {:.2} frequency bins (reaching {reach:.3} cycles/mirror) needs a {}-fold padded, {}-fold oversampled grid of {side} > {MAX_GRID} samples; an opening must span at least 4 bins (widen it or use fewer mirrors) and reach well below 2 cycles/mirror",
                bins, pad, os
            ),
        ));
    }
    Ok(Grid {
        pad: pad as usize,
        oversample: os as usize,
        reach,
        wd,
        hd,
    })
}

/// The modulator's spectrum on the padded mirror grid: B(f mod 1)·envelope with a DMD, the
/// band-limited target without; for coherent light, of the field (amplitude √intensity).
struct ModulatorSpectrum {
    coarse: HalfSpectrum,
    dmd: Option<DmdConfig>,
    wc: usize,
    hc: usize,
}

impl ModulatorSpectrum {
    /// The FFT of what the modulator shows, zero-padded onto the grid's coarse size.
    fn new(
        dmd: Option<&DmdConfig>,
        display: &Display,
        grid: &Grid,
        coherent: bool,
    ) -> ModulatorSpectrum {
        let (wc, hc) = grid.coarse();
        let mut padded = vec![0.0f32; wc * hc];
        for (row, src) in padded
            .chunks_exact_mut(wc)
            .zip(display.shown.chunks_exact(grid.wd))
        {
            for (d, &v) in row.iter_mut().zip(src) {
                *d = if coherent { v.sqrt() } else { v };
            }
        }
        ModulatorSpectrum {
            coarse: Fft2::new(wc, hc).forward(&padded),
            dmd: dmd.cloned(),
            wc,
            hc,
        }
    }

    /// The spectrum at bin (kx, ky), f = (kx/wc, ky/hc). A grey modulator's Nyquist component
    /// is a real cosine: on the frequency lattice of the mask (where ±½ are two points) each
    /// half gets `split` = ½ of it; on the grid of the unfiltered path (one bin) it is whole.
    fn at(&self, kx: i64, ky: i64, split: f64) -> Complex64 {
        let v = self.coarse.at(kx, ky);
        let v = Complex64::new(v.re as f64, v.im as f64);
        v * (self.along(kx, self.wc, split) * self.along(ky, self.hc, split))
    }

    /// The factor of bin k of n along one axis that multiplies the shown pattern's periodic
    /// spectrum: the mirror envelope's with a DMD, the band limit's without.
    fn along(&self, k: i64, n: usize, split: f64) -> f64 {
        match &self.dmd {
            Some(d) => d.mirror_envelope_along(k as f64 / n as f64),
            None => nyquist(k, n, split),
        }
    }

    /// The spectrum the mask sees (the Nyquist component split between ±½).
    fn source(&self, kx: i64, ky: i64) -> Complex64 {
        self.at(kx, ky, 0.5)
    }
}

/// A band-limited grid's share of bin k of n: inside the band 1, at Nyquist `split`, past it 0.
fn nyquist(k: i64, n: usize, split: f64) -> f64 {
    match (2 * k.unsigned_abs() as usize).cmp(&n) {
        std::cmp::Ordering::Less => 1.0,
        std::cmp::Ordering::Equal => split,
        std::cmp::Ordering::Greater => 0.0,
    }
}

/// The intensity past the 4f relay, as spectra on the padded mirror grid.
pub struct IntensitySpectrum {
    /// Light passed by the mask (1 without a filter), see [`PatternSet::throughput`].
    pub throughput: f64,
    grid: Grid,
    geometry: Geometry,
    relayed: Relayed,
}

/// What the relay passes, before the lens.
enum Relayed {
    /// Past a Fourier filter: the moment spectra s0, s1 of the passed bins' pairs (relay/).
    /// For incoherent light they are the mask's OTF, which multiplies the modulator's spectrum.
    Filtered {
        sums: PairSums,
        incoherent_source: Option<ModulatorSpectrum>,
    },
    /// No filter: the modulator's own band-limited spectrum.
    Open(ModulatorSpectrum),
}

/// The relay with the experiment's Fourier filter (its pair sums on `pairs`), or the open
/// relay without one.
pub fn relay(
    cfg: &OpticsConfig,
    m: &DmdConfig,
    display: &Display,
    light: &PatternLight,
    pairs: &dyn PairSummer,
) -> Result<IntensitySpectrum> {
    match &cfg.fourier_filter {
        Some(f) => relay_filtered(cfg.dmd.as_ref(), f, m, display, light, pairs),
        None => Ok(relay_open(cfg.dmd.as_ref(), m, display)),
    }
}

/// The intensity spectrum past the Fourier mask: the moment spectra s0, s1 of the pairs of
/// bins the openings pass (exact over the light's wavelengths, summed on `pairs`), and the
/// share of light passed.
pub fn relay_filtered(
    dmd: Option<&DmdConfig>,
    f: &FourierFilterConfig,
    m: &DmdConfig,
    display: &Display,
    light: &PatternLight,
    pairs: &dyn PairSummer,
) -> Result<IntensitySpectrum> {
    let g = display.geometry;
    let (ap, grid) = filtered_grid(dmd.is_some(), f, m, &g, light)?;
    let coherent = f.illumination == Illumination::Coherent;
    let spectrum = ModulatorSpectrum::new(dmd, display, &grid, coherent);
    let bins = passed_bins(&ap, light, f.illumination, grid.coarse(), |kx, ky| {
        spectrum.source(kx, ky)
    })?;
    let sums = pairs.pair_sums(&bins)?;
    let throughput = if coherent {
        coherent_throughput(&bins, &spectrum, &grid)
    } else {
        incoherent_throughput(&bins, &grid)
    };
    Ok(IntensitySpectrum {
        throughput,
        grid,
        geometry: g,
        relayed: Relayed::Filtered {
            sums,
            incoherent_source: (!coherent).then_some(spectrum),
        },
    })
}

/// The filter's openings as `light` sees them through geometry `g`, and the grid the relay
/// runs on for them (padded where the openings are narrow).
fn filtered_grid(
    dithered: bool,
    f: &FourierFilterConfig,
    m: &DmdConfig,
    g: &Geometry,
    light: &PatternLight,
) -> Result<(Aperture, Grid)> {
    let ap = f.aperture(m.pitch_um, g.fxd, g.fyd, light);
    let grid = grid(dithered, m, g, &ap, light)?;
    Ok((ap, grid))
}

/// Without a filter the relay passes the modulator's whole band-limited spectrum.
pub fn relay_open(dmd: Option<&DmdConfig>, m: &DmdConfig, display: &Display) -> IntensitySpectrum {
    let grid = Grid::mirrors(m);
    IntensitySpectrum {
        throughput: 1.0,
        grid,
        geometry: display.geometry,
        relayed: Relayed::Open(ModulatorSpectrum::new(dmd, display, &grid, false)),
    }
}

/// Coherent throughput: the passed share, over the light, of the field's energy at frequencies
/// up to the openings' reach (at least the mirror grid's band). The source is the periodic
/// spectrum times separable factors, so the window's energy is Σ over one period of |B|² times
/// each axis's squared factors summed over the bins of that residue.
fn coherent_throughput(bins: &[PassedBin], source: &ModulatorSpectrum, grid: &Grid) -> f64 {
    let (wc, hc) = grid.coarse();
    let residues = |n: usize| {
        let k = (grid.reach.max(0.5) * n as f64).floor() as i64;
        let mut sums = vec![0.0; n];
        for q in -k..=k {
            sums[q.rem_euclid(n as i64) as usize] += source.along(q, n, 0.5).powi(2);
        }
        sums
    };
    let (rx, ry) = (residues(wc), residues(hc));
    // The stored half: column kx holds bins (kx, ky) and, but for kx = 0 and kx = wc/2, their
    // mirrors (wc − kx, −ky) of the same energy.
    let ry_mirrored: Vec<f64> = (0..hc).map(|by| ry[(hc - by) % hc]).collect();
    let coarse = &source.coarse;
    let all: f64 = (coarse.data.par_chunks(hc).enumerate())
        .map(|(kx, column)| {
            let (mut own, mut mirrored) = (0.0, 0.0);
            for ((v, a), b) in column.iter().zip(&ry).zip(&ry_mirrored) {
                let e = Complex64::new(v.re as f64, v.im as f64).norm_sqr();
                own += e * a;
                mirrored += e * b;
            }
            let mirror = wc - kx;
            let mirrors = if kx != 0 && mirror != kx {
                mirrored * rx[mirror]
            } else {
                0.0
            };
            own * rx[kx] + mirrors
        })
        .sum();
    let passed: f64 = bins.iter().map(|b| b.value.norm_sqr() * b.weight).sum();
    passed / all.max(f64::MIN_POSITIVE)
}

/// Incoherent throughput: the open share of the mirror grid's band, over the light.
fn incoherent_throughput(bins: &[PassedBin], grid: &Grid) -> f64 {
    let (wc, hc) = grid.coarse();
    let band = |k: i64, n: usize| 2 * k >= -(n as i64) && 2 * k < n as i64;
    let open: f64 = bins
        .iter()
        .filter(|b| band(b.kx, wc) && band(b.ky, hc))
        .map(|b| b.weight)
        .sum();
    open / (wc * hc) as f64
}

/// The lens at bin (kx, ky) of the padded mirror grid: its Airy OTF at the light's centroid and
/// the OTF's slope over wavelength, each times the pixel box; [1, 0] without a lens.
struct LensOtf<'a> {
    lens: Option<&'a LensConfig>,
    pitch: f64,
    centroid: f64,
    wc: usize,
    hc: usize,
}

impl LensOtf<'_> {
    fn at(&self, kx: i64, ky: i64) -> [f64; 2] {
        let (fx, fy) = (kx as f64 / self.wc as f64, ky as f64 / self.hc as f64);
        self.lens.map_or([1.0, 0.0], |l| {
            let px = l.pixel_transfer(self.pitch, fx, fy);
            [
                l.airy(self.pitch, fx, fy, self.centroid) * px,
                l.airy_slope(self.pitch, fx, fy, self.centroid) * px,
            ]
        })
    }
}

/// The image's spectrum on the oversampled grid's half plane, ready for the inverse FFT.
pub struct ImageSpectrum {
    grid: Grid,
    geometry: Geometry,
    half: Vec<Complex32>,
}

/// The image on the sample: the relay's moment spectra combined with the lens OTF (per
/// wavelength, to first order about the centroid) and the pixel box; `None`: no lens, unblurred.
pub fn lens(
    lens: Option<&LensConfig>,
    m: &DmdConfig,
    spectrum: &IntensitySpectrum,
    light: &PatternLight,
) -> ImageSpectrum {
    let (wc, hc) = spectrum.grid.coarse();
    let otf = LensOtf {
        lens,
        pitch: m.pitch_um,
        centroid: light.centroid_nm(),
        wc,
        hc,
    };
    let half = match &spectrum.relayed {
        Relayed::Filtered {
            sums,
            incoherent_source,
        } => fold_moments(sums, incoherent_source.as_ref(), &otf, &spectrum.grid),
        Relayed::Open(modulator) => open_image(modulator, &otf, &spectrum.grid),
    };
    ImageSpectrum {
        grid: spectrum.grid,
        geometry: spectrum.geometry,
        half,
    }
}

/// Î(q) = s0·OTF + s1·∂OTF (times the source for incoherent light) for the stored half of q,
/// folded onto the grid's torus with Î(−q) = Î(q)* (sampling on the nodes is exact for the folded
/// spectrum).
fn fold_moments(
    sums: &PairSums,
    source: Option<&ModulatorSpectrum>,
    otf: &LensOtf,
    grid: &Grid,
) -> Vec<Complex32> {
    let (wf, hf) = grid.fine();
    let values: Vec<(i64, i64, Complex64, bool)> = (sums.half_plane())
        .map(|((qx, qy), [s0, s1], mirrored)| {
            let [l0, l1] = otf.at(qx, qy);
            let x = s0 * l0 + s1 * l1;
            (qx, qy, source.map_or(x, |s| x * s.source(qx, qy)), mirrored)
        })
        .collect();
    // Only the torus's half kx ≤ wf/2 is kept: each of its cells adds what it receives in the
    // order the whole torus would.
    let columns = wf / 2 + 1;
    let mut half = vec![Complex64::default(); columns * hf];
    let mut add = |qx: i64, qy: i64, x: Complex64| {
        let kx = qx.rem_euclid(wf as i64) as usize;
        if kx < columns {
            half[kx * hf + qy.rem_euclid(hf as i64) as usize] += x;
        }
    };
    for (qx, qy, x, mirrored) in values {
        add(qx, qy, x);
        if mirrored {
            add(-qx, -qy, x.conj());
        }
    }
    half.iter()
        .map(|t| Complex32::new(t.re as f32, t.im as f32))
        .collect()
}

/// Without a filter: the modulator's spectrum (Nyquist bins whole) times the lens OTF.
fn open_image(modulator: &ModulatorSpectrum, otf: &LensOtf, grid: &Grid) -> Vec<Complex32> {
    let (wf, hf) = grid.fine();
    let mut spec = vec![Complex32::default(); (wf / 2 + 1) * hf];
    spec.par_chunks_mut(hf).enumerate().for_each(|(kx, col)| {
        for (i, v) in col.iter_mut().enumerate() {
            let (kx, ky) = (kx as i64, signed_bin(i, hf));
            let x = modulator.at(kx, ky, 1.0) * otf.at(kx, ky)[0];
            *v = Complex32::new(x.re as f32, x.im as f32);
        }
    });
    spec
}

/// The pattern at the sensor pixels: the image back from the Fourier domain, Keys-cubic
/// resampled at each pixel's place on the grid, normalised by its mean (see the module doc).
pub fn pixel_sampling(image: &ImageSpectrum, c: &Carrier, w: usize, h: usize) -> Result<Vec<f32>> {
    let (wf, hf) = image.grid.fine();
    let field = Fft2::new(wf, hf).inverse(&image.half);
    let out = resample(&field, image, w, h);
    normalise(out, c, w, h)
}

/// Keys cubic interpolation of the image `field` on the fine grid at the sensor pixels (fine
/// sample j sits at mirror coordinate j / oversample, periodic).
fn resample(field: &[f32], image: &ImageSpectrum, w: usize, h: usize) -> Vec<f32> {
    let (wf, hf) = image.grid.fine();
    let (g, os) = (&image.geometry, image.grid.oversample as f64);
    let xs: Vec<(i64, [f64; 4])> = (0..w)
        .map(|x| keys(os * g.mirror_of(x as f64, 0.0).0))
        .collect();
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let (iy, wy) = keys(os * g.mirror_of(0.0, y as f64).1);
        for (x, o) in row.iter_mut().enumerate() {
            let (ix, wx) = xs[x];
            let mut acc = 0.0f64;
            for (j, wyj) in wy.iter().enumerate() {
                if *wyj == 0.0 {
                    continue;
                }
                let r = (iy + j as i64 - 1).rem_euclid(hf as i64) as usize * wf;
                for (i, wxi) in wx.iter().enumerate() {
                    if *wxi != 0.0 {
                        acc += wyj
                            * wxi
                            * field[r + (ix + i as i64 - 1).rem_euclid(wf as i64) as usize] as f64;
                    }
                }
            }
            *o = acc as f32;
        }
    });
    out
}

/// s̃ = I · mean(ideal)/mean(I): the pattern's scale is the design's, whatever light was lost;
/// refused when no light reaches the sensor.
fn normalise(mut out: Vec<f32>, c: &Carrier, w: usize, h: usize) -> Result<Vec<f32>> {
    let ideal = c.ideal_pattern(w, h);
    let mean = |v: &[f32]| v.iter().map(|&a| a as f64).sum::<f64>() / v.len() as f64;
    let (mi, mo) = (mean(&ideal), mean(&out));
    if !(mo.is_finite() && mo > 1e-9 * mi.abs().max(1e-30)) {
        return Err(Error::Numerical(format!(
            "carrier ({}, {}): the imaged pattern has mean {mo:.3e}; no light reaches the sensor",
            c.fx, c.fy
        )));
    }
    let k = (mi / mo) as f32;
    out.iter_mut().for_each(|v| *v *= k);
    Ok(out)
}

/// Keys cubic convolution (a = −½) at fractional position `t`: base index and the four weights
/// of samples base−1 … base+2. At whole positions the weights are exactly (0, 1, 0, 0).
fn keys(t: f64) -> (i64, [f64; 4]) {
    let base = t.floor();
    let f = t - base;
    if f == 0.0 {
        return (base as i64, [0.0, 1.0, 0.0, 0.0]);
    }
    let (f2, f3) = (f * f, f * f * f);
    (
        base as i64,
        [
            (-f3 + 2.0 * f2 - f) / 2.0,
            (3.0 * f3 - 5.0 * f2 + 2.0) / 2.0,
            (-3.0 * f3 + 4.0 * f2 + f) / 2.0,
            (f3 - f2) / 2.0,
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::dither::DitherMethod;
    use crate::optics::fourier_filter::PinholeShape;
    use specmux_core::carriers::default_layout;
    use specmux_core::fft::dft_at;
    use std::f64::consts::PI;

    /// The 532 nm line for `n` patterns: the monochromatic cases worked by hand.
    fn line(n: usize) -> Vec<PatternLight> {
        vec![PatternLight::Line(532.0); n]
    }

    /// Pinhole radius in µm that is `cpp` cycles/mirror at 532 nm, the default 4f and pitch.
    fn radius_um(cpp: f64) -> f64 {
        cpp * 0.532 * 100_000.0 / 13.68
    }

    fn filter(cpp: f64, illumination: Illumination) -> FourierFilterConfig {
        FourierFilterConfig {
            pinhole_radius_um: radius_um(cpp),
            illumination,
            ..Default::default()
        }
    }

    #[test]
    fn no_stage_gives_exactly_the_ideal_patterns() {
        let c = default_layout();
        let out = imaged_patterns(&OpticsConfig::default(), &c, &line(c.len()), 48, 40).unwrap();
        for (i, ci) in c.iter().enumerate() {
            assert_eq!(out.plane(i), &ci.ideal_pattern(48, 40)[..]);
        }
    }

    #[test]
    fn open_pinhole_returns_the_ideal_sinusoid_unchanged() {
        // Coherent light from a grey modulator (field √t); a DC opening of 0.75 cycles/mirror
        // covers its whole band, so |field|² = t at every mirror.
        let cfg = OpticsConfig {
            fourier_filter: Some(filter(0.75, Illumination::Coherent)),
            ..Default::default()
        };
        let c = [
            Carrier {
                fx: 0.25,
                fy: -0.125,
                phase_rad: 0.4,
            },
            Carrier {
                fx: 0.1,
                fy: 0.3,
                phase_rad: 1.0,
            },
        ];
        let out = imaged_patterns(&cfg, &c, &line(2), 64, 48).unwrap();
        for (i, ci) in c.iter().enumerate() {
            let err = out
                .plane(i)
                .iter()
                .zip(ci.ideal_pattern(64, 48))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(err < 1e-4, "carrier {i}: {err}");
        }
    }

    #[test]
    fn incoherent_three_openings_pass_the_carrier_at_two_thirds() {
        // OTF(ω) = 2/3 for three disjoint openings (see fourier_filter); the grey target has only
        // DC and ±ω, so s̃ = 1 + (2/3) cos(ω·p + φ).
        let cfg = OpticsConfig {
            fourier_filter: Some(filter(4.1 / 64.0, Illumination::Incoherent)),
            ..Default::default()
        };
        let c = Carrier {
            fx: 0.25,
            fy: 0.0,
            phase_rad: 0.3,
        };
        let set = simulate_patterns(&cfg, &[c], &line(1), 64, 64).unwrap();
        for (p, v) in set.imaged.data.iter().enumerate() {
            let want = 1.0 + 2.0 / 3.0 * (2.0 * PI * 0.25 * (p % 64) as f64 + 0.3).cos();
            assert!((*v as f64 - want).abs() < 1e-4, "pixel {p}: {v} vs {want}");
        }
    }

    #[test]
    fn coherent_binary_grating_makes_the_hand_computed_second_harmonic() {
        // A 50 % grating (fill factor 1, period 8) has field orders c₀ = ½, c±₁ = 1/π. Past the
        // openings at 0, ±ω the field is ½ + (2/π) cos θ, so the intensity is
        //   ¼ + 2/π² + (2/π) cos θ + (2/π²) cos 2θ   (cos² θ = ½ + ½ cos 2θ).
        // Normalised by its mean D = ¼ + 2/π²: s̃ = 1 + (2/π)/D cos θ + (2/π²)/D cos 2θ, i.e. the
        // ±2ω term is (1/π²)/D = 0.2238 against 0.5 for the carrier of an ideal pattern.
        let dmd = DmdConfig {
            width: 128,
            height: 128,
            fill_factor: 1.0,
            dither: DitherMethod::Threshold,
            ..Default::default()
        };
        let cfg = OpticsConfig {
            dmd: Some(dmd),
            fourier_filter: Some(filter(0.05, Illumination::Coherent)),
            lens: None,
        };
        let c = Carrier {
            fx: 0.125,
            fy: 0.0,
            phase_rad: PI / 8.0,
        };
        let set = simulate_patterns(&cfg, &[c], &line(1), 128, 128).unwrap();
        let s = set.imaged.plane(0);
        let d = 0.25 + 2.0 / (PI * PI);
        let a1 = dft_at(s, 128, 128, 16, 0).norm();
        let a2 = dft_at(s, 128, 128, 32, 0).norm();
        assert!(
            (a1 - (1.0 / PI) / d).abs() < 1e-4,
            "carrier {a1} vs {}",
            (1.0 / PI) / d
        );
        assert!(
            (a2 - (1.0 / (PI * PI)) / d).abs() < 1e-4,
            "2ω {a2} vs {}",
            (1.0 / (PI * PI)) / d
        );
        assert!(dft_at(s, 128, 128, 48, 0).norm() < 1e-4, "3ω is blocked");
        // Coherent throughput: the passed orders carry D of the field energy inside the mirror
        // grid's band, D + 2/(9π²) (orders ±3; ±5, ±7 lie past ½ cycle/mirror).
        let band = d + 2.0 / (9.0 * PI * PI);
        assert!(
            (set.throughput[0] - d / band).abs() < 1e-4,
            "{}",
            set.throughput[0]
        );
    }

    #[test]
    fn broadband_light_through_a_disc_keeps_the_carrier_of_its_window_only() {
        // The 50 % grating of the test above (period 8, fill 1) on 512 mirrors, flat light on
        // 420–580 nm, discs of 0.01 cycles/mirror cut for 500 nm. The ±1 orders (0.125) pass
        // while |λ − 500|·0.125 ≤ 0.01·500, i.e. on 460–540 nm: half the light (f = ½). Outside
        // that window the field is ½ (DC alone), inside ½ + (2/π) cos θ, so the mean intensity
        // is D = ¼ + f·2/π² and, normalised by it, the carrier is f·(1/π)/D per exponential and
        // 2ω is f·(1/π²)/D. A streak over the band passes the orders everywhere: f = 1.
        let n = 512;
        let band = Curve::new("flat", vec![420.0, 580.0], vec![1.0, 1.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        let c = Carrier {
            fx: 0.125,
            fy: 0.0,
            phase_rad: PI / 8.0,
        };
        for (shape, f) in [(PinholeShape::Circle, 0.5), (PinholeShape::Streak, 1.0)] {
            let cfg = OpticsConfig {
                dmd: Some(DmdConfig {
                    width: n,
                    height: n,
                    fill_factor: 1.0,
                    dither: DitherMethod::Threshold,
                    ..Default::default()
                }),
                fourier_filter: Some(FourierFilterConfig {
                    pinhole_radius_um: 0.01
                        * 500.0
                        * FourierFilterConfig::default().um_per_cycle_nm(13.68),
                    design_wavelength_nm: Some(500.0),
                    shape,
                    ..Default::default()
                }),
                lens: None,
            };
            let set = simulate_patterns(&cfg, &[c], std::slice::from_ref(&light), n, n).unwrap();
            let s = set.imaged.plane(0);
            let d = 0.25 + f * 2.0 / (PI * PI);
            let a1 = dft_at(s, n, n, 64, 0).norm();
            let a2 = dft_at(s, n, n, 128, 0).norm();
            assert!(
                (a1 - f / PI / d).abs() < 1e-3,
                "{shape:?}: carrier {a1} vs {}",
                f / PI / d
            );
            assert!(
                (a2 - f / (PI * PI) / d).abs() < 1e-3,
                "{shape:?}: 2ω {a2} vs {}",
                f / (PI * PI) / d
            );
        }
    }

    #[test]
    fn a_broadband_lens_blurs_as_the_light_weighted_mean_of_its_otfs() {
        // Grey modulator, lens only, flat light on 420–680 nm: the carrier's gain is
        // ∫ w(λ)·OTF_λ dλ × pixel box; the model takes the OTF at the centroid, exact to first
        // order (the first moment about the centroid vanishes), so the difference is the
        // curvature term, far below 10⁻³ here.
        let band = Curve::new("flat", vec![420.0, 680.0], vec![1.0, 1.0]).unwrap();
        let (lens, g) = lens_only_carrier(PatternLight::band(&band).unwrap());
        let g = g.norm() / 0.5;
        let steps = 2600;
        let mean_otf = (0..steps)
            .map(|i| {
                lens.airy(
                    13.68,
                    0.25,
                    0.125,
                    420.0 + 260.0 * (i as f64 + 0.5) / steps as f64,
                )
            })
            .sum::<f64>()
            / steps as f64;
        let want = mean_otf * lens.pixel_transfer(13.68, 0.25, 0.125);
        assert!((g - want).abs() < 1e-3, "{g} vs {want}");
        // and the wavelength matters: the 420 nm and 680 nm OTFs differ by more than that.
        let spread = lens.airy(13.68, 0.25, 0.125, 420.0) - lens.airy(13.68, 0.25, 0.125, 680.0);
        assert!(spread > 0.05, "{spread}");
    }

    /// A grey modulator imaged by an NA 0.02 lens alone (inverted, one pixel per mirror) with
    /// `light`: the lens and the complex amplitude of the carrier (0.25, 0.125), phase 0.7.
    fn lens_only_carrier(light: PatternLight) -> (LensConfig, rustfft::num_complex::Complex64) {
        let lens = LensConfig {
            na: 0.02,
            ..Default::default()
        };
        let cfg = OpticsConfig {
            lens: Some(lens.clone()),
            ..Default::default()
        };
        let c = Carrier {
            fx: 0.25,
            fy: 0.125,
            phase_rad: 0.7,
        };
        let s = imaged_patterns(&cfg, &[c], &[light], 64, 64).unwrap();
        (lens, dft_at(s.plane(0), 64, 64, 16, 8))
    }

    #[test]
    fn lens_and_pixel_transfer_scale_the_carrier_by_hand() {
        // Grey modulator, inverted unit-magnification image, one pixel per mirror: the carrier
        // amplitude is ½ e^{iφ} times the Airy OTF times sinc(fx)·sinc(fy).
        let (lens, g) = lens_only_carrier(PatternLight::Line(532.0));
        let t = lens.airy(13.68, 0.25, 0.125, 532.0) * lens.pixel_transfer(13.68, 0.25, 0.125);
        assert!(t < 0.9 && t > 0.1, "{t}");
        let want = rustfft::num_complex::Complex64::from_polar(0.5 * t, 0.7);
        assert!((g - want).norm() < 1e-4, "{g} vs {want}");
    }

    #[test]
    fn under_resolved_pinhole_is_refined_or_refused() {
        let dmd = DmdConfig {
            width: 64,
            height: 64,
            ..Default::default()
        };
        let c = [Carrier {
            fx: 0.25,
            fy: 0.0,
            phase_rad: 0.0,
        }];
        // 2 bins of radius: padded twice to reach 4.
        let cfg = OpticsConfig {
            dmd: Some(dmd.clone()),
            fourier_filter: Some(filter(2.0 / 64.0, Illumination::Coherent)),
            lens: None,
        };
        let set = simulate_patterns(&cfg, &c, &line(c.len()), 64, 64).unwrap();
        assert_eq!(set.grid[0].0, 2);
        assert!(set.imaged.all_finite());
        // A 0.01-bin opening would need a 400-fold padded grid: refused, naming the key.
        let cfg = OpticsConfig {
            fourier_filter: Some(filter(0.01 / 64.0, Illumination::Coherent)),
            ..cfg
        };
        let e = imaged_patterns(&cfg, &c, &line(c.len()), 64, 64)
            .unwrap_err()
            .to_string();
        assert!(e.contains("rig.fourier_filter.pinhole_radius_um"), "{e}");
    }

    #[test]
    fn prototype_path_keeps_mean_one_and_a_usable_gain() {
        // A DMD larger than the sensor, every stage on, both illuminations.
        for ill in [Illumination::Coherent, Illumination::Incoherent] {
            let cfg = OpticsConfig {
                dmd: Some(DmdConfig {
                    width: 80,
                    height: 72,
                    ..Default::default()
                }),
                fourier_filter: Some(FourierFilterConfig {
                    illumination: ill,
                    ..filter(5.0 / 64.0, ill)
                }),
                lens: Some(LensConfig::default()),
            };
            let c = default_layout();
            let set = simulate_patterns(&cfg, &c, &line(c.len()), 64, 64).unwrap();
            for (i, ci) in c.iter().enumerate() {
                let s = set.imaged.plane(i);
                let mean = s.iter().map(|&v| v as f64).sum::<f64>() / s.len() as f64;
                let ideal_mean = ci
                    .ideal_pattern(64, 64)
                    .iter()
                    .map(|&v| v as f64)
                    .sum::<f64>()
                    / s.len() as f64;
                assert!((mean - ideal_mean).abs() < 1e-5, "{ill:?} {i}: mean {mean}");
                let g = dft_at(s, 64, 64, Carrier::bin(ci.fx, 64), Carrier::bin(ci.fy, 64)).norm()
                    / 0.5;
                // At (0.5, 0.25) the pixel box and the mirror envelope alone give 0.38, the
                // incoherent OTF another 2/3: the gain is far from 1 but never vanishes.
                assert!(g > 0.15 && g < 2.0, "{ill:?} {i}: gain {g}");
            }
        }
    }

    #[test]
    fn sensor_larger_than_the_dmd_field_is_refused() {
        let cfg = OpticsConfig {
            dmd: Some(DmdConfig {
                width: 32,
                height: 32,
                ..Default::default()
            }),
            ..Default::default()
        };
        let e = imaged_patterns(&cfg, &default_layout(), &line(6), 64, 64)
            .unwrap_err()
            .to_string();
        assert!(e.contains("rig.dmd.width"), "{e}");
    }

    /// A real relay with the GPU's pair sums against the CPU's: DMD 80 × 72, the default six
    /// carriers, both illuminations, a 532 nm line and a 480–620 nm band. Each pattern's sums
    /// within 1e-5 of its largest |sum| per component, the imaged patterns within 1e-5 NRMSE.
    #[cfg(feature = "gpu")]
    #[test]
    fn gpu_pair_sums_give_the_cpus_relay_and_patterns() {
        use crate::optics::relay::{relative_difference, GpuPairSummer};
        let Some(ctx) = crate::forward::gpu_tests::context() else {
            return;
        };
        let gpu: Arc<dyn PairSummer> = Arc::new(GpuPairSummer::new(&ctx));
        let c = default_layout();
        let band = Curve::new("ramp", vec![480.0, 620.0], vec![1.0, 3.0]).unwrap();
        let band = vec![PatternLight::band(&band).unwrap(); c.len()];
        for ill in [Illumination::Coherent, Illumination::Incoherent] {
            for lights in [line(c.len()), band.clone()] {
                let cfg = OpticsConfig {
                    dmd: Some(DmdConfig {
                        width: 80,
                        height: 72,
                        ..Default::default()
                    }),
                    fourier_filter: Some(filter(5.0 / 64.0, ill)),
                    lens: Some(LensConfig::default()),
                };
                let cpu = Chain::new(&cfg, &c, &lights, 64, 64).unwrap();
                let on_gpu = Chain::new(&cfg, &c, &lights, 64, 64).unwrap();
                let on_gpu = on_gpu.with_pair_summer(gpu.clone());
                let displays = cpu.dither().unwrap();
                let f = cfg.fourier_filter.as_ref().unwrap();
                let t = std::time::Instant::now();
                let a = cpu.relay_filtered(f, &displays).unwrap();
                let t_cpu = t.elapsed().as_secs_f64();
                let t = std::time::Instant::now();
                let b = on_gpu.relay_filtered(f, &displays).unwrap();
                let t_gpu = t.elapsed().as_secs_f64();
                let mut worst = [0.0f64; 2];
                for (x, y) in a.iter().zip(&b) {
                    let (Relayed::Filtered { sums: s, .. }, Relayed::Filtered { sums: g, .. }) =
                        (&x.relayed, &y.relayed)
                    else {
                        panic!("a relay with a filter gave an open spectrum")
                    };
                    let e = relative_difference(g, s);
                    worst = [0, 1].map(|k| worst[k].max(e[k]));
                }
                let image = |ch: &Chain, r: &[IntensitySpectrum]| {
                    ch.pixel_sampling(&ch.lens(cfg.lens.as_ref(), r)).unwrap()
                };
                let nrmse = specmux_core::metrics::compare(&image(&cpu, &a), &image(&on_gpu, &b))
                    .unwrap()
                    .nrmse;
                eprintln!(
                    "{ill:?} {}: pair sums {:.1e}, {:.1e}; patterns NRMSE {nrmse:.1e} \
                     (relay CPU {t_cpu:.2} s, lavapipe {t_gpu:.2} s)",
                    if lights[0].centroid_nm() == 532.0 {
                        "line"
                    } else {
                        "band"
                    },
                    worst[0],
                    worst[1]
                );
                assert!(worst[0] < 1e-5 && worst[1] < 1e-5, "{worst:?}");
                assert!(nrmse < 1e-5, "{nrmse:.1e}");
            }
        }
    }
}
