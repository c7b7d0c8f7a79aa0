//! The predicted crosstalk of a layout, from measured scene spectra.
//!
//! With ideal patterns the frame is y = Σ_j x_j + Σ_j ½x_j (e^{iω_j·p} + e^{−iω_j·p}), so window i
//! (centred on +ω_i) receives, besides its own channel, the DC term's spectrum |FFT Σ_j x_j|²,
//! each other carrier's ¼|X_j(k ∓ ω_j)|² and its own mirror ¼|X_i(k + ω_i)|², and, where the
//! pattern optics add a harmonic of relative amplitude a, a²|X_j(k ∓ 2ω_j)|². The prediction adds
//! these energies over the window's bins (cross terms between sources are left out) and turns
//! them into a channel MSE: x̂_i = 2 Re IFFT(window), so MSE = 2 E / (w h)².
//!
//! A scene's spectra are measured once on its own grid and read at the design grid's frequencies
//! (nearest bin, energy per bin rescaled), then divided by the scene's peak², so scenes of
//! different sizes and brightness weigh alike. Window sums are O(1) from periodic summed-area
//! tables, so a layout is scored in O(J²) lookups and the search can try millions.

use crate::layout::Layout;
use specmux_core::fft::Fft2;
use specmux_core::{Cube, Error, Result};

/// Window sums of a periodic N × N table in O(1).
#[derive(Clone, Debug)]
pub struct PeriodicSums {
    n: usize,
    /// (n+1)² prefix sums, row-major.
    s: Vec<f64>,
}

impl PeriodicSums {
    /// From an n × n table (row-major, index ky·n + kx).
    pub fn new(table: &[f64], n: usize) -> PeriodicSums {
        let mut s = vec![0.0; (n + 1) * (n + 1)];
        for y in 0..n {
            for x in 0..n {
                s[(y + 1) * (n + 1) + x + 1] =
                    table[y * n + x] + s[y * (n + 1) + x + 1] + s[(y + 1) * (n + 1) + x]
                        - s[y * (n + 1) + x];
            }
        }
        PeriodicSums { n, s }
    }

    /// Sum over [x0, x0+len) × [y0, y0+len) with 0 ≤ x0, y0 < n and len ≤ n, unwrapped.
    fn rect(&self, x0: usize, y0: usize, wx: usize, wy: usize) -> f64 {
        let m = self.n + 1;
        let (x1, y1) = (x0 + wx, y0 + wy);
        self.s[y1 * m + x1] - self.s[y0 * m + x1] - self.s[y1 * m + x0] + self.s[y0 * m + x0]
    }

    /// Sum over the `w × w` window centred on bin (cx, cy) (spanning c − ⌊w/2⌋ … c − ⌊w/2⌋ + w − 1,
    /// as the demultiplexer's windows), wrapping around the plane.
    pub fn window(&self, cx: i64, cy: i64, w: usize) -> f64 {
        let n = self.n as i64;
        let w = w.min(self.n);
        let x0 = (cx - (w / 2) as i64).rem_euclid(n) as usize;
        let y0 = (cy - (w / 2) as i64).rem_euclid(n) as usize;
        let split = |a0: usize| -> [(usize, usize); 2] {
            let first = w.min(self.n - a0);
            [(a0, first), (0, w - first)]
        };
        let mut total = 0.0;
        for (xs, xw) in split(x0) {
            for (ys, yw) in split(y0) {
                if xw > 0 && yw > 0 {
                    total += self.rect(xs, ys, xw, yw);
                }
            }
        }
        total
    }
}

/// One scene's spectra on the design grid: the DC term and each channel, scaled so that a window
/// sum is that source's contribution to the channel MSE over peak².
#[derive(Clone, Debug)]
pub struct SceneSpectra {
    pub name: String,
    pub dc: PeriodicSums,
    pub channels: Vec<PeriodicSums>,
    /// The mean channel power (unscaled layout of the design grid), for drawing.
    pub mean_power: Vec<f64>,
}

/// |FFT|² of a plane on its own w × h grid, full plane, row-major ky·w + kx.
fn power(fft: &Fft2, plane: &[f32]) -> Vec<f64> {
    let s = fft.forward(plane);
    let (w, h) = (fft.w as i64, fft.h as i64);
    (0..h)
        .flat_map(|ky| (0..w).map(move |kx| (kx, ky)))
        .map(|(kx, ky)| s.at(kx, ky).norm_sqr() as f64)
        .collect()
}

/// Read a w × h power table at the frequencies of an n × n grid (nearest bin), rescaled.
fn to_grid(p: &[f64], w: usize, h: usize, n: usize, scale: f64) -> Vec<f64> {
    let mut out = vec![0.0; n * n];
    let area = (w * h) as f64 / (n * n) as f64;
    for ky in 0..n {
        let sy = ((ky as f64 * h as f64 / n as f64).round() as usize) % h;
        for kx in 0..n {
            let sx = ((kx as f64 * w as f64 / n as f64).round() as usize) % w;
            out[ky * n + kx] = p[sy * w + sx] * area * scale;
        }
    }
    out
}

