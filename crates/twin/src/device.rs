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
    /// `gpu` is refused (as `specmux bench` and `reconstruct` refuse it) and `auto` is the CPU.
    pub fn open(device: specmux_core::reconstructor::ComputeDevice) -> Result<OpenDevice> {
        #[cfg(feature = "gpu")]
        return Ok(OpenDevice {
            gpu: specmux_gpu::backend::open(device)?,
        });
        #[cfg(not(feature = "gpu"))]
        match device {
            specmux_core::reconstructor::ComputeDevice::Gpu => {
                Err(specmux_core::reconstructor::ComputeDevice::not_built(
                    specmux_core::error::UNNAMED_FILE,
                ))
            }
            _ => Ok(OpenDevice {}),
        }
    }

    /// The GPU's context, if the device is one.
    #[cfg(feature = "gpu")]
    pub fn gpu(&self) -> Option<&specmux_gpu::GpuContext> {
        self.gpu.as_ref()
    }
}

#[cfg(all(test, not(feature = "gpu")))]
mod tests {
    use super::*;
    use specmux_core::reconstructor::ComputeDevice;

    /// Without the GPU backend `gpu` is refused by its key (it used to run on the CPU without a
    /// word); `cpu` and `auto` open.
    #[test]
    fn a_gpu_device_is_refused_without_the_backend() {
        let e = OpenDevice::open(ComputeDevice::Gpu).err().expect("refused");
        let e = e.in_file("x.toml").to_string();
        assert!(
            e.starts_with("x.toml: `compute.device` = \"gpu\"") && e.contains("--features gpu"),
            "{e}"
        );
        assert!(OpenDevice::open(ComputeDevice::Cpu).is_ok());
        assert!(OpenDevice::open(ComputeDevice::Auto).is_ok());
    }
}
