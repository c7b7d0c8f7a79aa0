//! The choice of compute device for an experiment (`[compute] device`): the CPU, the GPU
//! (an error without one), or `auto` (the GPU when an adapter opens, else the CPU, said in one
//! line).

use crate::context::GpuContext;
use crate::error::{GpuError, Result};
use specmux_core::reconstructor::ComputeDevice;

/// The GPU context `device` asks for: None for the CPU. `Gpu` without an adapter is an error;
/// `Auto` without one prints one line on stderr and returns None.
pub fn open(device: ComputeDevice) -> Result<Option<GpuContext>> {
    match device {
        ComputeDevice::Cpu => Ok(None),
        ComputeDevice::Gpu => GpuContext::new().map(Some),
        ComputeDevice::Auto => match GpuContext::new() {
            Ok(ctx) => Ok(Some(ctx)),
            Err(e @ (GpuError::NoAdapter(_) | GpuError::Device(_))) => {
                eprintln!("compute device auto: {e}; staying on the CPU");
                Ok(None)
            }
            Err(e) => Err(e),
        },
    }
}
