//! WGSL kernels with their host side: pipelines built once, buffers passed per call.

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

/// A direct 2-D convolution, NCHW, one invocation per output element.
#[derive(Debug)]
pub struct Conv2d {
    pipeline: wgpu::ComputePipeline,
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

impl Conv2d {
    /// Compile the kernel.
    pub fn new(gpu: &Gpu) -> Self {
        Self { pipeline: pipeline(gpu, include_str!("conv2d.wgsl"), "conv2d") }
    }

    /// `y = act(conv(x, w) + bias)`; `y` must hold `n * m * oh * ow` floats. Submits the work
    /// (read `y` back with [`Gpu::download`]).
    #[allow(clippy::too_many_arguments)]
    pub fn run(
        &self,
        gpu: &Gpu,
        shape: &ConvShape,
        x: &wgpu::Buffer,
        w: &wgpu::Buffer,
        bias: &wgpu::Buffer,
        y: &wgpu::Buffer,
        act: Activation,
    ) -> Result<(), GpuError> {
        let (oh, ow) = shape.output()?;
        let [n, c, h, wd] = shape.input;
        let [m, kh, kw] = shape.kernel;
        let p = [
            n,
            c,
            h,
            wd,
            m,
            oh,
            ow,
            kh,
            kw,
            shape.stride[0],
            shape.stride[1],
            shape.pads[0],
            shape.pads[1],
            shape.dilation[0],
            shape.dilation[1],
            shape.group,
            act as usize,
            0,
        ];
        let words: Vec<u32> = p
            .iter()
            .map(|&v| u32::try_from(v).map_err(|_| GpuError::Shape("conv dimension over u32".into())))
            .collect::<Result<_, _>>()?;
        let params = gpu.uniform(&words);
        let group = bind(gpu, &self.pipeline, &[x, w, bias, y, &params]);
        gpu.dispatch(&self.pipeline, &group, n * m * oh * ow);
        Ok(())
    }
}

/// Element-wise binary op on two buffers of the same length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BinaryOp {
    /// `a + b`.
    Add = 0,
    /// `a * b`.
    Mul = 1,
}

impl BinaryOp {
    /// Compile the kernel.
    pub fn pipeline(gpu: &Gpu) -> wgpu::ComputePipeline {
        pipeline(gpu, include_str!("binary.wgsl"), "binary")
    }

    /// `y = a (op) b` over `len` elements.
    pub fn run(
        self,
        gpu: &Gpu,
        pipeline: &wgpu::ComputePipeline,
        a: &wgpu::Buffer,
        b: &wgpu::Buffer,
        y: &wgpu::Buffer,
        len: usize,
    ) -> Result<(), GpuError> {
        let n = u32::try_from(len).map_err(|_| GpuError::Shape("length over u32".into()))?;
        let params = gpu.uniform(&[n, self as u32, 0, 0]);
        let group = bind(gpu, pipeline, &[a, b, y, &params]);
        gpu.dispatch(pipeline, &group, len);
        Ok(())
    }
}
