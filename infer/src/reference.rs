//! The reference executor: every supported ONNX op as a plain, obviously-correct loop nest
//! over `f32` (shape arithmetic in `i64`), run node by node in file order. It defines what
//! the model computes here (checked against onnxruntime in CI) and is what the GPU kernels
//! are tested against; speed is not its job.

use std::collections::HashMap;

use crate::onnx::{Attribute, Model, Node, Op};
pub use crate::tensor::Tensor;
use crate::tensor::{norm_axis, reshape_shape, strides};

/// Why a model cannot run.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum RunError {
    /// An op the executor does not have.
    #[error("unsupported ONNX op `{op}` at node {node}")]
    UnsupportedOp {
        /// Op type.
        op: String,
        /// Node label.
        node: String,
    },
    /// Shapes or values the op cannot take.
    #[error("node {node}: {message}")]
    Invalid {
        /// Node label.
        node: String,
        /// What is wrong.
        message: String,
    },
    /// A backend refused the model or a run (its message).
    #[error("{0}")]
    Backend(String),
    /// An input the model needs was not given.
    #[error("input `{0}` not given")]
    MissingInput(String),
}

/// Ops this executor runs (the union of YOLOX-nano's and FastestDet's): every [`Op`] but
/// `Other`.
pub const SUPPORTED: &[&str] = Op::NAMES;

/// Check every node's op before running anything.
pub fn check_ops(model: &Model) -> Result<(), RunError> {
    for n in &model.nodes {
        if matches!(n.op, Op::Other(_)) || !(n.domain.is_empty() || n.domain == "ai.onnx") {
            return Err(RunError::UnsupportedOp { op: n.op.name().to_owned(), node: n.label() });
        }
    }
    Ok(())
}

/// Run `model` on the named inputs; returns the graph outputs in order.
pub fn run(model: &Model, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, RunError> {
    check_ops(model)?;
    let mut env: HashMap<String, Tensor> = HashMap::new();
    for (k, t) in &model.initializers {
        env.insert(k.clone(), Tensor::from_data(t));
    }
    for (k, t) in inputs {
        env.insert((*k).to_string(), t.clone());
    }
    for n in &model.nodes {
        let err = |m: String| RunError::Invalid { node: n.label(), message: m };
        let args: Vec<Option<&Tensor>> =
            n.inputs.iter().map(|i| if i.is_empty() { None } else { env.get(i) }).collect();
        if n.inputs.iter().zip(&args).any(|(i, a)| !i.is_empty() && a.is_none()) {
            return Err(err("an input is not computed before this node".into()));
        }
        let out = eval(n, &args).map_err(err)?;
        for (name, t) in n.outputs.iter().zip(out) {
            env.insert(name.clone(), t);
        }
    }
    model
        .outputs
        .iter()
        .map(|o| {
            env.remove(&o.name)
                .ok_or_else(|| RunError::Invalid { node: o.name.clone(), message: "output never computed".into() })
        })
        .collect()
}

fn f32_arg<'a>(args: &[Option<&'a Tensor>], i: usize) -> Result<(&'a [usize], &'a [f32]), String> {
    match args.get(i).copied().flatten() {
        Some(Tensor::F32 { shape, data }) => Ok((shape, data)),
        Some(Tensor::I64 { .. }) => Err(format!("input {i} is an integer tensor, expected float")),
        None => Err(format!("input {i} is missing")),
    }
}

fn int_arg(args: &[Option<&Tensor>], i: usize) -> Option<Vec<i64>> {
    args.get(i).copied().flatten().map(Tensor::ints)
}

/// Broadcast two shapes (numpy rules).
fn broadcast(a: &[usize], b: &[usize]) -> Result<Vec<usize>, String> {
    let n = a.len().max(b.len());
    (0..n)
        .map(|i| {
            let x = if i + a.len() >= n { a[i + a.len() - n] } else { 1 };
            let y = if i + b.len() >= n { b[i + b.len() - n] } else { 1 };
            match (x, y) {
                (x, y) if x == y => Ok(x),
                (1, y) => Ok(y),
                (x, 1) => Ok(x),
                _ => Err(format!("shapes {a:?} and {b:?} do not broadcast")),
            }
        })
        .collect()
}

