//! Pooling: `MaxPool` and `AveragePool` (2-D, explicit pads, `count_include_pad`) and
//! `GlobalAveragePool`.

use super::{conv_pads, f32_arg};
use crate::Error;
use crate::onnx::{Node, Op};
use crate::tensor::Tensor;

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
pub fn pool_plan(n: &Node, shape: &[usize]) -> Result<PoolPlan, Error> {
    pool_plan_msg(n, shape).map_err(Error::Shape)
}

fn pool_plan_msg(n: &Node, shape: &[usize]) -> Result<PoolPlan, String> {
    if shape.len() != 4 {
        return Err(format!("pooling wants 4-D input, got {shape:?}"));
    }
    if n.int("ceil_mode", 0) != 0 {
        return Err("ceil_mode pooling is not supported".into());
    }
    let k = n.ints("kernel_shape").ok_or("no kernel_shape")?.to_vec();
    let st = n.ints("strides").map_or(vec![1, 1], <[i64]>::to_vec);
    if k.len() != 2 || st.len() != 2 || k.iter().chain(&st).any(|&v| v < 0) {
        return Err(format!("pooling attributes kernel {k:?}, strides {st:?}"));
    }
    let (kh, kw, sh, sw) = (k[0] as usize, k[1] as usize, st[0].max(1) as usize, st[1].max(1) as usize);
    let p = conv_pads(n, [shape[2], shape[3]], [kh, kw], [sh, sw], [1, 1]).map_err(|e| e.to_string())?;
    let oh = (shape[2] + p[0] + p[2]).checked_sub(kh).ok_or("pool kernel larger than input")? / sh + 1;
    let ow = (shape[3] + p[1] + p[3]).checked_sub(kw).ok_or("pool kernel larger than input")? / sw + 1;
    Ok(PoolPlan { kernel: [kh, kw], strides: [sh, sw], pads: [p[0], p[1], p[2], p[3]], out: [oh, ow] })
}

pub(super) fn pool(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
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

/// `GlobalAveragePool`: the mean of each channel's plane, `N x C x 1 x 1`.
pub(super) fn global_average_pool(args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    if s.len() != 4 || s[2] * s[3] == 0 {
        return Err(format!("GlobalAveragePool wants a non-empty 4-D input, got {s:?}"));
    }
    let plane = s[2] * s[3];
    let data = x.chunks(plane).map(|p| p.iter().sum::<f32>() / plane as f32).collect();
    Ok(Tensor::F32 { shape: vec![s[0], s[1], 1, 1], data })
}
