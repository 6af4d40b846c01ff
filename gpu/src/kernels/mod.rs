//! WGSL kernels and their pipelines, compiled once per model. Every kernel binds its buffers in
//! the order inputs, weights, output, parameters, offsets: the last is a `vec4<u32>` of element
//! offsets (first input, second input, output) so a value can live inside a larger buffer (a
//! concatenation's output) and Concat costs nothing.

use crate::{Gpu, GpuError};

/// Activation fused into a kernel's output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// None.
    Identity = 0,
    /// `x * sigmoid(x)` (YOLOX).
    Silu = 1,
    /// `sigmoid(x)`.
    Sigmoid = 2,
    /// `max(x, 0)` (FastestDet).
    Relu = 3,
}

/// Shape and attributes of one convolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvShape {
    /// Batch, input channels, height, width.
    pub input: [usize; 4],
    /// Output channels, kernel height, kernel width.
    pub kernel: [usize; 3],
    /// Stride (y, x).
    pub stride: [usize; 2],
    /// Padding top, left (bottom and right as ONNX's `pads` 2 and 3).
    pub pads: [usize; 4],
    /// Dilation (y, x).
    pub dilation: [usize; 2],
    /// Groups.
    pub group: usize,
}

impl ConvShape {
    /// Output height and width.
    pub fn output(&self) -> Result<(usize, usize), GpuError> {
        let [_, c, h, w] = self.input;
        let [m, kh, kw] = self.kernel;
        if self.group == 0 || c % self.group != 0 || m % self.group != 0 || kh == 0 || kw == 0 {
            return Err(GpuError::Shape(format!("conv: {c} -> {m} channels in {} groups", self.group)));
        }
        let span = |k: usize, d: usize| d.max(1) * (k - 1) + 1;
        let oh = (h + self.pads[0] + self.pads[2]).checked_sub(span(kh, self.dilation[0]));
        let ow = (w + self.pads[1] + self.pads[3]).checked_sub(span(kw, self.dilation[1]));
        match (oh, ow) {
            (Some(oh), Some(ow)) => Ok((oh / self.stride[0].max(1) + 1, ow / self.stride[1].max(1) + 1)),
            _ => Err(GpuError::Shape("conv kernel larger than its padded input".into())),
        }
    }
}

pub(crate) fn pipeline(gpu: &Gpu, source: &str, label: &str) -> wgpu::ComputePipeline {
    let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: wgpu::PipelineCompilationOptions::default(),
        cache: None,
    })
}

pub(crate) fn bind(gpu: &Gpu, pipeline: &wgpu::ComputePipeline, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.as_entire_binding() })
        .collect();
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

/// The kernels a plan dispatches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Kind {
    /// Direct convolution (grouped and depthwise).
    ConvDirect,
    /// Implicit-GEMM convolution (one group), register-tiled, 64 channels x 64 pixels a tile.
    ConvGemm,
    /// The same with 32 channels x 128 pixels a tile, for layers of 17 to 32 channels.
    ConvGemm32,
    /// The same with 16 channels x 256 pixels a tile, for layers of at most 16 channels.
    ConvGemm16,
    /// Transposed convolution (a gather per output element).
    ConvTranspose,
    /// Sigmoid / ReLU not fused into a convolution; hard sigmoid, hard swish, clip.
    Unary,
    /// Add / Mul / Sub / Div of equal shapes, or with one value or one per channel.
    Binary,
    /// Strided gather: Slice, Transpose, Gather of one index.
    Gather,
    /// One part of a concatenation that could not be produced in place.
    CopyBlock,
    /// Max and average pooling.
    Pool,
    /// Nearest (asymmetric, floor) and bilinear resize.
    Resize,
    /// Constant pad.
    Pad,
    /// Softmax along an axis.
    Softmax,
}

impl Kind {
    /// Name in profiles.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kind::ConvDirect => "conv_direct",
            Kind::ConvGemm => "conv_gemm",
            Kind::ConvGemm32 => "conv_gemm_32x128",
            Kind::ConvGemm16 => "conv_gemm_16x256",
            Kind::ConvTranspose => "conv_transpose",
            Kind::Unary => "unary",
            Kind::Binary => "binary",
            Kind::Gather => "gather",
            Kind::CopyBlock => "copy_block",
            Kind::Pool => "pool",
            Kind::Resize => "resize",
            Kind::Pad => "pad",
            Kind::Softmax => "softmax",
        }
    }

    fn source(self) -> std::borrow::Cow<'static, str> {
        let gemm = include_str!("conv_gemm.wgsl");
        std::borrow::Cow::Borrowed(match self {
            Kind::ConvDirect => include_str!("conv2d.wgsl"),
            Kind::ConvGemm => gemm,
            Kind::ConvGemm32 | Kind::ConvGemm16 => {
                let (tm, tn) = if self == Kind::ConvGemm32 { (32, 128) } else { (16, 256) };
                return std::borrow::Cow::Owned(
                    gemm.replace("const TM: u32 = 64u;", &format!("const TM: u32 = {tm}u;"))
                        .replace("const TN: u32 = 64u;", &format!("const TN: u32 = {tn}u;")),
                );
            }
            Kind::ConvTranspose => include_str!("conv_transpose.wgsl"),
            Kind::Unary => include_str!("unary.wgsl"),
            Kind::Binary => include_str!("binary.wgsl"),
            Kind::Gather => include_str!("gather.wgsl"),
            Kind::CopyBlock => include_str!("copy_block.wgsl"),
            Kind::Pool => include_str!("maxpool.wgsl"),
            Kind::Resize => include_str!("resize.wgsl"),
            Kind::Pad => include_str!("pad.wgsl"),
            Kind::Softmax => include_str!("softmax.wgsl"),
        })
    }
}

/// Pipelines compiled on first use.
#[derive(Debug, Default)]
pub(crate) struct Kernels {
    compiled: std::collections::HashMap<Kind, wgpu::ComputePipeline>,
}

impl Kernels {
    /// The pipeline of `kind`, compiled if it is not yet.
    pub(crate) fn get(&mut self, gpu: &Gpu, kind: Kind) -> &wgpu::ComputePipeline {
        self.compiled.entry(kind).or_insert_with(|| pipeline(gpu, &kind.source(), kind.name()))
    }

    /// The pipeline of `kind` if compiled.
    pub(crate) fn compiled(&self, kind: Kind) -> Option<&wgpu::ComputePipeline> {
        self.compiled.get(&kind)
    }
}