impl SceneSpectra {
    /// Measure the spectra of a scene's true channels `x` for a design grid of `n` bins.
    pub fn measure(name: &str, x: &Cube, n: usize) -> Result<SceneSpectra> {
        let (w, h) = (x.width, x.height);
        let peak = x.max() as f64;
        if !(peak > 0.0) || x.planes == 0 {
            return Err(Error::Numerical(format!(
                "scene {name}: its channels are dark"
            )));
        }
        let fft = Fft2::new(w, h);
        // MSE = 2 E / (w h)²; energy per design bin is the scene's bin energy × (w h)/(n n).
        let scale = 2.0 / ((w * h) as f64).powi(2) / (peak * peak);
        let dc_plane = x.mix(&[vec![1.0; x.planes]])?;
        let dc = to_grid(&power(&fft, dc_plane.plane(0)), w, h, n, scale);
        let mut mean_power = vec![0.0; n * n];
        let mut channels = Vec::with_capacity(x.planes);
        for k in 0..x.planes {
            let p = to_grid(&power(&fft, x.plane(k)), w, h, n, scale);
            mean_power.iter_mut().zip(&p).for_each(|(m, v)| *m += v);
            channels.push(PeriodicSums::new(&p, n));
        }
        Ok(SceneSpectra {
            name: name.to_string(),
            dc: PeriodicSums::new(&dc, n),
            channels,
            mean_power,
        })
    }

    /// Predicted MSE/peak² that leaks into channel `t`'s window, from every source; `a2` is the
    /// squared relative amplitude of the 2ω harmonics.
    pub fn leak_into(&self, l: &Layout, t: usize, a2: f64) -> f64 {
        let (cx, cy) = l.bins[t];
        let w = l.window;
        let mut e = self.dc.window(cx, cy, w);
        for j in 0..l.bins.len() {
            e += self.from_source(l, j, t, a2);
        }
        e
    }

    /// Leak of carrier `j`'s terms into channel `t`'s window (its mirror when j = t).
    pub fn from_source(&self, l: &Layout, j: usize, t: usize, a2: f64) -> f64 {
        let ((cx, cy), (x, y), w) = (l.bins[t], l.bins[j], l.window);
        let p = &self.channels[j];
        let mut e = 0.25 * p.window(cx + x, cy + y, w);
        if j != t {
            e += 0.25 * p.window(cx - x, cy - y, w);
        }
        if a2 > 0.0 {
            e += a2 * (p.window(cx - 2 * x, cy - 2 * y, w) + p.window(cx + 2 * x, cy + 2 * y, w));
        }
        e
    }
}

/// The objective of a layout on a set of scenes: Σ_scenes Σ_t g_t · leak_t, where g_t weighs
/// channel t's error by how much of it the unmixing carries into the cube.
pub struct Objective<'a> {
    pub scenes: &'a [SceneSpectra],
    pub weights: Vec<f64>,
    pub a2: f64,
}

impl Objective<'_> {
    /// The whole cost.
    pub fn cost(&self, l: &Layout) -> f64 {
        (0..l.bins.len())
            .map(|t| {
                self.weights[t]
                    * self
                        .scenes
                        .iter()
                        .map(|s| s.leak_into(l, t, self.a2))
                        .sum::<f64>()
            })
            .sum()
    }

    /// The part of the cost that depends on carrier `i`: its own window's leak and its
    /// terms' leak into every other window (cost(new) − cost(old) = partial(new) − partial(old)).
    pub fn partial(&self, l: &Layout, i: usize) -> f64 {
        let mut c = 0.0;
        for s in self.scenes {
            c += self.weights[i] * s.leak_into(l, i, self.a2);
            for t in (0..l.bins.len()).filter(|&t| t != i) {
                c += self.weights[t] * s.from_source(l, i, t, self.a2);
            }
        }
        c
    }

    /// Predicted leak per channel and scene, as dB below peak² (higher = smaller leak).
    pub fn leak_db(&self, l: &Layout) -> Vec<Vec<f64>> {
        self.scenes
            .iter()
            .map(|s| {
                (0..l.bins.len())
                    .map(|t| -10.0 * s.leak_into(l, t, self.a2).log10())
                    .collect()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_sums_match_the_slow_sum_with_wrap() {
        let n = 9;
        let t: Vec<f64> = (0..n * n).map(|i| ((i * 37) % 11) as f64).collect();
        let p = PeriodicSums::new(&t, n);
        for (cx, cy, w) in [(0, 0, 3), (8, 1, 4), (-3, 7, 5), (4, 4, 9)] {
            let mut slow = 0.0;
            for dy in 0..w as i64 {
                for dx in 0..w as i64 {
                    let x = (cx - (w / 2) as i64 + dx).rem_euclid(n as i64) as usize;
                    let y = (cy - (w / 2) as i64 + dy).rem_euclid(n as i64) as usize;
                    slow += t[y * n + x];
                }
            }
            assert!((p.window(cx, cy, w) - slow).abs() < 1e-9, "{cx},{cy},{w}");
        }
    }

    #[test]
    fn partial_cost_differences_equal_whole_cost_differences() {
        let n = 32;
        let x = Cube::from_vec(
            n,
            n,
            2,
            (0..2 * n * n)
                .map(|i| ((i * 7919) % 97) as f32 / 97.0)
                .collect(),
        )
        .unwrap();
        let s = [SceneSpectra::measure("t", &x, n).unwrap()];
        let o = Objective {
            scenes: &s,
            weights: vec![1.0, 2.0],
            a2: 0.01,
        };
        let a = Layout {
            size: n,
            window: 6,
            bins: vec![(8, 0), (8, 8)],
        };
        let mut b = a.clone();
        b.bins[1] = (-8, 10);
        let whole = o.cost(&b) - o.cost(&a);
        let part = o.partial(&b, 1) - o.partial(&a, 1);
        assert!(
            (whole - part).abs() < 1e-12 * o.cost(&a).max(1.0),
            "{whole} {part}"
        );
    }
}
