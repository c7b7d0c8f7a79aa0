//! The rig's optics along the light path: colour wheel, modulation carriers (later: DMD,
//! 4f Fourier filter, lens PSF).

pub mod carriers;
pub mod dither;
pub mod wheel;

pub use carriers::Carrier;
pub use wheel::ColorWheel;
