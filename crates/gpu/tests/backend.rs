//! `[compute] device`: cpu never opens a GPU; gpu and auto open one exactly when an adapter
//! exists, and auto falls back to the CPU (None) where none does.

use specmux_core::reconstructor::ComputeDevice;
use specmux_gpu::backend::open;
use specmux_gpu::{GpuContext, GpuError};

#[test]
fn each_device_choice_opens_what_it_names() {
    assert!(open(ComputeDevice::Cpu).unwrap().is_none());
    let adapter = match GpuContext::new() {
        Ok(_) => true,
        Err(GpuError::NoAdapter(_)) => false,
        Err(e) => panic!("a GPU adapter exists but could not be opened: {e}"),
    };
    assert_eq!(open(ComputeDevice::Auto).unwrap().is_some(), adapter);
    match open(ComputeDevice::Gpu) {
        Ok(ctx) => assert!(adapter && ctx.is_some()),
        Err(GpuError::NoAdapter(_)) => assert!(!adapter),
        Err(e) => panic!("{e}"),
    }
}
