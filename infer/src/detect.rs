//! Detector pre- and post-processing, as the model authors define it.
//!
//! YOLOX (Megvii): letterbox into a square input (scale `min(S/w, S/h)`, bilinear resize,
//! pasted top-left on grey 114), BGR, raw 0..255; output rows `[x, y, w, h, obj, cls...]` per
//! grid cell of strides 8, 16, 32, decoded as `cx = (x + gx) * stride`, `w = exp(w) * stride`,
//! score `obj * cls`. Then class-wise non-maximum suppression.

/// One detection in original image pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// Class index.
    pub class: usize,
    /// Score in 0..1.
    pub score: f32,
    /// Left, top, right, bottom (pixels of the original image).
    pub bbox: [f32; 4],
}

/// How an image was placed into the model input.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Letterbox {
    /// Input pixels per image pixel.
    pub scale: f32,
    /// Model input side.
    pub size: usize,
}

/// Bilinear resize of RGB8 (`width x height`) to `nw x nh` with pixel centres aligned
/// (OpenCV's `INTER_LINEAR`), written top-left into three planes of `pw x ph` (RGB order, or
/// BGR with `bgr`), each value passed through `map`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn resize_planes(
    rgb: &[u8],
    width: usize,
    height: usize,
    (nw, nh): (usize, usize),
    (pw, ph): (usize, usize),
    bgr: bool,
    out: &mut [f32],
    map: impl Fn(f32) -> f32,
) {
    let (fx, fy) = (width as f32 / nw.max(1) as f32, height as f32 / nh.max(1) as f32);
    for y in 0..nh.min(ph) {
        let sy = ((y as f32 + 0.5) * fy - 0.5).clamp(0.0, (height - 1) as f32);
        let (y0, wy) = (sy.floor() as usize, sy - sy.floor());
        let y1 = (y0 + 1).min(height - 1);
        for x in 0..nw.min(pw) {
            let sx = ((x as f32 + 0.5) * fx - 0.5).clamp(0.0, (width - 1) as f32);
            let (x0, wx) = (sx.floor() as usize, sx - sx.floor());
            let x1 = (x0 + 1).min(width - 1);
            for c in 0..3 {
                let p = |yy: usize, xx: usize| f32::from(rgb[(yy * width + xx) * 3 + c]);
                let v = (1.0 - wy) * ((1.0 - wx) * p(y0, x0) + wx * p(y0, x1))
                    + wy * ((1.0 - wx) * p(y1, x0) + wx * p(y1, x1));
                let plane = if bgr { 2 - c } else { c };
                out[plane * pw * ph + y * pw + x] = map(v);
            }
        }
    }
}

/// Letterbox an RGB8 image (`width x height`) into YOLOX's input: NCHW, BGR, 0..255, `size` x
/// `size`, bilinear resize with pixel centres aligned (OpenCV's `INTER_LINEAR`), grey 114
/// padding right and below.
pub fn letterbox_bgr(rgb: &[u8], width: usize, height: usize, size: usize) -> (Vec<f32>, Letterbox) {
    let mut out = vec![114.0f32; 3 * size * size];
    if width == 0 || height == 0 || rgb.len() < 3 * width * height {
        return (out, Letterbox { scale: 1.0, size });
    }
    let scale = (size as f32 / width as f32).min(size as f32 / height as f32);
    let (nw, nh) = (((width as f32 * scale) as usize).min(size), ((height as f32 * scale) as usize).min(size));
    resize_planes(rgb, width, height, (nw, nh), (size, size), true, &mut out, f32::round);
    (out, Letterbox { scale, size })
}

/// Decode YOLOX's raw output (`rows x (5 + classes)`) into detections above `threshold`.
pub fn decode_yolox(output: &[f32], classes: usize, lb: &Letterbox, threshold: f32) -> Vec<Detection> {
    let width = 5 + classes;
    let mut grids = Vec::new();
    for stride in [8usize, 16, 32] {
        let g = lb.size / stride;
        for gy in 0..g {
            for gx in 0..g {
                grids.push((gx as f32, gy as f32, stride as f32));
            }
        }
    }
    let mut out = Vec::new();
    for (row, &(gx, gy, s)) in output.chunks_exact(width).zip(&grids) {
        let obj = row[4];
        let Some((class, &cls)) = row[5..].iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else { continue };
        let score = obj * cls;
        if score < threshold || score.is_nan() {
            continue;
        }
        let (cx, cy) = ((row[0] + gx) * s, (row[1] + gy) * s);
        let (w, h) = (row[2].exp() * s, row[3].exp() * s);
        let k = 1.0 / lb.scale;
        out.push(Detection {
            class,
            score,
            bbox: [(cx - w / 2.0) * k, (cy - h / 2.0) * k, (cx + w / 2.0) * k, (cy + h / 2.0) * k],
        });
    }
    out
}

