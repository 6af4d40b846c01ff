//! A whole ONNX model planned once at load and run with one submit per frame.
//!
//! Planning (in [`GpuModel::with_inputs`]), for fixed input shapes:
//! 1. **Fusion** on the ONNX graph: `Conv -> Relu`, `Conv -> Sigmoid` and YOLOX's SiLU
//!    (`Conv -> Sigmoid -> Mul(conv, sigmoid)`) become one convolution with the activation in
//!    its store, when the intermediate values have no other reader.
//! 2. **Lowering**: shape arithmetic on constants (`Shape`, integer `Gather`, `Unsqueeze`,
//!    `Constant`...) runs on the host with the reference executor's own code; every float op
//!    becomes a kernel with its parameters computed now. Dense convolutions go to the
//!    register-tiled implicit GEMM, grouped and depthwise ones to the direct kernel.
//! 3. **Placement**: each value gets a region (buffer, element offset) in an arena allocated
//!    once. Concat is free: walking the graph backwards, a concatenation's inputs are placed
//!    inside its output (when the axis is outermost after batch 1), so their producers write
//!    there directly; `Reshape` is an alias. A part that cannot be placed (a graph input, a
//!    value two concatenations want, a kernel that would read and write one buffer) is copied.
//! 4. **Binding**: every bind group, parameter and offset buffer is created once.
//!
//! Per frame ([`GpuModel::run`]): one upload per input, one encoder with one compute pass of
//! every dispatch, one copy of the outputs into a staging buffer, one submit, one read-back.
//! [`GpuModel::profile`] times every dispatch with timestamp queries where the adapter has them.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};

mod plan;

use dynaflow_infer::onnx::{Model, Op};
use dynaflow_infer::reference::eval_node;
use dynaflow_infer::tensor::Tensor;

use crate::kernels::{Kernels, bind};
use crate::{Gpu, GpuError};
use plan::*;

/// Ops with a GPU kernel here.
pub const GPU_OPS: &[&str] = &[
    "Add",
    "AveragePool",
    "Clip",
    "Concat",
    "Conv",
    "ConvTranspose",
    "Div",
    "Gather",
    "GlobalAveragePool",
    "HardSigmoid",
    "HardSwish",
    "MaxPool",
    "Mul",
    "Pad",
    "Relu",
    "Reshape",
    "Resize",
    "Sigmoid",
    "Slice",
    "Softmax",
    "Sub",
    "Transpose",
];
/// Ops run on the host (shape arithmetic on constants).
const HOST_OPS: &[&str] = &["Constant", "Gather", "Shape", "Unsqueeze"];

/// What planning did, for reports and benchmarks.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PlanStats {
    /// ONNX nodes in the model.
    pub nodes: usize,
    /// Dispatches per frame.
    pub dispatches: usize,
    /// Activations fused into convolutions.
    pub fused_activations: usize,
    /// Concatenation inputs written in place by their producers.
    pub concat_in_place: usize,
    /// Concatenation inputs copied.
    pub concat_copied: usize,
    /// Bytes of the activation arena (weights excluded).
    pub arena_bytes: usize,
    /// Bytes of weights on the GPU.
    pub weight_bytes: usize,
}

/// Time of one dispatch, from timestamp queries.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelTime {
    /// The ONNX node (the first of a fused group).
    pub node: String,
    /// The kernel.
    pub kernel: &'static str,
    /// GPU time in nanoseconds.
    pub ns: f64,
}

/// A model planned onto a GPU for fixed input shapes.
pub struct GpuModel {
    gpu: Gpu,
    kernels: Kernels,
    arena: Vec<wgpu::Buffer>,
    steps: Vec<Step>,
    inputs: Vec<(String, Vec<usize>, Region)>,
    outputs: Vec<Out>,
    staging: wgpu::Buffer,
    staging_len: usize,
    stats: PlanStats,
    /// Serialises runs (one staging buffer).
    lock: Mutex<()>,
}

impl std::fmt::Debug for GpuModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuModel").field("adapter", &self.gpu.adapter).field("stats", &self.stats).finish()
    }
}

