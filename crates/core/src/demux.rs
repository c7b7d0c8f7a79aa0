//! Fourier demultiplexing (the paper's "Fourier spectrum cropping and zero padding"): FFT the
//! frame, crop the window around each carrier +ω_i, shift it to the origin, divide by the
//! carrier's complex amplitude, zero-pad and inverse-FFT; the real part is x̂_i.

use crate::calibration::MeasuredCarrier;
use crate::carriers::window_bins;
use crate::carriers::Carrier;
use crate::error::Error;
use crate::error::Result;
use crate::fft::Fft2;
use crate::fft::HalfSpectrum;
use crate::Cube;
use rayon::prelude::*;
use rustfft::num_complex::{Complex32, Complex64};

/// Window shape for the Fourier crop: how the bins of the crop·N box around a carrier are weighed
/// before the inverse FFT (docs/results.md). Every shape stays inside the box, so the layout
/// check holds for all of them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WindowShape {
    /// Every bin of the box at weight 1 (the paper's crop).
    Square,
    /// The disc (ellipse for a non-square frame) inscribed in the box: diameter crop·N bins per axis.
    Circular,
    /// A flat-topped taper: per axis exp(−|d/r0|^(2p)), r0 = the box's half-extent to the outer edge
    /// of its outermost bin, p = `SUPER_GAUSSIAN_ORDER` (4); tends to `Square` as p → ∞.
    SuperGaussian,
}

impl std::fmt::Display for WindowShape {
    /// The name an experiment file gives it (`reconstruct.window`).
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(match self {
            WindowShape::Square => "square",
            WindowShape::Circular => "circular",
            WindowShape::SuperGaussian => "super-gaussian",
        })
    }
}

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

/// Order p of the super-Gaussian window used by `reconstruct.window = "super-gaussian"`: a flat
/// top over most of the box and a roll-off of a few bins at its edge (no source fixes it; p = 4
/// keeps ≥ 90 % weight over the inner 70 % of each axis).
pub const SUPER_GAUSSIAN_ORDER: f64 = 4.0;

/// Weight of the bin at offset (dx, dy) from the centre of a `wx × wy` crop box (dx in
/// [−⌊wx/2⌋, wx − ⌊wx/2⌋)), in [0, 1]; 0 outside the box.
/// - square: 1;
/// - circular: 1 inside the ellipse (dx/(wx/2))² + (dy/(wy/2))² ≤ 1 (a disc of diameter crop·N
///   bins on each axis);
/// - super-Gaussian: exp(−|dx/r0x|^(2p)) · exp(−|dy/r0y|^(2p)), r0 = ⌊w/2⌋ + ½ (the box's
///   half-extent to the outer edge of its outermost bin, = crop·N/2 for an odd bin count), so
///   every bin of the box tends to 1 as p → ∞: the square window.
pub fn window_weight(
    shape: WindowShape,
    order: f64,
    wx: usize,
    wy: usize,
    dx: i64,
    dy: i64,
) -> f64 {
    let win = Window {
        cx: 0,
        cy: 0,
        wx,
        wy,
    };
    if !win.contains(dx, dy) {
        return 0.0;
    }
    match shape {
        WindowShape::Square => 1.0,
        WindowShape::Circular => {
            let (u, v) = (2.0 * dx as f64 / wx as f64, 2.0 * dy as f64 / wy as f64);
            if u * u + v * v <= 1.0 {
                1.0
            } else {
                0.0
            }
        }
        WindowShape::SuperGaussian => {
            let sg = |d: i64, w: usize| {
                let r0 = (w / 2) as f64 + 0.5;
                (-(d.abs() as f64 / r0).powf(2.0 * order)).exp()
            };
            sg(dx, wx) * sg(dy, wy)
        }
    }
}

