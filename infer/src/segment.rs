//! Semantic segmentation pre- and post-processing: a model's input contract (fixed
//! `1x3xHxW`, RGB, a normalisation), its output read as per-class scores (`1xCxhxw`), resized
//! to the frame, decided per pixel, optionally dilated, and split into instances.
//!
//! Output kinds, told from the model itself: one channel is the probability of class 1
//! (a sigmoid, e.g. MediaPipe's selfie segmenter); several channels are per-class scores,
//! probabilities when the graph ends in `Softmax` (PP-HumanSeg) and logits otherwise
//! (DeepLabV3, made probabilities here by a softmax). The scores are resized to the frame
//! bilinearly (half-pixel centres, as OpenCV's `INTER_LINEAR` and the models' own demos do)
//! before the decision, so mask edges fall between model pixels, not on their grid.

use crate::Error;
use crate::onnx::{Model, Op};
use crate::tensor::Tensor;

/// How pixels are scaled into the model's input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Normalise {
    /// `pixel / 255`, in [0, 1] (MediaPipe).
    Unit,
    /// `pixel / 127.5 - 1`, in [-1, 1] (PaddleSeg, DeepLab).
    Symmetric,
}

/// What the model's output channels are.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scores {
    /// One channel: the probability of class 1 (the rest is class 0).
    Probability,
    /// One channel per class, probabilities (the graph ends in a softmax).
    Softmax,
    /// One channel per class, raw scores.
    Logits,
}

/// A loaded segmenter: the model, its input size and names, how to read its output.
#[derive(Clone, Debug)]
pub struct Segmenter {
    model: Model,
    input_name: String,
    /// Input height and width.
    size: (usize, usize),
    normalise: Normalise,
    scores: Scores,
    classes: Vec<String>,
}

/// One frame's segmentation at the frame's size.
#[derive(Clone, Debug, PartialEq)]
pub struct ClassMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Class index per pixel (0 = background), row-major.
    pub class: Vec<u16>,
}

impl Segmenter {
    /// Check `model` against the segmentation contract: one fixed `1x3xHxW` input, a first
    /// output `1xCxhxw` with `C == classes.len()`, or `C == 1` with two classes (background
    /// and the probability's class).
    pub fn new(model: Model, classes: Vec<String>, normalise: Normalise) -> Result<Self, Error> {
        let Contract { input, size, channels } = contract(&model)?;
        let contract = |m: String| Error::Contract(m);
        let output = &model.outputs[0];
        if classes.len() < 2 {
            return Err(contract(format!(
                "{} class names; a segmenter needs background and at least one class",
                classes.len()
            )));
        }
        let last_op = model.nodes.iter().rev().find(|n| n.outputs.contains(&output.name)).map(|n| &n.op);
        let scores = match (channels, last_op) {
            (1, _) if classes.len() == 2 => Scores::Probability,
            (1, _) => {
                return Err(contract(format!(
                    "the model's one output channel is one class's probability, but {} class names are given",
                    classes.len()
                )));
            }
            (c, _) if c != 0 && c != classes.len() => {
                return Err(contract(format!(
                    "the model scores {c} classes but {} class names are given (one per output channel)",
                    classes.len()
                )));
            }
            (_, Some(Op::Softmax)) => Scores::Softmax,
            _ => Scores::Logits,
        };
        Ok(Self { input_name: input, model, size, normalise, scores, classes })
    }

    /// The model.
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The input's name.
    pub fn input_name(&self) -> &str {
        &self.input_name
    }

    /// Input height and width.
    pub fn input_size(&self) -> (usize, usize) {
        self.size
    }

    /// The class names, index = class id.
    pub fn classes(&self) -> &[String] {
        &self.classes
    }

    /// How the output is read.
    pub fn scores(&self) -> Scores {
        self.scores
    }

    /// The model input for an RGB8 frame (`width x height`): the whole frame resized
    /// bilinearly to the input size (the aspect ratio changes, as the models' contracts say),
    /// RGB planes, normalised.
    pub fn input(&self, rgb: &[u8], width: usize, height: usize) -> Tensor {
        let (h, w) = self.size;
        let mut data = vec![0.0f32; 3 * h * w];
        let map = match self.normalise {
            Normalise::Unit => |v: f32| v / 255.0,
            Normalise::Symmetric => |v: f32| v / 127.5 - 1.0,
        };
        crate::detect::resize_planes(rgb, width, height, (w, h), (w, h), false, &mut data, map);
        Tensor::F32 { shape: vec![1, 3, h, w], data }
    }

