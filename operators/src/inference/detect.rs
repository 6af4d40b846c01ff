//! `detect`.

use std::sync::Arc;

use std::path::PathBuf;

use super::runner::{Backend, Runner};
use dynaflow_engine::msg::{Detection, Detections, Image};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::{param_enum, params};
use dynaflow_infer::detect::{Decoder, Detector};
use dynaflow_infer::onnx;

/// The default model, vendored under `models/yolox_nano/` (Apache-2.0, see its SOURCE.md).
pub const YOLOX_NANO: &[u8] = include_bytes!("../../../models/yolox_nano/yolox_nano.onnx");
/// COCO-80 class names (index 0 = person).
pub const COCO_NAMES: &str = include_str!("../../../models/yolox_nano/coco.names");

param_enum! {
    /// How a detector's output is decoded (and its input prepared).
    pub enum DecoderName {
        /// YOLOX: per-anchor boxes, objectness times class score.
        Yolox = "yolox",
        /// FastestDet: one box per grid cell.
        FastestDet = "fastestdet",
    }
}

params! {
    struct Config {
        /// ONNX model file; empty: the embedded YOLOX-nano (COCO-80)
        model: PathBuf = PathBuf::new(),
        /// how the model's output is decoded (and its input prepared)
        decoder: DecoderName = DecoderName::Yolox,
        /// where the model runs: `cpu` (rten: SIMD, multi-threaded), `wgpu` (our planned executor on any Vulkan, Metal or DX12 adapter: one submit per frame) or `reference` (plain loops, the oracle the others are tested against; slow). Without an adapter, or for a model the GPU plan cannot take, `wgpu` falls back to `cpu` with a warning (and says so in the summary)
        backend: Backend = Backend::Cpu,
        /// detections scoring below this are dropped (YOLOX's demo: 0.3)
        score_threshold: f64 [0.0, 1.0] = 0.3,
        /// overlap above which a lower-scored box of the same class is suppressed (YOLOX: 0.45)
        nms_iou: f64 [0.0, 1.0] = 0.45,
        /// `wgpu`: use a software adapter (Mesa's lavapipe, WARP) too; otherwise such an adapter counts as no GPU and the model runs on the CPU (rten, about 40x faster than lavapipe on the same cores)
        allow_software: bool = false,
    }
}

const IMAGE: In<Image> = In::required("image", "RGB8 image");
const DETECTIONS: Out<Detections> = Out::new("detections", "boxes, classes and scores, highest score first");

impl DecoderName {
    /// The decoder it names.
    pub fn decoder(self) -> Decoder {
        match self {
            DecoderName::Yolox => Decoder::Yolox,
            DecoderName::FastestDet => Decoder::FastestDet,
        }
    }
}

/// The `detect` operator (its doc: `dynaflow ops detect`).
pub const DETECT: OpSpec = OpSpec::transform(
    "detect",
    "inference",
    dynaflow_engine::op::doc_line(include_str!("docs/detect.md")),
    |p: &Params| {
        let c = Config::from_params(p)?;
        let embedded = c.model.as_os_str().is_empty();
        let (model, bytes) = if embedded {
            let m = onnx::parse(YOLOX_NANO).map_err(|e| OpError::Input(format!("embedded YOLOX-nano: {e}")))?;
            (m, YOLOX_NANO.to_vec())
        } else {
            onnx::load_with_bytes(&c.model).map_err(OpError::library)?
        };
        let decoder = c.decoder.decoder();
        let which = if embedded { "the embedded YOLOX-nano".to_owned() } else { c.model.display().to_string() };
        let detector = Detector::new(model, decoder).map_err(|e| OpError::Input(format!("{which}: {e}")))?;
        let names: Vec<Arc<str>> = COCO_NAMES.lines().map(Arc::from).collect();
        let (runner, backend) =
            Runner::new(&bytes, detector.model(), c.backend, c.allow_software).map_err(OpError::library)?;
        Ok(Instance::Transform(Box::new(Detect { config: c, detector, names, runner, backend })))
    },
)
.inputs(&[IMAGE.spec])
.outputs(&[DETECTIONS.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct Detect {
    config: Config,
    detector: Detector,
    names: Vec<Arc<str>>,
    runner: Runner,
    /// What runs the model, for the summary.
    backend: String,
}

impl Operator for Detect {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, img) = IMAGE.require(inputs)?;
        let (w, h) = (img.width as usize, img.height as usize);
        let rgb = super::rgb_pixels(img);
        let (score, iou) = (self.config.score_threshold as f32, self.config.nms_iou as f32);
        let classes = self.names.len();
        let runner = &self.runner;
        let found = self
            .detector
            .detect_with(&rgb, w, h, classes, score, iou, |name, input| runner.run(name, input))
            .map_err(OpError::library)?;
        let detections = found
            .into_iter()
            .map(|d| Detection {
                bbox: d.bbox,
                class_id: d.class as u32,
                label: self.names.get(d.class).cloned().unwrap_or_else(|| Arc::from(format!("class{}", d.class))),
                score: d.score,
            })
            .collect();
        Ok(Outputs::new().send(&DETECTIONS, msg.header.clone(), Detections { detections }))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let report = crate::report::InferenceReport { backend: self.backend.clone() };
        ctx.report = Some(crate::report::NodeReport::from(report).to_json());
        Ok(())
    }
}