/// The demultiplexer for one frame size, carrier set and crop.
pub struct Demux {
    fft: Fft2,
    pub windows: Vec<Window>,
    /// Complex amplitude of the e^{+iω·p} term of each pattern (½e^{iφ} for an ideal sinusoid).
    pub gains: Vec<Complex64>,
    /// Each carrier's frequency minus its window's centre bin, cycles/px (zero on the grid).
    pub offsets: Vec<[f64; 2]>,
    pub dc: Window,
    /// The window's shape and its weights on the wx × wy box (row-major from (−⌊wx/2⌋, −⌊wy/2⌋));
    /// None for the square window (all ones).
    pub shape: WindowShape,
    taper: Option<Vec<f32>>,
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
            offsets: vec![[0.0; 2]; carriers.len()],
            windows,
            gains,
            dc: Window {
                cx: 0,
                cy: 0,
                wx,
                wy,
            },
            shape: WindowShape::Square,
            taper: None,
        }
    }

    /// Weigh every crop window (carriers and DC) by `shape`; `order` is the super-Gaussian's p
    /// (ignored by the other shapes; `SUPER_GAUSSIAN_ORDER` for the config's `super-gaussian`).
    pub fn with_window(mut self, shape: WindowShape, order: f64) -> Result<Demux> {
        if shape == WindowShape::SuperGaussian && !(order.is_finite() && order > 0.0) {
            return Err(Error::Numerical(format!(
                "super-Gaussian window order {order} must be finite and > 0"
            )));
        }
        let (wx, wy) = (self.dc.wx, self.dc.wy);
        let (hx, hy) = ((wx / 2) as i64, (wy / 2) as i64);
        self.shape = shape;
        self.taper = (shape != WindowShape::Square).then(|| {
            (0..wy as i64)
                .flat_map(|j| {
                    (0..wx as i64)
                        .map(move |i| window_weight(shape, order, wx, wy, i - hx, j - hy) as f32)
                })
                .collect()
        });
        Ok(self)
    }

    /// Centre each window on the calibrated carrier's nearest bin and divide by its measured
    /// amplitude; a carrier off the bin grid is demodulated by its residual frequency
    /// (e^{−2πi δ·p} before the real part), so the estimate does not rotate across the frame.
    pub fn with_calibration(mut self, measured: &[MeasuredCarrier]) -> Result<Demux> {
        if measured.len() != self.windows.len() {
            return Err(Error::Shape(format!(
                "{} calibrated carriers for {} windows",
                measured.len(),
                self.windows.len()
            )));
        }
        let (w, h) = (self.fft.w, self.fft.h);
        for (i, m) in measured.iter().enumerate() {
            let g = m.amplitude();
            if !(g.norm() > 0.0 && g.norm().is_finite()) {
                return Err(Error::Numerical(format!(
                    "carrier {i}: calibrated amplitude {:.3e} cannot be divided by",
                    g.norm()
                )));
            }
            let (cx, cy) = (Carrier::bin(m.carrier.fx, w), Carrier::bin(m.carrier.fy, h));
            self.windows[i].cx = cx;
            self.windows[i].cy = cy;
            self.offsets[i] = [
                m.carrier.fx - cx as f64 / w as f64,
                m.carrier.fy - cy as f64 / h as f64,
            ];
            self.gains[i] = g;
        }
        Ok(self)
    }

    /// The frame width and height this demultiplexer was planned for.
    pub fn size(&self) -> (usize, usize) {
        (self.fft.w, self.fft.h)
    }

    /// The window's weights on the wx × wy box (row-major from (−⌊wx/2⌋, −⌊wy/2⌋)); None for
    /// the square window (all ones). Another implementation of `extract` (the GPU's) reads it.
    pub fn taper(&self) -> Option<&[f32]> {
        self.taper.as_deref()
    }

    /// The forward spectrum of a frame.
    pub fn spectrum(&self, frame: &[f32]) -> HalfSpectrum {
        self.fft.forward(frame)
    }

    /// x̂ for window `win`: Re(e^{−2πi δ·p} · IFFT(weight · crop(Y, win) shifted to 0) / gain),
    /// the weight being this demultiplexer's window shape (`win` must have the size of the
    /// demultiplexer's windows) and δ the carrier's offset from its bin (cycles/px; zero on the
    /// grid, where one real inverse transform suffices).
    pub fn extract(
        &self,
        spec: &HalfSpectrum,
        win: &Window,
        gain: Complex64,
        offset: [f64; 2],
    ) -> Vec<f32> {
        let mut out = vec![0.0f32; self.fft.w * self.fft.h];
        self.extract_into(spec, win, gain, offset, &mut out);
        out
    }

    /// [`Demux::extract`] written into `out` (one plane of the frame's size).
    fn extract_into(
        &self,
        spec: &HalfSpectrum,
        win: &Window,
        gain: Complex64,
        offset: [f64; 2],
        out: &mut [f32],
    ) {
        let inv_gain = Complex32::new((1.0 / gain).re as f32, (1.0 / gain).im as f32);
        let z = |dx: i64, dy: i64| -> Complex32 {
            if !win.contains(dx, dy) {
                return Complex32::default();
            }
            let v = spec.at(win.cx + dx, win.cy + dy) * inv_gain;
            match &self.taper {
                None => v,
                Some(t) => {
                    let (hx, hy) = ((win.wx / 2) as i64, (win.wy / 2) as i64);
                    v * t[((dy + hy) * win.wx as i64 + dx + hx) as usize]
                }
            }
        };
        // IFFT(Z) = c2r(H₁) + i·c2r(H₂), H₁ = (Z(k) + Z*(−k))/2, H₂ = (Z(k) − Z*(−k))/2i.
        let re = self.hermitian(win, spec.h, |dx, dy| (z(dx, dy) + z(-dx, -dy).conj()) * 0.5);
        self.fft.inverse_into(re, out);
        if offset == [0.0, 0.0] {
            return;
        }
        let mut im = vec![0.0f32; out.len()];
        self.fft.inverse_into(
            self.hermitian(win, spec.h, |dx, dy| {
                (z(dx, dy) - z(-dx, -dy).conj()) * Complex32::new(0.0, -0.5)
            }),
            &mut im,
        );
        demodulate(out, &im, offset, self.fft.w);
    }

    /// The half plane kx ≥ 0 (column-major, as the c2r inverse takes it) of a Hermitian
    /// spectrum given by `value(dx, dy)` on the window's extent around the origin.
    fn hermitian(
        &self,
        win: &Window,
        h: usize,
        value: impl Fn(i64, i64) -> Complex32,
    ) -> Vec<Complex32> {
        let kx_end = (win.wx - win.wx / 2).max(win.wx / 2 + 1);
        let mut cols = vec![Complex32::default(); kx_end * h];
        for dx in 0..kx_end as i64 {
            let col = &mut cols[dx as usize * h..(dx as usize + 1) * h];
            for dy in -(win.wy as i64)..=(win.wy as i64) {
                let v = value(dx, dy);
                if v != Complex32::default() {
                    col[dy.rem_euclid(h as i64) as usize] = v;
                }
            }
        }
        cols
    }

    /// Demultiplex a frame (one plane) into one plane x̂_i per carrier.
    pub fn run(&self, frame: &Cube) -> Result<Cube> {
        let mut out = Cube::zeros(frame.width, frame.height, self.windows.len());
        self.run_into(frame, &mut out)?;
        Ok(out)
    }

    /// [`Demux::run`] into a cube that the caller keeps from frame to frame (every value is
    /// overwritten), so a camera loop does not clear a new one each frame.
    pub fn run_into(&self, frame: &Cube, out: &mut Cube) -> Result<()> {
        let planes = self.windows.len();
        if (out.width, out.height, out.planes) != (frame.width, frame.height, planes) {
            return Err(Error::Shape(format!(
                "demultiplexing into a {}×{}×{} cube; {}×{}×{planes} expected",
                out.width, out.height, out.planes, frame.width, frame.height
            )));
        }
        if frame.planes != 1 || frame.width != self.fft.w || frame.height != self.fft.h {
            return Err(Error::Shape(format!(
                "frame {}×{}×{} for a demultiplexer of {}×{}",
                frame.width, frame.height, frame.planes, self.fft.w, self.fft.h
            )));
        }
        if let Some(why) = frame.frame_problem("frame") {
            return Err(Error::Numerical(why));
        }
        let spec = self.spectrum(&frame.data);
        out.planes_mut()
            .collect::<Vec<_>>()
            .into_par_iter()
            .zip(self.windows.par_iter().zip(&self.gains).zip(&self.offsets))
            .for_each(|(plane, ((win, g), o))| self.extract_into(&spec, win, *g, *o, plane));
        Ok(())
    }

    /// The best any crop of this size can do: each plane of `channels` low-passed by the same
    /// window centred at the origin, without multiplexing.
    pub fn crop_bound(&self, channels: &Cube) -> Cube {
        let mut out = Cube::zeros(channels.width, channels.height, channels.planes);
        for k in 0..channels.planes {
            let spec = self.spectrum(channels.plane(k));
            let one = Complex64::new(1.0, 0.0);
            self.extract_into(&spec, &self.dc, one, [0.0, 0.0], out.plane_mut(k));
        }
        out
    }
}

