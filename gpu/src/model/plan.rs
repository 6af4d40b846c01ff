//! Planning a model for the GPU at load time: fusion on the ONNX graph, lowering of each
//! node to a kernel (or host-side shape arithmetic), placement of every value in one arena
//! (Concat free, Reshape an alias), and the dispatch list with its bind groups. The steps are
//! described in the parent module; `GpuModel` drives them and runs the result.
//!
//! Why one file of this size: `lower` is one `match` over every op the GPU runs, each arm
//! that op's whole lowering (shape checks, parameter words, kernel choice); split across
//! files, the table of what the GPU takes would be too.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use dynaflow_infer::onnx::{Model, Node, Op};
use dynaflow_infer::reference::{conv_pads, conv_transpose_geometry, pool_plan, resize_geometry, slice_plan};
use dynaflow_infer::tensor::{Tensor, norm_axis, reshape_shape, strides};

use crate::kernels::Kind;
use crate::{Activation, ConvShape, GpuError};

/// `v` widened to 4 entries on the left with `fill` (callers check the rank is at most 4).
pub(super) fn left4(v: &[usize], fill: usize) -> Vec<usize> {
    let mut o = vec![fill; 4usize.saturating_sub(v.len())];
    o.extend(v);
    o
}

pub(super) fn u32s(v: &[usize]) -> Result<Vec<u32>, GpuError> {
    v.iter().map(|&x| u32::try_from(x).map_err(|_| GpuError::Shape("dimension over u32".into()))).collect()
}

/// A value while planning.
pub(super) enum PVal {
    /// A float tensor that will live on the GPU (its shape).
    Gpu(Vec<usize>),
    /// A host tensor (weights, shapes, indices).
    Host(Tensor),
}

/// How many invocations a kernel needs.
#[derive(Clone, Copy, Debug)]
pub(super) enum Grid {
    /// One invocation per element, workgroups of 64.
    Flat(usize),
    /// Implicit GEMM: tiles of `tile` (pixels, channels), one layer of tiles per batch item.
    Gemm { pixels: usize, channels: usize, batch: usize, tile: [usize; 2] },
}

impl Grid {
    pub(super) fn groups(self) -> Result<[u32; 3], GpuError> {
        let cap = |v: usize| {
            u32::try_from(v).ok().filter(|&v| v <= 65_535).ok_or_else(|| GpuError::Shape("dispatch too large".into()))
        };
        match self {
            Grid::Flat(n) => {
                let groups = n.div_ceil(64).max(1);
                let x = groups.min(65_535);
                Ok([cap(x)?, cap(groups.div_ceil(x))?, 1])
            }
            Grid::Gemm { pixels, channels, batch, tile } => {
                Ok([cap(pixels.div_ceil(tile[0]).max(1))?, cap(channels.div_ceil(tile[1]).max(1))?, cap(batch.max(1))?])
            }
        }
    }
}

/// A float node after lowering.
pub(super) enum Lowered {
    /// A kernel.
    Kernel {
        kind: Kind,
        /// GPU inputs, in binding order.
        inputs: Vec<String>,
        weights: Vec<Arc<wgpu::Buffer>>,
        words: Vec<u32>,
        grid: Grid,
    },
    /// The input under another shape (Reshape).
    Alias { input: String },
    /// A concatenation along `axis`.
    Concat { parts: Vec<(String, Vec<usize>)>, axis: usize },
}

/// One lowered node with its output.
pub(super) struct Planned {
    pub(super) label: String,
    pub(super) out: String,
    pub(super) shape: Vec<usize>,
    pub(super) what: Lowered,
}

/// Where a value lives: arena buffer and element offset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Region {
    pub(super) root: usize,
    pub(super) off: usize,
}

/// One recorded dispatch.
pub(super) struct Step {
    pub(super) label: String,
    pub(super) kind: Kind,
    pub(super) bind: wgpu::BindGroup,
    pub(super) groups: [u32; 3],
}

/// A graph output: read back from the GPU, or a host constant.
pub(super) enum Out {
    Gpu { region: Region, shape: Vec<usize>, staging_off: usize },
    Host(Tensor),
}

