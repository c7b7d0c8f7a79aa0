//! The rig's optics along the light path: colour wheel, modulation carriers, DMD and
//! dithering, 4f Fourier filter, lens PSF and pixel integration.

pub mod alignment;
pub mod dither;
pub mod dmd;
pub mod fourier_filter;
pub mod imaging;
pub mod light;
pub mod psf;
pub mod relay;
pub mod wheel;

pub use wheel::ColorWheel;