/// Decode FastestDet's raw output (`(5 + classes) x g x g`, one cell per grid position) for an
/// image `width x height`: objectness in channel 0, box offsets `tanh` (x, y) and sizes
/// `sigmoid` (w, h) normalised to the image, class probabilities after; score
/// `obj^0.6 * cls^0.4` (the authors' weighting).
pub fn decode_fastestdet(
    output: &[f32],
    classes: usize,
    grid: usize,
    width: f32,
    height: f32,
    threshold: f32,
) -> Vec<Detection> {
    let cells = grid * grid;
    let mut out = Vec::new();
    if output.len() < (5 + classes) * cells {
        return out;
    }
    let at = |ch: usize, cell: usize| output[ch * cells + cell];
    let sigmoid = |v: f32| 1.0 / (1.0 + (-v).exp());
    for cell in 0..cells {
        let (row, col) = (cell / grid, cell % grid);
        let obj = at(0, cell);
        let Some((class, cls)) = (0..classes).map(|k| (k, at(5 + k, cell))).max_by(|a, b| a.1.total_cmp(&b.1)) else {
            continue;
        };
        let score = obj.max(0.0).powf(0.6) * cls.max(0.0).powf(0.4);
        if score < threshold || score.is_nan() {
            continue;
        }
        let cx = (col as f32 + at(1, cell).tanh()) / grid as f32;
        let cy = (row as f32 + at(2, cell).tanh()) / grid as f32;
        let (w, h) = (sigmoid(at(3, cell)), sigmoid(at(4, cell)));
        out.push(Detection {
            class,
            score,
            bbox: [(cx - w / 2.0) * width, (cy - h / 2.0) * height, (cx + w / 2.0) * width, (cy + h / 2.0) * height],
        });
    }
    out
}

/// Resize RGB8 to FastestDet's input (`size x size`, no letterbox), bilinear, BGR, 0..1.
pub fn resize_bgr_unit(rgb: &[u8], width: usize, height: usize, size: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; 3 * size * size];
    if width == 0 || height == 0 || rgb.len() < 3 * width * height {
        return out;
    }
    resize_planes(rgb, width, height, (size, size), (size, size), true, &mut out, |v| v / 255.0);
    out
}

/// Which output decoding (and input preparation) a model needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoder {
    /// YOLOX: letterbox, BGR 0..255, grid decoding.
    Yolox,
    /// FastestDet: plain resize, BGR 0..1, tanh/sigmoid decoding.
    FastestDet,
}

/// The decoder's contract on the model's first output, checked where the model declares its
/// dimensions (a symbolic one passes): YOLOX `1 x N x (5 + classes)` with N the cells of its
/// three strides (8, 16, 32) for the input side; FastestDet `1 x (5 + classes) x G x G` with
/// G a sixteenth of the side. A model of the other family decodes to garbage (negative boxes,
/// scores far outside 0..1), so it is refused here, naming the decoder and the shapes.
fn check_output(model: &crate::onnx::Model, decoder: Decoder, side: usize) -> Result<(), String> {
    let out = model.outputs.first().ok_or("the model has no output")?;
    let dims = &out.shape;
    let fits = |want: &[Option<usize>]| {
        dims.len() == want.len()
            && dims.iter().zip(want).all(|(d, w)| match (d, w) {
                (Some(d), Some(w)) => usize::try_from(*d).is_ok_and(|d| d == *w),
                (Some(d), None) => *d > 5,
                _ => true,
            })
    };
    let (ok, contract) = match decoder {
        Decoder::Yolox => {
            let cells: usize = [8, 16, 32].iter().map(|s| (side / s) * (side / s)).sum();
            (fits(&[Some(1), Some(cells), None]), format!("1 x {cells} x (5 + classes)"))
        }
        Decoder::FastestDet => {
            let g = side / 16;
            (fits(&[Some(1), None, Some(g), Some(g)]), format!("1 x (5 + classes) x {g} x {g}"))
        }
    };
    if ok {
        Ok(())
    } else {
        let shape: Vec<String> = dims.iter().map(|d| d.map_or_else(|| "?".to_owned(), |d| d.to_string())).collect();
        Err(format!(
            "the model's output `{}` is {} but the {decoder:?} decoder reads {contract} for a {side}x{side} input: is this a model of the other family? (choose the decoder with `decoder:` / `--decoder`)",
            out.name,
            shape.join(" x ")
        ))
    }
}

/// A loaded detector: the model, its square input side, the decoding.
#[derive(Clone, Debug)]
pub struct Detector {
    model: crate::onnx::Model,
    input_name: String,
    side: usize,
    decoder: Decoder,
}

impl Detector {
    /// Check that `model` takes a fixed `1x3xSxS` input (which ops it uses is the executor's
    /// business).
    pub fn new(model: crate::onnx::Model, decoder: Decoder) -> Result<Self, crate::Error> {
        let input = model.inputs.first().ok_or_else(|| crate::Error::Contract("the model has no input".into()))?;
        let dims: Vec<usize> = input.shape.iter().map(|d| d.unwrap_or(0).max(0) as usize).collect();
        let side = match dims.as_slice() {
            [1, 3, h, w] if h == w && *h > 0 => *h,
            _ => {
                return Err(crate::Error::Contract(format!(
                    "model input `{}` has shape {:?}; a detector takes a fixed square 1x3xSxS input",
                    input.name, input.shape
                )));
            }
        };
        check_output(&model, decoder, side).map_err(crate::Error::Contract)?;
        Ok(Self { input_name: input.name.clone(), model, side, decoder })
    }

