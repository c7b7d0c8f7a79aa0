//! Fourier demultiplexing (the paper's "Fourier spectrum cropping and zero padding"): FFT the
//! frame, crop the window around each carrier +ω_i, shift it to the origin, divide by the
//! carrier's complex amplitude, zero-pad and inverse-FFT; the real part is x̂_i.

use super::fft2::{Fft2, HalfSpectrum};
use crate::error::{Error, Result};
use crate::optics::carriers::{window_bins, Carrier};
use crate::scene::Cube;
use rustfft::num_complex::{Complex32, Complex64};

/// A rectangular crop window: centre bin and size in bins; it spans [c − s/2, c − s/2 + s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Window {
    pub cx: i64,
    pub cy: i64,
    pub wx: usize,
    pub wy: usize,
}

impl Window {
    fn contains(&self, dx: i64, dy: i64) -> bool {
        let (hx, hy) = ((self.wx / 2) as i64, (self.wy / 2) as i64);
        dx >= -hx && dx < self.wx as i64 - hx && dy >= -hy && dy < self.wy as i64 - hy
    }
}

/// The demultiplexer for one frame size, carrier set and crop.
pub struct Demux {
    fft: Fft2,
    pub windows: Vec<Window>,
    /// Complex amplitude of the e^{+iω·p} term of each pattern (½e^{iφ} for an ideal sinusoid).
    pub gains: Vec<Complex64>,
    pub dc: Window,
}

impl Demux {
    /// Windows of `crop` × the frame size around each carrier; `gains` default to the ideal ½e^{iφ}.
    pub fn new(w: usize, h: usize, carriers: &[Carrier], crop: f64) -> Demux {
        let (wx, wy) = (window_bins(crop, w), window_bins(crop, h));
        let windows = carriers
            .iter()
            .map(|c| Window {
                cx: Carrier::bin(c.fx, w),
                cy: Carrier::bin(c.fy, h),
                wx,
                wy,
            })
            .collect();
        let gains = carriers
            .iter()
            .map(|c| Complex64::from_polar(0.5, c.phase_rad))
            .collect();
        Demux {
            fft: Fft2::new(w, h),
            windows,
            gains,
            dc: Window {
                cx: 0,
                cy: 0,
                wx,
                wy,
            },
        }
    }

    /// Use the carrier amplitudes measured on the patterns as imaged (one plane per carrier):
    /// the DFT of s̃_i at its carrier bin divided by the pixel count.
    pub fn with_measured_gains(mut self, patterns: &Cube) -> Result<Demux> {
        if patterns.planes != self.windows.len() || patterns.pixels() != self.fft.w * self.fft.h {
            return Err(Error::Shape(format!(
                "patterns {}×{}×{} for {} carriers on {}×{}",
                patterns.width,
                patterns.height,
                patterns.planes,
                self.windows.len(),
                self.fft.w,
                self.fft.h
            )));
        }
        for (i, win) in self.windows.iter().enumerate() {
            let g = dft_at(patterns.plane(i), self.fft.w, self.fft.h, win.cx, win.cy);
            if !(g.norm() > 1e-6) {
                return Err(Error::Numerical(format!(
                    "pattern {i} carries no energy at its carrier (amplitude {:.3e}); it cannot be demultiplexed",
                    g.norm()
                )));
            }
            self.gains[i] = g;
        }
        Ok(self)
    }

    /// The forward spectrum of a frame.
    pub fn spectrum(&self, frame: &[f32]) -> HalfSpectrum {
        self.fft.forward(frame)
    }

    /// x̂ for window `win`: Re(IFFT(crop(Y, win) shifted to 0) / gain).
    pub fn extract(&self, spec: &HalfSpectrum, win: &Window, gain: Complex64) -> Vec<f32> {
        let h = spec.h as i64;
        let inv_gain = Complex32::new((1.0 / gain).re as f32, (1.0 / gain).im as f32);
        // Hermitian part of the shifted window, on the half plane kx ≥ 0 that the c2r needs.
        let kx_end = (win.wx - win.wx / 2).max(win.wx / 2 + 1);
        let mut cols = vec![Complex32::default(); kx_end * spec.h];
        let z = |dx: i64, dy: i64| -> Complex32 {
            if win.contains(dx, dy) {
                spec.at(win.cx + dx, win.cy + dy) * inv_gain
            } else {
                Complex32::default()
            }
        };
        for dx in 0..kx_end as i64 {
            let col = &mut cols[dx as usize * spec.h..(dx as usize + 1) * spec.h];
            for dy in -(win.wy as i64)..=(win.wy as i64) {
                let v = (z(dx, dy) + z(-dx, -dy).conj()) * 0.5;
                if v != Complex32::default() {
                    col[dy.rem_euclid(h) as usize] = v;
                }
            }
        }
        self.fft.inverse(&cols)
    }