fn binary(args: &[Option<&Tensor>], f: impl Fn(f32, f32) -> f32) -> Result<Tensor, String> {
    let (sa, a) = f32_arg(args, 0)?;
    let (sb, b) = f32_arg(args, 1)?;
    let shape = broadcast(sa, sb)?;
    let st = strides(&shape);
    let index = |s: &[usize], flat: usize| {
        let off = shape.len() - s.len();
        let ss = strides(s);
        let mut idx = 0;
        for (d, &dim) in s.iter().enumerate() {
            let coord = (flat / st[d + off]) % shape[d + off];
            idx += if dim == 1 { 0 } else { coord * ss[d] };
        }
        idx
    };
    let n: usize = shape.iter().product();
    let data = if sa == sb {
        a.iter().zip(b).map(|(x, y)| f(*x, *y)).collect()
    } else {
        (0..n).map(|i| f(a[index(sa, i)], b[index(sb, i)])).collect()
    };
    Ok(Tensor::F32 { shape, data })
}

fn pads_of(n: &Node, k: usize) -> Vec<usize> {
    n.ints("pads").map_or(vec![0; 2 * k], |p| p.iter().map(|&v| v.max(0) as usize).collect())
}

/// One node on host tensors (also what a GPU executor uses for shape arithmetic).
pub fn eval_node(n: &Node, args: &[Option<&Tensor>]) -> Result<Vec<Tensor>, String> {
    eval(n, args)
}

fn eval(n: &Node, args: &[Option<&Tensor>]) -> Result<Vec<Tensor>, String> {
    let one = |t: Tensor| Ok(vec![t]);
    match &n.op {
        Op::Constant => match n.attributes.get("value") {
            Some(Attribute::Tensor(t)) => one(Tensor::from_data(t)),
            _ => Err("Constant without a tensor `value`".into()),
        },
        Op::Add => one(binary(args, |a, b| a + b)?),
        Op::Mul => one(binary(args, |a, b| a * b)?),
        Op::Relu => {
            let (s, x) = f32_arg(args, 0)?;
            one(Tensor::F32 { shape: s.to_vec(), data: x.iter().map(|v| v.max(0.0)).collect() })
        }
        Op::Sigmoid => {
            let (s, x) = f32_arg(args, 0)?;
            one(Tensor::F32 { shape: s.to_vec(), data: x.iter().map(|v| 1.0 / (1.0 + (-v).exp())).collect() })
        }
        Op::Conv => one(conv(n, args)?),
        Op::MaxPool | Op::AveragePool => one(pool(n, args)?),
        Op::Concat => one(concat(n, args)?),
        Op::Slice => one(slice(args)?),
        Op::Resize => one(resize(n, args)?),
        Op::Reshape => {
            let t = args.first().copied().flatten().ok_or("missing data")?;
            let spec = int_arg(args, 1).ok_or("missing shape")?;
            let shape = reshape_shape(t.shape(), &spec)?;
            one(match t {
                Tensor::F32 { data, .. } => Tensor::F32 { shape, data: data.clone() },
                Tensor::I64 { data, .. } => Tensor::I64 { shape, data: data.clone() },
            })
        }
        Op::Transpose => {
            let (s, x) = f32_arg(args, 0)?;
            let perm: Vec<usize> = n
                .ints("perm")
                .map_or_else(|| (0..s.len()).rev().collect(), |p| p.iter().map(|&v| v as usize).collect());
            if perm.len() != s.len() || perm.iter().any(|&p| p >= s.len()) {
                return Err(format!("perm {perm:?} does not fit shape {s:?}"));
            }
            let shape: Vec<usize> = perm.iter().map(|&p| s[p]).collect();
            let (si, so) = (strides(s), strides(&shape));
            let total = x.len();
            let mut data = vec![0.0; total];
            for (o, v) in data.iter_mut().enumerate() {
                let mut src = 0;
                for (d, &p) in perm.iter().enumerate() {
                    src += ((o / so[d]) % shape[d]) * si[p];
                }
                *v = x[src];
            }
            one(Tensor::F32 { shape, data })
        }
        Op::Softmax => {
            let (s, x) = f32_arg(args, 0)?;
            let axis = norm_axis(n.int("axis", -1), s.len())?;
            let st = strides(s);
            let (len, step) = (s[axis], st[axis]);
            let mut data = x.to_vec();
            for base in 0..x.len() {
                if (base / step) % len != 0 {
                    continue;
                }
                let m = (0..len).map(|k| x[base + k * step]).fold(f32::NEG_INFINITY, f32::max);
                let sum: f32 = (0..len).map(|k| (x[base + k * step] - m).exp()).sum();
                for k in 0..len {
                    data[base + k * step] = (x[base + k * step] - m).exp() / sum;
                }
            }
            one(Tensor::F32 { shape: s.to_vec(), data })
        }
        Op::Shape => {
            let t = args.first().copied().flatten().ok_or("missing data")?;
            let dims: Vec<i64> = t.shape().iter().map(|&d| d as i64).collect();
            one(Tensor::I64 { shape: vec![dims.len()], data: dims })
        }
        Op::Unsqueeze => {
            let t = args.first().copied().flatten().ok_or("missing data")?;
            let axes = n.ints("axes").map(<[i64]>::to_vec).or_else(|| int_arg(args, 1)).ok_or("no axes")?;
            let rank = t.shape().len() + axes.len();
            let mut axes: Vec<usize> = axes.iter().map(|&a| norm_axis(a, rank)).collect::<Result<_, _>>()?;
            axes.sort_unstable();
            let mut shape = t.shape().to_vec();
            for a in axes {
                shape.insert(a.min(shape.len()), 1);
            }
            one(match t {
                Tensor::F32 { data, .. } => Tensor::F32 { shape, data: data.clone() },
                Tensor::I64 { data, .. } => Tensor::I64 { shape, data: data.clone() },
            })
        }
        Op::Gather => one(gather(n, args)?),
        Op::Pad => one(pad(n, args)?),
        other => Err(format!("op {other} is not implemented")),
    }
}