/// Fuse activations into convolutions: the node list with fused nodes removed, each node's
/// activation, and how many were fused.
pub(super) fn fuse(model: &Model) -> (Vec<Node>, Vec<Activation>, usize) {
    let mut consumers: HashMap<&str, Vec<usize>> = HashMap::new();
    for (i, n) in model.nodes.iter().enumerate() {
        for x in n.inputs.iter().filter(|x| !x.is_empty()) {
            consumers.entry(x.as_str()).or_default().push(i);
        }
    }
    let graph_out: HashSet<&str> = model.outputs.iter().map(|o| o.name.as_str()).collect();
    let private = |name: &str| !graph_out.contains(name);
    let readers = |name: &str| consumers.get(name).cloned().unwrap_or_default();
    let mut nodes = model.nodes.clone();
    let mut acts = vec![Activation::Identity; nodes.len()];
    let mut dropped = vec![false; nodes.len()];
    let mut fused = 0;
    for i in 0..nodes.len() {
        if nodes[i].op != Op::Conv || nodes[i].outputs.len() != 1 || !private(&nodes[i].outputs[0]) {
            continue;
        }
        let y = nodes[i].outputs[0].clone();
        let r = readers(&y);
        let op = |j: usize| model.nodes[j].op.name();
        let single = |j: usize| model.nodes[j].outputs.len() == 1 && !dropped[j];
        let (act, gone): (Activation, Vec<usize>) = match r.as_slice() {
            [j] if single(*j) && op(*j) == "Relu" => (Activation::Relu, vec![*j]),
            [j] if single(*j) && op(*j) == "Sigmoid" => (Activation::Sigmoid, vec![*j]),
            [a, b] => {
                let (s, m) = if op(*a) == "Sigmoid" { (*a, *b) } else { (*b, *a) };
                let s_out = model.nodes[s].outputs.first().map(String::as_str).unwrap_or_default();
                let mut mul_in: Vec<&str> = model.nodes[m].inputs.iter().map(String::as_str).collect();
                mul_in.sort_unstable();
                let mut want = vec![y.as_str(), s_out];
                want.sort_unstable();
                if op(s) == "Sigmoid"
                    && op(m) == "Mul"
                    && single(s)
                    && single(m)
                    && private(s_out)
                    && readers(s_out) == [m]
                    && mul_in == want
                {
                    (Activation::Silu, vec![s, m])
                } else {
                    continue;
                }
            }
            _ => continue,
        };
        let last = *gone.last().unwrap_or(&i);
        nodes[i].outputs[0] = model.nodes[last].outputs[0].clone();
        acts[i] = act;
        for g in gone {
            dropped[g] = true;
        }
        fused += 1;
    }
    let keep: Vec<usize> = (0..nodes.len()).filter(|&i| !dropped[i]).collect();
    let acts = keep.iter().map(|&i| acts[i]).collect();
    let nodes = keep.into_iter().map(|i| nodes[i].clone()).collect();
    (nodes, acts, fused)
}

/// Regions of every GPU value, the arena sizes (floats), given values that must own their
/// buffer (`forbidden`).
pub(super) fn place(
    plan: &[Planned],
    inputs: &[(String, Vec<usize>)],
    forbidden: &HashSet<String>,
) -> (HashMap<String, Region>, Vec<usize>) {
    let mut at: HashMap<String, Region> = HashMap::new();
    let mut roots: Vec<usize> = Vec::new();
    let new_root = |roots: &mut Vec<usize>, len: usize| {
        roots.push(len.max(1));
        Region { root: roots.len() - 1, off: 0 }
    };
    for (name, shape) in inputs {
        let r = new_root(&mut roots, shape.iter().product());
        at.insert(name.clone(), r);
    }
    let produced: HashSet<&str> = plan.iter().map(|p| p.out.as_str()).collect();
    let movable =
        |at: &HashMap<String, Region>, v: &str| produced.contains(v) && !at.contains_key(v) && !forbidden.contains(v);
    for p in plan.iter().rev() {
        match &p.what {
            Lowered::Concat { parts, axis } if p.shape[..*axis].iter().product::<usize>() == 1 => {
                let r = match at.get(&p.out) {
                    Some(r) => *r,
                    None => {
                        let r = new_root(&mut roots, p.shape.iter().product());
                        at.insert(p.out.clone(), r);
                        r
                    }
                };
                let mut off = r.off;
                for (name, shape) in parts {
                    if movable(&at, name) {
                        at.insert(name.clone(), Region { root: r.root, off });
                    }
                    off += shape.iter().product::<usize>();
                }
            }
            Lowered::Alias { input } => {
                if let Some(r) = at.get(&p.out).copied()
                    && movable(&at, input)
                {
                    at.insert(input.clone(), r);
                }
            }
            _ => {}
        }
    }
    for p in plan {
        if at.contains_key(&p.out) {
            continue;
        }
        let r = match &p.what {
            Lowered::Alias { input } => at.get(input).copied(),
            _ => None,
        };
        let r = r.unwrap_or_else(|| new_root(&mut roots, p.shape.iter().product()));
        at.insert(p.out.clone(), r);
    }
    (at, roots)
}