impl GpuModel {
    /// The first op of `model` this executor cannot run, with its node, if any.
    pub fn unsupported(model: &Model) -> Option<String> {
        model
            .nodes
            .iter()
            .find(|n| !GPU_OPS.contains(&n.op.name()) && !HOST_OPS.contains(&n.op.name()))
            .map(|n| format!("op `{}` at node {} has no GPU kernel yet", n.op, n.label()))
    }

    /// Plan `model` for the input shapes its file declares (all fixed).
    pub fn new(gpu: Gpu, model: &Model) -> Result<Self, GpuError> {
        let inputs: Vec<(String, Vec<usize>)> = model
            .inputs
            .iter()
            .filter(|i| !model.initializers.contains_key(&i.name))
            .map(|i| {
                let dims: Option<Vec<usize>> =
                    i.shape.iter().map(|d| d.and_then(|v| usize::try_from(v).ok()).filter(|&v| v > 0)).collect();
                dims.map(|d| (i.name.clone(), d)).ok_or_else(|| {
                    GpuError::Shape(format!(
                        "input `{}` has shape {:?}: the GPU plan needs fixed input shapes",
                        i.name, i.shape
                    ))
                })
            })
            .collect::<Result<_, _>>()?;
        let refs: Vec<(&str, Vec<usize>)> = inputs.iter().map(|(n, s)| (n.as_str(), s.clone())).collect();
        Self::with_inputs(gpu, model, &refs)
    }

