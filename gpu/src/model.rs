//! A whole ONNX model on the GPU, node by node: float activations stay in GPU buffers,
//! weights are uploaded once at load, shape arithmetic (`Shape`, `Constant`, integer
//! `Gather`/`Unsqueeze`...) runs on the host with the reference executor's own code. One
//! dispatch per node for now; planning (fusion, one submit per frame, buffers reused) is next.

use std::collections::HashMap;

use dynaflow_infer::cpu::{Tensor, eval_node, norm_axis, reshape_shape, slice_plan, strides};
use dynaflow_infer::onnx::{Model, Node};

use crate::kernels::{bind, pipeline};
use crate::{Activation, Conv2d, ConvShape, Gpu, GpuError};

/// A value during a run.
enum Value {
    /// Float tensor in a GPU buffer.
    Gpu { buf: std::sync::Arc<wgpu::Buffer>, shape: Vec<usize> },
    /// Host tensor (weights, shapes, indices).
    Host(Tensor),
}

impl Value {
    fn shape(&self) -> &[usize] {
        match self {
            Value::Gpu { shape, .. } => shape,
            Value::Host(t) => t.shape(),
        }
    }
}

/// A model loaded onto a GPU.
pub struct GpuModel {
    gpu: Gpu,
    model: Model,
    weights: HashMap<String, wgpu::Buffer>,
    conv: Conv2d,
    unary: wgpu::ComputePipeline,
    binary: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    copy_block: wgpu::ComputePipeline,
    maxpool: wgpu::ComputePipeline,
    resize: wgpu::ComputePipeline,
    pad: wgpu::ComputePipeline,
    softmax: wgpu::ComputePipeline,
}

impl std::fmt::Debug for GpuModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuModel").field("adapter", &self.gpu.adapter).field("nodes", &self.model.nodes.len()).finish()
    }
}

/// `v` widened to 4 entries on the left with `fill` (callers check the rank is at most 4).
fn left4(v: &[usize], fill: usize) -> Vec<usize> {
    let mut o = vec![fill; 4usize.saturating_sub(v.len())];
    o.extend(v);
    o
}

fn u32s(v: &[usize]) -> Result<Vec<u32>, GpuError> {
    v.iter().map(|&x| u32::try_from(x).map_err(|_| GpuError::Shape("dimension over u32".into()))).collect()
}

/// Ops with a GPU kernel here.
pub const GPU_OPS: &[&str] = &[
    "Add",
    "AveragePool",
    "Concat",
    "Conv",
    "Gather",
    "MaxPool",
    "Mul",
    "Pad",
    "Relu",
    "Reshape",
    "Resize",
    "Sigmoid",
    "Slice",
    "Softmax",
    "Transpose",
];
/// Ops run on the host (shape arithmetic on constants).
const HOST_OPS: &[&str] = &["Constant", "Gather", "Shape", "Unsqueeze"];

impl GpuModel {
    /// The first op of `model` this executor cannot run, with its node, if any.
    pub fn unsupported(model: &Model) -> Option<String> {
        model
            .nodes
            .iter()
            .find(|n| !GPU_OPS.contains(&n.op_type.as_str()) && !HOST_OPS.contains(&n.op_type.as_str()))
            .map(|n| format!("op `{}` at node {} has no GPU kernel yet", n.op_type, n.label()))
    }

    /// Upload `model`'s float initializers and compile the kernels.
    pub fn new(gpu: Gpu, model: Model) -> Self {
        let weights = model
            .initializers
            .iter()
            .filter(|(_, t)| !t.floats.is_empty())
            .map(|(k, t)| (k.clone(), gpu.upload(&t.floats)))
            .collect();
        Self {
            conv: Conv2d::new(&gpu),
            unary: pipeline(&gpu, include_str!("kernels/unary.wgsl"), "unary"),
            binary: pipeline(&gpu, include_str!("kernels/binary.wgsl"), "binary"),
            gather: pipeline(&gpu, include_str!("kernels/gather.wgsl"), "gather"),
            copy_block: pipeline(&gpu, include_str!("kernels/copy_block.wgsl"), "copy_block"),
            maxpool: pipeline(&gpu, include_str!("kernels/maxpool.wgsl"), "maxpool"),
            resize: pipeline(&gpu, include_str!("kernels/resize.wgsl"), "resize"),
            pad: pipeline(&gpu, include_str!("kernels/pad.wgsl"), "pad"),
            softmax: pipeline(&gpu, include_str!("kernels/softmax.wgsl"), "softmax"),
            weights,
            gpu,
            model,
        }
    }

