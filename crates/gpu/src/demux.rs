//! Fourier demultiplexing on the GPU, built from the core's `Demux` (windows, gains, sub-bin
//! offsets, window shape) so both compute the same x̂: frame → complex plane → forward FFT →
//! per-carrier crop/shift/weigh/divide → one batched inverse FFT → demodulation by the sub-bin
//! offset ramp and the crosstalk mix. Every buffer is made once; a frame is one upload, one
//! command buffer and (only if asked) one read-back.

use crate::context::{groups, linear_groups, GpuContext, Launch};
use crate::error::{GpuError, Result};
use crate::fft::{Direction, GpuFft2};
use specmux_core::demux::Demux;
use specmux_core::Cube;

/// Stages recorded by `GpuDemux::encode` (see `encode_stage`).
pub const STAGES: usize = 5;

/// Largest number of carriers (the `MAX_PLANES` of shaders/demux.wgsl).
pub const MAX_CARRIERS: usize = 16;

/// The `Params` struct of shaders/demux.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    w: u32,
    h: u32,
    wx: u32,
    wy: u32,
    planes: u32,
    _pad: [u32; 3],
}

/// The `Carrier` struct of shaders/demux.wgsl: window centre bin and 1/gain.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct CarrierParams {
    cx: i32,
    cy: i32,
    inv_gain: [f32; 2],
}

/// The GPU demultiplexer of one rig: its buffers hold the last frame and its x̂ planes.
pub struct GpuDemux {
    pub w: usize,
    pub h: usize,
    /// Number of carriers = output planes.
    pub planes: usize,
    frame: wgpu::Buffer,
    spectrum: wgpu::Buffer,
    z: wgpu::Buffer,
    out: wgpu::Buffer,
    staging: wgpu::Buffer,
    forward: GpuFft2,
    inverse: GpuFft2,
    to_complex: Launch,
    crop: Launch,
    demod: Launch,
}

impl GpuDemux {
    /// Mirror `demux` on the GPU; `mix` (planes × planes, row-major rows) is applied to the
    /// demultiplexed planes in the same kernel (the core's `Reconstructor::to_channels`).
    pub fn new(ctx: &GpuContext, demux: &Demux, mix: Option<&[Vec<f64>]>) -> Result<GpuDemux> {
        let (w, h) = demux.size();
        let k = demux.windows.len();
        if !(1..=MAX_CARRIERS).contains(&k) {
            return Err(GpuError::Unsupported(format!(
                "{k} carriers (1..={MAX_CARRIERS})"
            )));
        }
        let (wx, wy) = (demux.dc.wx, demux.dc.wy);
        let params = Params {
            w: w as u32,
            h: h as u32,
            wx: wx as u32,
            wy: wy as u32,
            planes: k as u32,
            _pad: [0; 3],
        };
        let npx = (w * h) as u64;
        let frame = ctx.storage("frame", npx * 4);
        let spectrum = ctx.storage("spectrum", npx * 8);
        let z = ctx.storage("windows", npx * 8 * k as u64);
        let out = ctx.storage("xhat", npx * 4 * k as u64);
        let forward = GpuFft2::new(ctx, &spectrum, w, h, 1)?;
        let inverse = GpuFft2::new(ctx, &z, w, h, k)?;
        let module = ctx.module("demux", include_str!("shaders/demux.wgsl"));
        let uniform = ctx.uniform("demux params", &params);
        let to_complex = Launch::new(
            ctx,
            &module,
            "to_complex",
            &[&frame, &spectrum, &uniform],
            linear_groups(w * h, 256),
        );
        let carriers = ctx.storage_init("carriers", &carrier_params(demux));
        let ones = vec![1.0f32; wx * wy];
        let weights = ctx.storage_init("window", demux.taper().unwrap_or(&ones));
        let crop = Launch::new(
            ctx,
            &module,
            "crop",
            &[&spectrum, &z, &carriers, &weights, &uniform],
            [groups(w, 16), groups(h, 16), k as u32],
        );
        let (ex, ey) = ramps(demux, w, h);
        let (ex, ey) = (
            ctx.storage_init("ramp x", &ex),
            ctx.storage_init("ramp y", &ey),
        );
        let m = ctx.storage_init("mix", &mix_matrix(mix, k)?);
        let demod = Launch::new(
            ctx,
            &module,
            "demod",
            &[&z, &out, &ex, &ey, &m, &uniform],
            [groups(w, 16), groups(h, 16), 1],
        );
        let staging = ctx.readback("xhat staging", npx * 4 * k as u64);
        Ok(GpuDemux {
            w,
            h,
            planes: k,
            frame,
            spectrum,
            z,
            out,
            staging,
            forward,
            inverse,
            to_complex,
            crop,
            demod,
        })
    }

