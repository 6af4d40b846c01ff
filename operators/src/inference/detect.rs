//! `detect`.

use std::sync::Arc;

use dynaflow_engine::msg::{Body, Detection, Detections, PixelFormat, PortType};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_infer::cpu::{self, Tensor};
use dynaflow_infer::detect::{Letterbox, decode_fastestdet, decode_yolox, letterbox_bgr, nms, resize_bgr_unit};
use dynaflow_infer::onnx::{self, Model};

/// The default model, vendored under `models/yolox_nano/` (Apache-2.0, see its SOURCE.md).
const YOLOX_NANO: &[u8] = include_bytes!("../../../models/yolox_nano/yolox_nano.onnx");
/// COCO-80 class names (index 0 = person).
const COCO_NAMES: &str = include_str!("../../../models/yolox_nano/coco.names");

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    model: String,
    decoder: String,
    /// Only `cpu` exists yet; kept so graphs can name it.
    #[allow(dead_code)]
    backend: String,
    score_threshold: f64,
    nms_iou: f64,
}

pub const DETECT: OpSpec = OpSpec {
    name: "detect",
    family: "inference",
    doc: "Object detection with an ONNX model: YOLOX (letterbox, BGR 0..255, grid decoding, score obj x cls) or FastestDet (resize, BGR 0..1, tanh/sigmoid box decoding, score obj^0.6 x cls^0.4), then class-wise NMS; boxes in image pixels with COCO class names. The default model is the vendored YOLOX-nano (embedded in the binary). Backend `cpu` is the reference executor (plain loops, checked against onnxruntime); the wgpu executor is being built (issue 12).",
    kind: OpKind::Transform,
    inputs: &[PortSpec::input("image", PortType::Image, "RGB8 image")],
    outputs: &[PortSpec::output("detections", PortType::Detections, "boxes, classes and scores, highest score first")],
    params: &[
        ParamSpec {
            name: "model",
            ty: ParamType::Path,
            default: Default::Str(""),
            doc: "ONNX model file; empty: the embedded YOLOX-nano (COCO-80)",
        },
        ParamSpec {
            name: "decoder",
            ty: ParamType::Enum { values: &["yolox", "fastestdet"] },
            default: Default::Str("yolox"),
            doc: "how the model's output is decoded (and its input prepared)",
        },
        ParamSpec {
            name: "backend",
            ty: ParamType::Enum { values: &["cpu"] },
            default: Default::Str("cpu"),
            doc: "where the model runs: `cpu`, the reference executor",
        },
        ParamSpec {
            name: "score_threshold",
            ty: ParamType::Float { min: 0.0, max: 1.0 },
            default: Default::Float(0.3),
            doc: "detections scoring below this are dropped (YOLOX's demo: 0.3)",
        },
        ParamSpec {
            name: "nms_iou",
            ty: ParamType::Float { min: 0.0, max: 1.0 },
            default: Default::Float(0.45),
            doc: "overlap above which a lower-scored box of the same class is suppressed (YOLOX: 0.45)",
        },
    ],
    cpu_heavy: true,
    build: |p: &Params| {
        let c: Config = p.parse()?;
        let model = if c.model.is_empty() {
            onnx::parse(YOLOX_NANO).map_err(|e| OpError::Input(format!("embedded YOLOX-nano: {e}")))?
        } else {
            onnx::load(&p.resolve_path(&c.model)).map_err(|e| OpError::Input(e.to_string()))?
        };
        cpu::check_ops(&model).map_err(|e| OpError::Input(e.to_string()))?;
        let input = model.inputs.first().ok_or_else(|| OpError::Input("the model has no input".into()))?;
        let dims: Vec<usize> = input.shape.iter().map(|d| d.unwrap_or(0).max(0) as usize).collect();
        let side = match dims.as_slice() {
            [1, 3, h, w] if h == w && *h > 0 => *h,
            _ => {
                return Err(OpError::Input(format!(
                    "model input `{}` has shape {:?}; `detect` takes a fixed square 1x3xSxS input",
                    input.name, input.shape
                )));
            }
        };
        let input_name = input.name.clone();
        let names: Vec<Arc<str>> = COCO_NAMES.lines().map(Arc::from).collect();
        Ok(Instance::Transform(Box::new(Detect { config: c, model, input_name, side, names })))
    },
};

struct Detect {
    config: Config,
    model: Model,
    input_name: String,
    side: usize,
    names: Vec<Arc<str>>,
}

impl Operator for Detect {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("image")?;
        let Body::Image(img) = &msg.body else { return Err(OpError::Input("`image` is not an image".into())) };
        let (w, h, s) = (img.width as usize, img.height as usize, self.side);
        let grey_as_rgb: Vec<u8>;
        let rgb: &[u8] = match img.format {
            PixelFormat::Rgb8 => &img.data,
            PixelFormat::Gray8 => {
                grey_as_rgb = img.data.iter().flat_map(|&v| [v, v, v]).collect();
                &grey_as_rgb
            }
        };
        let yolox = self.config.decoder == "yolox";
        let (x, lb) = if yolox {
            letterbox_bgr(rgb, w, h, s)
        } else {
            (resize_bgr_unit(rgb, w, h, s), Letterbox { scale: 1.0, size: s })
        };
        let out =
            cpu::run(&self.model, &[(self.input_name.as_str(), Tensor::F32 { shape: vec![1, 3, s, s], data: x })])
                .map_err(|e| OpError::Input(e.to_string()))?;
        let raw = out.first().map(Tensor::floats).unwrap_or_default();
        let classes = self.names.len();
        let threshold = self.config.score_threshold as f32;
        let dets = if yolox {
            decode_yolox(&raw, classes, &lb, threshold)
        } else {
            let grid = out.first().map_or(0, |t| t.shape().last().copied().unwrap_or(0));
            decode_fastestdet(&raw, classes, grid, w as f32, h as f32, threshold)
        };
        let detections = nms(dets, self.config.nms_iou as f32)
            .into_iter()
            .map(|d| Detection {
                bbox: [d.bbox[0].max(0.0), d.bbox[1].max(0.0), d.bbox[2].min(w as f32), d.bbox[3].min(h as f32)],
                class_id: d.class as u32,
                label: self.names.get(d.class).cloned().unwrap_or_else(|| Arc::from(format!("class{}", d.class))),
                score: d.score,
            })
            .collect();
        Ok(Outputs::new().with("detections", msg.header.clone(), Body::Detections(Detections { detections })))
    }
}