    /// The adapter it runs on.
    pub fn adapter(&self) -> &str {
        &self.gpu.adapter
    }

    fn simple(&self, p: &wgpu::ComputePipeline, bufs: &[&wgpu::Buffer], words: &[u32], n: usize) {
        let params = self.gpu.uniform(words);
        let mut all: Vec<&wgpu::Buffer> = bufs.to_vec();
        all.push(&params);
        let group = bind(&self.gpu, p, &all);
        self.gpu.dispatch(p, &group, n);
    }

    /// Run on the named float inputs; the graph outputs, downloaded.
    pub fn run(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, GpuError> {
        let mut env: HashMap<String, Value> = HashMap::new();
        for (k, t) in &self.model.initializers {
            env.insert(k.clone(), Value::Host(Tensor::from_data(t)));
        }
        for (k, t) in inputs {
            let buf = std::sync::Arc::new(self.gpu.upload(&t.floats()));
            env.insert((*k).to_string(), Value::Gpu { buf, shape: t.shape().to_vec() });
        }
        for n in &self.model.nodes {
            let err = |m: String| GpuError::Shape(format!("node {}: {m}", n.label()));
            let args: Vec<Option<&Value>> =
                n.inputs.iter().map(|i| if i.is_empty() { None } else { env.get(i) }).collect();
            if n.inputs.iter().zip(&args).any(|(i, a)| !i.is_empty() && a.is_none()) {
                return Err(err("an input is not computed before this node".into()));
            }
            let on_gpu = args.iter().flatten().any(|v| matches!(v, Value::Gpu { .. }));
            let out = if !on_gpu || n.op_type == "Shape" {
                let host: Vec<Option<Tensor>> = args
                    .iter()
                    .map(|a| {
                        a.map(|v| match v {
                            Value::Host(t) => t.clone(),
                            // `Shape` only looks at the shape.
                            Value::Gpu { shape, .. } => Tensor::F32 { shape: shape.clone(), data: Vec::new() },
                        })
                    })
                    .collect();
                let refs: Vec<Option<&Tensor>> = host.iter().map(Option::as_ref).collect();
                eval_node(n, &refs).map_err(err)?.into_iter().map(Value::Host).collect()
            } else {
                vec![self.node(n, &args).map_err(|e| match e {
                    GpuError::Shape(m) => err(m),
                    other => other,
                })?]
            };
            for (name, v) in n.outputs.iter().zip(out) {
                env.insert(name.clone(), v);
            }
        }
        self.model
            .outputs
            .iter()
            .map(|o| match env.remove(&o.name) {
                Some(Value::Gpu { buf, shape }) => {
                    let len = shape.iter().product();
                    Ok(Tensor::F32 { data: self.gpu.download(&buf, len)?, shape })
                }
                Some(Value::Host(t)) => Ok(t),
                None => Err(GpuError::Shape(format!("output `{}` never computed", o.name))),
            })
            .collect()
    }

    fn gpu_arg<'a>(args: &'a [Option<&'a Value>], i: usize) -> Result<(&'a wgpu::Buffer, &'a [usize]), GpuError> {
        match args.get(i).copied().flatten() {
            Some(Value::Gpu { buf, shape }) => Ok((buf, shape)),
            _ => Err(GpuError::Shape(format!("input {i} is not a float tensor on the GPU"))),
        }
    }

    fn ints(args: &[Option<&Value>], i: usize) -> Option<Vec<i64>> {
        match args.get(i).copied().flatten() {
            Some(Value::Host(Tensor::I64 { data, .. })) => Some(data.clone()),
            Some(Value::Host(Tensor::F32 { data, .. })) => Some(data.iter().map(|&v| v as i64).collect()),
            _ => None,
        }
    }

    /// `y[o] = x[base + sum_d coord_d(o) * src_strides_d]` for an output of rank <= 4.
    fn strided_gather(
        &self,
        x: &wgpu::Buffer,
        out_shape: Vec<usize>,
        src_strides: &[usize],
        base: usize,
    ) -> Result<Value, GpuError> {
        let (d, s) = (left4(&out_shape, 1), left4(src_strides, 0));
        let len: usize = out_shape.iter().product();
        let (buf, shape) = self.out(len, out_shape);
        let words = u32s(&[d[0], d[1], d[2], d[3], s[0], s[1], s[2], s[3], base, len, 0, 0])?;
        self.simple(&self.gather, &[x, &buf], &words, len);
        Ok(Value::Gpu { buf, shape })
    }

    fn out(&self, len: usize, shape: Vec<usize>) -> (std::sync::Arc<wgpu::Buffer>, Vec<usize>) {
        (std::sync::Arc::new(self.gpu.storage(len)), shape)
    }

    fn node(&self, n: &Node, args: &[Option<&Value>]) -> Result<Value, GpuError> {
        let attr = |k: &str, d: Vec<i64>| n.ints(k).map_or(d, <[i64]>::to_vec);
        match n.op_type.as_str() {
            "Conv" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let wname = n.inputs.get(1).cloned().unwrap_or_default();
                let w = self
                    .weights
                    .get(&wname)
                    .ok_or_else(|| GpuError::Shape("Conv weights must be initializers".into()))?;
                let ws = args.get(1).copied().flatten().map(Value::shape).unwrap_or(&[]).to_vec();
                if xs.len() != 4 || ws.len() != 4 {
                    return Err(GpuError::Shape(format!("Conv on {xs:?} with weights {ws:?}")));
                }
                let bias_owned;
                let bias = match n.inputs.get(2).and_then(|b| self.weights.get(b)) {
                    Some(b) => b,
                    None => {
                        bias_owned = self.gpu.upload(&vec![0.0; ws[0]]);
                        &bias_owned
                    }
                };
                let p = attr("pads", vec![0; 4]);
                let st = attr("strides", vec![1, 1]);
                let dl = attr("dilations", vec![1, 1]);
                let shape = ConvShape {
                    input: [xs[0], xs[1], xs[2], xs[3]],
                    kernel: [ws[0], ws[2], ws[3]],
                    stride: [st[0] as usize, st[1] as usize],
                    pads: [p[0] as usize, p[1] as usize, p[2] as usize, p[3] as usize],
                    dilation: [dl[0] as usize, dl[1] as usize],
                    group: n.int("group", 1).max(1) as usize,
                };
                let (oh, ow) = shape.output()?;
                let (buf, shape_out) = self.out(xs[0] * ws[0] * oh * ow, vec![xs[0], ws[0], oh, ow]);
                self.conv.run(&self.gpu, &shape, x, w, bias, &buf, Activation::Identity)?;
                Ok(Value::Gpu { buf, shape: shape_out })
            }
            "Sigmoid" | "Relu" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let len: usize = xs.iter().product();
                let (buf, shape) = self.out(len, xs.to_vec());
                let op = if n.op_type == "Sigmoid" { 2 } else { 3 };
                self.simple(&self.unary, &[x, &buf], &[u32s(&[len])?[0], op, 0, 0], len);
                Ok(Value::Gpu { buf, shape })
            }
            "Add" | "Mul" => {
                let (a, sa) = Self::gpu_arg(args, 0)?;
                let (b, sb) = Self::gpu_arg(args, 1)?;
                if sa != sb {
                    return Err(GpuError::Shape(format!(
                        "{} of {sa:?} and {sb:?}: broadcasting is not on the GPU yet",
                        n.op_type
                    )));
                }
                let len: usize = sa.iter().product();
                let (buf, shape) = self.out(len, sa.to_vec());
                let op = u32::from(n.op_type == "Mul");
                self.simple(&self.binary, &[a, b, &buf], &[u32s(&[len])?[0], op, 0, 0], len);
                Ok(Value::Gpu { buf, shape })
            }
            "Concat" => {
                let parts: Vec<(&wgpu::Buffer, &[usize])> =
                    (0..args.len()).map(|i| Self::gpu_arg(args, i)).collect::<Result<_, _>>()?;
                let first = parts.first().ok_or_else(|| GpuError::Shape("Concat of nothing".into()))?.1;
                let axis = norm_axis(n.int("axis", 0), first.len()).map_err(GpuError::Shape)?;
                let mut shape = first.to_vec();
                shape[axis] = parts.iter().map(|p| p.1[axis]).sum();
                let outer: usize = first[..axis].iter().product();
                let inner_dst: usize = shape[axis..].iter().product();
                let (buf, shape) = self.out(shape.iter().product(), shape);
                let mut offset = 0;
                for (src, s) in &parts {
                    let inner_src: usize = s[axis..].iter().product();
                    self.simple(
                        &self.copy_block,
                        &[src, &buf],
                        &u32s(&[outer, inner_src, inner_dst, offset])?,
                        outer * inner_src,
                    );
                    offset += inner_src;
                }
                Ok(Value::Gpu { buf, shape })
            }
            "Slice" | "Transpose" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                if xs.len() > 4 {
                    return Err(GpuError::Shape(format!("{} of rank {} (4 at most on the GPU)", n.op_type, xs.len())));
                }
                let si = strides(xs);
                let (out_shape, src_strides, base) = if n.op_type == "Transpose" {
                    let perm: Vec<usize> = n
                        .ints("perm")
                        .map_or_else(|| (0..xs.len()).rev().collect(), |p| p.iter().map(|&v| v as usize).collect());
                    (
                        perm.iter().map(|&p| xs[p]).collect::<Vec<_>>(),
                        perm.iter().map(|&p| si[p]).collect::<Vec<_>>(),
                        0,
                    )
                } else {
                    let starts = Self::ints(args, 1).ok_or_else(|| GpuError::Shape("Slice without starts".into()))?;
                    let ends = Self::ints(args, 2).ok_or_else(|| GpuError::Shape("Slice without ends".into()))?;
                    let (axes, steps) = (Self::ints(args, 3), Self::ints(args, 4));
                    let (lo, step, shape) =
                        slice_plan(xs, &starts, &ends, axes.as_deref(), steps.as_deref()).map_err(GpuError::Shape)?;
                    let base = lo.iter().zip(&si).map(|(l, s)| l * s).sum();
                    (shape, si.iter().zip(&step).map(|(s, k)| s * k).collect(), base)
                };
                self.strided_gather(x, out_shape, &src_strides, base)
            }
            "MaxPool" | "AveragePool" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let k = attr("kernel_shape", vec![1, 1]);
                let st = attr("strides", vec![1, 1]);
                let p = attr("pads", vec![0; 4]);
                if xs.len() != 4 || n.int("ceil_mode", 0) != 0 {
                    return Err(GpuError::Shape("MaxPool on 4-D input without ceil_mode only".into()));
                }
                let (h, w) = (xs[2], xs[3]);
                let (kh, kw, sh, sw) = (k[0] as usize, k[1] as usize, st[0].max(1) as usize, st[1].max(1) as usize);
                let (pt, pl, pb, pr) = (p[0] as usize, p[1] as usize, p[2] as usize, p[3] as usize);
                let oh =
                    (h + pt + pb).checked_sub(kh).ok_or_else(|| GpuError::Shape("pool kernel too large".into()))? / sh
                        + 1;
                let ow =
                    (w + pl + pr).checked_sub(kw).ok_or_else(|| GpuError::Shape("pool kernel too large".into()))? / sw
                        + 1;
                let planes = xs[0] * xs[1];
                let (buf, shape) = self.out(planes * oh * ow, vec![xs[0], xs[1], oh, ow]);
                let mode = match n.op_type.as_str() {
                    "MaxPool" => 0,
                    _ if n.int("count_include_pad", 0) != 0 => 2,
                    _ => 1,
                };
                let words = u32s(&[planes, h, w, oh, ow, kh, kw, sh, sw, pt, pl, mode])?;
                self.simple(&self.maxpool, &[x, &buf], &words, planes * oh * ow);
                Ok(Value::Gpu { buf, shape })
            }
            "Resize" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let scales: Option<Vec<f32>> = match args.get(2).copied().flatten() {
                    Some(Value::Host(t)) => Some(t.floats()).filter(|v| v.len() == 4),
                    _ => None,
                };
                let mode = (
                    n.string("mode", "nearest"),
                    n.string("coordinate_transformation_mode", "half_pixel"),
                    n.string("nearest_mode", ""),
                );
                if xs.len() != 4 || mode.0 != "nearest" || mode.1 != "asymmetric" || mode.2 != "floor" {
                    return Err(GpuError::Shape(format!(
                        "Resize {mode:?} is not on the GPU (nearest, asymmetric, floor)"
                    )));
                }
                let sc = scales.ok_or_else(|| GpuError::Shape("Resize needs constant scales on the GPU".into()))?;
                let (oh, ow) = ((xs[2] as f32 * sc[2]).floor() as usize, (xs[3] as f32 * sc[3]).floor() as usize);
                let planes = xs[0] * xs[1];
                let (buf, shape) = self.out(planes * oh * ow, vec![xs[0], xs[1], oh, ow]);
                let mut words = u32s(&[planes, xs[2], xs[3], oh, ow])?;
                words.extend([sc[2].to_bits(), sc[3].to_bits(), 0]);
                self.simple(&self.resize, &[x, &buf], &words, planes * oh * ow);
                Ok(Value::Gpu { buf, shape })
            }
            "Reshape" => {
                let (x, xs) = match args.first().copied().flatten() {
                    Some(Value::Gpu { buf, shape }) => (buf.clone(), shape.clone()),
                    _ => return Err(GpuError::Shape("Reshape input is not on the GPU".into())),
                };
                let spec =
                    Self::ints(args, 1).ok_or_else(|| GpuError::Shape("Reshape needs a constant shape".into()))?;
                let shape = reshape_shape(&xs, &spec).map_err(GpuError::Shape)?;
                Ok(Value::Gpu { buf: x, shape })
            }
            "Pad" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let pads = n.ints("pads").map(<[i64]>::to_vec).or_else(|| Self::ints(args, 1)).unwrap_or_default();
                let value = match args.get(2).copied().flatten() {
                    Some(Value::Host(t)) => t.floats().first().copied().unwrap_or(0.0),
                    _ => n.float("value", 0.0),
                };
                let r = xs.len();
                if r > 4
                    || pads.len() != 2 * r
                    || pads.iter().any(|&p| p < 0)
                    || n.string("mode", "constant") != "constant"
                {
                    return Err(GpuError::Shape(format!(
                        "Pad {pads:?} of rank {r}: constant, non-negative, rank <= 4 only"
                    )));
                }
                let out_shape: Vec<usize> = (0..r).map(|d| xs[d] + pads[d] as usize + pads[d + r] as usize).collect();
                let (d, i) = (left4(&out_shape, 1), left4(xs, 1));
                let b = left4(&pads[..r].iter().map(|&p| p as usize).collect::<Vec<_>>(), 0);
                let len: usize = out_shape.iter().product();
                let (buf, shape) = self.out(len, out_shape);
                let mut words = u32s(&[d[0], d[1], d[2], d[3], i[0], i[1], i[2], i[3], b[0], b[1], b[2], b[3], len])?;
                words.extend([value.to_bits(), 0, 0]);
                self.simple(&self.pad, &[x, &buf], &words, len);
                Ok(Value::Gpu { buf, shape })
            }
            "Softmax" => {
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let axis = norm_axis(n.int("axis", -1), xs.len()).map_err(GpuError::Shape)?;
                let step: usize = xs[axis + 1..].iter().product();
                let total: usize = xs.iter().product();
                let rows = total / xs[axis].max(1);
                let (buf, shape) = self.out(total, xs.to_vec());
                self.simple(&self.softmax, &[x, &buf], &u32s(&[rows, xs[axis], step, 0])?, rows);
                Ok(Value::Gpu { buf, shape })
            }
            "Gather" => {
                // A float tensor indexed by one constant index (ShuffleNet's channel split): a
                // strided gather that drops the axis.
                let (x, xs) = Self::gpu_arg(args, 0)?;
                let idx = match args.get(1).copied().flatten() {
                    Some(Value::Host(t)) if t.shape().is_empty() || t.shape() == [1] => {
                        Self::ints(args, 1).unwrap_or_default()
                    }
                    _ => return Err(GpuError::Shape("Gather on the GPU takes one constant index".into())),
                };
                let axis = norm_axis(n.int("axis", 0), xs.len()).map_err(GpuError::Shape)?;
                let i = idx.first().copied().unwrap_or(0);
                let i = if i < 0 { i + xs[axis] as i64 } else { i };
                if axis >= xs.len() || !(0..xs[axis] as i64).contains(&i) {
                    return Err(GpuError::Shape(format!("Gather index {i} on axis {axis} of {xs:?}")));
                }
                let si = strides(xs);
                let keep: Vec<usize> = (0..xs.len()).filter(|&d| d != axis).collect();
                let mut out_shape: Vec<usize> = keep.iter().map(|&d| xs[d]).collect();
                let mut st: Vec<usize> = keep.iter().map(|&d| si[d]).collect();
                if idx.len() == 1 && args.get(1).copied().flatten().is_some_and(|v| v.shape() == [1]) {
                    out_shape.insert(axis, 1);
                    st.insert(axis, 0);
                }
                if out_shape.len() > 4 {
                    return Err(GpuError::Shape(format!(
                        "Gather output of rank {} (4 at most on the GPU)",
                        out_shape.len()
                    )));
                }
                self.strided_gather(x, out_shape, &st, i as usize * si[axis])
            }
            other => Err(GpuError::Shape(format!("op `{other}` is not on the GPU yet"))),
        }
    }
}
