//! The reconstruction core, the same code on the twin and on the rig: Fourier demultiplexing
//! and per-pixel spectral unmixing.

pub mod demux;
pub mod fft2;
pub mod gap;
pub mod tv;
pub mod wavelet;

pub use demux::Demux;
