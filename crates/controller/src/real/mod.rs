//! Real device backends, each behind a cargo feature so the default build needs no vendor SDK:
//! `serial-wheel` (a colour-wheel motor controller on a serial line), `alp4` (a ViALUX
//! ALP-4 DMD, its library loaded at run time) and `aravis` (a GenICam camera through libaravis-0.8).

#[cfg(feature = "alp4")]
pub mod alp4;
#[cfg(feature = "aravis")]
pub mod aravis_camera;
#[cfg(feature = "serial-wheel")]
pub mod serial_wheel;
