//! A carrier layout on the exact FFT bins of an N × N frame: J carriers ω_i = (kx_i, ky_i)/N and
//! the square crop windows (`window` bins a side) around DC and every ±ω_i. A layout is feasible
//! when the 2J + 1 windows do not overlap (the core's `check_layout`, which names the pair) and,
//! under a guard, when no 2ω_i harmonic (and, under the full guard, no ω_i ± ω_j term) lands
//! inside a window. Baselines: the paper's default layout and the diamond rule.

use serde::{Deserialize, Serialize};
use specmux_core::carriers::{check_layout, default_layout, window_bins};
use specmux_core::{Carrier, Error, Result};

/// Which spurious terms of the pattern optics a layout must keep out of every window.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Guard {
    /// Windows apart, nothing more.
    None,
    /// Also ±2ω_i (the coherent and incoherent 4f models both pass a 2ω_i term).
    Harmonics,
    /// Also ±(ω_i + ω_j) and ±(ω_i − ω_j) (any nonlinearity of the rig mixes carriers).
    All,
}

/// A layout: frame size, window size in bins, carrier bins (one per channel, in channel order).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Layout {
    pub size: usize,
    pub window: usize,
    pub bins: Vec<(i64, i64)>,
}

/// Circular distance on an n-point axis.
fn cdist(a: i64, b: i64, n: i64) -> i64 {
    let d = (a - b).rem_euclid(n);
    d.min(n - d)
}

impl Layout {
    /// A layout of `carriers` snapped to the bins of an `size`-point FFT, windows of `crop`.
    pub fn from_carriers(carriers: &[Carrier], size: usize, crop: f64) -> Layout {
        Layout {
            size,
            window: window_bins(crop, size),
            bins: carriers
                .iter()
                .map(|c| (Carrier::bin(c.fx, size), Carrier::bin(c.fy, size)))
                .collect(),
        }
    }

    /// The carriers (cycles/pixel, phase 0).
    pub fn carriers(&self) -> Vec<Carrier> {
        let n = self.size as f64;
        self.bins
            .iter()
            .map(|&(x, y)| Carrier {
                fx: x as f64 / n,
                fy: y as f64 / n,
                phase_rad: 0.0,
            })
            .collect()
    }

    /// The crop fraction of the windows.
    pub fn crop(&self) -> f64 {
        self.window as f64 / self.size as f64
    }

    /// Window centres: DC, then +ω_i and −ω_i of each carrier.
    fn centres(&self) -> Vec<(i64, i64)> {
        let mut c = vec![(0, 0)];
        for &(x, y) in &self.bins {
            c.push((x, y));
            c.push((-x, -y));
        }
        c
    }

    /// The spurious terms the guard keeps out of the windows, with a name each.
    fn spurious(&self, guard: Guard) -> Vec<(String, (i64, i64))> {
        let mut out = Vec::new();
        if guard == Guard::None {
            return out;
        }
        for (i, &(x, y)) in self.bins.iter().enumerate() {
            out.push((format!("2ω{i}"), (2 * x, 2 * y)));
        }
        if guard == Guard::All {
            for (i, &(x, y)) in self.bins.iter().enumerate() {
                for (j, &(u, v)) in self.bins.iter().enumerate().skip(i + 1) {
                    out.push((format!("ω{i}+ω{j}"), (x + u, y + v)));
                    out.push((format!("ω{i}−ω{j}"), (x - u, y - v)));
                }
            }
        }
        out
    }

    /// Every ω_i ± ω_j (i < j, both signs), wrapped into the Nyquist square: for drawing.
    pub fn intermodulation(&self) -> Vec<(i64, i64)> {
        let n = self.size as i64;
        let wrap = |v: i64| (v + n / 2).rem_euclid(n) - n / 2;
        self.spurious(Guard::All)
            .into_iter()
            .filter(|(name, _)| !name.starts_with('2'))
            .flat_map(|(_, (x, y))| [(wrap(x), wrap(y)), (wrap(-x), wrap(-y))])
            .collect()
    }

    /// The first spurious term inside a window, as "term at bin … lies in window …".
    fn guard_violation(&self, guard: Guard) -> Option<String> {
        let n = self.size as i64;
        let h = (self.window / 2) as i64;
        let names = |k: usize| match k {
            0 => "DC".to_string(),
            k if k % 2 == 1 => format!("+ω{}", (k - 1) / 2),
            k => format!("−ω{}", (k - 2) / 2),
        };
        let centres = self.centres();
        for (term, (x, y)) in self.spurious(guard) {
            for (sx, sy) in [(x, y), (-x, -y)] {
                let hit = centres
                    .iter()
                    .position(|&(cx, cy)| cdist(sx, cx, n) <= h && cdist(sy, cy, n) <= h);
                if let Some(k) = hit {
                    return Some(format!(
                        "{term} at bin ({sx},{sy}) lies in the {} window",
                        names(k)
                    ));
                }
            }
        }
        None
    }

    /// Refuse an infeasible layout; the error names the overlapping pair or the spurious term.
    pub fn check(&self, guard: Guard, file: &str) -> Result<()> {
        let (n, c) = (self.size, self.crop());
        check_layout(&self.carriers(), c, n, n, file)?;
        match self.guard_violation(guard) {
            None => Ok(()),
            Some(what) => Err(Error::config(
                file,
                "rig.carriers.frequencies",
                what,
                "a spurious term of the pattern optics would leak into that channel; move the carriers or use --guard none",
            )),
        }
    }

