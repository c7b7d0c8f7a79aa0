//! The 4f relay with a mask in its Fourier plane: openings at 0 and ±ω_i pass the pattern's DC
//! and carrier orders and block the dither noise and the DMD's grating orders. A point ξ (µm)
//! of the Fourier plane holds the spatial frequency ξ·pitch/(λ·f) cycles per mirror: the mask
//! is fixed in µm, so each wavelength of a broadband pattern sees it scaled, and the carrier
//! order of light λ passes a disc cut for λ_d only while |λ − λ_d|·|ω|·f/pitch ≤ radius.

use crate::optics::light::PatternLight;
use serde::{Deserialize, Serialize};
use specmux_core::error::Error;
use specmux_core::error::Result;

/// How the light that forms the pattern is filtered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Illumination {
    /// Laser-like: the mask filters the field; the intensity is |field|², so the passed orders
    /// −1, 0, +1 beat into a 2ω_i harmonic.
    Coherent,
    /// Extended source: the intensity is filtered by the mask's OTF (its normalised
    /// autocorrelation), which also passes 2ω_i.
    Incoherent,
}

/// Shape of each opening.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PinholeShape {
    /// A disc, placed where the carrier order of the design wavelength lands.
    Circle,
    /// A square of side 2 × radius, aligned with the mirror axes, placed like the disc.
    Square,
    /// A disc swept along the order's dispersion over the pattern's band (its 1–99 % weight
    /// quantiles): every wavelength's carrier order passes. The DC opening stays a disc.
    Streak,
}

/// Which light forms the pattern.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Light {
    /// The pattern's own wheel segment: the band T_i·L·QE, integrated exactly over λ.
    Channel,
    /// A laser line at `wavelength_nm` for every pattern.
    Line,
}

/// Fraction of the band's weight left outside a streak at each end.
pub const STREAK_QUANTILE: f64 = 0.01;

/// `[rig.fourier_filter]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FourierFilterConfig {
    /// Focal length of the Fourier lens in mm (100 mm: assumed; the paper's concave mirror is
    /// not specified). At 532 nm and 13.68 µm pitch, 1 cycle/mirror lies 3.89 mm off axis.
    pub focal_length_mm: f64,
    /// The light that forms each pattern (default: its wheel segment's band).
    pub light: Light,
    /// The laser line of `light = "line"`, nm (532 nm).
    pub wavelength_nm: f64,
    /// Wavelength a disc or square opening is placed for, nm; absent: the centroid of the
    /// pattern's light (a mask cut per wheel segment, as the DMD half that forms the mask can).
    pub design_wavelength_nm: Option<f64>,
    /// Radius (half-width) of each opening in µm (25 µm: 0.0064 cycles/mirror at 532 nm and
    /// the defaults, 4.9 bins of a 768-mirror pattern).
    pub pinhole_radius_um: f64,
    pub shape: PinholeShape,
    /// Spatial coherence of the light on the DMD.
    pub illumination: Illumination,
}

impl Default for FourierFilterConfig {
    fn default() -> Self {
        FourierFilterConfig {
            focal_length_mm: 100.0,
            light: Light::Channel,
            wavelength_nm: 532.0,
            design_wavelength_nm: None,
            pinhole_radius_um: 25.0,
            shape: PinholeShape::Streak,
            illumination: Illumination::Coherent,
        }
    }
}

