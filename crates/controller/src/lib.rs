//! specmux-controller: the code that runs the rig — device traits named as their users know
//! them (`ColorWheel`, `Dmd`, `Camera`), an acquisition plan checked before any device is
//! touched, simulated devices on a virtual clock fed by the twin, fault detection, and an
//! OME-TIFF recorder that writes frames as they arrive. The same controller drives simulated
//! and real devices, so an experiment is rehearsed before the hardware is powered
//! (docs/controller.md).

pub mod commands;
pub mod devices;
pub mod error;
pub mod log;
pub mod ome;
pub mod patterns;
pub mod plan;
pub mod real;
pub mod reconstruct;
pub mod record;
pub mod run;
pub mod sim;
pub mod trigger_chain;

pub use error::{Error, Result};