/// re ← Re(e^{−2πi δ·p}·(re + i·im)) = re·cos θ + im·sin θ, θ = 2π(δx·x + δy·y), the phasor
/// e^{iθ} formed as the product of a per-column and a per-row one (no sin/cos per pixel).
fn demodulate(re: &mut [f32], im: &[f32], offset: [f64; 2], w: usize) {
    let tau = std::f64::consts::TAU;
    let ex: Vec<Complex64> = (0..w)
        .map(|x| Complex64::from_polar(1.0, tau * offset[0] * x as f64))
        .collect();
    re.par_chunks_mut(w)
        .zip(im.par_chunks(w))
        .enumerate()
        .for_each(|(y, (re, im))| {
            let ey = Complex64::from_polar(1.0, tau * offset[1] * y as f64);
            for ((a, &b), e) in re.iter_mut().zip(im).zip(&ex) {
                let p = e * ey;
                *a = (*a as f64 * p.re + b as f64 * p.im) as f32;
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::carriers::default_layout;
    use crate::fft::dft_at;

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
        let xs: Vec<Vec<f32>> = (0..6).map(|i| smooth(w, h, i as f64)).collect();
        let (carriers, y) = multiplex(&xs, w, h);
        let out = Demux::new(w, h, &carriers, 0.25).run(&y).unwrap();
        for (i, x) in xs.iter().enumerate() {
            let err = max_diff(out.plane(i), x);
            assert!(err < 1e-4, "channel {i}: {err}");
        }
    }

    /// A frame multiplexing `xs` with the default carriers at phases 0.4·i.
    fn multiplex(xs: &[Vec<f32>], w: usize, h: usize) -> (Vec<Carrier>, Cube) {
        let carriers: Vec<Carrier> = default_layout()
            .into_iter()
            .enumerate()
            .map(|(i, c)| Carrier {
                phase_rad: 0.4 * i as f64,
                ..c
            })
            .collect();
        let mut y = vec![0.0f32; w * h];
        for (x, c) in xs.iter().zip(&carriers) {
            for (yy, (xv, sv)) in y.iter_mut().zip(x.iter().zip(c.ideal_pattern(w, h))) {
                *yy += xv * sv;
            }
        }
        (carriers, Cube::from_vec(w, h, 1, y).unwrap())
    }

    fn max_diff(a: &[f32], b: &[f32]) -> f32 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn circular_window_recovers_channels_band_limited_inside_the_disc() {
        // A non-square frame: the disc becomes an ellipse of crop·N bins on each axis (16 × 12).
        let (w, h) = (64, 48);
        let xs: Vec<Vec<f32>> = (0..6).map(|i| smooth(w, h, i as f64)).collect();
        let (carriers, y) = multiplex(&xs, w, h);
        let d = Demux::new(w, h, &carriers, 0.25)
            .with_window(WindowShape::Circular, SUPER_GAUSSIAN_ORDER)
            .unwrap();
        let out = d.run(&y).unwrap();
        for (i, x) in xs.iter().enumerate() {
            let err = max_diff(out.plane(i), x);
            assert!(err < 1e-4, "channel {i}: {err}");
        }
    }

    #[test]
    fn circular_window_drops_the_box_corners_that_the_square_keeps() {
        // cos at (6, 6) cycles on 64²: inside the 16-bin box (|6| < 8) but outside its disc
        // (6² + 6² > 8²). The DC window of the crop bound keeps it with the square, not the disc.
        let (w, h) = (64, 64);
        let tau = std::f64::consts::TAU;
        let base = smooth(w, h, 0.3);
        let corner: Vec<f32> = (0..w * h)
            .map(|p| {
                let (x, y) = ((p % w) as f64, (p / w) as f64);
                (tau * 6.0 * (x + y) / 64.0).cos() as f32
            })
            .collect();
        let img: Vec<f32> = base.iter().zip(&corner).map(|(a, b)| a + b).collect();
        let c = Cube::from_vec(w, h, 1, img.clone()).unwrap();
        let sq = Demux::new(w, h, &default_layout(), 0.25).crop_bound(&c);
        let disc = Demux::new(w, h, &default_layout(), 0.25)
            .with_window(WindowShape::Circular, SUPER_GAUSSIAN_ORDER)
            .unwrap()
            .crop_bound(&c);
        assert!(max_diff(&sq.data, &img) < 1e-4);
        assert!(max_diff(&disc.data, &base) < 1e-4);
    }

    #[test]
    fn super_gaussian_of_high_order_is_the_square_window() {
        let (w, h) = (64, 48);
        for (wx, wy) in [(16, 12), (15, 9), (2, 3)] {
            let (hx, hy) = ((wx / 2) as i64, (wy / 2) as i64);
            for dy in -hy - 2..wy as i64 - hy + 2 {
                for dx in -hx - 2..wx as i64 - hx + 2 {
                    let sq = window_weight(WindowShape::Square, 0.0, wx, wy, dx, dy);
                    let sg = window_weight(WindowShape::SuperGaussian, 1e4, wx, wy, dx, dy);
                    assert!((sq - sg).abs() < 1e-9, "({dx},{dy}) in {wx}×{wy}: {sg}");
                    // A finite order tapers the box's edge: below 1 there, 1 only at the centre.
                    let sg4 = window_weight(WindowShape::SuperGaussian, 4.0, wx, wy, dx, dy);
                    assert!(sg4 <= sq && (dx != 0 || dy != 0 || sg4 > 0.99));
                }
            }
            if wx >= 8 {
                let edge = window_weight(WindowShape::SuperGaussian, 4.0, wx, wy, -hx, 0);
                assert!(edge < 0.75, "{wx}: {edge}");
            }
        }
        // And the demultiplexed channels agree with the square crop's.
        let xs: Vec<Vec<f32>> = (0..6)
            .map(|i| {
                (0..w * h)
                    .map(|p| ((p * 37 + i * 11) % 23) as f32)
                    .collect()
            })
            .collect();
        let (carriers, y) = multiplex(&xs, w, h);
        let sq = Demux::new(w, h, &carriers, 0.25).run(&y).unwrap();
        let sg = Demux::new(w, h, &carriers, 0.25)
            .with_window(WindowShape::SuperGaussian, 1e4)
            .unwrap()
            .run(&y)
            .unwrap();
        assert!(max_diff(&sq.data, &sg.data) < 1e-3);
        let sg4 = Demux::new(w, h, &carriers, 0.25)
            .with_window(WindowShape::SuperGaussian, 4.0)
            .unwrap()
            .run(&y)
            .unwrap();
        assert!(max_diff(&sq.data, &sg4.data) > 0.1);
    }

    #[test]
    fn bad_super_gaussian_order_is_an_error() {
        for p in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = Demux::new(32, 32, &default_layout(), 0.25)
                .with_window(WindowShape::SuperGaussian, p)
                .err()
                .expect("refused");
            assert!(e.to_string().contains("order"), "{e}");
        }
    }

    proptest::proptest! {
        #[test]
        fn window_weights_lie_in_zero_one_and_are_symmetric(
            wx in 2usize..40, wy in 2usize..40, dx in -25i64..25, dy in -25i64..25,
            order in 0.1f64..50.0, k in 0usize..3,
        ) {
            let shape = [WindowShape::Square, WindowShape::Circular, WindowShape::SuperGaussian][k];
            let v = window_weight(shape, order, wx, wy, dx, dy);
            proptest::prop_assert!((0.0..=1.0).contains(&v), "{v}");
            // Symmetric under d → −d wherever both bins are in the box (the Hermitian part needs it).
            let m = window_weight(shape, order, wx, wy, -dx, -dy);
            if m > 0.0 && v > 0.0 {
                proptest::prop_assert!((v - m).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn demodulation_by_hand() {
        // δ = (¼, ½) cycles/px: θ(x, y) = π/2·x + π·y, so re·cos θ + im·sin θ at (1, 0) is im,
        // at (2, 0) −re, at (0, 1) −re, at (1, 1) −im.
        let (mut re, im) = (vec![3.0f32; 6], vec![5.0f32; 6]);
        demodulate(&mut re, &im, [0.25, 0.5], 3);
        let want = [3.0, 5.0, -3.0, -3.0, -5.0, 3.0];
        for (g, w) in re.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{re:?}");
        }
    }

    proptest::proptest! {
        #[test]
        fn separable_phasors_match_the_direct_angle(
            fx in -0.02f64..0.02, fy in -0.02f64..0.02, w in 1usize..50, h in 1usize..40,
        ) {
            let re: Vec<f32> = (0..w * h).map(|i| ((i * 37) % 17) as f32 - 8.0).collect();
            let im: Vec<f32> = (0..w * h).map(|i| ((i * 11) % 13) as f32 - 6.0).collect();
            let mut got = re.clone();
            demodulate(&mut got, &im, [fx, fy], w);
            for p in 0..w * h {
                let t = std::f64::consts::TAU * (fx * (p % w) as f64 + fy * (p / w) as f64);
                let want = re[p] as f64 * t.cos() + im[p] as f64 * t.sin();
                proptest::prop_assert!((got[p] as f64 - want).abs() < 1e-5, "{p}: {} vs {want}", got[p]);
            }
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