impl FourierFilterConfig {
    pub fn validate(&self, file: &str) -> Result<()> {
        let k = "rig.fourier_filter.";
        if !(self.focal_length_mm.is_finite()
            && self.focal_length_mm >= 1.0
            && self.focal_length_mm <= 10_000.0)
        {
            return Err(Error::config(
                file,
                &format!("{k}focal_length_mm"),
                self.focal_length_mm,
                "must be 1–10000 mm",
            ));
        }
        for (name, v) in [
            ("wavelength_nm", Some(self.wavelength_nm)),
            ("design_wavelength_nm", self.design_wavelength_nm),
        ] {
            if let Some(v) = v.filter(|v| !(v.is_finite() && (200.0..=2000.0).contains(v))) {
                return Err(Error::config(
                    file,
                    &format!("{k}{name}"),
                    v,
                    "must be a wavelength of 200–2000 nm",
                ));
            }
        }
        if !(self.pinhole_radius_um.is_finite()
            && self.pinhole_radius_um > 0.0
            && self.pinhole_radius_um <= 1e5)
        {
            return Err(Error::config(
                file,
                &format!("{k}pinhole_radius_um"),
                self.pinhole_radius_um,
                "must be a radius of (0, 100000] µm",
            ));
        }
        Ok(())
    }

    /// µm of the Fourier plane per (cycle/mirror · nm): a frequency f of light λ lands at
    /// ξ = f·λ·F/pitch.
    pub fn um_per_cycle_nm(&self, pitch_um: f64) -> f64 {
        self.focal_length_mm * 1e3 / pitch_um * 1e-3
    }

    /// A Fourier-plane distance `length_um` in cycles per mirror for light of `wavelength_nm`.
    pub fn cycles_per_mirror(&self, length_um: f64, pitch_um: f64, wavelength_nm: f64) -> f64 {
        length_um / (wavelength_nm * self.um_per_cycle_nm(pitch_um))
    }

    /// The physical mask for a carrier (fx, fy) in cycles per mirror formed by `light`.
    pub fn aperture(&self, pitch_um: f64, fx: f64, fy: f64, light: &PatternLight) -> Aperture {
        let k = self.um_per_cycle_nm(pitch_um);
        let at = |l: f64| (fx * l * k, fy * l * k);
        let neg = |(x, y): (f64, f64)| (-x, -y);
        let (a, b) = match self.shape {
            PinholeShape::Streak => (
                at(light.quantile_nm(STREAK_QUANTILE)),
                at(light.quantile_nm(1.0 - STREAK_QUANTILE)),
            ),
            _ => {
                let c = at(self.design_wavelength_nm.unwrap_or(light.centroid_nm()));
                (c, c)
            }
        };
        Aperture {
            openings: vec![
                Opening {
                    a: (0.0, 0.0),
                    b: (0.0, 0.0),
                },
                Opening { a, b },
                Opening {
                    a: neg(a),
                    b: neg(b),
                },
            ],
            radius_um: self.pinhole_radius_um,
            square: self.shape == PinholeShape::Square,
            um_per_cycle_nm: k,
        }
    }
}

/// One opening: the points within the radius of the segment from `a` to `b` (a disc when
/// a = b; with `square`, the square around a).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Opening {
    pub a: (f64, f64),
    pub b: (f64, f64),
}

impl Opening {
    fn scaled(&self, k: f64) -> Opening {
        Opening {
            a: (self.a.0 * k, self.a.1 * k),
            b: (self.b.0 * k, self.b.1 * k),
        }
    }