    /// Decide every pixel of a `width x height` frame from the model's first output:
    /// class 1 where its probability reaches `threshold` (one-channel and two-class models);
    /// for more classes the most probable class, kept where its probability reaches
    /// `threshold` (background otherwise).
    pub fn decode(&self, output: &Tensor, width: usize, height: usize, threshold: f32) -> Result<ClassMap, Error> {
        let Tensor::F32 { shape, data } = output else {
            return Err(Error::Contract("the model's output is not a float tensor".into()));
        };
        let channels = match self.scores {
            Scores::Probability => 1,
            _ => self.classes.len(),
        };
        let [1, c, h, w] = shape.as_slice() else {
            return Err(Error::Contract(format!("the model's output has shape {shape:?}, not 1xCxHxW")));
        };
        if *c != channels || *h == 0 || *w == 0 || data.len() != c * h * w {
            return Err(Error::Contract(format!(
                "the model's output has shape {shape:?}; {channels} channels were expected"
            )));
        }
        let (h, w) = (*h, *w);
        let taps = |len_in: usize, len_out: usize| -> Vec<(usize, usize, f32)> {
            let f = len_in as f32 / len_out as f32;
            (0..len_out)
                .map(|o| {
                    let v = ((o as f32 + 0.5) * f - 0.5).clamp(0.0, (len_in - 1) as f32);
                    let i0 = v.floor() as usize;
                    (i0, (i0 + 1).min(len_in - 1), v - i0 as f32)
                })
                .collect()
        };
        let (ys, xs) = (taps(h, height), taps(w, width));
        let sample = |ch: usize, (y0, y1, wy): (usize, usize, f32), (x0, x1, wx): (usize, usize, f32)| {
            let p = &data[ch * h * w..(ch + 1) * h * w];
            let top = p[y0 * w + x0] + (p[y0 * w + x1] - p[y0 * w + x0]) * wx;
            let bottom = p[y1 * w + x0] + (p[y1 * w + x1] - p[y1 * w + x0]) * wx;
            top + (bottom - top) * wy
        };
        let mut class = Vec::with_capacity(width * height);
        let mut scores = vec![0.0f32; channels];
        for &ty in &ys {
            for &tx in &xs {
                let k = match self.scores {
                    Scores::Probability => u16::from(sample(0, ty, tx) >= threshold),
                    Scores::Softmax | Scores::Logits => {
                        for (ch, s) in scores.iter_mut().enumerate() {
                            *s = sample(ch, ty, tx);
                        }
                        if self.scores == Scores::Logits {
                            softmax(&mut scores);
                        }
                        if channels == 2 {
                            // Two classes: the same threshold rule as one probability channel.
                            u16::from(scores[1] >= threshold)
                        } else {
                            let (best, p) = scores
                                .iter()
                                .copied()
                                .enumerate()
                                .fold((0, f32::NEG_INFINITY), |a, (i, v)| if v > a.1 { (i, v) } else { a });
                            if p < threshold { 0 } else { best as u16 }
                        }
                    }
                };
                class.push(k);
            }
        }
        Ok(ClassMap { width, height, class })
    }
}

/// What [`contract`] reads from a model: its input's name and size, its output's channels.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Contract {
    /// The input's name.
    pub input: String,
    /// Input height and width.
    pub size: (usize, usize),
    /// Output channels (0: symbolic in the file).
    pub channels: usize,
}

/// Check the shapes a segmenter must have, before its class names are read: one fixed
/// `1x3xHxW` input, a first output `1xCxhxw`.
pub fn contract(model: &Model) -> Result<Contract, Error> {
    let contract = |m: String| Error::Contract(m);
    let input = model.inputs.first().ok_or_else(|| contract("the model has no input".into()))?;
    let dims: Vec<i64> = input.shape.iter().map(|d| d.unwrap_or(0)).collect();
    let size = match dims.as_slice() {
        [1, 3, h, w] if *h > 0 && *w > 0 => (*h as usize, *w as usize),
        _ => {
            return Err(contract(format!(
                "model input `{}` has shape {}; a segmenter takes a fixed 1x3xHxW RGB input",
                input.name,
                shape_text(&input.shape)
            )));
        }
    };
    let output = model.outputs.first().ok_or_else(|| contract("the model has no output".into()))?;
    let channels = match output.shape.as_slice() {
        // A symbolic channel count is checked on the first output instead.
        [n, c, _, _] if n.is_none_or(|n| n == 1) && c.is_none_or(|c| c > 0) => c.map_or(0, |c| c as usize),
        _ => {
            return Err(contract(format!(
                "model output `{}` has shape {}; a segmenter gives 1xCxHxW class scores",
                output.name,
                shape_text(&output.shape)
            )));
        }
    };
    Ok(Contract { input: input.name.clone(), size, channels })
}

fn softmax(v: &mut [f32]) {
    let max = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let mut sum = 0.0;
    for x in v.iter_mut() {
        *x = (*x - max).exp();
        sum += *x;
    }
    for x in v.iter_mut() {
        *x /= sum;
    }
}

fn shape_text(shape: &[Option<i64>]) -> String {
    shape.iter().map(|d| d.map_or_else(|| "?".to_owned(), |d| d.to_string())).collect::<Vec<_>>().join("x")
}

