//! The 4f relay's output for a pattern's light, exact in wavelength. The mask is fixed in µm, so
//! frequency bin k passes for the wavelengths of one interval (the ray ξ = f·λ·F/pitch crosses
//! each convex opening once). Summing over λ then needs no sampling: for coherent light
//!   Î(q) = Σ_{k, k'} F(k)·F*(k')·∫ w(λ)·[k passes at λ]·[k' passes at λ] dλ,  q = k − k',
//! and for incoherent light the OTF is the same pair sum with F = 1 and weight w(λ)·λ² (each
//! wavelength's OTF normalised by its pupil area, which scales as 1/λ²). The integral over the
//! overlap of two intervals is a difference of the light's cumulative weight at their ends, so
//! each pair costs a few operations. A second sum with the weight's first moment about the
//! centroid carries the wavelength dependence of the lens OTF to first order. Large sets of bins
//! are summed by slices of wavelength (`relay/sliced.rs`): the same sums, mostly by FFT.

use crate::optics::fourier_filter::Aperture;
use crate::optics::fourier_filter::Illumination;
use crate::optics::light::PatternLight;
use rayon::prelude::*;
use rustfft::num_complex::Complex64;
use specmux_core::error::Error;
use specmux_core::error::Result;
use specmux_core::error::UNNAMED_FILE;
use std::sync::Arc;

mod pairs;
mod shear;
mod sliced;

pub use pairs::direct_pair_sums;
pub use pairs::relative_difference;
use pairs::Interval;
pub use pairs::PairSums;
pub use pairs::PassedBin;
pub use sliced::SLICED_FROM_BINS;

/// Most frequency bins the openings may pass over the band: the pair loop over 60 000 bins
/// would visit 1.8·10⁹ pairs (about 10 s on two cores); the sums by slices (`relay/sliced.rs`) take a
/// fraction of that where the bins lie along streaks, not everywhere.
pub const MAX_PASSED_BINS: usize = 60_000;

/// The pair weights of the light: (weight, first moment about the centroid) of w for coherent
/// light, of w·λ²/λc² for incoherent light, from the moments ∫ w·(λ − λc)^p.
fn pair_weights(light: &PatternLight, ill: Illumination, m: [f64; 4]) -> [f64; 2] {
    match ill {
        Illumination::Coherent => [m[0], m[1]],
        Illumination::Incoherent => {
            let c = light.centroid_nm();
            let (a, b) = (2.0 / c, 1.0 / (c * c));
            [m[0] + a * m[1] + b * m[2], m[1] + a * m[2] + b * m[3]]
        }
    }
}

