//! dynaflow's wgpu compute executor: the device (any Vulkan, Metal or DX12 adapter; Mesa's
//! lavapipe in CI) and a planned executor for ONNX detectors, each kernel tested against
//! `dynaflow-infer`'s reference executor on odd shapes.
//!
//! - [`Gpu`]: instance, adapter and device, with a clear error when there is no adapter.
//! - [`GpuModel`]: a whole ONNX model planned at load time (activations fused into
//!   convolutions, Concat free, one arena, every bind group made once) and run with one submit
//!   per frame; [`GpuModel::profile`] times each dispatch with timestamp queries.
//! - `kernels` (WGSL): implicit-GEMM convolution (register-tiled 64x64 tiles, 1x1 and dense
//!   3x3 alike), direct convolution (grouped, depthwise), `binary` (add, multiply), `unary`,
//!   `gather` (slices, transposes, one-index gathers), `copy_block` (concat parts that cannot be
//!   written in place), pooling (max, average), `resize` (nearest), `pad` (constant),
//!   `softmax`.

#![warn(missing_docs)]

mod kernels;
mod model;

pub use kernels::{Activation, ConvShape};
pub use model::{GPU_OPS, GpuModel, KernelTime, PlanStats};

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
#[derive(Clone, Debug)]
pub struct Gpu {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name and backend, for reports.
    pub adapter: String,
    /// The adapter is a software renderer on the CPU (Mesa's llvmpipe/lavapipe, WARP).
    pub software: bool,
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
        let software = info.device_type == wgpu::DeviceType::Cpu;
        let limits = adapter.limits();
        let (device, queue) = futures::executor::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("dynaflow"),
            required_limits: wgpu::Limits {
                max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
                max_buffer_size: limits.max_buffer_size,
                ..wgpu::Limits::downlevel_defaults()
            },
            // Timestamp queries where the adapter has them (`GpuModel::profile`).
            required_features: adapter.features() & wgpu::Features::TIMESTAMP_QUERY,
            ..wgpu::DeviceDescriptor::default()
        }))
        .map_err(|e| GpuError::Device { adapter: name.clone(), message: e.to_string() })?;
        Ok(Self { device, queue, adapter: name, software })
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

    /// Map `staging` (a `MAP_READ` buffer the submitted work fills), wait, and read `len`
    /// little-endian words of `N` bytes.
    fn read_words<const N: usize>(&self, staging: &wgpu::Buffer, len: usize) -> Result<Vec<[u8; N]>, GpuError> {
        let slice = staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| GpuError::Readback(e.to_string()))?;
        rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
        let data = slice.get_mapped_range().map_err(|e| GpuError::Readback(e.to_string()))?;
        let out = data.chunks_exact(N).take(len).map(|c| c.try_into().unwrap_or([0; N])).collect();
        drop(data);
        staging.unmap();
        Ok(out)
    }

    /// `len` floats of a mapped-readable buffer.
    pub(crate) fn read_mapped(&self, staging: &wgpu::Buffer, len: usize) -> Result<Vec<f32>, GpuError> {
        Ok(self.read_words::<4>(staging, len)?.into_iter().map(f32::from_le_bytes).collect())
    }

    /// `len` u64 of a mapped-readable buffer (timestamps).
    pub(crate) fn read_mapped_u64(&self, staging: &wgpu::Buffer, len: usize) -> Result<Vec<u64>, GpuError> {
        Ok(self.read_words::<8>(staging, len)?.into_iter().map(u64::from_le_bytes).collect())
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
}