    /// The model.
    pub fn model(&self) -> &crate::onnx::Model {
        &self.model
    }

    /// Detections in an RGB8 image (`width x height`), above `score`, after class-wise NMS at
    /// `iou`, clipped to the image; the model run by `run` (input name, input tensor ->
    /// outputs): rten, the reference executor or a GPU.
    #[allow(clippy::too_many_arguments)]
    pub fn detect_with<E>(
        &self,
        rgb: &[u8],
        width: usize,
        height: usize,
        classes: usize,
        score: f32,
        iou: f32,
        run: impl FnOnce(&str, crate::tensor::Tensor) -> Result<Vec<crate::tensor::Tensor>, E>,
    ) -> Result<Vec<Detection>, E> {
        let s = self.side;
        let (x, lb) = match self.decoder {
            Decoder::Yolox => letterbox_bgr(rgb, width, height, s),
            Decoder::FastestDet => (resize_bgr_unit(rgb, width, height, s), Letterbox { scale: 1.0, size: s }),
        };
        let input = crate::tensor::Tensor::F32 { shape: vec![1, 3, s, s], data: x };
        let out = run(self.input_name.as_str(), input)?;
        let raw = out.first().map(crate::tensor::Tensor::floats).unwrap_or_default();
        let dets = match self.decoder {
            Decoder::Yolox => decode_yolox(&raw, classes, &lb, score),
            Decoder::FastestDet => {
                let grid = out.first().map_or(0, |t| t.shape().last().copied().unwrap_or(0));
                decode_fastestdet(&raw, classes, grid, width as f32, height as f32, score)
            }
        };
        let (w, h) = (width as f32, height as f32);
        Ok(nms(dets, iou)
            .into_iter()
            .map(|d| Detection {
                bbox: [d.bbox[0].max(0.0), d.bbox[1].max(0.0), d.bbox[2].min(w), d.bbox[3].min(h)],
                ..d
            })
            .collect())
    }
}

fn iou(a: &[f32; 4], b: &[f32; 4]) -> f32 {
    let iw = (a[2].min(b[2]) - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let area = |r: &[f32; 4]| (r[2] - r[0]).max(0.0) * (r[3] - r[1]).max(0.0);
    let union = area(a) + area(b) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// Class-wise greedy non-maximum suppression: highest score first, drop boxes of the same
/// class overlapping a kept one by more than `iou_threshold`. Deterministic order: score,
/// then class, then position.
pub fn nms(mut dets: Vec<Detection>, iou_threshold: f32) -> Vec<Detection> {
    dets.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.class.cmp(&b.class)).then(a.bbox[0].total_cmp(&b.bbox[0])));
    let mut keep: Vec<Detection> = Vec::new();
    for d in dets {
        if keep.iter().all(|k| k.class != d.class || iou(&k.bbox, &d.bbox) <= iou_threshold) {
            keep.push(d);
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nms_keeps_the_best_of_overlapping_boxes_per_class() {
        let d = |class, score, x: f32| Detection { class, score, bbox: [x, 0.0, x + 10.0, 10.0] };
        let kept = nms(vec![d(0, 0.5, 1.0), d(0, 0.9, 0.0), d(1, 0.4, 0.0), d(0, 0.3, 50.0)], 0.45);
        assert_eq!(kept, vec![d(0, 0.9, 0.0), d(1, 0.4, 0.0), d(0, 0.3, 50.0)]);
    }

    #[test]
    fn letterbox_scales_and_pads() {
        let rgb: Vec<u8> = (0..4 * 2 * 3).map(|i| (i * 10) as u8).collect();
        let (t, lb) = letterbox_bgr(&rgb, 4, 2, 8);
        assert_eq!(lb.scale, 2.0);
        assert_eq!(t.len(), 3 * 64);
        // Below the 4-row image: padding.
        assert_eq!(t[5 * 8], 114.0);
        // Top-left pixel, blue plane = source channel 2.
        assert_eq!(t[0], 20.0);
    }

    #[test]
    fn decoding_undoes_the_grid_and_the_scale() {
        let lb = Letterbox { scale: 0.5, size: 32 };
        // 16 + 4 + 1 rows of 6 (one class); one confident cell at stride 8, grid (1, 2).
        let mut out = vec![0.0f32; 21 * 6];
        let row = 2 * 4 + 1;
        out[row * 6..row * 6 + 6].copy_from_slice(&[0.5, 0.5, 0.0, 0.0, 0.9, 1.0]);
        let d = decode_yolox(&out, 1, &lb, 0.5);
        assert_eq!(d.len(), 1);
        // centre (1.5 * 8, 2.5 * 8) = (12, 20), size 8 -> in the original: x2.
        assert_eq!(d[0].bbox, [16.0, 32.0, 32.0, 48.0]);
    }
}
