//! `segment`.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use super::runner::{Backend, Runner};
use dynaflow_engine::msg::{DepthImage, Image, SegmentationMask};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::{param_enum, params};
use dynaflow_infer::onnx;
use dynaflow_infer::segment::{self, Normalise, Segmenter};

/// The default segmenter, vendored under `models/seg/pp_humansegv2_lite/` (Apache-2.0, see
/// its SOURCE.md): PP-HumanSegV2-Lite, person vs background, 256x144.
pub const PP_HUMANSEG: &[u8] = include_bytes!("../../../models/seg/pp_humansegv2_lite/pp_humansegv2_lite_256x144.onnx");
/// Its class names.
pub const PP_HUMANSEG_CLASSES: &str = include_str!("../../../models/seg/pp_humansegv2_lite/classes.txt");

param_enum! {
    /// How pixels are scaled into a segmenter's input (its SOURCE.md says which).
    pub enum InputRange {
        /// `pixel / 255` (MediaPipe's selfie segmenter).
        Unit = "unit",
        /// `pixel / 127.5 - 1` (PP-HumanSeg, DeepLabV3).
        Symmetric = "symmetric",
    }
}

params! {
    struct Config {
        /// ONNX segmenter; empty: the embedded PP-HumanSegV2-Lite (person vs background)
        model: PathBuf = PathBuf::new(),
        /// class names, one per output channel; empty: `classes.txt` beside the model
        classes: PathBuf = PathBuf::new(),
        /// how pixels are scaled into the model's input: `symmetric` [-1, 1] (PP-HumanSeg, DeepLabV3) or `unit` [0, 1] (MediaPipe)
        input_range: InputRange = InputRange::Symmetric,
        /// where the model runs: `cpu` (rten), `wgpu` (our executor; falls back to `cpu` with a warning) or `reference` (plain loops, the oracle)
        backend: Backend = Backend::Cpu,
        /// `wgpu`: use a software adapter (lavapipe) too
        allow_software: bool = false,
        /// probability a pixel needs for its class (the models' own decision boundary, 0.5); below it the pixel is background
        threshold: f64 [0.0, 1.0] = 0.5,
        /// grow every class region by this many pixels (square): 15 = ORB-SLAM2's HALF_PATCH_SIZE, so no keypoint whose 31x31 descriptor patch overlaps a person is left outside the mask (culling wants recall)
        dilate: u64 [0, 255] = 15,
        /// with `depth` wired: neighbouring pixels whose depths differ by more than this (metres) belong to different instances (4 sigma of Kinect v1 depth noise at 4 m, as `cull_depth`: one body's neighbouring pixels stay together)
        depth_step: f64 [0.001, 10.0] = 0.1,
    }
}

const IMAGE: In<Image> = In::required("image", "RGB8 image");
const DEPTH: In<DepthImage> =
    In::optional("depth", "depth in metres, same image: instances are also split where depth jumps by `depth_step`");
const MASK: Out<SegmentationMask> = Out::new(
    "mask",
    "class per pixel (the model's class ids and names, 0 = background) at the image's size; instances = connected components",
);

/// The `segment` operator (its doc: `dynaflow ops segment`).
pub const SEGMENT: OpSpec = OpSpec::transform(
    "segment",
    "inference",
    dynaflow_engine::op::doc_line(include_str!("docs/segment.md")),
    |p: &Params| {
        let c = Config::from_params(p)?;
        let (segmenter, runner, backend) = load(&c.model, &c.classes, c.input_range, c.backend, c.allow_software)?;
        let names = segmenter.classes().iter().map(|s| Arc::from(s.as_str())).collect();
        Ok(Instance::Transform(Box::new(Segment { config: c, segmenter, names, runner, backend })))
    },
)
.inputs(&[IMAGE.spec, DEPTH.spec])
.outputs(&[MASK.spec])
.params(Config::PARAMS)
.cpu_heavy();

impl InputRange {
    /// The normalisation it names.
    pub fn normalise(self) -> Normalise {
        match self {
            InputRange::Unit => Normalise::Unit,
            InputRange::Symmetric => Normalise::Symmetric,
        }
    }
}

