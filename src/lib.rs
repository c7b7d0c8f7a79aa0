//! specmux: a digital twin of a snapshot hyperspectral camera that multiplexes spectral channels
//! in the Fourier domain (Deng et al., "Snapshot hyperspectral imaging via spectral basis
//! multiplexing in Fourier domain"). The modules follow the light path: spectra and scenes, the
//! rig's optics, the sensor, the reconstruction core, metrics and reports.

pub mod atomic;
pub mod bench;
pub mod error;
pub mod forward;
pub mod metrics;
pub mod optics;
pub mod recon;
pub mod report;
pub mod rig;
pub mod run;
pub mod scene;
pub mod sensor;
pub mod spectral;
pub mod sweep;
pub mod timing;

pub use error::{Error, Result};
pub use scene::Cube;
