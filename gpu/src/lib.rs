//! dynaflow's wgpu compute executor, first part: the device (any Vulkan, Metal or DX12
//! adapter; Mesa's lavapipe in CI) and WGSL kernels for the detectors' heavy ops, each tested
//! against `dynaflow-infer`'s reference executor on odd shapes.
//!
//! - [`Gpu`]: instance, adapter and device, with a clear error when there is no adapter.
//! - `kernels`: `conv2d` (groups, strides, padding, dilation, fused SiLU / sigmoid / ReLU),
//!   `binary` (add, multiply), `unary`, `gather` (slices, transposes), `copy_block` (concat),
//!   pooling (max, average), `resize` (nearest), `pad` (constant), `softmax`.
//! - [`GpuModel`]: a whole ONNX model node by node (YOLOX-nano and FastestDet: their raw
//!   outputs equal the reference within 8e-5 on real images).
//!
//! Still to come (issue 12): planning a whole model at load time (buffers and bind groups
//! allocated once, Conv + activation fused, Concat made free, one submit per frame),
//! register-tiled GEMM for 1x1 convolutions, timestamp queries.

mod kernels;
mod model;

pub use kernels::{Activation, BinaryOp, Conv2d, ConvShape};
pub use model::{GPU_OPS, GpuModel};

/// Why the GPU cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum GpuError {
    /// No adapter on this machine (no GPU driver, no software Vulkan).
    #[error(
        "no GPU adapter found (install a Vulkan driver, e.g. Debian's mesa-vulkan-drivers for the software one; or use backend `cpu`)"
    )]
    NoAdapter,
    /// The adapter refused a device.
    #[error("the GPU adapter `{adapter}` gave no device: {message}")]
    Device {
        /// Adapter name.
        adapter: String,
        /// Why.
        message: String,
    },
    /// A buffer could not be read back.
    #[error("reading a GPU buffer back failed: {0}")]
    Readback(String),
    /// Shapes a kernel cannot take.
    #[error("{0}")]
    Shape(String),
}

/// A wgpu device and queue.
#[derive(Debug)]
pub struct Gpu {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter: String,
}

impl Gpu {
    /// The first high-performance adapter of any primary backend (Vulkan, Metal, DX12),
    /// software adapters (lavapipe) included; `WGPU_BACKEND` narrows the backends.
    pub fn new() -> Result<Self, GpuError> {
        // `WGPU_BACKEND` and the other wgpu environment variables apply.
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if wgpu::Backends::from_env().is_none() {
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let adapter = futures::executor::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..wgpu::RequestAdapterOptions::default()
        }))
        .map_err(|_| GpuError::NoAdapter)?;
        let info = adapter.get_info();
        let name = format!("{} ({:?})", info.name, info.backend);
        let limits = adapter.limits();
        let (device, queue) = futures::executor::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("dynaflow"),
            required_limits: wgpu::Limits {
                max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
                max_buffer_size: limits.max_buffer_size,
                ..wgpu::Limits::downlevel_defaults()
            },
            ..wgpu::DeviceDescriptor::default()
        }))
        .map_err(|e| GpuError::Device { adapter: name.clone(), message: e.to_string() })?;
        Ok(Self { device, queue, adapter: name })
    }

    /// A storage buffer holding `data`.
    pub fn upload(&self, data: &[f32]) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        let bytes: Vec<u8> =
            if data.is_empty() { vec![0; 4] } else { data.iter().flat_map(|v| v.to_le_bytes()).collect() };
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: &bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        })
    }

    /// An uninitialised storage buffer of `len` floats.
    pub fn storage(&self, len: usize) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: (4 * len.max(1)) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Copy `len` floats of `buffer` back to the host (waits for the GPU).
    pub fn download(&self, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<f32>, GpuError> {
        let size = (4 * len.max(1)) as u64;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        enc.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
        self.queue.submit([enc.finish()]);
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = data.chunks_exact(4).take(len).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
        drop(data);
        staging.unmap();
        Ok(out)
    }

    /// A uniform buffer holding `words`.
    pub(crate) fn uniform(&self, words: &[u32]) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        let bytes: Vec<u8> = words.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: &bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        })
    }

    /// Record and submit one compute dispatch of `pipeline` over `invocations` threads
    /// (workgroups of 64, spread over x and y to stay under the 65 535 limit).
    pub(crate) fn dispatch(&self, pipeline: &wgpu::ComputePipeline, bind: &wgpu::BindGroup, invocations: usize) {
        let groups = invocations.div_ceil(64).max(1) as u32;
        let x = groups.min(65_535);
        let y = groups.div_ceil(x);
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes: None });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.queue.submit([enc.finish()]);
    }
}
