//! The reference executor: every supported ONNX op as a plain, obviously-correct loop nest
//! over `f32` (shape arithmetic in `i64`), run node by node in file order. It defines what
//! the model computes here (checked against onnxruntime in CI) and is what the GPU kernels
//! are tested against; speed is not its job.

use std::collections::HashMap;

mod conv_transpose;
mod pool;
mod resize;

pub use conv_transpose::conv_transpose_geometry;
pub use pool::{PoolPlan, pool_plan};
pub use resize::resize_geometry;

use crate::onnx::{Attribute, Model, Node, Op};
pub use crate::tensor::Tensor;
use crate::tensor::{norm_axis, reshape_shape, strides};

use crate::Error;

/// Ops this executor runs (the union of YOLOX-nano's and FastestDet's): every [`Op`] but
/// `Other`.
pub const SUPPORTED: &[&str] = Op::NAMES;

/// Check every node's op before running anything.
pub fn check_ops(model: &Model) -> Result<(), Error> {
    for n in &model.nodes {
        if matches!(n.op, Op::Other(_)) || !(n.domain.is_empty() || n.domain == "ai.onnx") {
            return Err(Error::UnsupportedOp { op: n.op.name().to_owned(), node: n.label() });
        }
    }
    Ok(())
}

/// Run `model` on the named inputs; returns the graph outputs in order.
pub fn run(model: &Model, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, Error> {
    check_ops(model)?;
    let mut env: HashMap<String, Tensor> = HashMap::new();
    for (k, t) in &model.initializers {
        env.insert(k.clone(), Tensor::from_data(t));
    }
    for (k, t) in inputs {
        env.insert((*k).to_string(), t.clone());
    }
    for n in &model.nodes {
        let err = |m: String| Error::Invalid { node: n.label(), message: m };
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
                .ok_or_else(|| Error::Invalid { node: o.name.clone(), message: "output never computed".into() })
        })
        .collect()
}

pub(super) fn f32_arg<'a>(args: &[Option<&'a Tensor>], i: usize) -> Result<(&'a [usize], &'a [f32]), String> {
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

fn unary(args: &[Option<&Tensor>], f: impl Fn(f32) -> f32) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    Ok(Tensor::F32 { shape: s.to_vec(), data: x.iter().map(|&v| f(v)).collect() })
}

/// `Clip` (opset 11+): bounds from the optional second and third inputs, each absent bound
/// unbounded.
fn clip(args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let bound = |i: usize, default: f32| -> Result<f32, String> {
        match args.get(i).copied().flatten() {
            None => Ok(default),
            Some(t) => t.floats().first().copied().ok_or_else(|| format!("Clip bound {i} is empty")),
        }
    };
    let (lo, hi) = (bound(1, f32::NEG_INFINITY)?, bound(2, f32::INFINITY)?);
    unary(args, |v| v.max(lo).min(hi))
}

/// The padding (top, left, bottom, right) of a 2-D `Conv` or pooling node on an input of
/// `hw` with kernel `k`, strides `s` and dilations `d`: explicit `pads`, or what `auto_pad`
/// (`SAME_UPPER`, `SAME_LOWER`, `VALID`) makes them (the output `ceil(in / stride)`; the odd
/// pixel at the end for `SAME_UPPER`, at the start for `SAME_LOWER`).
pub fn conv_pads(n: &Node, hw: [usize; 2], k: [usize; 2], s: [usize; 2], d: [usize; 2]) -> Result<[usize; 4], Error> {
    let same = |i: usize| {
        let out = hw[i].div_ceil(s[i].max(1));
        ((out.max(1) - 1) * s[i].max(1) + (k[i].max(1) - 1) * d[i].max(1) + 1).saturating_sub(hw[i])
    };
    match n.string("auto_pad", "NOTSET").as_str() {
        "NOTSET" => {
            let p = pads_of(n, 2);
            match p.as_slice() {
                [a, b, c, e] => Ok([*a, *b, *c, *e]),
                _ => Err(Error::Shape(format!("pads {p:?}: four values (top, left, bottom, right) expected"))),
            }
        }
        "VALID" => Ok([0; 4]),
        mode @ ("SAME_UPPER" | "SAME_LOWER") => {
            let (th, tw) = (same(0), same(1));
            let begin = |t: usize| if mode == "SAME_UPPER" { t / 2 } else { t - t / 2 };
            Ok([begin(th), begin(tw), th - begin(th), tw - begin(tw)])
        }
        other => Err(Error::Shape(format!("auto_pad `{other}` is not an ONNX padding mode"))),
    }
}

pub(super) fn pads_of(n: &Node, k: usize) -> Vec<usize> {
    n.ints("pads").map_or(vec![0; 2 * k], |p| p.iter().map(|&v| v.max(0) as usize).collect())
}

/// One node on host tensors (also what a GPU executor uses for shape arithmetic).
pub fn eval_node(n: &Node, args: &[Option<&Tensor>]) -> Result<Vec<Tensor>, Error> {
    eval(n, args).map_err(|message| Error::Invalid { node: n.label(), message })
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
        Op::Relu => one(unary(args, |v| v.max(0.0))?),
        Op::Sigmoid => one(unary(args, |v| 1.0 / (1.0 + (-v).exp()))?),
        Op::Conv => one(conv(n, args)?),
        Op::MaxPool | Op::AveragePool => one(pool::pool(n, args)?),
        Op::Concat => one(concat(n, args)?),
        Op::Slice => one(slice(args)?),
        Op::Resize => one(resize::resize(n, args)?),
        Op::ConvTranspose => one(conv_transpose::conv_transpose(n, args)?),
        Op::Div => one(binary(args, |a, b| a / b)?),
        Op::Sub => one(binary(args, |a, b| a - b)?),
        Op::Clip => one(clip(args)?),
        Op::HardSigmoid => {
            let (alpha, beta) = (n.float("alpha", 0.2), n.float("beta", 0.5));
            one(unary(args, |v| (alpha * v + beta).clamp(0.0, 1.0))?)
        }
        Op::HardSwish => one(unary(args, |v| v * (v / 6.0 + 0.5).clamp(0.0, 1.0))?),
        Op::GlobalAveragePool => one(pool::global_average_pool(args)?),
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
    if st.len() != 2 || dl.len() != 2 {
        return Err(format!("Conv strides {st:?} and dilations {dl:?}: two values each expected"));
    }
    let (sh, sw, dh, dw) = (st[0].max(1) as usize, st[1].max(1) as usize, dl[0].max(1) as usize, dl[1].max(1) as usize);
    let p = conv_pads(n, [h, wd], [kh, kw], [sh, sw], [dh, dw])?;
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
) -> Result<SlicePlan, Error> {
    slice_plan_msg(s, starts, ends, axes, steps).map_err(Error::Shape)
}

fn slice_plan_msg(
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
        let y = pool::pool(&p, &[Some(&xt)]).unwrap();
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
        let y = resize::resize(&r, &[Some(&xt), None, Some(&scales)]).unwrap();
        assert_eq!(y.shape(), &[1, 1, 6, 10]);
        assert_eq!(y.floats()[..4], [0.0, 0.0, 1.0, 1.0]);
    }
}
