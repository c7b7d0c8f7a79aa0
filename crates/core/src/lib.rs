//! specmux-core: the reconstruction core of a Fourier-spectral-multiplexing snapshot
//! hyperspectral camera — the code that runs on the real rig. It knows the design (carriers,
//! filters, basis, crop, window) and the frames a rig captures (dark, flat, patterns on a
//! uniform target); it knows nothing of the simulator. Modules follow the reconstruction:
//! calibration → demultiplexing → crosstalk → de-aliasing → unmixing → metrics.

pub mod auto;
pub mod calibration;
pub mod carriers;
pub mod crosstalk;
pub mod cube;
pub mod dead_leaves;
pub mod demux;
pub mod denoise;
pub mod error;
pub mod fft;
pub mod fft_backend;
pub mod gap;
pub mod interrupt;
pub mod joint;
pub mod metrics;
pub mod noise;
pub mod pages;
pub mod reconstructor;
pub mod spectral;
pub mod tv;
pub mod unmix;
pub mod wavelet;

pub use carriers::Carrier;
pub use cube::Cube;
pub use error::{Error, Result};
pub use rustfft::num_complex::{Complex32, Complex64};