fn conv(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (xs, x) = f32_arg(args, 0)?;
    let (ws, w) = f32_arg(args, 1)?;
    let bias = match args.get(2).copied().flatten() {
        Some(Tensor::F32 { data, .. }) => Some(data.as_slice()),
        _ => None,
    };
    if xs.len() != 4 || ws.len() != 4 {
        return Err(format!("Conv wants 4-D input and weights, got {xs:?} and {ws:?}"));
    }
    let (nb, c, h, wd) = (xs[0], xs[1], xs[2], xs[3]);
    let (m, cg, kh, kw) = (ws[0], ws[1], ws[2], ws[3]);
    let group = n.int("group", 1).max(1) as usize;
    if c != cg * group || m % group != 0 {
        return Err(format!("Conv: {c} input channels, weights {ws:?}, group {group}"));
    }
    let st = n.ints("strides").map_or(vec![1, 1], <[i64]>::to_vec);
    let dl = n.ints("dilations").map_or(vec![1, 1], <[i64]>::to_vec);
    let p = pads_of(n, 2);
    let (sh, sw, dh, dw) = (st[0].max(1) as usize, st[1].max(1) as usize, dl[0].max(1) as usize, dl[1].max(1) as usize);
    let oh = (h + p[0] + p[2]).checked_sub(dh * (kh - 1) + 1).ok_or("Conv kernel larger than input")? / sh + 1;
    let ow = (wd + p[1] + p[3]).checked_sub(dw * (kw - 1) + 1).ok_or("Conv kernel larger than input")? / sw + 1;
    let mg = m / group;
    let mut out = vec![0.0f32; nb * m * oh * ow];
    for b in 0..nb {
        for oc in 0..m {
            let g = oc / mg;
            let plane = &mut out[(b * m + oc) * oh * ow..(b * m + oc + 1) * oh * ow];
            plane.fill(bias.map_or(0.0, |bs| bs[oc]));
            for icg in 0..cg {
                let ic = g * cg + icg;
                let xin = &x[(b * c + ic) * h * wd..(b * c + ic + 1) * h * wd];
                for ky in 0..kh {
                    for kx in 0..kw {
                        let wv = w[((oc * cg + icg) * kh + ky) * kw + kx];
                        // Output columns whose input column is inside the image: no test in
                        // the inner loop (it vectorises at stride 1).
                        let off = (kx * dw) as isize - p[1] as isize;
                        let lo = if off >= 0 { 0 } else { ((-off) as usize).div_ceil(sw) };
                        let last = wd as isize - 1 - off;
                        if last < 0 {
                            continue;
                        }
                        let hi = ((last as usize) / sw + 1).min(ow);
                        if lo >= hi {
                            continue;
                        }
                        for oy in 0..oh {
                            let iy = (oy * sh + ky * dh) as isize - p[0] as isize;
                            if iy < 0 || iy >= h as isize {
                                continue;
                            }
                            let row = &xin[iy as usize * wd..(iy as usize + 1) * wd];
                            let orow = &mut plane[oy * ow + lo..oy * ow + hi];
                            let start = (lo * sw) as isize + off;
                            if sw == 1 {
                                let src = &row[start as usize..start as usize + orow.len()];
                                for (o, &v) in orow.iter_mut().zip(src) {
                                    *o += wv * v;
                                }
                            } else {
                                for (k, o) in orow.iter_mut().enumerate() {
                                    *o += wv * row[start as usize + k * sw];
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    Ok(Tensor::F32 { shape: vec![nb, m, oh, ow], data: out })
}

/// Geometry of a 2-D pooling node (MaxPool, AveragePool) on an NCHW input: what the reference
/// and the GPU executor both compute from the node's attributes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PoolPlan {
    /// Kernel height and width.
    pub kernel: [usize; 2],
    /// Strides (y, x).
    pub strides: [usize; 2],
    /// Pads top, left, bottom, right (negative ones count as 0).
    pub pads: [usize; 4],
    /// Output height and width.
    pub out: [usize; 2],
}

/// The [`PoolPlan`] of node `n` on an input of `shape`.
pub fn pool_plan(n: &Node, shape: &[usize]) -> Result<PoolPlan, String> {
    if shape.len() != 4 {
        return Err(format!("pooling wants 4-D input, got {shape:?}"));
    }
    if n.int("ceil_mode", 0) != 0 {
        return Err("ceil_mode pooling is not supported".into());
    }
    let k = n.ints("kernel_shape").ok_or("no kernel_shape")?.to_vec();
    let st = n.ints("strides").map_or(vec![1, 1], <[i64]>::to_vec);
    let p = pads_of(n, 2);
    if k.len() != 2 || st.len() != 2 || p.len() != 4 || k.iter().chain(&st).any(|&v| v < 0) {
        return Err(format!("pooling attributes kernel {k:?}, strides {st:?}, pads {p:?}"));
    }
    let (kh, kw, sh, sw) = (k[0] as usize, k[1] as usize, st[0].max(1) as usize, st[1].max(1) as usize);
    let oh = (shape[2] + p[0] + p[2]).checked_sub(kh).ok_or("pool kernel larger than input")? / sh + 1;
    let ow = (shape[3] + p[1] + p[3]).checked_sub(kw).ok_or("pool kernel larger than input")? / sw + 1;
    Ok(PoolPlan { kernel: [kh, kw], strides: [sh, sw], pads: [p[0], p[1], p[2], p[3]], out: [oh, ow] })
}

fn pool(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (xs, x) = f32_arg(args, 0)?;
    let PoolPlan { kernel: [kh, kw], strides: [sh, sw], pads: p, out: [oh, ow] } = pool_plan(n, xs)?;
    let max = n.op == Op::MaxPool;
    let count_pad = n.int("count_include_pad", 0) != 0;
    let (nb, c, h, w) = (xs[0], xs[1], xs[2], xs[3]);
    let mut out = vec![0.0f32; nb * c * oh * ow];
    for bc in 0..nb * c {
        let xin = &x[bc * h * w..(bc + 1) * h * w];
        for oy in 0..oh {
            for ox in 0..ow {
                let (mut acc, mut cnt) = (if max { f32::NEG_INFINITY } else { 0.0 }, 0usize);
                for ky in 0..kh {
                    for kx in 0..kw {
                        let iy = (oy * sh + ky) as isize - p[0] as isize;
                        let ix = (ox * sw + kx) as isize - p[1] as isize;
                        if iy >= 0 && ix >= 0 && iy < h as isize && ix < w as isize {
                            let v = xin[iy as usize * w + ix as usize];
                            acc = if max { acc.max(v) } else { acc + v };
                            cnt += 1;
                        }
                    }
                }
                let div = if count_pad { kh * kw } else { cnt.max(1) };
                out[(bc * oh + oy) * ow + ox] = if max { acc } else { acc / div as f32 };
            }
        }
    }
    Ok(Tensor::F32 { shape: vec![nb, c, oh, ow], data: out })
}

fn concat(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let parts: Vec<(&[usize], &[f32])> = (0..args.len()).map(|i| f32_arg(args, i)).collect::<Result<_, _>>()?;
    let first = parts.first().ok_or("Concat of nothing")?.0;
    let axis = norm_axis(n.int("axis", 0), first.len())?;
    let mut shape = first.to_vec();
    shape[axis] = 0;
    for (s, _) in &parts {
        if s.len() != first.len() || s.iter().enumerate().any(|(d, &v)| d != axis && v != first[d]) {
            return Err(format!("Concat of {first:?} and {s:?} on axis {axis}"));
        }
        shape[axis] += s[axis];
    }
    let outer: usize = first[..axis].iter().product();
    let mut data = Vec::with_capacity(shape.iter().product());
    for o in 0..outer {
        for (s, d) in &parts {
            let inner: usize = s[axis..].iter().product();
            data.extend_from_slice(&d[o * inner..(o + 1) * inner]);
        }
    }
    Ok(Tensor::F32 { shape, data })
}

/// An ONNX `Slice` of a tensor of shape `s` (opset 10+ inputs: `axes` and `steps` default to
/// all axes and 1): per dimension the first index and the step, and the output shape.
pub type SlicePlan = (Vec<usize>, Vec<usize>, Vec<usize>);

/// Plan a `Slice` (see [`SlicePlan`]); ends are clamped as ONNX does, steps must be positive.
pub fn slice_plan(
    s: &[usize],
    starts: &[i64],
    ends: &[i64],
    axes: Option<&[i64]>,
    steps: Option<&[i64]>,
) -> Result<SlicePlan, String> {
    let mut lo = vec![0usize; s.len()];
    let mut step = vec![1usize; s.len()];
    let mut shape = s.to_vec();
    for (k, &start) in starts.iter().enumerate() {
        let a = match axes {
            Some(ax) => *ax.get(k).ok_or("axes shorter than starts")?,
            None => k as i64,
        };
        let a = norm_axis(a, s.len())?;
        let (dim, st) = (s[a] as i64, steps.and_then(|v| v.get(k).copied()).unwrap_or(1));
        if st <= 0 {
            return Err("Slice steps <= 0 are not supported".into());
        }
        let clamp = |v: i64| if v < 0 { (v + dim).max(0) } else { v.min(dim) };
        let (b, e) = (clamp(start), clamp(*ends.get(k).ok_or("ends shorter than starts")?));
        lo[a] = b as usize;
        step[a] = st as usize;
        shape[a] = if e > b { ((e - b + st - 1) / st) as usize } else { 0 };
    }
    Ok((lo, step, shape))
}

fn slice(args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    let starts = int_arg(args, 1).ok_or("Slice without starts")?;
    let ends = int_arg(args, 2).ok_or("Slice without ends")?;
    let (axes, steps) = (int_arg(args, 3), int_arg(args, 4));
    let (lo, step, shape) = slice_plan(s, &starts, &ends, axes.as_deref(), steps.as_deref())?;
    let (si, so) = (strides(s), strides(&shape));
    let total: usize = shape.iter().product();
    let data = (0..total)
        .map(|o| {
            let mut src = 0usize;
            for d in 0..shape.len() {
                src += (lo[d] + ((o / so[d]) % shape[d]) * step[d]) * si[d];
            }
            x[src]
        })
        .collect();
    Ok(Tensor::F32 { shape, data })
}

fn resize(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    if s.len() != 4 {
        return Err(format!("Resize wants 4-D input, got {s:?}"));
    }
    let mode = n.string("mode", "nearest");
    let ctm = n.string("coordinate_transformation_mode", "half_pixel");
    let nearest_mode = n.string("nearest_mode", "round_prefer_floor");
    let scales = args.get(2).copied().flatten().map(Tensor::floats).filter(|v| v.len() == 4);
    let sizes = args.get(3).copied().flatten().map(Tensor::ints).filter(|v| v.len() == 4);
    let (oh, ow, fy, fx) = match (sizes, scales) {
        (Some(z), _) => (z[2] as usize, z[3] as usize, z[2] as f32 / s[2] as f32, z[3] as f32 / s[3] as f32),
        (None, Some(sc)) => {
            ((s[2] as f32 * sc[2]).floor() as usize, (s[3] as f32 * sc[3]).floor() as usize, sc[2], sc[3])
        }
        _ => return Err("Resize needs scales or sizes".into()),
    };
    if mode != "nearest" || ctm != "asymmetric" || !(nearest_mode == "floor" || nearest_mode == "round_prefer_floor") {
        return Err(format!("Resize mode {mode}/{ctm}/{nearest_mode} is not supported (nearest, asymmetric)"));
    }
    let (h, w) = (s[2], s[3]);
    let src = |o: usize, f: f32, lim: usize| {
        let v = o as f32 / f;
        let i = if nearest_mode == "floor" { v.floor() } else { (v - 0.5).ceil() };
        (i.max(0.0) as usize).min(lim - 1)
    };
    let mut data = Vec::with_capacity(s[0] * s[1] * oh * ow);
    for bc in 0..s[0] * s[1] {
        for oy in 0..oh {
            let iy = src(oy, fy, h);
            for ox in 0..ow {
                data.push(x[(bc * h + iy) * w + src(ox, fx, w)]);
            }
        }
    }
    Ok(Tensor::F32 { shape: vec![s[0], s[1], oh, ow], data })
}

fn gather(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let t = args.first().copied().flatten().ok_or("missing data")?;
    let idx_t = args.get(1).copied().flatten().ok_or("missing indices")?;
    let idx = idx_t.ints();
    let s = t.shape();
    let axis = norm_axis(n.int("axis", 0), s.len())?;
    let (outer, inner): (usize, usize) = (s[..axis].iter().product(), s[axis + 1..].iter().product());
    let mut shape = s[..axis].to_vec();
    shape.extend_from_slice(idx_t.shape());
    shape.extend_from_slice(&s[axis + 1..]);
    let pick = |i: i64| -> Result<usize, String> {
        let v = if i < 0 { i + s[axis] as i64 } else { i };
        if (0..s[axis] as i64).contains(&v) { Ok(v as usize) } else { Err(format!("Gather index {i} out of range")) }
    };
    let idx: Vec<usize> = idx.iter().map(|&i| pick(i)).collect::<Result<_, _>>()?;
    match t {
        Tensor::F32 { data, .. } => {
            let mut out = Vec::with_capacity(outer * idx.len() * inner);
            for o in 0..outer {
                for &i in &idx {
                    out.extend_from_slice(&data[(o * s[axis] + i) * inner..(o * s[axis] + i + 1) * inner]);
                }
            }
            Ok(Tensor::F32 { shape, data: out })
        }
        Tensor::I64 { data, .. } => {
            let mut out = Vec::with_capacity(outer * idx.len() * inner);
            for o in 0..outer {
                for &i in &idx {
                    out.extend_from_slice(&data[(o * s[axis] + i) * inner..(o * s[axis] + i + 1) * inner]);
                }
            }
            Ok(Tensor::I64 { shape, data: out })
        }
    }
}

fn pad(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    let pads = n.ints("pads").map(<[i64]>::to_vec).or_else(|| int_arg(args, 1)).ok_or("Pad without pads")?;
    let value =
        args.get(2).copied().flatten().map_or(n.float("value", 0.0), |t| t.floats().first().copied().unwrap_or(0.0));
    if n.string("mode", "constant") != "constant" {
        return Err("only constant Pad is supported".into());
    }
    let r = s.len();
    if pads.len() != 2 * r || pads.iter().any(|&p| p < 0) {
        return Err(format!("Pad pads {pads:?} for rank {r}"));
    }
    let shape: Vec<usize> = (0..r).map(|d| s[d] + pads[d] as usize + pads[d + r] as usize).collect();
    let (si, so) = (strides(s), strides(&shape));
    let total: usize = shape.iter().product();
    let data = (0..total)
        .map(|o| {
            let mut src = 0usize;
            for d in 0..r {
                let c = (o / so[d]) % shape[d];
                let i = c as i64 - pads[d];
                if i < 0 || i >= s[d] as i64 {
                    return value;
                }
                src += i as usize * si[d];
            }
            x[src]
        })
        .collect();
    Ok(Tensor::F32 { shape, data })
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;
    use crate::onnx::ValueInfo;

    fn model(op: &str) -> Model {
        Model {
            ir_version: 7,
            opset: 11,
            producer: String::new(),
            nodes: vec![Node {
                name: "odd_node".into(),
                op: Op::parse(op),
                domain: String::new(),
                inputs: vec!["x".into()],
                outputs: vec!["y".into()],
                attributes: BTreeMap::new(),
            }],
            initializers: BTreeMap::new(),
            inputs: vec![ValueInfo { name: "x".into(), elem_type: 1, shape: vec![Some(2)] }],
            outputs: vec![ValueInfo { name: "y".into(), elem_type: 1, shape: vec![Some(2)] }],
        }
    }

    #[test]
    fn an_unsupported_op_is_named_with_its_node() {
        let e = run(&model("LSTM"), &[("x", Tensor::F32 { shape: vec![2], data: vec![1.0, -1.0] })]).unwrap_err();
        assert_eq!(e.to_string(), "unsupported ONNX op `LSTM` at node odd_node (LSTM)");
        let y = run(&model("Relu"), &[("x", Tensor::F32 { shape: vec![2], data: vec![1.0, -1.0] })]).unwrap();
        assert_eq!(y[0].floats(), vec![1.0, 0.0]);
    }

    #[test]
    fn conv_pool_slice_resize_on_odd_shapes_match_hand_computed_values() {
        // 1x1x3x5 input 0..15, 2x2 kernel of ones, stride 1, pad 0: sums of 2x2 windows.
        let x: Vec<f32> = (0..15).map(|v| v as f32).collect();
        let mut attrs = BTreeMap::new();
        attrs.insert("kernel_shape".into(), Attribute::Ints(vec![2, 2]));
        let n = Node {
            name: String::new(),
            op: Op::parse("Conv"),
            domain: String::new(),
            inputs: vec![],
            outputs: vec![],
            attributes: attrs.clone(),
        };
        let xt = Tensor::F32 { shape: vec![1, 1, 3, 5], data: x.clone() };
        let wt = Tensor::F32 { shape: vec![1, 1, 2, 2], data: vec![1.0; 4] };
        let y = conv(&n, &[Some(&xt), Some(&wt)]).unwrap();
        assert_eq!(y.shape(), &[1, 1, 2, 4]);
        assert_eq!(y.floats(), vec![12.0, 16.0, 20.0, 24.0, 32.0, 36.0, 40.0, 44.0]);
        let mut p = n.clone();
        p.op = Op::parse("MaxPool");
        p.attributes.insert("pads".into(), Attribute::Ints(vec![1, 1, 1, 1]));
        p.attributes.insert("kernel_shape".into(), Attribute::Ints(vec![3, 3]));
        let y = pool(&p, &[Some(&xt)]).unwrap();
        assert_eq!(y.shape(), &[1, 1, 3, 5]);
        assert_eq!(y.floats()[0], 6.0);
        assert_eq!(y.floats()[14], 14.0);
        // Slice with step 2 on the last axis (YOLOX's Focus): columns 0, 2, 4.
        let st = |v: Vec<i64>| Tensor::I64 { shape: vec![v.len()], data: v };
        let (s0, s1, s2, s3) = (st(vec![0]), st(vec![i64::MAX]), st(vec![3]), st(vec![2]));
        let y = slice(&[Some(&xt), Some(&s0), Some(&s1), Some(&s2), Some(&s3)]).unwrap();
        assert_eq!(y.shape(), &[1, 1, 3, 3]);
        assert_eq!(y.floats(), vec![0.0, 2.0, 4.0, 5.0, 7.0, 9.0, 10.0, 12.0, 14.0]);
        // Nearest x2 resize, asymmetric, floor.
        let mut r = n.clone();
        r.op = Op::parse("Resize");
        r.attributes.insert("mode".into(), Attribute::String(b"nearest".to_vec()));
        r.attributes.insert("coordinate_transformation_mode".into(), Attribute::String(b"asymmetric".to_vec()));
        r.attributes.insert("nearest_mode".into(), Attribute::String(b"floor".to_vec()));
        let scales = Tensor::F32 { shape: vec![4], data: vec![1.0, 1.0, 2.0, 2.0] };
        let y = resize(&r, &[Some(&xt), None, Some(&scales)]).unwrap();
        assert_eq!(y.shape(), &[1, 1, 6, 10]);
        assert_eq!(y.floats()[..4], [0.0, 0.0, 1.0, 1.0]);
    }
}
