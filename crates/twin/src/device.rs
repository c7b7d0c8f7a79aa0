//! The compute device of the forward model's GPU stages (`[compute] device`), opened once per
//! pipeline and lent to each stage that has a GPU kernel.

use specmux_core::error::Result;

/// The device `[compute] device` names, opened once per pipeline: its GPU stages (the multiplex,
/// the relay's pair sums) share one context, and `auto` says once that it stays on the CPU.
pub struct OpenDevice {
    #[cfg(feature = "gpu")]
    gpu: Option<specmux_gpu::GpuContext>,
}

impl OpenDevice {
    /// The CPU for `cpu`; with the `gpu` feature the GPU for `gpu` (an error without an
    /// adapter) and for `auto` (the CPU, said in one line, without one); without the feature
    /// the CPU (the reconstruction reports the missing feature).
    pub fn open(device: specmux_core::reconstructor::ComputeDevice) -> Result<OpenDevice> {
        #[cfg(feature = "gpu")]
        return Ok(OpenDevice {
            gpu: specmux_gpu::backend::open(device)?,
        });
        #[cfg(not(feature = "gpu"))]
        {
            let _ = device;
            Ok(OpenDevice {})
        }
    }

    /// The GPU's context, if the device is one.
    #[cfg(feature = "gpu")]
    pub fn gpu(&self) -> Option<&specmux_gpu::GpuContext> {
        self.gpu.as_ref()
    }
}