/// Grow every non-background region by `radius` pixels (a square structuring element, the
/// Chebyshev distance): a background pixel takes the class of the nearest labelled pixel
/// along its row, then along its column, within `radius`. Labelled pixels keep theirs.
pub fn dilate(class: &mut [u16], width: usize, height: usize, radius: usize) {
    if radius == 0 || class.len() != width * height {
        return;
    }
    let pass = |src: &[u16], len: usize, step: usize, lines: usize, line_step: usize, dst: &mut [u16]| {
        for l in 0..lines {
            let at = |i: usize| l * line_step + i * step;
            // Distance to the nearest labelled pixel before and after, with its class.
            let mut near: Vec<(usize, u16)> = vec![(usize::MAX, 0); len];
            let mut last: Option<(usize, u16)> = None;
            for i in 0..len {
                let v = src[at(i)];
                if v != 0 {
                    last = Some((i, v));
                }
                if let Some((j, c)) = last {
                    near[i] = (i - j, c);
                }
            }
            last = None;
            for i in (0..len).rev() {
                let v = src[at(i)];
                if v != 0 {
                    last = Some((i, v));
                }
                if let Some((j, c)) = last
                    && j - i < near[i].0
                {
                    near[i] = (j - i, c);
                }
            }
            for (i, &(d, c)) in near.iter().enumerate() {
                dst[at(i)] = if src[at(i)] != 0 {
                    src[at(i)]
                } else if d <= radius {
                    c
                } else {
                    0
                };
            }
        }
    };
    let src = class.to_vec();
    let mut rows = vec![0u16; class.len()];
    pass(&src, width, 1, height, width, &mut rows);
    pass(&rows, height, width, width, 1, class);
}

/// Instances by connected components (4-neighbours) of pixels of the same non-background
/// class; with `depth` (metres, 0 = unknown) two neighbours also join only if both depths are
/// known and differ by at most `max_depth_step`, so two people of one class, one behind the
/// other, come apart. Ids from 1 in raster order of each component's first pixel (0 =
/// background or unknown depth under `depth`); at most `u16::MAX` instances, later ones
/// merged into the last id.
pub fn instances(class: &[u16], width: usize, height: usize, depth: Option<(&[f32], f32)>) -> Vec<u16> {
    let n = width * height;
    let mut id = vec![0u16; n];
    if class.len() != n || depth.is_some_and(|(d, _)| d.len() != n) {
        return id;
    }
    let joins = |a: usize, b: usize| {
        class[a] == class[b] && depth.is_none_or(|(d, step)| d[a] > 0.0 && d[b] > 0.0 && (d[a] - d[b]).abs() <= step)
    };
    let mut next = 0u16;
    let mut stack = Vec::new();
    for start in 0..n {
        if class[start] == 0 || id[start] != 0 || depth.is_some_and(|(d, _)| d[start] <= 0.0) {
            continue;
        }
        next = next.saturating_add(1);
        id[start] = next;
        stack.push(start);
        while let Some(p) = stack.pop() {
            let (x, y) = (p % width, p / width);
            let mut visit = |q: usize| {
                if id[q] == 0 && joins(p, q) {
                    id[q] = next;
                    stack.push(q);
                }
            };
            if x > 0 {
                visit(p - 1);
            }
            if x + 1 < width {
                visit(p + 1);
            }
            if y > 0 {
                visit(p - width);
            }
            if y + 1 < height {
                visit(p + width);
            }
        }
    }
    id
}

/// Read a classes file: one name per line, index = class id; blank lines and `#` comments
/// skipped. The error names the file.
pub fn read_classes(path: &std::path::Path) -> Result<Vec<String>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
        path: path.display().to_string(),
        message: format!("{e} (a segmenter's class names, one per output channel, in `classes.txt` beside the model)"),
    })?;
    let names: Vec<String> =
        text.lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).map(str::to_owned).collect();
    if names.is_empty() {
        return Err(Error::Contract(format!("{}: no class names", path.display())));
    }
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dilation_grows_labels_by_the_radius_in_the_chebyshev_metric() {
        let (w, h) = (9, 7);
        let mut c = vec![0u16; w * h];
        c[3 * w + 4] = 2;
        dilate(&mut c, w, h, 2);
        for y in 0..h {
            for x in 0..w {
                let inside = x.abs_diff(4) <= 2 && y.abs_diff(3) <= 2;
                assert_eq!(c[y * w + x], if inside { 2 } else { 0 }, "({x}, {y})");
            }
        }
    }

    #[test]
    fn components_split_by_class_gap_and_depth_step() {
        // Two blobs of class 1 with a gap, and one blob split by a depth step.
        let (w, h) = (6, 2);
        let class = vec![1, 1, 0, 1, 1, 1, 1, 1, 0, 1, 1, 1];
        let id = instances(&class, w, h, None);
        assert_eq!(id, vec![1, 1, 0, 2, 2, 2, 1, 1, 0, 2, 2, 2]);
        let depth = vec![1.0, 1.0, 0.0, 1.0, 3.0, 3.0, 1.0, 1.0, 0.0, 1.0, 3.0, 3.0];
        let id = instances(&class, w, h, Some((&depth, 0.5)));
        assert_eq!(id, vec![1, 1, 0, 2, 3, 3, 1, 1, 0, 2, 3, 3]);
    }
}
