//! specmux-gpu: the reconstruction core on a GPU through wgpu — a batched 2-D FFT in WGSL,
//! Fourier demultiplexing, GAP and GAP-TV de-aliasing (wavelet group shrinkage with an exact
//! GPU selection of its threshold, TV denoising), the exact per-pixel non-negative unmixing
//! and the joint reconstruction's Chambolle–Pock iterations — giving the CPU's answers within
//! stated f32 tolerances (docs/gpu.md) — and the forward model's multiplex and 4f-relay pair
//! sums. Data stays on the GPU from the uploaded frame to the cube; buffers are made once per
//! rig and reused per frame.

pub mod backend;
pub mod context;
pub mod demux;
pub mod error;
pub mod fft;
pub mod fft_backend;
pub mod gap;
pub mod joint;
pub mod mix;
pub mod multiplex;
pub mod pair_sums;
pub mod reconstructor;
pub mod select;
pub mod tv;
pub mod unmix;
pub mod wavelet;

pub use context::GpuContext;
pub use error::{GpuError, Result};
pub use reconstructor::{GpuReconstructor, GpuRun};
pub use wgpu;
