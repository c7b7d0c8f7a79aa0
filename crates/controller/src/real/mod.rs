//! Real device backends, each behind a cargo feature so the default build needs no vendor SDK:
//! `serial-wheel` (a colour-wheel motor controller on a serial line) and `alp4` (a ViALUX
//! ALP-4 DMD, its library loaded at run time).

#[cfg(feature = "alp4")]
pub mod alp4;
#[cfg(feature = "serial-wheel")]
pub mod serial_wheel;
