//! Shared by the GPU tests: open the adapter, or say there is none and skip. Only a missing
//! adapter skips; any other failure to open one fails the test.

// Each test file uses only some of these helpers.
#![allow(dead_code)]

use specmux_gpu::{wgpu, GpuContext, GpuError};

/// The GPU context, or None (with one printed line) when this machine has no adapter.
pub fn context() -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(c) => {
            eprintln!("GPU adapter: {}", c.adapter_name());
            Some(c)
        }
        Err(GpuError::NoAdapter(e)) => {
            eprintln!("no GPU adapter found ({e}): GPU test skipped");
            None
        }
        Err(e) => panic!("a GPU adapter exists but could not be opened: {e}"),
    }
}

/// ‖a − b‖₂ / ‖b‖₂ over interleaved complex or real values, in f64.
pub fn rel_l2(a: &[f32], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let num: f64 = a.iter().zip(b).map(|(x, y)| (*x as f64 - y).powi(2)).sum();
    let den: f64 = b.iter().map(|y| y * y).sum();
    (num / den).sqrt()
}

/// Deterministic pseudo-random values in [−1, 1).
pub fn noise(len: usize, seed: u64) -> Vec<f32> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    (0..len).map(|_| rng.gen_range(-1.0..1.0)).collect()
}

/// A storage buffer holding `data` that can be read back (`GpuContext::read`).
pub fn upload<T: bytemuck::Pod>(ctx: &GpuContext, label: &str, data: &[T]) -> wgpu::Buffer {
    let buf = ctx.storage(label, std::mem::size_of_val(data) as u64);
    ctx.queue.write_buffer(&buf, 0, bytemuck::cast_slice(data));
    buf
}