    /// Demultiplex a frame (one plane) into one plane x̂_i per carrier.
    pub fn run(&self, frame: &Cube) -> Result<Cube> {
        if frame.planes != 1 || frame.width != self.fft.w || frame.height != self.fft.h {
            return Err(Error::Shape(format!(
                "frame {}×{}×{} for a demultiplexer of {}×{}",
                frame.width, frame.height, frame.planes, self.fft.w, self.fft.h
            )));
        }
        if !frame.all_finite() {
            return Err(Error::Numerical(
                "the frame contains NaN or infinite values".into(),
            ));
        }
        let spec = self.spectrum(&frame.data);
        let mut out = Cube::zeros(frame.width, frame.height, self.windows.len());
        for (i, (win, g)) in self.windows.iter().zip(&self.gains).enumerate() {
            out.plane_mut(i)
                .copy_from_slice(&self.extract(&spec, win, *g));
        }
        Ok(out)
    }

    /// The best any crop of this size can do: each plane of `channels` low-passed by the same
    /// window centred at the origin, without multiplexing.
    pub fn crop_bound(&self, channels: &Cube) -> Cube {
        let mut out = Cube::zeros(channels.width, channels.height, channels.planes);
        for k in 0..channels.planes {
            let spec = self.spectrum(channels.plane(k));
            let lp = self.extract(&spec, &self.dc, Complex64::new(1.0, 0.0));
            out.plane_mut(k).copy_from_slice(&lp);
        }
        out
    }
}

/// (1/N) Σ_p s(p) e^{−2πi(kx·x/w + ky·y/h)}: the complex amplitude of one frequency bin.
pub fn dft_at(plane: &[f32], w: usize, h: usize, kx: i64, ky: i64) -> Complex64 {
    let tau = std::f64::consts::TAU;
    let ex: Vec<Complex64> = (0..w)
        .map(|x| Complex64::from_polar(1.0, -tau * (kx * x as i64) as f64 / w as f64))
        .collect();
    let mut acc = Complex64::default();
    for (y, row) in plane.chunks_exact(w).enumerate() {
        let ey = Complex64::from_polar(1.0, -tau * (ky * y as i64) as f64 / h as f64);
        let r: Complex64 = row.iter().zip(&ex).map(|(&v, e)| e * v as f64).sum();
        acc += r * ey;
    }
    acc / (w * h) as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::carriers::default_layout;

    /// A smooth image band-limited well inside a window of `crop` (a few low harmonics).
    fn smooth(w: usize, h: usize, seed: f64) -> Vec<f32> {
        let tau = std::f64::consts::TAU;
        (0..w * h)
            .map(|p| {
                let (x, y) = ((p % w) as f64 / w as f64, (p / w) as f64 / h as f64);
                (2.0 + (tau * (2.0 * x + seed)).cos() + 0.5 * (tau * (3.0 * y - x) + seed).sin())
                    as f32
            })
            .collect()
    }

    #[test]
    fn band_limited_channels_are_recovered_exactly() {
        let (w, h) = (64, 64);
        let carriers: Vec<Carrier> = default_layout()
            .into_iter()
            .enumerate()
            .map(|(i, c)| Carrier {
                phase_rad: 0.4 * i as f64,
                ..c
            })
            .collect();
        let xs: Vec<Vec<f32>> = (0..6).map(|i| smooth(w, h, i as f64)).collect();
        let mut y = vec![0.0f32; w * h];
        for (x, c) in xs.iter().zip(&carriers) {
            for (yy, (xv, sv)) in y.iter_mut().zip(x.iter().zip(c.ideal_pattern(w, h))) {
                *yy += xv * sv;
            }
        }
        let d = Demux::new(w, h, &carriers, 0.25);
        let out = d.run(&Cube::from_vec(w, h, 1, y).unwrap()).unwrap();
        for (i, x) in xs.iter().enumerate() {
            let err = out
                .plane(i)
                .iter()
                .zip(x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(err < 1e-4, "channel {i}: {err}");
        }
    }

    #[test]
    fn measured_gain_of_ideal_pattern_is_half_phasor() {
        let c = Carrier {
            fx: 0.25,
            fy: 0.125,
            phase_rad: 0.7,
        };
        let p = c.ideal_pattern(32, 32);
        let g = dft_at(&p, 32, 32, 8, 4);
        assert!((g - Complex64::from_polar(0.5, 0.7)).norm() < 1e-6);
    }

    #[test]
    fn demux_is_linear() {
        let (w, h) = (32, 32);
        let d = Demux::new(w, h, &default_layout(), 0.25);
        let a: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 17) as f32).collect();
        let b: Vec<f32> = (0..w * h).map(|i| ((i * 11) % 13) as f32).collect();
        let ab: Vec<f32> = a.iter().zip(&b).map(|(x, y)| 2.0 * x - y).collect();
        let run = |v: Vec<f32>| d.run(&Cube::from_vec(w, h, 1, v).unwrap()).unwrap();
        let (ra, rb, rab) = (run(a), run(b), run(ab));
        for k in 0..ra.data.len() {
            assert!((rab.data[k] - (2.0 * ra.data[k] - rb.data[k])).abs() < 1e-3);
        }
    }
}