/// Every bin that passes some opening for some wavelength of `light`, sorted by (kx, ky).
/// `value(kx, ky)` is the source spectrum (used for coherent light; bins where it is zero are
/// left out). Refuses more than [`MAX_PASSED_BINS`] bins, naming the pinhole radius.
pub fn passed_bins(
    aperture: &Aperture,
    light: &PatternLight,
    ill: Illumination,
    (wc, hc): (usize, usize),
    value: impl Fn(i64, i64) -> Complex64 + Sync,
) -> Result<Vec<PassedBin>> {
    let (l1, l2) = light.support_nm();
    let r = aperture.radius_um;
    let k = aperture.um_per_cycle_nm;
    let one = Complex64::new(1.0, 0.0);
    let mut found: Vec<(i64, i64, (f64, f64), Complex64)> = Vec::new();
    for (j, o) in aperture.openings.iter().enumerate() {
        // Bounding box of the opening as the light's wavelengths see it, in bins.
        let range = |a: f64, b: f64, n: usize| {
            let (lo, hi) = (a.min(b) - r, a.max(b) + r);
            let c = [lo / l1, lo / l2, hi / l1, hi / l2].map(|v| v / k * n as f64);
            let (min, max) = c
                .iter()
                .fold((f64::MAX, f64::MIN), |(x, y), &v| (x.min(v), y.max(v)));
            (min.ceil() as i64, max.floor() as i64)
        };
        let (x0, x1) = range(o.a.0, o.b.0, wc);
        let (y0, y1) = range(o.a.1, o.b.1, hc);
        let cells = (x1 - x0 + 1).max(0) as f64 * (y1 - y0 + 1).max(0) as f64;
        if cells > 64.0 * MAX_PASSED_BINS as f64 {
            return Err(too_many(aperture, cells as usize));
        }
        let part: Vec<(i64, i64, (f64, f64), Complex64)> = (x0..=x1)
            .into_par_iter()
            .flat_map_iter(|kx| {
                let value = &value;
                (y0..=y1).filter_map(move |ky| {
                    let (fx, fy) = (kx as f64 / wc as f64, ky as f64 / hc as f64);
                    let (lo, hi) = aperture.pass_interval(j, fx, fy)?;
                    // A band carries no light outside its support (a line's support is a point,
                    // which would leave no interval).
                    let (lo, hi) = match light {
                        PatternLight::Band(_) => (lo.max(l1), hi.min(l2)),
                        PatternLight::Line(_) => (lo, hi),
                    };
                    if light.moments(lo, hi)[0] <= 0.0 {
                        return None;
                    }
                    let v = match ill {
                        Illumination::Coherent => value(kx, ky),
                        Illumination::Incoherent => one,
                    };
                    (v != Complex64::default()).then_some((kx, ky, (lo, hi), v))
                })
            })
            .collect();
        found.extend(part);
        if found.len() > MAX_PASSED_BINS * aperture.openings.len() {
            return Err(too_many(aperture, found.len()));
        }
    }
    // One entry per bin: the union of its openings' intervals, as disjoint intervals.
    found.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)).then(a.2 .0.total_cmp(&b.2 .0)));
    let mut bins: Vec<PassedBin> = Vec::with_capacity(found.len());
    for (kx, ky, (lo, hi), value) in found {
        if let Some(b) = bins.last_mut().filter(|b| (b.kx, b.ky) == (kx, ky)) {
            let last = &mut b.ivs[b.n - 1];
            if lo <= last.hi {
                last.hi = last.hi.max(hi);
            } else {
                b.ivs[b.n] = Interval {
                    lo,
                    hi,
                    ..Default::default()
                };
                b.n += 1;
            }
            continue;
        }
        bins.push(PassedBin {
            kx,
            ky,
            value,
            weight: 0.0,
            ivs: [
                Interval {
                    lo,
                    hi,
                    ..Default::default()
                },
                Interval::default(),
                Interval::default(),
            ],
            n: 1,
        });
    }
    if bins.len() > MAX_PASSED_BINS {
        return Err(too_many(aperture, bins.len()));
    }
    bins.par_iter_mut().for_each(|b| {
        for iv in b.ivs[..b.n].iter_mut() {
            iv.c_lo = pair_weights(light, ill, light.below(iv.lo));
            iv.c_hi = pair_weights(light, ill, light.through(iv.hi));
        }
        b.weight = b.ivs[..b.n]
            .iter()
            .map(|iv| light.moments(iv.lo, iv.hi)[0])
            .sum();
    });
    Ok(bins)
}

fn too_many(aperture: &Aperture, n: usize) -> Error {
    Error::config(
        UNNAMED_FILE,
        "rig.fourier_filter.pinhole_radius_um",
        aperture.radius_um,
        &format!(
            "the openings pass {n} frequency bins over the pattern's band, more than {MAX_PASSED_BINS}; \
             the exact sum over wavelengths runs over their pairs: use smaller openings, fewer mirrors or light = \"line\""
        ),
    )
}

/// The pair sums of `bins` (sorted by kx, as [`passed_bins`] returns them): by slices of
/// wavelength where that is cheaper (`relay/sliced.rs`), pair by pair otherwise.
pub fn pair_sums(bins: &[PassedBin]) -> PairSums {
    match sliced::Plan::new(bins) {
        Some(plan) => plan.sums(bins),
        None => direct_pair_sums(bins),
    }
}

/// The pair loop on some device: [`CpuPairSums`] and, behind the `gpu` feature,
/// [`GpuPairSummer`]; `[compute] device` picks one ([`pair_summer_for`]). Whatever the device,
/// bins that slicing takes are summed by slices on the CPU: on an H200 machine those sums beat
/// the GPU's pair loop 2–22× a relay (docs/gpu.md).
pub trait PairSummer: Send + Sync {
    /// [`direct_pair_sums`] of `bins` (sorted by (kx, ky), as [`passed_bins`] returns them) on
    /// this device.
    fn pair_loop(&self, bins: &[PassedBin]) -> Result<PairSums>;
    /// "cpu" or "gpu".
    fn device(&self) -> &'static str;