    /// Check a frame (one plane of this size, finite and in range, as `Demux::run` requires) and
    /// copy it to the GPU.
    pub fn upload(&self, ctx: &GpuContext, frame: &Cube) -> Result<()> {
        if frame.planes != 1 || frame.width != self.w || frame.height != self.h {
            return Err(GpuError::Shape(format!(
                "frame {}×{}×{} for a demultiplexer of {}×{}",
                frame.width, frame.height, frame.planes, self.w, self.h
            )));
        }
        if let Some(why) = frame.frame_problem("frame") {
            return Err(GpuError::Numerical(why));
        }
        ctx.queue
            .write_buffer(&self.frame, 0, bytemuck::cast_slice(&frame.data));
        Ok(())
    }

    /// Record the whole demultiplexing of the uploaded frame into `enc`.
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder) {
        for stage in 0..STAGES {
            self.encode_stage(enc, stage);
        }
    }

    /// Record one stage: 0 the frame to a complex plane, 1 its forward FFT (in the spectrum
    /// buffer), 2 the windows' crop (in the windows buffer), 3 their inverse FFT, 4 the
    /// demodulation and mix (in `output`). Tests check each against its CPU reference.
    pub fn encode_stage(&self, enc: &mut wgpu::CommandEncoder, stage: usize) {
        match stage {
            0 => self
                .to_complex
                .record(&mut enc.begin_compute_pass(&Default::default())),
            1 => self.forward.encode(enc, &self.spectrum, Direction::Forward),
            2 => self
                .crop
                .record(&mut enc.begin_compute_pass(&Default::default())),
            3 => self.inverse.encode(enc, &self.z, Direction::Inverse),
            _ => self
                .demod
                .record(&mut enc.begin_compute_pass(&Default::default())),
        }
    }

    /// The spectrum (w × h complex) and windows (planes × w × h complex) buffers.
    pub fn intermediates(&self) -> (&wgpu::Buffer, &wgpu::Buffer) {
        (&self.spectrum, &self.z)
    }

    /// The frame (w × h f32) the last `upload` wrote.
    pub fn frame(&self) -> &wgpu::Buffer {
        &self.frame
    }

    /// The x̂ planes (planes × w × h f32) the last `encode` wrote; they stay on the GPU.
    pub fn output(&self) -> &wgpu::Buffer {
        &self.out
    }

    /// Demultiplex one frame and read x̂ back: the GPU twin of `Demux::run` (followed by the
    /// mix given at construction).
    pub fn run(&self, ctx: &GpuContext, frame: &Cube) -> Result<Cube> {
        self.upload(ctx, frame)?;
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        self.encode(&mut enc);
        let bytes = (self.planes * self.w * self.h * 4) as u64;
        enc.copy_buffer_to_buffer(&self.out, 0, &self.staging, 0, bytes);
        ctx.queue.submit([enc.finish()]);
        let mut out = Cube::zeros(self.w, self.h, self.planes);
        ctx.read_into(&self.staging, &mut out.data)?;
        Ok(out)
    }
}

/// Window centres and 1/gain of each carrier.
fn carrier_params(demux: &Demux) -> Vec<CarrierParams> {
    demux
        .windows
        .iter()
        .zip(&demux.gains)
        .map(|(win, g)| {
            let inv = 1.0 / g;
            CarrierParams {
                cx: win.cx as i32,
                cy: win.cy as i32,
                inv_gain: [inv.re as f32, inv.im as f32],
            }
        })
        .collect()
}

/// Per carrier, e^{−2πi δx·x}/(w·h) for x < w and e^{−2πi δy·y} for y < h, in f64.
fn ramps(demux: &Demux, w: usize, h: usize) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    let tau = std::f64::consts::TAU;
    let norm = 1.0 / (w * h) as f64;
    let phasor = |f: f64, t: usize, scale: f64| {
        let (s, c) = (-tau * f * t as f64).sin_cos();
        [(c * scale) as f32, (s * scale) as f32]
    };
    let ex = demux
        .offsets
        .iter()
        .flat_map(|o| (0..w).map(move |x| phasor(o[0], x, norm)))
        .collect();
    let ey = demux
        .offsets
        .iter()
        .flat_map(|o| (0..h).map(move |y| phasor(o[1], y, 1.0)))
        .collect();
    (ex, ey)
}

/// The mix as a row-major k × k f32 matrix (identity when None).
fn mix_matrix(mix: Option<&[Vec<f64>]>, k: usize) -> Result<Vec<f32>> {
    let Some(m) = mix else {
        return Ok((0..k * k).map(|i| (i / k == i % k) as u8 as f32).collect());
    };
    if m.len() != k || m.iter().any(|r| r.len() != k) {
        return Err(GpuError::Shape(format!(
            "mixing matrix for {k} planes must be {k}×{k}"
        )));
    }
    Ok(m.iter().flatten().map(|&v| v as f32).collect())
}
