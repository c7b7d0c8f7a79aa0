//! The compute device `[compute] device` (or `--device`) names, opened once per run and lent to
//! every stage that has a GPU kernel: the forward model's multiplex and relay pair sums, and
//! the reconstruction ([`DeviceReconstructor`]) of runs, `reconstruct`, recordings and the
//! work–precision bench.

use specmux_core::error::Result;
use specmux_core::reconstructor::ComputeDevice;

mod reconstructor;

pub use reconstructor::{DeviceReconstructor, FrameRun};

/// The device a run computes on: the CPU, or one GPU context its GPU stages share (a clone
/// shares the context).
#[derive(Clone)]
pub struct OpenDevice {
    #[cfg(feature = "gpu")]
    gpu: Option<specmux_gpu::GpuContext>,
}

impl OpenDevice {
    /// The CPU.
    pub fn cpu() -> OpenDevice {
        OpenDevice {
            #[cfg(feature = "gpu")]
            gpu: None,
        }
    }

    /// The CPU for `cpu`; with the `gpu` feature the GPU for `gpu` (an error without an
    /// adapter) and for `auto` (the CPU, said in one line, without one); without the feature
    /// `gpu` is refused by its key (it used to run on the CPU without a word) and `auto` is the
    /// CPU, said in one line. The caller names the file (`Error::in_file`).
    pub fn open(device: ComputeDevice) -> Result<OpenDevice> {
        #[cfg(feature = "gpu")]
        return Ok(OpenDevice {
            gpu: specmux_gpu::backend::open(device)?,
        });
        #[cfg(not(feature = "gpu"))]
        match device {
            ComputeDevice::Gpu => Err(ComputeDevice::not_built(specmux_core::error::UNNAMED_FILE)),
            ComputeDevice::Auto => {
                eprintln!("compute device auto: built without the gpu feature; staying on the CPU");
                Ok(OpenDevice::cpu())
            }
            ComputeDevice::Cpu => Ok(OpenDevice::cpu()),
        }
    }

    /// The GPU's context, if the device is one.
    #[cfg(feature = "gpu")]
    pub fn gpu(&self) -> Option<&specmux_gpu::GpuContext> {
        self.gpu.as_ref()
    }

    /// A GPU that is not a software adapter (lavapipe emulates one on the CPU, slower than
    /// the CPU path).
    pub fn is_hardware_gpu(&self) -> bool {
        #[cfg(feature = "gpu")]
        if let Some(ctx) = &self.gpu {
            return !ctx.is_software();
        }
        false
    }

    /// The work–precision table `method = "auto"` reads on this device: the GPU's for a
    /// hardware adapter, else the CPU's (a software adapter is slower than the CPU path).
    pub fn auto_table(&self) -> specmux_core::auto::Table<'static> {
        match self.is_hardware_gpu() {
            true => specmux_core::auto::GPU,
            false => specmux_core::auto::CPU,
        }
    }

    /// "CPU, N threads", or "GPU NAME (backend, type)" flagged when the adapter is software.
    pub fn describe(&self) -> String {
        #[cfg(feature = "gpu")]
        if let Some(ctx) = &self.gpu {
            let software = if ctx.is_software() {
                " — a software adapter: its times are a CPU emulating a GPU, not a GPU's"
            } else {
                ""
            };
            return format!("GPU {}{software}", ctx.adapter_name());
        }
        format!("CPU, {} threads", rayon::current_num_threads())
    }

    /// `describe` short enough for a plot's title: the adapter's name up to its first
    /// parenthesis, and "software" for a software adapter.
    pub fn short(&self) -> String {
        #[cfg(feature = "gpu")]
        if let Some(ctx) = &self.gpu {
            let name = ctx.name().split(" (").next().unwrap_or("");
            return match ctx.is_software() {
                true => format!("GPU {name} (software: not a GPU's speed)"),
                false => format!("GPU {name}"),
            };
        }
        self.describe()
    }
}

#[cfg(all(test, not(feature = "gpu")))]
mod tests {
    use super::*;

    /// Without the GPU backend `gpu` is refused by its key (it used to run on the CPU without a
    /// word); `cpu` and `auto` open on the CPU and read the CPU's `auto` table.
    #[test]
    fn a_gpu_device_is_refused_without_the_backend() {
        let e = OpenDevice::open(ComputeDevice::Gpu).err().expect("refused");
        let e = e.in_file("x.toml").to_string();
        assert!(
            e.starts_with("x.toml: `compute.device` = \"gpu\"") && e.contains("--features gpu"),
            "{e}"
        );
        assert!(OpenDevice::open(ComputeDevice::Cpu).is_ok());
        let auto = OpenDevice::open(ComputeDevice::Auto).unwrap();
        assert!(auto.describe().starts_with("CPU"));
        assert_eq!(auto.auto_table(), specmux_core::auto::CPU);
    }
}