    /// Plan `model` for float inputs of the given shapes (see the module documentation).
    pub fn with_inputs(gpu: Gpu, model: &Model, inputs: &[(&str, Vec<usize>)]) -> Result<Self, GpuError> {
        if let Some(why) = Self::unsupported(model) {
            return Err(GpuError::Shape(why));
        }
        let (nodes, acts, fused) = fuse(model);
        let mut weights: HashMap<String, Arc<wgpu::Buffer>> = HashMap::new();
        let mut weight_bytes = 0;
        let mut env: HashMap<String, PVal> = HashMap::new();
        for (k, t) in &model.initializers {
            env.insert(k.clone(), PVal::Host(Tensor::from_data(t)));
        }
        let graph_inputs: Vec<(String, Vec<usize>)> =
            inputs.iter().map(|(n, s)| ((*n).to_string(), s.clone())).collect();
        for (name, shape) in &graph_inputs {
            env.insert(name.clone(), PVal::Gpu(shape.clone()));
        }
        let mut plan: Vec<Planned> = Vec::new();
        for (n, &act) in nodes.iter().zip(&acts) {
            let err = |m: String| GpuError::Shape(format!("node {}: {m}", n.label()));
            let args: Vec<Option<(&str, &PVal)>> = n
                .inputs
                .iter()
                .map(|i| if i.is_empty() { None } else { env.get(i).map(|v| (i.as_str(), v)) })
                .collect();
            if n.inputs.iter().zip(&args).any(|(i, a)| !i.is_empty() && a.is_none()) {
                return Err(err("an input is not computed before this node".into()));
            }
            let on_gpu = args.iter().flatten().any(|(_, v)| matches!(v, PVal::Gpu(_)));
            if !on_gpu || n.op == Op::Shape {
                let host: Vec<Option<Tensor>> = args
                    .iter()
                    .map(|a| {
                        a.map(|(_, v)| match v {
                            PVal::Host(t) => t.clone(),
                            // `Shape` only looks at the shape.
                            PVal::Gpu(shape) => Tensor::F32 { shape: shape.clone(), data: Vec::new() },
                        })
                    })
                    .collect();
                let refs: Vec<Option<&Tensor>> = host.iter().map(Option::as_ref).collect();
                let outs = eval_node(n, &refs).map_err(|e| GpuError::Shape(e.to_string()))?;
                for (name, t) in n.outputs.iter().zip(outs) {
                    env.insert(name.clone(), PVal::Host(t));
                }
                continue;
            }
            let mut weight = |name: &str, len: usize, given: Option<&[f32]>| -> Arc<wgpu::Buffer> {
                if let Some(b) = weights.get(name) {
                    return b.clone();
                }
                let data = match (given, model.initializers.get(name)) {
                    (Some(d), _) => d.to_vec(),
                    (None, Some(t)) if !t.floats.is_empty() => t.floats.clone(),
                    _ => vec![0.0; len],
                };
                weight_bytes += 4 * data.len();
                let b = Arc::new(gpu.upload(&data));
                weights.insert(name.to_string(), b.clone());
                b
            };
            let (what, shape) = lower(n, act, &args, &mut weight).map_err(|e| match e {
                GpuError::Shape(m) => err(m),
                other => other,
            })?;
            let out = n.outputs.first().cloned().ok_or_else(|| err("no output".into()))?;
            env.insert(out.clone(), PVal::Gpu(shape.clone()));
            plan.push(Planned { label: n.label(), out, shape, what });
        }

        // Place, giving up in-place writes that would read and write one buffer.
        let mut forbidden: HashSet<String> = HashSet::new();
        let (at, roots, list, in_place, copied) = loop {
            let (at, roots) = place(&plan, &graph_inputs, &forbidden);
            let (list, in_place, copied) = dispatches(&plan, &at)?;
            let clash: Vec<String> = list
                .iter()
                .filter(|d| d.reads.iter().any(|r| r.root == d.write.root))
                .map(|d| d.owner.clone())
                .filter(|o| !forbidden.contains(o))
                .collect();
            if clash.is_empty() {
                break (at, roots, list, in_place, copied);
            }
            forbidden.extend(clash);
            if forbidden.len() > plan.len() {
                return Err(GpuError::Shape("cannot place the model's values without aliasing".into()));
            }
        };
        if let Some(d) = list.iter().find(|d| d.reads.iter().any(|r| r.root == d.write.root)) {
            return Err(GpuError::Shape(format!("node {} would read and write one buffer", d.label)));
        }

        let arena: Vec<wgpu::Buffer> = roots.iter().map(|&len| gpu.storage(len)).collect();
        let mut kernels = Kernels::default();
        let mut steps = Vec::with_capacity(list.len());
        for d in &list {
            let pipeline = kernels.get(&gpu, d.kind);
            let params = gpu.uniform(&d.words);
            let offs = |i: usize| d.reads.get(i).map_or(0, |r| r.off);
            let offsets = gpu.uniform(&u32s(&[offs(0), offs(1), d.write.off, 0])?);
            let mut bufs: Vec<&wgpu::Buffer> = d.reads.iter().map(|r| &arena[r.root]).collect();
            bufs.extend(d.weights.iter().map(|w| w.as_ref()));
            bufs.push(&arena[d.write.root]);
            bufs.push(&params);
            bufs.push(&offsets);
            let bind = bind(&gpu, pipeline, &bufs);
            steps.push(Step { label: d.label.clone(), kind: d.kind, bind, groups: d.grid.groups()? });
        }

        let mut staging_len = 0;
        let outputs = model
            .outputs
            .iter()
            .map(|o| match (env.remove(&o.name), at.get(&o.name)) {
                (Some(PVal::Gpu(shape)), Some(&region)) => {
                    let out = Out::Gpu { region, staging_off: staging_len, shape: shape.clone() };
                    staging_len += shape.iter().product::<usize>();
                    Ok(out)
                }
                (Some(PVal::Host(t)), _) => Ok(Out::Host(t)),
                _ => Err(GpuError::Shape(format!("output `{}` never computed", o.name))),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("outputs"),
            size: (4 * staging_len.max(1)) as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let inputs = graph_inputs
            .into_iter()
            .map(|(name, shape)| {
                let r = at[&name];
                (name, shape, r)
            })
            .collect();
        let stats = PlanStats {
            nodes: model.nodes.len(),
            dispatches: steps.len(),
            fused_activations: fused,
            concat_in_place: in_place,
            concat_copied: copied,
            arena_bytes: 4 * roots.iter().sum::<usize>(),
            weight_bytes,
        };
        Ok(Self { gpu, kernels, arena, steps, inputs, outputs, staging, staging_len, stats, lock: Mutex::new(()) })
    }

    /// The adapter it runs on.
    pub fn adapter(&self) -> &str {
        &self.gpu.adapter
    }

    /// What planning did.
    pub fn stats(&self) -> &PlanStats {
        &self.stats
    }

    fn upload_inputs(&self, inputs: &[(&str, Tensor)]) -> Result<(), GpuError> {
        for (name, shape, r) in &self.inputs {
            let t = inputs
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, t)| t)
                .ok_or_else(|| GpuError::Shape(format!("input `{name}` not given")))?;
            if t.shape() != shape.as_slice() {
                return Err(GpuError::Shape(format!(
                    "input `{name}` has shape {:?}; the model was planned for {shape:?}",
                    t.shape()
                )));
            }
            let bytes: Vec<u8> = t.floats().iter().flat_map(|v| v.to_le_bytes()).collect();
            self.gpu.queue.write_buffer(&self.arena[r.root], (4 * r.off) as u64, &bytes);
        }
        Ok(())
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>, step: &Step) -> Result<(), GpuError> {
        let pipeline = self
            .kernels
            .compiled(step.kind)
            .ok_or_else(|| GpuError::Shape(format!("kernel {} not compiled", step.kind.name())))?;
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &step.bind, &[]);
        pass.dispatch_workgroups(step.groups[0], step.groups[1], step.groups[2]);
        Ok(())
    }

    /// Run on the named float inputs (the shapes planned for); the graph outputs, read back.
    pub fn run(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, GpuError> {
        let _guard = self.lock.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        self.upload_inputs(inputs)?;
        let mut enc = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        {
            let mut pass =
                enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("model"), timestamp_writes: None });
            for s in &self.steps {
                self.record(&mut pass, s)?;
            }
        }
        for o in &self.outputs {
            if let Out::Gpu { region, shape, staging_off } = o {
                let len: usize = shape.iter().product();
                enc.copy_buffer_to_buffer(
                    &self.arena[region.root],
                    (4 * region.off) as u64,
                    &self.staging,
                    (4 * staging_off) as u64,
                    Some((4 * len) as u64),
                );
            }
        }
        self.gpu.queue.submit([enc.finish()]);
        let all = self.gpu.read_mapped(&self.staging, self.staging_len)?;
        Ok(self
            .outputs
            .iter()
            .map(|o| match o {
                Out::Gpu { shape, staging_off, .. } => {
                    let len: usize = shape.iter().product();
                    Tensor::F32 { shape: shape.clone(), data: all[*staging_off..staging_off + len].to_vec() }
                }
                Out::Host(t) => t.clone(),
            })
            .collect())
    }

    /// GPU time of every dispatch of one run (each in its own compute pass with timestamp
    /// writes, so the figures include a pass boundary each); an error where the adapter has no
    /// timestamp queries.
    pub fn profile(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<KernelTime>, GpuError> {
        if !self.gpu.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            return Err(GpuError::Shape(format!("adapter `{}` has no timestamp queries", self.gpu.adapter)));
        }
        let _guard = self.lock.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        self.upload_inputs(inputs)?;
        let period = f64::from(self.gpu.queue.get_timestamp_period());
        let mut times = Vec::with_capacity(self.steps.len());
        for chunk in self.steps.chunks(1024) {
            let count = 2 * chunk.len() as u32;
            let set = self.gpu.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("profile"),
                ty: wgpu::QueryType::Timestamp,
                count,
            });
            let size = 8 * u64::from(count);
            let resolve = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps"),
                size,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
            let read = self.gpu.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("timestamps read"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut enc = self.gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
            for (i, s) in chunk.iter().enumerate() {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: None,
                    timestamp_writes: Some(wgpu::ComputePassTimestampWrites {
                        query_set: &set,
                        beginning_of_pass_write_index: Some(2 * i as u32),
                        end_of_pass_write_index: Some(2 * i as u32 + 1),
                    }),
                });
                self.record(&mut pass, s)?;
            }
            enc.resolve_query_set(&set, 0..count, &resolve, 0);
            enc.copy_buffer_to_buffer(&resolve, 0, &read, 0, Some(size));
            self.gpu.queue.submit([enc.finish()]);
            let words = self.gpu.read_mapped_u64(&read, count as usize)?;
            for (s, t) in chunk.iter().zip(words.chunks_exact(2)) {
                times.push(KernelTime {
                    node: s.label.clone(),
                    kernel: s.kind.name(),
                    ns: t[1].saturating_sub(t[0]) as f64 * period,
                });
            }
        }
        Ok(times)
    }
}

/// The WGSL executor behind the inference crate's common interface.
impl dynaflow_infer::Executor for GpuModel {
    fn run(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, dynaflow_infer::Error> {
        GpuModel::run(self, inputs).map_err(|e| dynaflow_infer::Error::Backend(e.to_string()))
    }
}