/// Load a segmenter (`model` empty: the embedded PP-HumanSeg) with its class names (`classes`
/// empty: `classes.txt` beside the model) on `backend`: the segmenter, its runner and what
/// runs it. Errors are the `model` or `classes` parameter's, naming the file; the model's
/// shapes are checked before its class names are read.
pub fn load(
    model: &Path,
    classes: &Path,
    range: InputRange,
    backend: Backend,
    allow_software: bool,
) -> Result<(Segmenter, Runner, String), OpError> {
    let embedded = model.as_os_str().is_empty();
    let which = if embedded { "the embedded PP-HumanSegV2-Lite".to_owned() } else { model.display().to_string() };
    let bad = |key: &str, message: String| OpError::Config { key: key.into(), message };
    let (parsed, bytes) = if embedded {
        (onnx::parse(PP_HUMANSEG).map_err(|e| bad("model", format!("{which}: {e}")))?, PP_HUMANSEG.to_vec())
    } else {
        onnx::load_with_bytes(model).map_err(|e| bad("model", e.to_string()))?
    };
    segment::contract(&parsed).map_err(|e| bad("model", format!("{which}: {e}")))?;
    let names = if !classes.as_os_str().is_empty() {
        segment::read_classes(classes).map_err(|e| bad("classes", format!("{which}: {e}")))?
    } else if embedded {
        PP_HUMANSEG_CLASSES.lines().map(str::to_owned).collect()
    } else {
        let beside = model.with_file_name("classes.txt");
        segment::read_classes(&beside).map_err(|e| bad("classes", format!("{which}: {e}")))?
    };
    let segmenter =
        Segmenter::new(parsed, names, range.normalise()).map_err(|e| bad("model", format!("{which}: {e}")))?;
    let (runner, backend) = Runner::new(&bytes, segmenter.model(), backend, allow_software)
        .map_err(|e| bad("model", format!("{which}: {e}")))?;
    Ok((segmenter, runner, backend))
}

/// Segment one RGB8 (or grey) frame: the class map after threshold and dilation, and its
/// instances (split at depth jumps when `depth` is given).
pub fn segment_frame(
    segmenter: &Segmenter,
    runner: &Runner,
    img: &Image,
    threshold: f32,
    dilate: usize,
    depth: Option<(&[f32], f32)>,
) -> Result<(Vec<u16>, Vec<u16>), String> {
    let (w, h) = (img.width as usize, img.height as usize);
    let input = segmenter.input(&super::rgb_pixels(img), w, h);
    let outputs = runner.run(segmenter.input_name(), input).map_err(|e| e.to_string())?;
    let first = outputs.first().ok_or("the model gave no output")?;
    let mut map = segmenter.decode(first, w, h, threshold).map_err(|e| e.to_string())?;
    segment::dilate(&mut map.class, w, h, dilate);
    let instances = segment::instances(&map.class, w, h, depth);
    Ok((map.class, instances))
}

struct Segment {
    config: Config,
    segmenter: Segmenter,
    names: Vec<Arc<str>>,
    runner: Runner,
    /// What runs the model, for the summary.
    backend: String,
}

impl Operator for Segment {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, img) = IMAGE.require(inputs)?;
        let depth = DEPTH.get(inputs)?;
        if let Some(d) = depth
            && (d.width, d.height) != (img.width, img.height)
        {
            return Err(OpError::Input(format!(
                "depth is {}x{} but the image is {}x{}",
                d.width, d.height, img.width, img.height
            )));
        }
        let (classes, instances) = segment_frame(
            &self.segmenter,
            &self.runner,
            img,
            self.config.threshold as f32,
            self.config.dilate as usize,
            depth.map(|d| (d.data.as_slice(), self.config.depth_step as f32)),
        )
        .map_err(OpError::Input)?;
        let mask = SegmentationMask {
            width: img.width,
            height: img.height,
            classes,
            instances: Some(instances),
            class_names: self.names.clone(),
        };
        Ok(Outputs::new().send(&MASK, msg.header.clone(), mask))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let report = crate::report::InferenceReport { backend: self.backend.clone() };
        ctx.report = Some(crate::report::NodeReport::from(report).to_json());
        Ok(())
    }
}
