//! The compute context: one adapter, its device and queue, and the few buffer helpers every
//! stage uses (storage buffers, uploads, a blocking read-back). Opening it is the only place
//! that looks for hardware, so a machine without a GPU fails here, once, with one line.

use crate::error::{GpuError, Result};
use wgpu::util::DeviceExt;

/// An open GPU: adapter description, device and queue (a clone is another handle to them).
#[derive(Clone)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
}

impl GpuContext {
    /// Open the highest-performance adapter of a native backend (Vulkan, Metal or DX12; a
    /// software one such as Mesa's lavapipe counts). `GpuError::NoAdapter` when there is none.
    /// The device gets the adapter's own limits, so frames larger than WebGPU's defaults fit.
    pub fn new() -> Result<GpuContext> {
        let instance = wgpu::Instance::new(&wgpu::InstanceDescriptor {
            backends: wgpu::Backends::PRIMARY,
            ..Default::default()
        });
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
        }))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("specmux"),
            required_limits: adapter.limits(),
            // GPU timestamps where the adapter has them (the bench's per-kernel times).
            required_features: adapter.features()
                & (wgpu::Features::TIMESTAMP_QUERY
                    | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS),
            ..Default::default()
        }))
        .map_err(|e| GpuError::Device(e.to_string()))?;
        Ok(GpuContext {
            device,
            queue,
            info: adapter.get_info(),
        })
    }

    /// "NAME (backend, device type)", e.g. "llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)".
    pub fn adapter_name(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// The adapter's own name, e.g. "NVIDIA H100 80GB HBM3" or "llvmpipe (LLVM 15.0.6, 256 bits)".
    pub fn name(&self) -> &str {
        &self.info.name
    }

    /// True for a software rasteriser (lavapipe, WARP): timings from it say nothing of a GPU.
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// A zeroed storage buffer of `bytes` bytes that can also be copied from and to.
    pub fn storage(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A storage buffer holding `data` (read-only tables: twiddles, windows, matrices).
    pub fn storage_init<T: bytemuck::Pod>(&self, label: &str, data: &[T]) -> wgpu::Buffer {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let padded;
        let contents = if bytes.is_empty() {
            padded = [0u8; 4];
            &padded[..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// A uniform buffer holding `value` (a kernel's parameters; writable, so a frame-level
    /// parameter such as the joint method's λ per |y| can be rewritten).
    pub fn uniform<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// A staging buffer the host maps to read results back.
    pub fn readback(&self, label: &str, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes.max(4),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Wait for the submitted work, then copy the first `out.len()` values of the mapped
    /// `staging` buffer into `out` (the caller has already encoded the copy into `staging`).
    pub fn read_into<T: bytemuck::Pod>(&self, staging: &wgpu::Buffer, out: &mut [T]) -> Result<()> {
        let bytes = std::mem::size_of_val(out) as u64;
        let slice = staging.slice(..bytes.max(4));
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Device(e.to_string()))?;
        rx.recv()
            .map_err(|e| GpuError::Device(e.to_string()))?
            .map_err(|e| GpuError::Device(e.to_string()))?;
        {
            let view = slice.get_mapped_range();
            out.copy_from_slice(bytemuck::cast_slice(&view[..bytes as usize]));
        }
        staging.unmap();
        Ok(())
    }

    /// Copy `len` values of type `T` from `src` to the host (one blocking round trip; tests and
    /// one-off reads — a frame loop keeps its own staging buffer).
    pub fn read<T: bytemuck::Pod + Default>(
        &self,
        src: &wgpu::Buffer,
        len: usize,
    ) -> Result<Vec<T>> {
        let bytes = (len * std::mem::size_of::<T>()) as u64;
        let staging = self.readback("read", bytes);
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &staging, 0, bytes);
        self.queue.submit([enc.finish()]);
        let mut out = vec![T::default(); len];
        self.read_into(&staging, &mut out)?;
        Ok(out)
    }

    /// Block until every submitted command has finished (for timing).
    pub fn wait(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| GpuError::Device(e.to_string()))
    }

    /// A compute pipeline for `entry` of a WGSL module, its bind group layout taken from the
    /// shader (group 0).
    pub fn pipeline(&self, module: &wgpu::ShaderModule, entry: &str) -> wgpu::ComputePipeline {
        self.device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
    }

    /// Compile a WGSL source.
    pub fn module(&self, label: &str, source: &str) -> wgpu::ShaderModule {
        self.device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    }

    /// A bind group of `pipeline`'s group 0 with `buffers` bound at 0, 1, 2, … in order.
    pub fn bind(
        &self,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let at: Vec<(u32, &wgpu::Buffer)> = (0..).zip(buffers.iter().copied()).collect();
        self.bind_at(pipeline, &at)
    }

    /// A bind group of `pipeline`'s group 0 with each buffer at its binding (an entry point
    /// that uses only some of its module's bindings gets only those).
    pub fn bind_at(
        &self,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[(u32, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .map(|&(binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }
}

/// Workgroups of `size` invocations needed to cover `n` items.
pub fn groups(n: usize, size: u32) -> u32 {
    n.div_ceil(size as usize) as u32
}

/// Workgroups of `size` covering `n` items in a 1-D kernel, folded into (x, y) so that no side
/// exceeds the 65535 a dispatch allows (the kernel reads item gid.x + gid.y·nwg.x·size).
pub fn linear_groups(n: usize, size: u32) -> [u32; 3] {
    let g = groups(n, size);
    [g.min(65535), g.div_ceil(65535), 1]
}

/// One kernel launch, recorded once at plan time: pipeline, bindings, workgroups.
pub struct Launch {
    pipeline: wgpu::ComputePipeline,
    bind: wgpu::BindGroup,
    groups: [u32; 3],
}

impl Launch {
    /// `entry` of `module` with `buffers` bound at 0, 1, 2, … and `groups` workgroups.
    pub fn new(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        entry: &str,
        buffers: &[&wgpu::Buffer],
        groups: [u32; 3],
    ) -> Launch {
        let at: Vec<(u32, &wgpu::Buffer)> = (0..).zip(buffers.iter().copied()).collect();
        Launch::bound(ctx, module, entry, &at, groups)
    }

    /// `entry` of `module` with each buffer at its own binding.
    pub fn bound(
        ctx: &GpuContext,
        module: &wgpu::ShaderModule,
        entry: &str,
        buffers: &[(u32, &wgpu::Buffer)],
        groups: [u32; 3],
    ) -> Launch {
        let pipeline = ctx.pipeline(module, entry);
        let bind = ctx.bind_at(&pipeline, buffers);
        Launch {
            pipeline,
            bind,
            groups,
        }
    }

    /// Record the dispatch into a compute pass.
    pub fn record(&self, cp: &mut wgpu::ComputePass) {
        cp.set_pipeline(&self.pipeline);
        cp.set_bind_group(0, &self.bind, &[]);
        cp.dispatch_workgroups(self.groups[0], self.groups[1], self.groups[2]);
    }
}