    /// [`pair_sums`] of `bins` with the pair loop on this device.
    fn pair_sums(&self, bins: &[PassedBin]) -> Result<PairSums> {
        match sliced::Plan::new(bins) {
            Some(plan) => Ok(plan.sums(bins)),
            None => self.pair_loop(bins),
        }
    }
    /// Where the sums run, as the relay stage describes it.
    fn describe(&self) -> String {
        format!(
            "pair sums on the {} below {SLICED_FROM_BINS} passed bins, by slices on the CPU above",
            self.device().to_uppercase()
        )
    }
}

/// The pair loop on the CPU, in f64.
pub struct CpuPairSums;

impl PairSummer for CpuPairSums {
    fn pair_loop(&self, bins: &[PassedBin]) -> Result<PairSums> {
        Ok(direct_pair_sums(bins))
    }
    fn device(&self) -> &'static str {
        "cpu"
    }
    fn describe(&self) -> String {
        "pair sums on the CPU".into()
    }
}

/// specmux-gpu's pair-sum kernel as the pair loop: per call one upload of the bins, one kernel,
/// one read-back, in f32 within 1e-5 of the largest |sum| of each component (docs/gpu.md).
#[cfg(feature = "gpu")]
pub struct GpuPairSummer {
    ctx: specmux_gpu::GpuContext,
    kernel: specmux_gpu::pair_sums::GpuPairSums,
}

#[cfg(feature = "gpu")]
impl GpuPairSummer {
    /// The kernel compiled on `ctx`.
    pub fn new(ctx: &specmux_gpu::GpuContext) -> GpuPairSummer {
        GpuPairSummer {
            ctx: ctx.clone(),
            kernel: specmux_gpu::pair_sums::GpuPairSums::new(ctx),
        }
    }
}

#[cfg(feature = "gpu")]
impl PairSummer for GpuPairSummer {
    fn pair_loop(&self, bins: &[PassedBin]) -> Result<PairSums> {
        use specmux_gpu::pair_sums::{PairBin, PassInterval};
        let interval = |iv: &Interval| PassInterval {
            lo: iv.lo,
            hi: iv.hi,
            c_lo: iv.c_lo,
            c_hi: iv.c_hi,
        };
        let plain: Vec<PairBin> = (bins.iter())
            .map(|b| PairBin {
                kx: b.kx,
                ky: b.ky,
                value: [b.value.re, b.value.im],
                intervals: b.ivs.each_ref().map(interval),
                n: b.n,
            })
            .collect();
        let g = self.kernel.run(&self.ctx, &plain)?;
        let component = |c: usize| {
            (g.sums.iter())
                .map(|v| Complex64::new(v[2 * c] as f64, v[2 * c + 1] as f64))
                .collect()
        };
        Ok(PairSums {
            map: shear::Shear::half_box(g.qx_max, g.qy_max),
            s: [component(0), component(1)],
        })
    }
    fn device(&self) -> &'static str {
        "gpu"
    }
}

/// The pair summer on `device` (the GPU's when it is one).
pub fn pair_summer_for(device: &crate::device::OpenDevice) -> Arc<dyn PairSummer> {
    #[cfg(feature = "gpu")]
    if let Some(ctx) = device.gpu() {
        return Arc::new(GpuPairSummer::new(ctx));
    }
    let _ = device;
    Arc::new(CpuPairSums)
}

#[cfg(test)]
mod tests {
    use super::pairs::overlap;
    use super::*;
    use crate::optics::fourier_filter::FourierFilterConfig;
    use crate::optics::fourier_filter::Light;
    use crate::optics::fourier_filter::PinholeShape;
    use specmux_core::spectral::Curve;

    /// A filter whose openings are `r` bins of a `n`-mirror grid at 532 nm.
    fn filter(r_bins: f64, n: usize, shape: PinholeShape) -> FourierFilterConfig {
        let f = FourierFilterConfig {
            light: Light::Line,
            shape,
            ..Default::default()
        };
        FourierFilterConfig {
            pinhole_radius_um: r_bins / n as f64 * 532.0 * f.um_per_cycle_nm(13.68),
            ..f
        }
    }

    /// Three discs of 4.1 bins at 0 and ±20 bins of a 128-mirror grid, a 532 nm line,
    /// incoherent light: the bins of the hand-solved OTF below.
    fn three_discs() -> Vec<PassedBin> {
        let n = 128;
        let light = PatternLight::Line(532.0);
        let ap = filter(4.1, n, PinholeShape::Circle).aperture(13.68, 20.0 / 128.0, 0.0, &light);
        let one = |_, _| Complex64::new(1.0, 0.0);
        passed_bins(&ap, &light, Illumination::Incoherent, (n, n), one).unwrap()
    }