    /// Whether (x, y) lies in the opening of radius (half-width) `r`.
    fn contains(&self, x: f64, y: f64, r: f64, square: bool) -> bool {
        if square {
            return (x - self.a.0).abs() <= r && (y - self.a.1).abs() <= r;
        }
        let (dx, dy) = (self.b.0 - self.a.0, self.b.1 - self.a.1);
        let len2 = dx * dx + dy * dy;
        let t = if len2 > 0.0 {
            (((x - self.a.0) * dx + (y - self.a.1) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        within(x - self.a.0 - t * dx, y - self.a.1 - t * dy, r)
    }
}

/// hypot(x, y) ≤ r, decided from x² + y² away from the circle (no square root) and by hypot
/// itself within 1e-9 of it, so the answer is hypot's to the last bit.
#[inline]
fn within(x: f64, y: f64, r: f64) -> bool {
    let (d2, r2) = (x * x + y * y, r * r);
    if d2 < r2 * (1.0 - 1e-9) {
        true
    } else if d2 > r2 * (1.0 + 1e-9) {
        false
    } else {
        x.hypot(y) <= r
    }
}

/// Values of s ≥ 0 with |d·s − c| ≤ r: an interval, or None.
fn disc_interval(d: (f64, f64), c: (f64, f64), r: f64) -> Option<(f64, f64)> {
    let dd = d.0 * d.0 + d.1 * d.1;
    let dc = d.0 * c.0 + d.1 * c.1;
    let cc = c.0 * c.0 + c.1 * c.1;
    if dd == 0.0 {
        return (cc <= r * r).then_some((0.0, f64::INFINITY));
    }
    let disc = dc * dc - dd * (cc - r * r);
    if disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    let (lo, hi) = ((dc - q) / dd, (dc + q) / dd);
    (hi >= 0.0).then_some((lo.max(0.0), hi))
}

/// Values of s with lo ≤ g·s − h ≤ hi (a slab along one direction), or None.
fn slab_interval(g: f64, h: f64, lo: f64, hi: f64) -> Option<(f64, f64)> {
    if g == 0.0 {
        return (lo <= -h && -h <= hi).then_some((f64::NEG_INFINITY, f64::INFINITY));
    }
    let (s1, s2) = ((lo + h) / g, (hi + h) / g);
    Some((s1.min(s2), s1.max(s2)))
}

fn intersect(a: Option<(f64, f64)>, b: Option<(f64, f64)>) -> Option<(f64, f64)> {
    let ((a0, a1), (b0, b1)) = (a?, b?);
    let (lo, hi) = (a0.max(b0), a1.min(b1));
    (lo <= hi).then_some((lo, hi))
}

/// The Fourier-plane mask in physical units (µm), the same at every wavelength.
#[derive(Clone, Debug, PartialEq)]
pub struct Aperture {
    /// The DC opening first, then the +ω and −ω ones.
    pub openings: Vec<Opening>,
    pub radius_um: f64,
    pub square: bool,
    /// See [`FourierFilterConfig::um_per_cycle_nm`].
    pub um_per_cycle_nm: f64,
}

impl Aperture {
    /// The mask as light of `wavelength_nm` sees it, in cycles per mirror.
    pub fn at_wavelength(&self, wavelength_nm: f64) -> Mask {
        let k = 1.0 / (wavelength_nm * self.um_per_cycle_nm);
        Mask {
            openings: self.openings.iter().map(|o| o.scaled(k)).collect(),
            radius: self.radius_um * k,
            square: self.square,
        }
    }

    /// The wavelengths (nm) for which frequency (fx, fy) cycles/mirror lands in opening `j`:
    /// the intersection of the ray ξ = f·λ·k (λ ≥ 0) with the convex opening.
    pub fn pass_interval(&self, j: usize, fx: f64, fy: f64) -> Option<(f64, f64)> {
        let o = &self.openings[j];
        let r = self.radius_um;
        let d = (fx * self.um_per_cycle_nm, fy * self.um_per_cycle_nm);
        let iv = if self.square {
            let x = slab_interval(d.0, o.a.0, -r, r);
            let y = slab_interval(d.1, o.a.1, -r, r);
            intersect(intersect(x, y), Some((0.0, f64::INFINITY)))
        } else {
            let (ex, ey) = (o.b.0 - o.a.0, o.b.1 - o.a.1);
            let len = ex.hypot(ey);
            let ends = [disc_interval(d, o.a, r), disc_interval(d, o.b, r)];
            // The rectangle between the end discs: 0 ≤ (p − a)·e ≤ len, |(p − a)·n| ≤ r.
            let body = (len > 0.0).then(|| {
                let (ux, uy) = (ex / len, ey / len);
                let along = slab_interval(d.0 * ux + d.1 * uy, o.a.0 * ux + o.a.1 * uy, 0.0, len);
                let across = slab_interval(-d.0 * uy + d.1 * ux, -o.a.0 * uy + o.a.1 * ux, -r, r);
                intersect(intersect(along, across), Some((0.0, f64::INFINITY)))
            });
            // The capsule is convex, so the pieces' intervals join into one.
            ends.into_iter()
                .chain(body)
                .flatten()
                .reduce(|(a0, a1), (b0, b1)| (a0.min(b0), a1.max(b1)))
        };
        iv.map(|(lo, hi)| (lo.max(0.0), hi))
    }
}

/// The mask's openings in frequency units (cycles per mirror) for one wavelength.
#[derive(Clone, Debug)]
pub struct Mask {
    pub openings: Vec<Opening>,
    pub radius: f64,
    pub square: bool,
}

impl Mask {
    /// Transmittance (0 or 1) at (fx, fy).
    pub fn at(&self, fx: f64, fy: f64) -> f64 {
        if self
            .openings
            .iter()
            .any(|o| o.contains(fx, fy, self.radius, self.square))
        {
            1.0
        } else {
            0.0
        }
    }

    /// Transmittance seen by a bin of the mirror grid, which stands for f and its replicas f + n.
    /// Replicas outside the openings' extent (with a margin for rounding) are passed over: no
    /// opening reaches them.
    pub fn at_periodic(&self, fx: f64, fy: f64) -> f64 {
        let (ex, ey) = self.extent();
        let (ex, ey) = (ex * (1.0 + 1e-9) + 1e-12, ey * (1.0 + 1e-9) + 1e-12);
        let mut v = 0.0f64;
        for nx in -1..=1 {
            for ny in -1..=1 {
                let (x, y) = (fx + nx as f64, fy + ny as f64);
                if x.abs() <= ex && y.abs() <= ey {
                    v = v.max(self.at(x, y));
                }
            }
        }
        v
    }

    /// Largest |fx| and |fy| any opening reaches.
    pub fn extent(&self) -> (f64, f64) {
        self.openings.iter().fold((0.0, 0.0), |(x, y), o| {
            (
                x.max(o.a.0.abs().max(o.b.0.abs()) + self.radius),
                y.max(o.a.1.abs().max(o.b.1.abs()) + self.radius),
            )
        })
    }
}

/// Incoherent OTF of a circular pupil at ν = f / f_cutoff (f_cutoff = pupil diameter in
/// frequency units): (2/π)(acos ν − ν√(1 − ν²)), zero beyond ν = 1.
pub fn circ_otf(nu: f64) -> f64 {
    let nu = nu.abs();
    if nu >= 1.0 {
        0.0
    } else {
        std::f64::consts::FRAC_2_PI * (nu.acos() - nu * (1.0 - nu * nu).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::relay::pair_sums;
    use crate::optics::relay::passed_bins;
    use rustfft::num_complex::Complex64;

    #[test]
    fn fourier_plane_scale_by_hand() {
        // 25 µm · 13.68 µm / (0.532 µm · 100 000 µm) = 0.006429 cycles/mirror.
        let f = FourierFilterConfig {
            shape: PinholeShape::Circle,
            design_wavelength_nm: Some(532.0),
            ..Default::default()
        };
        assert!((f.cycles_per_mirror(25.0, 13.68, 532.0) - 342.0 / 53200.0).abs() < 1e-12);
        // At 600 nm the openings cut for 532 nm sit at ω · 532/600.
        let ap = f.aperture(13.68, 0.25, 0.0, &PatternLight::Line(600.0));
        let m = ap.at_wavelength(600.0);
        assert!((m.openings[1].a.0 - 0.25 * 532.0 / 600.0).abs() < 1e-12);
        assert!((m.radius - 342.0 / 53200.0 * 532.0 / 600.0).abs() < 1e-12);
    }

    #[test]
    fn circular_pupil_otf_matches_the_closed_form() {
        // One disc of 30 bins at 532 nm: its autocorrelation, normalised, is the Airy OTF
        // (2/π)(acos ν − ν√(1 − ν²)) at ν = lag / 60 bins.
        let n = 256;
        let f = FourierFilterConfig::default();
        let k = f.um_per_cycle_nm(13.68);
        let ap = Aperture {
            openings: vec![Opening {
                a: (0.0, 0.0),
                b: (0.0, 0.0),
            }],
            radius_um: 30.0 / n as f64 * 532.0 * k,
            square: false,
            um_per_cycle_nm: k,
        };
        let light = PatternLight::Line(532.0);
        let one = |_, _| Complex64::new(1.0, 0.0);
        let bins = passed_bins(&ap, &light, Illumination::Incoherent, (n, n), one).unwrap();
        let otf = pair_sums(&bins);
        let dc = otf.at(0, 0)[0].re;
        for lag in [6i64, 15, 30, 45] {
            let want = circ_otf(lag as f64 / 60.0);
            for (qx, qy) in [(lag, 0), (0, lag)] {
                let got = otf.at(qx, qy)[0].re / dc;
                // A sampled disc of 30 bins: its area and overlaps are right to ~1 %.
                assert!((got - want).abs() < 0.01, "lag {lag}: {got} vs {want}");
            }
        }
        assert_eq!(otf.at(61, 0)[0], Complex64::default(), "beyond the cutoff");
    }

    #[test]
    fn within_is_hypot_by_hand_and_on_the_circle() {
        // (3, 4) lies at 5: inside a radius of 5, outside 5 − 1 ulp; (0, 0) in a radius of 0.
        assert!(within(3.0, 4.0, 5.0) && !within(3.0, 4.0, f64::from_bits(5.0f64.to_bits() - 1)));
        assert!(within(0.0, 0.0, 0.0) && !within(f64::NAN, 0.0, 1.0));
    }

    proptest::proptest! {
        #[test]
        fn within_agrees_with_hypot(x in -2.0f64..2.0, y in -2.0f64..2.0, scale in 0.5f64..1.5) {
            // Radii at, just off and far from the point's distance.
            let d = x.hypot(y);
            // One ulp either side (d > 0 but for a null draw, where d itself serves).
            let (up, down) = (f64::from_bits(d.to_bits() + 1), f64::from_bits(d.to_bits().max(1) - 1));
            for r in [d, up, down, d * scale] {
                proptest::prop_assert_eq!(within(x, y, r), x.hypot(y) <= r);
            }
        }

        #[test]
        fn periodic_mask_skips_only_replicas_it_cannot_reach(
            fx in -0.5f64..0.5, fy in -0.5f64..0.5, cx in -0.6f64..0.6, cy in -0.6f64..0.6,
            r in 0.001f64..0.3, streak in 0.0f64..0.2, square in proptest::bool::ANY,
        ) {
            let o = Opening { a: (cx, cy), b: (cx + streak, cy - streak) };
            let m = Mask {
                openings: vec![Opening { a: (0.0, 0.0), b: (0.0, 0.0) }, o, o.scaled(-1.0)],
                radius: r,
                square,
            };
            let all = (-1..=1)
                .flat_map(|nx| (-1..=1).map(move |ny| (nx as f64, ny as f64)))
                .map(|(nx, ny)| m.at(fx + nx, fy + ny))
                .fold(0.0f64, f64::max);
            proptest::prop_assert_eq!(m.at_periodic(fx, fy), all);
        }
    }

    #[test]
    fn bad_values_name_their_key() {
        for (f, key) in [
            (
                FourierFilterConfig {
                    design_wavelength_nm: Some(f64::NAN),
                    ..Default::default()
                },
                "design_wavelength_nm",
            ),
            (
                FourierFilterConfig {
                    pinhole_radius_um: 0.0,
                    ..Default::default()
                },
                "pinhole_radius_um",
            ),
        ] {
            let e = f.validate("x.toml").unwrap_err().to_string();
            assert!(e.contains(key) && e.contains("x.toml"), "{e}");
        }
    }
}