    /// True when the layout passes [`Layout::check`] (the fast path of the search).
    pub fn feasible(&self, guard: Guard) -> bool {
        let n = self.size as i64;
        let w = self.window as i64;
        let c = self.centres();
        let inside = |&(x, y): &(i64, i64)| x.abs() * 2 <= n && y.abs() * 2 <= n;
        if !self.bins.iter().all(inside) {
            return false;
        }
        for a in 0..c.len() {
            for b in a + 1..c.len() {
                if cdist(c[a].0, c[b].0, n) < w && cdist(c[a].1, c[b].1, n) < w {
                    return false;
                }
            }
        }
        self.guard_violation(guard).is_none()
    }

    /// The paper's layout (4 × 4 tiles of a quarter) on this frame's bins.
    pub fn paper_default(size: usize, crop: f64) -> Layout {
        Layout::from_carriers(&default_layout(), size, crop)
    }

    /// The diamond rule (after Li et al., JOSA A 2023, for FRAME-type multiplexing): carriers on
    /// the diamond (quincunx) lattice {(i, j)·w : i + j even} of the window pitch w, ring by ring
    /// of |i| + |j| away from DC, so no carrier sits on an axis next to DC; axial carriers only up
    /// to fs/4. Where fewer than J lattice sites pass, the fs/4 limit is dropped and a note says
    /// so; where still fewer, there is no diamond layout, and the error says why (a note for the
    /// report, not a refusal: the diamond is a baseline).
    pub fn diamond(
        size: usize,
        crop: f64,
        count: usize,
    ) -> std::result::Result<(Layout, Option<String>), String> {
        let w = window_bins(crop, size) as i64;
        let n = size as i64;
        let mut sites: Vec<(i64, i64)> = Vec::new();
        for j in 0..=n / (2 * w.max(1)) {
            for i in -(n / (2 * w.max(1)))..=n / (2 * w.max(1)) {
                let upper = j > 0 || i > 0;
                if (i + j) % 2 == 0 && upper {
                    sites.push((i * w, j * w));
                }
            }
        }
        let ring = |&(x, y): &(i64, i64)| ((x.abs() + y.abs()), (y as f64).atan2(x as f64));
        sites.sort_by(|a, b| {
            ring(a)
                .partial_cmp(&ring(b))
                .unwrap_or(std::cmp::Ordering::Equal)
        });
        let axial_ok = |&(x, y): &(i64, i64)| (x != 0 && y != 0) || 4 * (x.abs() + y.abs()) <= n;
        for (strict, note) in [(true, None), (false, Some(format!("the diamond rule's axial limit fs/4 cannot hold with {count} carriers at crop {crop}: axial carriers beyond it were admitted")))] {
            let mut l = Layout { size, window: w as usize, bins: Vec::new() };
            for s in sites.iter().filter(|s| !strict || axial_ok(s)) {
                l.bins.push(*s);
                if !l.feasible(Guard::None) {
                    l.bins.pop();
                }
                if l.bins.len() == count {
                    return Ok((l, note));
                }
            }
        }
        Err(format!(
            "the diamond lattice of crop {crop} holds fewer than {count} carriers on a {size}-point frame"
        ))
    }

    /// The `[rig.carriers]` section and the crop/window keys of `[reconstruct]`, as TOML.
    pub fn toml(&self, window_shape: &str) -> String {
        let f: Vec<String> = self
            .carriers()
            .iter()
            .map(|c| format!("[{}, {}]", c.fx, c.fy))
            .collect();
        format!(
            "[rig.carriers]\n# {} × {} frame, bins {:?}\nfrequencies = [{}]\n\n[reconstruct]\ncrop = {}\nwindow = \"{window_shape}\"\n",
            self.size,
            self.size,
            self.bins,
            f.join(", "),
            self.crop()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_overlapping_layout_is_refused_with_the_pair_named() {
        let mut l = Layout::paper_default(256, 0.25);
        l.check(Guard::Harmonics, "t").unwrap();
        l.bins[2] = (70, 10); // next to carrier 0 at (64, 0)
        assert!(!l.feasible(Guard::None));
        let e = l.check(Guard::None, "d.toml").unwrap_err().to_string();
        assert!(
            e.contains("+ω0") && e.contains("+ω2") && e.contains("overlap"),
            "{e}"
        );
    }

    #[test]
    fn a_harmonic_inside_a_window_is_named() {
        // 2·(51, 51) = (102, 102) lies on the window of a carrier placed there.
        let l = Layout {
            size: 256,
            window: 51,
            bins: vec![(51, 51), (102, 102)],
        };
        assert!(l.feasible(Guard::None));
        assert!(!l.feasible(Guard::Harmonics));
        let e = l.check(Guard::Harmonics, "t").unwrap_err().to_string();
        assert!(e.contains("2ω0") && e.contains("+ω1"), "{e}");
    }

    #[test]
    fn the_diamond_keeps_carriers_off_the_axes_next_to_dc() {
        let (d, note) = Layout::diamond(256, 0.125, 6).unwrap();
        assert!(note.is_none());
        assert!(d.feasible(Guard::None));
        let w = d.window as i64;
        for &(x, y) in &d.bins {
            assert_eq!((x / w + y / w) % 2, 0);
            assert!(
                x != 0 && y != 0 || 4 * (x.abs() + y.abs()) <= 256,
                "{x},{y}"
            );
        }
        let (d, note) = Layout::diamond(256, 0.2, 6).unwrap();
        assert!(note.is_some() && d.bins.len() == 6);
        assert!(Layout::diamond(256, 0.3, 6).is_err());
    }
}