    #[test]
    fn no_bins_give_one_zero_cell() {
        let s = pair_sums(&[]);
        assert_eq!(s.s[0].len(), 1);
        assert_eq!(s.at(0, 0), [Complex64::default(); 2]);
    }

    #[test]
    fn three_openings_pass_the_carrier_at_two_thirds_incoherently() {
        // Autocorrelation of three equal disjoint discs at 0, ±ω: 3 overlaps at 0, 2 at ±ω,
        // 1 at ±2ω, so OTF(ω) = 2/3 and OTF(2ω) = 1/3 exactly when ω is a whole bin shift.
        let s = pair_sums(&three_discs());
        let dc = s.at(0, 0)[0].re;
        assert!((s.at(20, 0)[0].re / dc - 2.0 / 3.0).abs() < 1e-12);
        assert!((s.at(40, 0)[0].re / dc - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(s.at(30, 0)[0], Complex64::default());
        // A line has no spread about its centroid.
        assert_eq!(s.at(20, 0)[1], Complex64::default());
    }

    #[test]
    fn a_streak_filters_bins_sum_by_slices_as_pair_by_pair_and_large_sets_are_sliced() {
        let band = Curve::new("ramp", vec![400.0, 700.0], vec![1.0, 2.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        let ap = FourierFilterConfig::default().aperture(13.68, 0.25, 0.125, &light);
        let value = |kx: i64, ky: i64| {
            let r = 1.0 / (1.0 + (kx * kx + ky * ky) as f64).sqrt();
            Complex64::from_polar(r, 0.37 * kx as f64 - 0.11 * ky as f64)
        };
        let bins = |n| passed_bins(&ap, &light, Illumination::Coherent, (n, n), value).unwrap();
        // The full rig's grid: slicing is chosen.
        let large = bins(1536);
        assert!(sliced::Plan::new(&large).is_some(), "{} bins", large.len());
        let small = bins(1024);
        let e = relative_difference(
            &sliced::Plan::with_slices(&small, 12).sums(&small),
            &direct_pair_sums(&small),
        );
        assert!(e[0] < 1e-12 && e[1] < 1e-12, "{e:?}");
    }

    #[test]
    fn sliced_three_discs_pass_the_carrier_at_two_thirds_incoherently() {
        // The hand-solved OTF above through every slicing, for a 532 nm line: its
        // weight sits at one wavelength, so all slices but one carry none and are skipped.
        let bins = three_discs();
        for k in [1, 3, 100] {
            let s = sliced::Plan::with_slices(&bins, k).sums(&bins);
            let dc = s.at(0, 0)[0].re;
            assert!(
                (s.at(20, 0)[0].re / dc - 2.0 / 3.0).abs() < 1e-12,
                "{k} slices"
            );
            assert!(
                (s.at(40, 0)[0].re / dc - 1.0 / 3.0).abs() < 1e-12,
                "{k} slices"
            );
            assert!(s.at(30, 0)[0].norm() < 1e-12 * dc, "{k} slices");
        }
    }

    #[test]
    fn a_disc_passes_the_carrier_of_a_narrow_band_only() {
        // Flat light on 500–600 nm; a disc cut for 550 nm at ω = 0.25 cycles/mirror, radius R µm:
        // the +ω bin passes while |λ − 550|·0.25·k ≤ R, a window of 2R/(0.25·k) nm.
        let band = Curve::new("flat", vec![500.0, 600.0], vec![1.0, 1.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        let f = FourierFilterConfig {
            pinhole_radius_um: 25.0,
            shape: PinholeShape::Circle,
            ..Default::default()
        };
        let ap = f.aperture(13.68, 0.25, 0.0, &light);
        let k = f.um_per_cycle_nm(13.68);
        let half = 25.0 / (0.25 * k);
        let (lo, hi) = ap.pass_interval(1, 0.25, 0.0).unwrap();
        assert!((lo - (550.0 - half)).abs() < 1e-9 && (hi - (550.0 + half)).abs() < 1e-9);
        let bins = passed_bins(&ap, &light, Illumination::Coherent, (64, 64), |_, _| {
            Complex64::new(1.0, 0.0)
        })
        .unwrap();
        let carrier = bins.iter().find(|b| (b.kx, b.ky) == (16, 0)).unwrap();
        assert!((carrier.weight - 2.0 * half / 100.0).abs() < 1e-12);
        // DC passes at every wavelength; the pair (ω, 0) only where both do.
        let dc = bins.iter().find(|b| (b.kx, b.ky) == (0, 0)).unwrap();
        assert!((dc.weight - 1.0).abs() < 1e-12);
        // Î(ω) = F(ω)F*(0) + F(0)F*(−ω): both pairs pass only in the carrier's window.
        let minus = bins.iter().find(|b| (b.kx, b.ky) == (-16, 0)).unwrap();
        let s = pair_sums(&bins);
        let want = overlap(carrier, dc)[0] + overlap(dc, minus)[0];
        assert!((want - 4.0 * half / 100.0).abs() < 1e-12);
        assert!((s.at(16, 0)[0].re - want).abs() < 1e-12);
    }

    #[test]
    fn a_streak_passes_the_carrier_of_the_whole_band() {
        let band = Curve::new("flat", vec![500.0, 600.0], vec![1.0, 1.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        let f = FourierFilterConfig::default();
        let ap = f.aperture(13.68, 0.25, 0.125, &light);
        let bins = passed_bins(&ap, &light, Illumination::Coherent, (64, 64), |_, _| {
            Complex64::new(1.0, 0.0)
        })
        .unwrap();
        let carrier = bins.iter().find(|b| (b.kx, b.ky) == (16, 8)).unwrap();
        assert!((carrier.weight - 1.0).abs() < 1e-12, "{}", carrier.weight);
        let minus = bins.iter().find(|b| (b.kx, b.ky) == (-16, -8)).unwrap();
        assert!((minus.weight - 1.0).abs() < 1e-12);
    }

    #[test]
    fn the_band_sum_is_the_limit_of_line_sums() {
        // Exactness in λ: Σ_j w_j·(pair sums of the line λ_j) on a fine grid of lines converges
        // to the band's pair sums, for both illuminations (incoherent lines weighted by λ²/λc²,
        // each line's OTF being normalised by its area).
        let band = Curve::new("ramp", vec![480.0, 620.0], vec![1.0, 3.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        let lc = light.centroid_nm();
        let f = FourierFilterConfig {
            shape: PinholeShape::Circle,
            pinhole_radius_um: 40.0,
            ..Default::default()
        };
        let (n, fx, fy) = (48, 0.25, 0.125);
        let value = |kx: i64, ky: i64| Complex64::new(1.0 + 0.1 * kx as f64, 0.05 * ky as f64);
        for ill in [Illumination::Coherent, Illumination::Incoherent] {
            let ap = f.aperture(13.68, fx, fy, &light);
            let exact = pair_sums(&passed_bins(&ap, &light, ill, (n, n), value).unwrap());
            let steps = 4000;
            let mut sum = [Complex64::default(); 3];
            for i in 0..steps {
                let (a, b) = (
                    480.0 + 140.0 * i as f64 / steps as f64,
                    480.0 + 140.0 * (i + 1) as f64 / steps as f64,
                );
                let w = light.moments(a, b)[0];
                let l = 0.5 * (a + b);
                let w = match ill {
                    Illumination::Coherent => w,
                    Illumination::Incoherent => w * l * l / (lc * lc),
                };
                let line = PatternLight::Line(l);
                let s = pair_sums(&passed_bins(&ap, &line, ill, (n, n), value).unwrap());
                for (acc, (qx, qy)) in sum.iter_mut().zip([(0, 0), (12, 6), (24, 12)]) {
                    *acc += s.at(qx, qy)[0] * w;
                }
            }
            for (acc, (qx, qy)) in sum.iter().zip([(0, 0), (12, 6), (24, 12)]) {
                let e = exact.at(qx, qy)[0];
                assert!(
                    (e - acc).norm() <= 2e-3 * e.norm().max(1e-9),
                    "{ill:?} ({qx}, {qy}): {e} vs {acc}"
                );
            }
        }
    }

    #[test]
    fn pass_intervals_agree_with_the_mask_at_every_wavelength() {
        // Brute force: the mask at λ contains f exactly when λ lies in the bin's interval.
        let band = Curve::new("b", vec![420.0, 680.0], vec![1.0, 2.0]).unwrap();
        let light = PatternLight::band(&band).unwrap();
        for shape in [
            PinholeShape::Circle,
            PinholeShape::Square,
            PinholeShape::Streak,
        ] {
            let f = FourierFilterConfig {
                shape,
                pinhole_radius_um: 60.0,
                ..Default::default()
            };
            let ap = f.aperture(13.68, 0.3, -0.2, &light);
            for (i, (fx, fy)) in [
                (0.3, -0.2),
                (0.31, -0.19),
                (0.24, -0.16),
                (0.4, -0.27),
                (0.005, 0.01),
                (-0.3, 0.2),
            ]
            .into_iter()
            .enumerate()
            {
                let ivs: Vec<(f64, f64)> =
                    (0..3).filter_map(|j| ap.pass_interval(j, fx, fy)).collect();
                for l in (300..=900).map(|l| l as f64 + 0.37) {
                    let inside = ap.at_wavelength(l).at(fx, fy) > 0.0;
                    let within = ivs.iter().any(|&(lo, hi)| lo <= l && l <= hi);
                    assert_eq!(inside, within, "{shape:?} point {i} at {l} nm: {ivs:?}");
                }
            }
        }
    }

    #[test]
    fn too_many_bins_are_refused_naming_the_radius() {
        let light = PatternLight::Line(532.0);
        let f = filter(400.0, 1024, PinholeShape::Circle);
        let ap = f.aperture(13.68, 0.25, 0.0, &light);
        let e = passed_bins(
            &ap,
            &light,
            Illumination::Incoherent,
            (1024, 1024),
            |_, _| Complex64::new(1.0, 0.0),
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("rig.fourier_filter.pinhole_radius_um"), "{e}");
    }

    /// The GPU's pair summer, or None (said in one line) without an adapter.
    #[cfg(feature = "gpu")]
    fn gpu() -> Option<GpuPairSummer> {
        crate::forward::gpu_tests::context().map(|ctx| GpuPairSummer::new(&ctx))
    }

    /// The GPU's sums on the hand-solved three discs (OTF 2/3 and 1/3) within 1e-5 of the
    /// largest |sum|, as the CPU's: the same reach, and the moment exactly 0 for a line.
    #[cfg(feature = "gpu")]
    #[test]
    fn gpu_pair_sums_solve_the_three_discs() {
        let Some(gpu) = gpu() else { return };
        let bins = three_discs();
        let (cpu, g) = (pair_sums(&bins), gpu.pair_sums(&bins).unwrap());
        let e = relative_difference(&g, &cpu);
        eprintln!(
            "three discs ({} bins): GPU against CPU {:.1e}, {:.1e}",
            bins.len(),
            e[0],
            e[1]
        );
        assert!(e[0] < 1e-5 && e[1] == 0.0, "{e:?}");
        let dc = g.at(0, 0)[0].re;
        assert!((g.at(20, 0)[0].re / dc - 2.0 / 3.0).abs() < 1e-5);
        assert!((g.at(40, 0)[0].re / dc - 1.0 / 3.0).abs() < 1e-5);
        assert_eq!(g.at(30, 0)[0], Complex64::default());
    }

    /// The interval lo–hi nm of flat light on 400–700 nm, with its cumulative pair weights
    /// (weight, first moment about 550 nm).
    #[cfg(feature = "gpu")]
    fn flat_interval(lo: f64, hi: f64) -> Interval {
        let c = |l: f64| {
            [
                (l - 400.0) / 300.0,
                ((l - 550.0).powi(2) - 150.0f64.powi(2)) / 600.0,
            ]
        };
        Interval {
            lo,
            hi,
            c_lo: c(lo),
            c_hi: c(hi),
        }
    }

    /// A bin at (kx, ky) of `value` that passes in `iv` alone.
    #[cfg(feature = "gpu")]
    fn one_interval_bin(kx: i64, ky: i64, value: Complex64, iv: Interval) -> PassedBin {
        PassedBin {
            kx,
            ky,
            value,
            weight: 0.0,
            ivs: [iv, Interval::default(), Interval::default()],
            n: 1,
        }
    }

    /// Bins past [`SLICED_FROM_BINS`] along a streak go to the CPU's slices: the GPU's summer
    /// gives the sliced f64 sums (within 1e-12), not the f32 kernel's (about 1e-7 off).
    #[cfg(feature = "gpu")]
    #[test]
    fn the_gpu_summer_hands_a_large_relay_to_the_slices() {
        let Some(gpu) = gpu() else { return };
        // A band 6 000 × 3 bins, each passing 450–650 nm of flat light on 400–700 nm.
        let bins: Vec<PassedBin> = (0..6000i64)
            .flat_map(|kx| (0..3i64).map(move |ky| (kx, ky)))
            .map(|(kx, ky)| {
                let value = Complex64::new((kx % 7) as f64 - 3.0, (ky - 1) as f64 + 0.5);
                one_interval_bin(kx, ky, value, flat_interval(450.0, 650.0))
            })
            .collect();
        assert!(bins.len() > SLICED_FROM_BINS && sliced::Plan::new(&bins).is_some());
        let e = relative_difference(&gpu.pair_sums(&bins).unwrap(), &pair_sums(&bins));
        assert!(e[0] < 1e-12 && e[1] < 1e-12, "{e:?}");
    }

    /// Columns along ky as a streak along ky gives them: four columns over 3 000 rows, one long
    /// run and one of many short runs (every other row, as a dithered pattern's spectrum holds
    /// them), so each cell's loops are long. The GPU's sums stay within 1e-5 of the CPU's
    /// (lavapipe once ended such loops early and summed a fraction of the pairs, silently).
    #[cfg(feature = "gpu")]
    #[test]
    fn gpu_pair_sums_match_the_cpu_along_long_columns() {
        let Some(gpu) = gpu() else { return };
        let kept = |kx: i64, ky: i64| kx != 2 || ky % 2 != 0 || ky % 64 == 0;
        let bins: Vec<PassedBin> = (0..4i64)
            .flat_map(|kx| (-1500..1500i64).map(move |ky| (kx, ky)))
            .filter(|&(kx, ky)| kept(kx, ky))
            .map(|(kx, ky)| {
                let value = Complex64::new(((ky * 7 + kx) % 5) as f64 - 2.0, 0.5 - kx as f64);
                let lo = 450.0 + (ky.rem_euclid(9) * 10) as f64;
                one_interval_bin(kx, ky, value, flat_interval(lo, 650.0))
            })
            .collect();
        assert!(bins.len() < SLICED_FROM_BINS);
        let e = relative_difference(&gpu.pair_sums(&bins).unwrap(), &pair_sums(&bins));
        eprintln!("long columns: GPU against CPU {:.1e}, {:.1e}", e[0], e[1]);
        assert!(e[0] < 1e-5 && e[1] < 1e-5, "{e:?}");
    }

    /// Random bins (a sparse random set of a box, so columns hold several runs; 1–3 intervals
    /// each with ends on a 10 nm grid, so ends tie; complex values; flat light on 400–700 nm):
    /// the GPU's sums within 1e-5 of the CPU's largest |sum| per component.
    #[cfg(feature = "gpu")]
    #[test]
    fn gpu_pair_sums_match_the_cpu_on_random_bins() {
        use rand::{Rng, SeedableRng};
        let Some(gpu) = gpu() else { return };
        let mut worst = [0.0f64; 2];
        for seed in 0..12u64 {
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
            let (w, h) = (rng.gen_range(1..40), rng.gen_range(1..40));
            let fill = rng.gen_range(0.2..1.0);
            let mut bins = Vec::new();
            for (kx, ky) in (0..w).flat_map(|x| (0..h).map(move |y| (x - w / 2, y - h / 3))) {
                if !rng.gen_bool(fill) {
                    continue;
                }
                let n = rng.gen_range(1..=3);
                let mut ends: Vec<f64> = (0..2 * n)
                    .map(|_| rng.gen_range(40..70) as f64 * 10.0)
                    .collect();
                ends.sort_by(f64::total_cmp);
                let mut ivs = [Interval::default(); 3];
                for (iv, e) in ivs.iter_mut().zip(ends.chunks(2)) {
                    *iv = flat_interval(e[0], e[1]);
                }
                let value = Complex64::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0));
                bins.push(PassedBin {
                    kx,
                    ky,
                    value,
                    weight: 0.0,
                    ivs,
                    n,
                });
            }
            let e = relative_difference(&gpu.pair_sums(&bins).unwrap(), &pair_sums(&bins));
            worst = [0, 1].map(|k| worst[k].max(e[k]));
        }
        eprintln!(
            "random bins: GPU against CPU, worst {:.1e}, {:.1e}",
            worst[0], worst[1]
        );
        assert!(worst[0] < 1e-5 && worst[1] < 1e-5, "{worst:?}");
    }
}
