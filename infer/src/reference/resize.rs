//! ONNX `Resize` on NCHW tensors: `nearest` (every `nearest_mode`) and `linear` (bilinear),
//! with the coordinate transformations `half_pixel`, `pytorch_half_pixel`, `align_corners`,
//! `asymmetric` and `tf_half_pixel_for_nn`, output sizes from `scales` or `sizes`, any factor
//! (non-integer included). What onnxruntime computes: the source coordinate of output `o` by
//! the transformation, clamped to the input for `linear`, then the two neighbours' weights.

use super::f32_arg;
use crate::Error;
use crate::onnx::Node;
use crate::tensor::Tensor;

/// How an output coordinate maps to the input (ONNX `coordinate_transformation_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Transform {
    HalfPixel,
    PytorchHalfPixel,
    AlignCorners,
    Asymmetric,
    TfHalfPixelForNn,
}

impl Transform {
    fn parse(s: &str) -> Result<Self, String> {
        Ok(match s {
            "half_pixel" => Self::HalfPixel,
            "pytorch_half_pixel" => Self::PytorchHalfPixel,
            "align_corners" => Self::AlignCorners,
            "asymmetric" => Self::Asymmetric,
            "tf_half_pixel_for_nn" => Self::TfHalfPixelForNn,
            other => return Err(format!("Resize coordinate_transformation_mode `{other}` is not supported")),
        })
    }

    /// The input coordinate of output coordinate `o` (`scale` = output / input length).
    fn source(self, o: usize, scale: f32, len_in: usize, len_out: usize) -> f32 {
        let o = o as f32;
        match self {
            Self::HalfPixel => (o + 0.5) / scale - 0.5,
            Self::PytorchHalfPixel => {
                if len_out > 1 {
                    (o + 0.5) / scale - 0.5
                } else {
                    0.0
                }
            }
            Self::AlignCorners => {
                if len_out > 1 {
                    o * (len_in as f32 - 1.0) / (len_out as f32 - 1.0)
                } else {
                    0.0
                }
            }
            Self::Asymmetric => o / scale,
            Self::TfHalfPixelForNn => (o + 0.5) / scale,
        }
    }
}

/// Rounding of the source coordinate for `nearest` (ONNX `nearest_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Nearest {
    RoundPreferFloor,
    RoundPreferCeil,
    Floor,
    Ceil,
}

impl Nearest {
    fn parse(s: &str) -> Result<Self, String> {
        Ok(match s {
            "round_prefer_floor" => Self::RoundPreferFloor,
            "round_prefer_ceil" => Self::RoundPreferCeil,
            "floor" => Self::Floor,
            "ceil" => Self::Ceil,
            other => return Err(format!("Resize nearest_mode `{other}` is not supported")),
        })
    }

    fn index(self, v: f32, len: usize) -> usize {
        let i = match self {
            Self::RoundPreferFloor => {
                if v.fract() == 0.5 {
                    v.floor()
                } else {
                    v.round()
                }
            }
            Self::RoundPreferCeil => {
                if v.fract() == 0.5 {
                    v.ceil()
                } else {
                    v.round()
                }
            }
            Self::Floor => v.floor(),
            Self::Ceil => v.ceil(),
        };
        (i.max(0.0) as usize).min(len - 1)
    }
}

/// Per output coordinate along one axis: the two input indices and the second's weight.
fn linear_taps(t: Transform, scale: f32, len_in: usize, len_out: usize) -> Vec<(usize, usize, f32)> {
    (0..len_out)
        .map(|o| {
            let v = t.source(o, scale, len_in, len_out).clamp(0.0, (len_in - 1) as f32);
            let i0 = v.floor() as usize;
            let i1 = (i0 + 1).min(len_in - 1);
            (i0, i1, v - i0 as f32)
        })
        .collect()
}