/// A dispatch before binding: kind, read values (region), written region, words, grid.
pub(super) struct Dispatch {
    pub(super) label: String,
    pub(super) kind: Kind,
    pub(super) reads: Vec<Region>,
    pub(super) weights: Vec<Arc<wgpu::Buffer>>,
    pub(super) write: Region,
    pub(super) words: Vec<u32>,
    pub(super) grid: Grid,
    /// The value whose placement to give up if this dispatch reads the buffer it writes.
    pub(super) owner: String,
}

/// A `copy_block` dispatch for node `p`: `outer` blocks of `inner_src` values from `src` into
/// `write`, blocks `inner_dst` apart, at `offset` within each.
pub(super) fn copy(
    p: &Planned,
    src: Region,
    write: Region,
    [outer, inner_src, inner_dst, offset]: [usize; 4],
) -> Result<Dispatch, GpuError> {
    Ok(Dispatch {
        label: p.label.clone(),
        kind: Kind::CopyBlock,
        reads: vec![src],
        weights: Vec::new(),
        write,
        words: u32s(&[outer, inner_src, inner_dst, offset])?,
        grid: Grid::Flat(outer * inner_src),
        owner: p.out.clone(),
    })
}

/// The dispatches of a placed plan, and the concat statistics (in place, copied).
pub(super) fn dispatches(
    plan: &[Planned],
    at: &HashMap<String, Region>,
) -> Result<(Vec<Dispatch>, usize, usize), GpuError> {
    let get = |v: &str| at.get(v).copied().ok_or_else(|| GpuError::Shape(format!("value `{v}` has no region")));
    let mut out = Vec::new();
    let (mut in_place, mut copied) = (0, 0);
    for p in plan {
        let write = get(&p.out)?;
        match &p.what {
            Lowered::Kernel { kind, inputs, weights, words, grid } => out.push(Dispatch {
                label: p.label.clone(),
                kind: *kind,
                reads: inputs.iter().map(|i| get(i)).collect::<Result<_, _>>()?,
                weights: weights.clone(),
                write,
                words: words.clone(),
                grid: *grid,
                owner: p.out.clone(),
            }),
            Lowered::Alias { input } => {
                let src = get(input)?;
                if src != write {
                    let len = p.shape.iter().product();
                    out.push(copy(p, src, write, [1, len, len, 0])?);
                }
            }
            Lowered::Concat { parts, axis } => {
                let outer: usize = p.shape[..*axis].iter().product();
                let inner_dst: usize = p.shape[*axis..].iter().product();
                let mut offset = 0;
                for (name, shape) in parts {
                    let inner_src: usize = shape[*axis..].iter().product();
                    let src = get(name)?;
                    if outer == 1 && src == (Region { root: write.root, off: write.off + offset }) {
                        in_place += 1;
                    } else {
                        copied += 1;
                        out.push(copy(p, src, write, [outer, inner_src, inner_dst, offset])?);
                    }
                    offset += inner_src;
                }
            }
        }
    }
    Ok((out, in_place, copied))
}

