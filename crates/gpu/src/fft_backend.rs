//! The GPU's 2-D FFT behind the core's `FftBackend` trait: the same calls as the CPU's `Fft2`
//! (half spectrum of a real frame, real frame from the first columns of a half spectrum) on
//! the Stockham kernels of `fft`, each call one upload, one submission and one read-back
//! through buffers made once. For checking the GPU FFT by the trait's contract and for callers
//! that want one transform; the real-time chain keeps its spectra on the GPU instead.

use crate::context::GpuContext;
use crate::error::Result;
use crate::fft::{Direction, GpuFft2};
use specmux_core::fft::HalfSpectrum;
use specmux_core::fft_backend::{check_columns, check_frame, FftBackend};
use specmux_core::Complex32;

/// A planned GPU FFT of real `w × h` frames with its own buffers.
pub struct GpuFftBackend {
    ctx: GpuContext,
    w: usize,
    h: usize,
    plan: GpuFft2,
    data: wgpu::Buffer,
    staging: wgpu::Buffer,
}

impl GpuFftBackend {
    /// Plan frames of `w × h` (each side a product of 2, 3 and 5) on `ctx`.
    pub fn new(ctx: &GpuContext, w: usize, h: usize) -> Result<GpuFftBackend> {
        let bytes = (w * h * 8) as u64;
        let data = ctx.storage("fft backend data", bytes);
        Ok(GpuFftBackend {
            plan: GpuFft2::new(ctx, &data, w, h, 1)?,
            staging: ctx.readback("fft backend staging", bytes),
            ctx: ctx.clone(),
            w,
            h,
            data,
        })
    }

    /// Transform the full complex plane `x` (row-major) on the GPU and read it back.
    fn transform(&self, x: &[Complex32], dir: Direction) -> Result<Vec<Complex32>> {
        let flat: Vec<[f32; 2]> = x.iter().map(|c| [c.re, c.im]).collect();
        self.ctx
            .queue
            .write_buffer(&self.data, 0, bytemuck::cast_slice(&flat));
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        self.plan.encode(&mut enc, &self.data, dir);
        enc.copy_buffer_to_buffer(&self.data, 0, &self.staging, 0, self.data.size());
        self.ctx.queue.submit([enc.finish()]);
        let mut out = vec![[0.0f32; 2]; x.len()];
        self.ctx.read_into(&self.staging, &mut out)?;
        Ok(out.iter().map(|v| Complex32::new(v[0], v[1])).collect())
    }

    /// The full spectrum of the Hermitian spectrum whose first columns are `cols`
    /// (column-major, as `HalfSpectrum`): the kx = 0 and Nyquist columns symmetrised (what the
    /// CPU's dropping of their inverse's imaginary parts amounts to), the rest mirrored.
    fn hermitian(&self, cols: &[Complex32]) -> Vec<Complex32> {
        let (w, h) = (self.w, self.h);
        let kept = cols.len() / h;
        let at = |kx: usize, ky: usize| match kx < kept {
            true => cols[kx * h + ky],
            false => Complex32::default(),
        };
        let mut full = vec![Complex32::default(); w * h];
        for ky in 0..h {
            let mirror = (h - ky) % h;
            for kx in 0..w {
                full[ky * w + kx] = if kx == 0 || 2 * kx == w {
                    (at(kx, ky) + at(kx, mirror).conj()) * 0.5
                } else if 2 * kx < w {
                    at(kx, ky)
                } else {
                    at(w - kx, mirror).conj()
                };
            }
        }
        full
    }
}

impl FftBackend for GpuFftBackend {
    fn size(&self) -> (usize, usize) {
        (self.w, self.h)
    }

    fn device(&self) -> String {
        format!("GPU {}", self.ctx.adapter_name())
    }

    fn forward(&self, frame: &[f32]) -> specmux_core::Result<HalfSpectrum> {
        check_frame(frame, self.size())?;
        let (w, h) = (self.w, self.h);
        let x: Vec<Complex32> = frame.iter().map(|&v| Complex32::new(v, 0.0)).collect();
        let full = self.transform(&x, Direction::Forward)?;
        let data = (0..=w / 2)
            .flat_map(|kx| (0..h).map(move |ky| (kx, ky)))
            .map(|(kx, ky)| full[ky * w + kx])
            .collect();
        Ok(HalfSpectrum { w, h, data })
    }

    fn inverse(&self, cols: &[Complex32]) -> specmux_core::Result<Vec<f32>> {
        check_columns(cols, self.size())?;
        let full = self.transform(&self.hermitian(cols), Direction::Inverse)?;
        let norm = 1.0 / (self.w * self.h) as f32;
        Ok(full.iter().map(|c| c.re * norm).collect())
    }
}