/// The output height and width and the two scales of a `Resize` of a 4-D input of shape `s`
/// by `sizes` (taking precedence) or `scales`, each of four values: only height and width may
/// change, scales must be finite and positive, and the output must not be empty. What the
/// reference executor and the GPU planner both compute.
pub fn resize_geometry(
    s: &[usize],
    scales: Option<&[f32]>,
    sizes: Option<&[i64]>,
) -> Result<(usize, usize, f32, f32), Error> {
    let (scales, sizes) = (scales.filter(|v| v.len() == 4), sizes.filter(|v| v.len() == 4));
    if s.len() != 4 || s.contains(&0) {
        return Err(Error::Shape(format!("Resize wants a non-empty 4-D input, got {s:?}")));
    }
    match (sizes, scales) {
        (Some(z), _) => {
            if z[0] as usize != s[0] || z[1] as usize != s[1] || z[2] <= 0 || z[3] <= 0 {
                return Err(Error::Shape(format!(
                    "Resize sizes {z:?} for input {s:?}: only height and width may change"
                )));
            }
            let (oh, ow) = (z[2] as usize, z[3] as usize);
            Ok((oh, ow, oh as f32 / s[2] as f32, ow as f32 / s[3] as f32))
        }
        (None, Some(sc)) => {
            if sc[0] != 1.0 || sc[1] != 1.0 || !(sc[2] > 0.0 && sc[3] > 0.0 && sc[2].is_finite() && sc[3].is_finite()) {
                return Err(Error::Shape(format!(
                    "Resize scales {sc:?}: only height and width may change, by finite factors"
                )));
            }
            let (oh, ow) = ((s[2] as f32 * sc[2]).floor() as usize, (s[3] as f32 * sc[3]).floor() as usize);
            if oh == 0 || ow == 0 {
                return Err(Error::Shape(format!("Resize scales {sc:?} leave nothing of input {s:?}")));
            }
            Ok((oh, ow, sc[2], sc[3]))
        }
        _ => Err(Error::Shape("Resize needs scales or sizes".into())),
    }
}

pub(super) fn resize(n: &Node, args: &[Option<&Tensor>]) -> Result<Tensor, String> {
    let (s, x) = f32_arg(args, 0)?;
    let transform = Transform::parse(&n.string("coordinate_transformation_mode", "half_pixel"))?;
    let scales = args.get(2).copied().flatten().map(Tensor::floats);
    let sizes = args.get(3).copied().flatten().map(Tensor::ints);
    let (oh, ow, fy, fx) = resize_geometry(s, scales.as_deref(), sizes.as_deref())?;
    let (h, w) = (s[2], s[3]);
    let planes = s[0] * s[1];
    let mut data = Vec::with_capacity(planes * oh * ow);
    match n.string("mode", "nearest").as_str() {
        "nearest" => {
            let rounding = Nearest::parse(&n.string("nearest_mode", "round_prefer_floor"))?;
            let ys: Vec<usize> = (0..oh).map(|o| rounding.index(transform.source(o, fy, h, oh), h)).collect();
            let xs: Vec<usize> = (0..ow).map(|o| rounding.index(transform.source(o, fx, w, ow), w)).collect();
            for bc in 0..planes {
                let plane = &x[bc * h * w..(bc + 1) * h * w];
                for &iy in &ys {
                    data.extend(xs.iter().map(|&ix| plane[iy * w + ix]));
                }
            }
        }
        "linear" => {
            if transform == Transform::TfHalfPixelForNn {
                return Err("Resize linear with tf_half_pixel_for_nn is not defined".into());
            }
            let ys = linear_taps(transform, fy, h, oh);
            let xs = linear_taps(transform, fx, w, ow);
            for bc in 0..planes {
                let plane = &x[bc * h * w..(bc + 1) * h * w];
                for &(y0, y1, wy) in &ys {
                    let (r0, r1) = (&plane[y0 * w..(y0 + 1) * w], &plane[y1 * w..(y1 + 1) * w]);
                    data.extend(xs.iter().map(|&(x0, x1, wx)| {
                        let top = r0[x0] + (r0[x1] - r0[x0]) * wx;
                        let bottom = r1[x0] + (r1[x1] - r1[x0]) * wx;
                        top + (bottom - top) * wy
                    }));
                }
            }
        }
        other => return Err(format!("Resize mode `{other}` is not supported (nearest, linear)")),
    }
    Ok(Tensor::F32 { shape: vec![s[0], s[1], oh, ow], data })
}
