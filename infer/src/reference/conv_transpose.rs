//! ONNX `ConvTranspose` (2-D, groups, strides, dilations, explicit or `SAME_*` padding,
//! `output_padding`, `output_shape`): each input pixel scattered through the kernel, the
//! definition of the op rather than a fast form of it.

use super::f32_arg;
use crate::Error;
use crate::onnx::Node;
use crate::tensor::Tensor;

/// Per spatial axis: begin and end padding and the output length.
fn axis(
    n: &Node,
    d: usize,
    len_in: usize,
    kernel: usize,
    stride: usize,
    dilation: usize,
) -> Result<(usize, usize, usize), String> {
    let out_pad = n.ints("output_padding").map_or(0, |v| v.get(d).copied().unwrap_or(0).max(0) as usize);
    let full = stride * (len_in - 1) + out_pad + (kernel - 1) * dilation + 1;
    let auto = n.string("auto_pad", "NOTSET");
    let wanted = n.ints("output_shape").and_then(|v| v.get(v.len().saturating_sub(2) + d).copied());
    let target = match (wanted, auto.as_str()) {
        (Some(o), _) if o > 0 => Some(o as usize),
        (_, "SAME_UPPER" | "SAME_LOWER") => Some(len_in * stride),
        _ => None,
    };
    if let Some(out) = target {
        let total = full.checked_sub(out).ok_or_else(|| format!("ConvTranspose output {out} larger than {full}"))?;
        // ONNX: the odd pad goes to the end for SAME_UPPER, to the beginning otherwise
        // (SAME_LOWER, or an explicit output_shape).
        let (begin, end) =
            if auto == "SAME_UPPER" { (total / 2, total - total / 2) } else { (total - total / 2, total / 2) };
        return Ok((begin, end, out));
    }
    let pads = n.ints("pads").map_or(vec![0; 4], <[i64]>::to_vec);
    let (begin, end) =
        (pads.get(d).copied().unwrap_or(0).max(0) as usize, pads.get(d + 2).copied().unwrap_or(0).max(0) as usize);
    let out = full.checked_sub(begin + end).filter(|&o| o > 0).ok_or("ConvTranspose pads leave no output")?;
    Ok((begin, end, out))
}

/// Output height and width and begin padding (top, left) of `ConvTranspose` node `n` on an
/// input of shape `x` with weights of shape `w` (C_in x M/group x kH x kW): what the reference
/// computes and the GPU planner takes.
pub fn conv_transpose_geometry(n: &Node, x: [usize; 4], w: [usize; 4]) -> Result<(usize, usize, usize, usize), Error> {
    if x.contains(&0) || w.contains(&0) {
        return Err(Error::Shape(format!("ConvTranspose of {x:?} with weights {w:?}")));
    }
    let st = n.ints("strides").map_or(vec![1, 1], <[i64]>::to_vec);
    let dl = n.ints("dilations").map_or(vec![1, 1], <[i64]>::to_vec);
    let at = |v: &[i64], i: usize| v.get(i).copied().unwrap_or(1).max(1) as usize;
    let (pt, _, oh) = axis(n, 0, x[2], w[2], at(&st, 0), at(&dl, 0)).map_err(Error::Shape)?;
    let (pl, _, ow) = axis(n, 1, x[3], w[3], at(&st, 1), at(&dl, 1)).map_err(Error::Shape)?;
    Ok((oh, ow, pt, pl))
}

pub(super) fn conv_transpose(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (xs, x) = f32_arg(args, 0)?;
    let (ws, w) = f32_arg(args, 1)?;
    let bias = match args.get(2).copied().flatten() {
        Some(Tensor::F32 { data, .. }) => Some(data.as_slice()),
        _ => None,
    };
    if xs.len() != 4 || ws.len() != 4 || xs.contains(&0) || ws.contains(&0) {
        return Err(format!("ConvTranspose wants non-empty 4-D input and weights, got {xs:?} and {ws:?}"));
    }
    let (nb, c, h, wd) = (xs[0], xs[1], xs[2], xs[3]);
    let group = n.int("group", 1).max(1) as usize;
    // Weights: C_in x (C_out / group) x kH x kW.
    let (cin, mg, kh, kw) = (ws[0], ws[1], ws[2], ws[3]);
    if cin != c || c % group != 0 {
        return Err(format!("ConvTranspose: {c} input channels, weights {ws:?}, group {group}"));
    }
    let m = mg * group;
    if bias.is_some_and(|b| b.len() != m) {
        return Err(format!("ConvTranspose: bias of {} for {m} output channels", bias.map_or(0, <[f32]>::len)));
    }
    let st = n.ints("strides").map_or(vec![1, 1], <[i64]>::to_vec);
    let dl = n.ints("dilations").map_or(vec![1, 1], <[i64]>::to_vec);
    let at = |v: &[i64], i: usize| v.get(i).copied().unwrap_or(1).max(1) as usize;
    let (sh, sw, dh, dw) = (at(&st, 0), at(&st, 1), at(&dl, 0), at(&dl, 1));
    let (oh, ow, pt, pl) = conv_transpose_geometry(n, [nb, c, h, wd], [cin, mg, kh, kw])?;
    let cg = c / group;
    let mut out = vec![0.0f32; nb * m * oh * ow];
    for b in 0..nb {
        for oc in 0..m {
            let plane = &mut out[(b * m + oc) * oh * ow..(b * m + oc + 1) * oh * ow];
            plane.fill(bias.map_or(0.0, |bs| bs[oc]));
            let (g, ocg) = (oc / mg, oc % mg);
            for icg in 0..cg {
                let ic = g * cg + icg;
                let xin = &x[(b * c + ic) * h * wd..(b * c + ic + 1) * h * wd];
                for ky in 0..kh {
                    for kx in 0..kw {
                        let wv = w[((ic * mg + ocg) * kh + ky) * kw + kx];
                        for iy in 0..h {
                            let Some(oy) = (iy * sh + ky * dh).checked_sub(pt).filter(|&v| v < oh) else { continue };
                            for ix in 0..wd {
                                if let Some(ox) = (ix * sw + kx * dw).checked_sub(pl).filter(|&v| v < ow) {
                                    plane[oy * ow + ox] += wv * xin[iy * wd + ix];
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