/// Uploads a weight once by name: `(name, length, values)`; without values the model's
/// initializer of that name, or zeros of that length (a missing bias).
pub(super) type WeightUpload<'a> = dyn FnMut(&str, usize, Option<&[f32]>) -> Arc<wgpu::Buffer> + 'a;

/// The lowering of one float node: what it becomes and its output shape.
pub(super) fn lower(
    n: &Node,
    act: Activation,
    args: &[Option<(&str, &PVal)>],
    weight: &mut WeightUpload<'_>,
) -> Result<(Lowered, Vec<usize>), GpuError> {
    let gpu_arg = |i: usize| -> Result<(String, Vec<usize>), GpuError> {
        match args.get(i).copied().flatten() {
            Some((name, PVal::Gpu(shape))) => Ok((name.to_string(), shape.clone())),
            _ => Err(GpuError::Shape(format!("input {i} is not a float tensor on the GPU"))),
        }
    };
    let host = |i: usize| match args.get(i).copied().flatten() {
        Some((_, PVal::Host(t))) => Some(t),
        _ => None,
    };
    let ints = |i: usize| -> Option<Vec<i64>> {
        match host(i)? {
            Tensor::I64 { data, .. } => Some(data.clone()),
            Tensor::F32 { data, .. } => Some(data.iter().map(|&v| v as i64).collect()),
        }
    };
    let attr = |k: &str, d: Vec<i64>| n.ints(k).map_or(d, <[i64]>::to_vec);
    let kernel = |kind, inputs: Vec<String>, words: Vec<u32>, len: usize| Lowered::Kernel {
        kind,
        inputs,
        weights: Vec::new(),
        words,
        grid: Grid::Flat(len),
    };
    let gather = |x: String, out_shape: Vec<usize>, src_strides: &[usize], base: usize| {
        let (d, s) = (left4(&out_shape, 1), left4(src_strides, 0));
        let len: usize = out_shape.iter().product();
        let words = u32s(&[d[0], d[1], d[2], d[3], s[0], s[1], s[2], s[3], base, len, 0, 0])?;
        Ok::<_, GpuError>((kernel(Kind::Gather, vec![x], words, len), out_shape))
    };
    match &n.op {
        Op::Conv => {
            let (x, xs) = gpu_arg(0)?;
            let wname = n.inputs.get(1).cloned().unwrap_or_default();
            let ws = match host(1) {
                Some(t) if matches!(t, Tensor::F32 { .. }) => t.shape().to_vec(),
                _ => return Err(GpuError::Shape("Conv weights must be float initializers".into())),
            };
            if xs.len() != 4 || ws.len() != 4 {
                return Err(GpuError::Shape(format!("Conv on {xs:?} with weights {ws:?}")));
            }
            if attr("pads", vec![0; 4]).iter().any(|&v| v < 0) {
                return Err(GpuError::Shape("negative Conv pads".into()));
            }
            let st = attr("strides", vec![1, 1]);
            let dl = attr("dilations", vec![1, 1]);
            let nonneg = |v: &[i64]| v.iter().map(|&x| usize::try_from(x).ok()).collect::<Option<Vec<usize>>>();
            let (Some(st), Some(dl)) = (nonneg(&st), nonneg(&dl)) else {
                return Err(GpuError::Shape("negative Conv attribute".into()));
            };
            if st.len() != 2 || dl.len() != 2 {
                return Err(GpuError::Shape("Conv attributes of the wrong length".into()));
            }
            let p = conv_pads(n, [xs[2], xs[3]], [ws[2], ws[3]], [st[0], st[1]], [dl[0], dl[1]])
                .map_err(|e| GpuError::Shape(e.to_string()))?;
            let shape = ConvShape {
                input: [xs[0], xs[1], xs[2], xs[3]],
                kernel: [ws[0], ws[2], ws[3]],
                stride: [st[0].max(1), st[1].max(1)],
                pads: [p[0], p[1], p[2], p[3]],
                dilation: [dl[0].max(1), dl[1].max(1)],
                group: n.int("group", 1).max(1) as usize,
            };
            let (oh, ow) = shape.output()?;
            if ws[1] * shape.group != xs[1] {
                return Err(GpuError::Shape(format!("Conv weights {ws:?} do not fit input {xs:?}")));
            }
            // Weights and bias as the host holds them (an initializer or a `Constant` node's
            // value); no bias is zeros.
            let w = weight(&wname, 0, host(1).map(Tensor::floats).as_deref());
            let bias_name =
                n.inputs.get(2).filter(|b| !b.is_empty()).cloned().unwrap_or_else(|| format!("{wname}#zero-bias"));
            let b = weight(&bias_name, ws[0], host(2).map(Tensor::floats).as_deref());
            let out = vec![xs[0], ws[0], oh, ow];
            // Both convolution kernels share these sixteen words; the direct one adds four.
            let k = xs[1] * ws[2] * ws[3];
            let (sd, dd) = (shape.stride, shape.dilation);
            let mut words = u32s(&[
                xs[1],
                xs[2],
                xs[3],
                ws[0],
                oh,
                ow,
                ws[2],
                ws[3],
                sd[0],
                sd[1],
                p[0],
                p[1],
                dd[0],
                dd[1],
                act as usize,
                k,
            ])?;
            let (kind, grid) = if shape.group == 1 {
                // Few output channels (a stem): narrower, wider tiles instead of wasting most of
                // a 64-channel one.
                let (kind, tile) = match ws[0] {
                    0..=16 => (Kind::ConvGemm16, [256, 16]),
                    17..=32 => (Kind::ConvGemm32, [128, 32]),
                    _ => (Kind::ConvGemm, [64, 64]),
                };
                (kind, Grid::Gemm { pixels: oh * ow, channels: ws[0], batch: xs[0], tile })
            } else {
                words.extend(u32s(&[xs[0], shape.group, 0, 0])?);
                (Kind::ConvDirect, Grid::Flat(xs[0] * ws[0] * oh * ow))
            };
            Ok((Lowered::Kernel { kind, inputs: vec![x], weights: vec![w, b], words, grid }, out))
        }
        Op::Sigmoid | Op::Relu | Op::HardSigmoid | Op::HardSwish | Op::Clip => {
            let (x, xs) = gpu_arg(0)?;
            let len: usize = xs.iter().product();
            let bound = |i: usize, default: f32| -> Result<f32, GpuError> {
                match args.get(i).copied().flatten() {
                    None => Ok(default),
                    Some(_) => host(i)
                        .and_then(|t| t.floats().first().copied())
                        .ok_or_else(|| GpuError::Shape("Clip bounds must be constants on the GPU".into())),
                }
            };
            let (op, a, b) = match n.op {
                Op::Sigmoid => (2, 0.0, 0.0),
                Op::Relu => (3, 0.0, 0.0),
                Op::HardSigmoid => (4, n.float("alpha", 0.2), n.float("beta", 0.5)),
                Op::HardSwish => (5, 0.0, 0.0),
                _ => (6, bound(1, f32::NEG_INFINITY)?, bound(2, f32::INFINITY)?),
            };
            Ok((kernel(Kind::Unary, vec![x], vec![u32s(&[len])?[0], op, a.to_bits(), b.to_bits()], len), xs))
        }
        Op::Add | Op::Mul | Op::Sub | Op::Div => {
            let (a, sa) = gpu_arg(0)?;
            let op = match n.op {
                Op::Add => 0,
                Op::Mul => 1,
                Op::Sub => 2,
                _ => 3,
            };
            let len: usize = sa.iter().product();
            // `b`: a GPU value, or a constant uploaded once as a weight.
            let (inputs, weights, sb) = match (gpu_arg(1), host(1)) {
                (Ok((b, sb)), _) => (vec![a, b], Vec::new(), sb),
                (Err(_), Some(t)) => {
                    let name = n.inputs.get(1).cloned().unwrap_or_default();
                    let data = t.floats();
                    (vec![a], vec![weight(&format!("{name}#operand"), data.len(), Some(&data))], t.shape().to_vec())
                }
                (Err(e), None) => return Err(e),
            };
            let count: usize = sb.iter().product();
            let per_channel = sa.len() == 4 && sb.len() == 4 && sb == [1, sa[1], 1, 1] && sa[0] == 1;
            let (bmode, plane, channels) = if sb == sa {
                (0, 0, 0)
            } else if count == 1 && sb.len() <= sa.len() {
                (2, 0, 0)
            } else if per_channel {
                (1, sa[2] * sa[3], sa[1])
            } else {
                return Err(GpuError::Shape(format!(
                    "{} of {sa:?} and {sb:?}: only equal shapes, one value or one per channel broadcast on the GPU",
                    n.op
                )));
            };
            let words = u32s(&[len, op, bmode, plane, channels, 0, 0, 0])?;
            Ok((Lowered::Kernel { kind: Kind::Binary, inputs, weights, words, grid: Grid::Flat(len) }, sa))
        }
        Op::GlobalAveragePool => {
            let (x, xs) = gpu_arg(0)?;
            if xs.len() != 4 || xs[2] * xs[3] == 0 {
                return Err(GpuError::Shape(format!("GlobalAveragePool of {xs:?}")));
            }
            let planes = xs[0] * xs[1];
            // The pooling kernel with one window over the whole plane (average, no padding).
            let words = u32s(&[planes, xs[2], xs[3], 1, 1, xs[2], xs[3], 1, 1, 0, 0, 1])?;
            Ok((kernel(Kind::Pool, vec![x], words, planes), vec![xs[0], xs[1], 1, 1]))
        }
        Op::ConvTranspose => {
            let (x, xs) = gpu_arg(0)?;
            let wname = n.inputs.get(1).cloned().unwrap_or_default();
            let ws = match host(1) {
                Some(t) if matches!(t, Tensor::F32 { .. }) => t.shape().to_vec(),
                _ => return Err(GpuError::Shape("ConvTranspose weights must be float initializers".into())),
            };
            if xs.len() != 4 || ws.len() != 4 || ws[0] != xs[1] {
                return Err(GpuError::Shape(format!("ConvTranspose of {xs:?} with weights {ws:?}")));
            }
            // The shape and padding as the reference executor computes them.
            let (oh, ow, pt, pl) =
                conv_transpose_geometry(n, [xs[0], xs[1], xs[2], xs[3]], [ws[0], ws[1], ws[2], ws[3]])
                    .map_err(|e| GpuError::Shape(e.to_string()))?;
            let group = n.int("group", 1).max(1) as usize;
            let m = ws[1] * group;
            let st = attr("strides", vec![1, 1]);
            let dl = attr("dilations", vec![1, 1]);
            let at = |v: &[i64], i: usize| v.get(i).copied().unwrap_or(1).max(1) as usize;
            let w = weight(&wname, 0, host(1).map(Tensor::floats).as_deref());
            let bias_name =
                n.inputs.get(2).filter(|b| !b.is_empty()).cloned().unwrap_or_else(|| format!("{wname}#zero-bias"));
            let b = weight(&bias_name, m, host(2).map(Tensor::floats).as_deref());
            let words = u32s(&[
                xs[1],
                xs[2],
                xs[3],
                m,
                oh,
                ow,
                ws[2],
                ws[3],
                at(&st, 0),
                at(&st, 1),
                pt,
                pl,
                at(&dl, 0),
                at(&dl, 1),
                xs[0],
                group,
            ])?;
            let len = xs[0] * m * oh * ow;
            Ok((
                Lowered::Kernel {
                    kind: Kind::ConvTranspose,
                    inputs: vec![x],
                    weights: vec![w, b],
                    words,
                    grid: Grid::Flat(len),
                },
                vec![xs[0], m, oh, ow],
            ))
        }
        Op::Concat => {
            let parts: Vec<(String, Vec<usize>)> = (0..args.len()).map(gpu_arg).collect::<Result<_, _>>()?;
            let first = &parts.first().ok_or_else(|| GpuError::Shape("Concat of nothing".into()))?.1;
            let axis = norm_axis(n.int("axis", 0), first.len()).map_err(|e| GpuError::Shape(e.to_string()))?;
            let mut shape = first.clone();
            if parts.iter().any(|(_, s)| {
                s.len() != first.len() || s.iter().zip(first.iter()).enumerate().any(|(d, (a, b))| d != axis && a != b)
            }) {
                return Err(GpuError::Shape("Concat of mismatched shapes".into()));
            }
            shape[axis] = parts.iter().map(|p| p.1[axis]).sum();
            Ok((Lowered::Concat { parts, axis }, shape))
        }
        Op::Slice | Op::Transpose => {
            let (x, xs) = gpu_arg(0)?;
            if xs.len() > 4 {
                return Err(GpuError::Shape(format!("{} of rank {} (4 at most on the GPU)", n.op, xs.len())));
            }
            let si = strides(&xs);
            if n.op == Op::Transpose {
                let perm: Vec<usize> = n
                    .ints("perm")
                    .map_or_else(|| (0..xs.len()).rev().collect(), |p| p.iter().map(|&v| v as usize).collect());
                if perm.len() != xs.len() || perm.iter().any(|&p| p >= xs.len()) {
                    return Err(GpuError::Shape(format!("Transpose perm {perm:?} of rank {}", xs.len())));
                }
                let shape = perm.iter().map(|&p| xs[p]).collect();
                let st: Vec<usize> = perm.iter().map(|&p| si[p]).collect();
                return gather(x, shape, &st, 0);
            }
            let starts = ints(1).ok_or_else(|| GpuError::Shape("Slice without constant starts".into()))?;
            let ends = ints(2).ok_or_else(|| GpuError::Shape("Slice without constant ends".into()))?;
            let (axes, steps) = (ints(3), ints(4));
            let (lo, step, shape) = slice_plan(&xs, &starts, &ends, axes.as_deref(), steps.as_deref())
                .map_err(|e| GpuError::Shape(e.to_string()))?;
            let base = lo.iter().zip(&si).map(|(l, s)| l * s).sum();
            let st: Vec<usize> = si.iter().zip(&step).map(|(s, k)| s * k).collect();
            gather(x, shape, &st, base)
        }
        Op::MaxPool | Op::AveragePool => {
            let (x, xs) = gpu_arg(0)?;
            if attr("pads", vec![]).iter().any(|&v| v < 0) {
                return Err(GpuError::Shape("negative pooling attribute".into()));
            }
            let plan = pool_plan(n, &xs).map_err(|e| GpuError::Shape(e.to_string()))?;
            let ([kh, kw], [sh, sw], [pt, pl, _, _], [oh, ow]) = (plan.kernel, plan.strides, plan.pads, plan.out);
            let (h, w) = (xs[2], xs[3]);
            let planes = xs[0] * xs[1];
            let mode = match &n.op {
                Op::MaxPool => 0,
                _ if n.int("count_include_pad", 0) != 0 => 2,
                _ => 1,
            };
            let words = u32s(&[planes, h, w, oh, ow, kh, kw, sh, sw, pt, pl, mode])?;
            Ok((kernel(Kind::Pool, vec![x], words, planes * oh * ow), vec![xs[0], xs[1], oh, ow]))
        }
        Op::Resize => {
            let (x, xs) = gpu_arg(0)?;
            let scales: Option<Vec<f32>> = host(2).map(Tensor::floats).filter(|v| v.len() == 4);
            let mode = (
                n.string("mode", "nearest"),
                n.string("coordinate_transformation_mode", "half_pixel"),
                n.string("nearest_mode", ""),
            );
            let kind = match (mode.0.as_str(), mode.1.as_str(), mode.2.as_str()) {
                ("nearest", "asymmetric", "floor") => 0,
                ("linear", "half_pixel", _) => 1,
                ("linear", "align_corners", _) => 2,
                ("linear", "asymmetric", _) => 3,
                ("linear", "pytorch_half_pixel", _) => 4,
                _ => {
                    return Err(GpuError::Shape(format!(
                        "Resize {mode:?} is not on the GPU (nearest asymmetric floor, or linear)"
                    )));
                }
            };
            let sizes = ints(3);
            let (oh, ow, fy, fx) = resize_geometry(&xs, scales.as_deref(), sizes.as_deref())
                .map_err(|e| GpuError::Shape(e.to_string()))?;
            let planes = xs[0] * xs[1];
            let mut words = u32s(&[planes, xs[2], xs[3], oh, ow])?;
            words.extend([fy.to_bits(), fx.to_bits(), kind]);
            Ok((kernel(Kind::Resize, vec![x], words, planes * oh * ow), vec![xs[0], xs[1], oh, ow]))
        }
        Op::Reshape => {
            let (x, xs) = gpu_arg(0)?;
            let spec = ints(1).ok_or_else(|| GpuError::Shape("Reshape needs a constant shape".into()))?;
            let shape = reshape_shape(&xs, &spec).map_err(|e| GpuError::Shape(e.to_string()))?;
            Ok((Lowered::Alias { input: x }, shape))
        }
        Op::Pad => {
            let (x, xs) = gpu_arg(0)?;
            let pads = n.ints("pads").map(<[i64]>::to_vec).or_else(|| ints(1)).unwrap_or_default();
            let value = match host(2) {
                Some(t) => t.floats().first().copied().unwrap_or(0.0),
                None => n.float("value", 0.0),
            };
            let r = xs.len();
            if r > 4 || pads.len() != 2 * r || pads.iter().any(|&p| p < 0) || n.string("mode", "constant") != "constant"
            {
                return Err(GpuError::Shape(format!(
                    "Pad {pads:?} of rank {r}: constant, non-negative, rank <= 4 only"
                )));
            }
            let out_shape: Vec<usize> = (0..r).map(|d| xs[d] + pads[d] as usize + pads[d + r] as usize).collect();
            let (d, i) = (left4(&out_shape, 1), left4(&xs, 1));
            let b = left4(&pads[..r].iter().map(|&p| p as usize).collect::<Vec<_>>(), 0);
            let len: usize = out_shape.iter().product();
            let mut words = u32s(&[d[0], d[1], d[2], d[3], i[0], i[1], i[2], i[3], b[0], b[1], b[2], b[3], len])?;
            words.extend([value.to_bits(), 0, 0]);
            Ok((kernel(Kind::Pad, vec![x], words, len), out_shape))
        }
        Op::Softmax => {
            let (x, xs) = gpu_arg(0)?;
            let axis = norm_axis(n.int("axis", -1), xs.len()).map_err(|e| GpuError::Shape(e.to_string()))?;
            let step: usize = xs[axis + 1..].iter().product();
            let total: usize = xs.iter().product();
            let rows = total / xs[axis].max(1);
            Ok((kernel(Kind::Softmax, vec![x], u32s(&[rows, xs[axis], step, 0])?, rows), xs))
        }
        Op::Gather => {
            // A float tensor indexed by one constant index (ShuffleNet's channel split): a
            // strided gather that drops the axis.
            let (x, xs) = gpu_arg(0)?;
            let index = host(1).filter(|t| t.shape().is_empty() || t.shape() == [1]);
            let Some(index) = index else {
                return Err(GpuError::Shape("Gather on the GPU takes one constant index".into()));
            };
            let keep_axis = index.shape() == [1];
            let axis = norm_axis(n.int("axis", 0), xs.len()).map_err(|e| GpuError::Shape(e.to_string()))?;
            let i = ints(1).and_then(|v| v.first().copied()).unwrap_or(0);
            let i = if i < 0 { i + xs[axis] as i64 } else { i };
            if !(0..xs[axis] as i64).contains(&i) {
                return Err(GpuError::Shape(format!("Gather index {i} on axis {axis} of {xs:?}")));
            }
            let si = strides(&xs);
            let keep: Vec<usize> = (0..xs.len()).filter(|&d| d != axis).collect();
            let mut out_shape: Vec<usize> = keep.iter().map(|&d| xs[d]).collect();
            let mut st: Vec<usize> = keep.iter().map(|&d| si[d]).collect();
            if keep_axis {
                out_shape.insert(axis, 1);
                st.insert(axis, 0);
            }
            if out_shape.len() > 4 {
                return Err(GpuError::Shape(format!(
                    "Gather output of rank {} (4 at most on the GPU)",
                    out_shape.len()
                )));
            }
            gather(x, out_shape, &st, i as usize * si[axis])
        }
        other => Err(GpuError::Shape(format!("op `{other}` is not on the GPU yet"))),
    }
}
