//! `orb_extract`.

use dynaflow_engine::msg::{Body, Descriptors, Keypoint, Keypoints, PortType};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_vision::GrayImage;
use dynaflow_vision::orb::{Distribution, OrbConfig, OrbExtractor};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    features: u64,
    scale_factor: f64,
    levels: u64,
    ini_threshold: u64,
    min_threshold: u64,
    distribution: String,
}

pub const ORB_EXTRACT: OpSpec = OpSpec {
    name: "orb_extract",
    family: "orb",
    doc: "ORB features as ORB-SLAM2/3 extract them: an image pyramid, FAST-9 per 30-px cell (threshold `ini_threshold`, or `min_threshold` where a cell has none), a quadtree spreading exactly `features` keypoints over the image (or OpenCV's Harris ranking with `distribution: harris`), intensity-centroid orientation and 256-bit steered BRIEF with the learned ORB pattern. No keypoint lies on a non-zero pixel of `mask`.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("image", PortType::Image, "RGB8 or grey image"),
        PortSpec::optional("mask", PortType::Mask, "pixels of a non-zero class get no keypoint (e.g. people)"),
    ],
    outputs: &[PortSpec::output(
        "keypoints",
        PortType::Keypoints,
        "keypoints (level-0 pixels, octave, angle in degrees, FAST response) with 32-byte descriptors",
    )],
    params: &[
        ParamSpec {
            name: "features",
            ty: ParamType::Int { min: 1, max: 100_000 },
            default: Default::Int(1000),
            doc: "keypoints wanted over all levels",
        },
        ParamSpec {
            name: "scale_factor",
            ty: ParamType::Float { min: 1.01, max: 4.0 },
            default: Default::Float(1.2),
            doc: "scale between pyramid levels",
        },
        ParamSpec {
            name: "levels",
            ty: ParamType::Int { min: 1, max: 16 },
            default: Default::Int(8),
            doc: "pyramid levels",
        },
        ParamSpec {
            name: "ini_threshold",
            ty: ParamType::Int { min: 1, max: 254 },
            default: Default::Int(20),
            doc: "FAST threshold tried first in each cell (ORB-SLAM's iniThFAST)",
        },
        ParamSpec {
            name: "min_threshold",
            ty: ParamType::Int { min: 1, max: 254 },
            default: Default::Int(7),
            doc: "FAST threshold for cells with no corner at the first (minThFAST)",
        },
        ParamSpec {
            name: "distribution",
            ty: ParamType::Enum { values: &["quadtree", "harris"] },
            default: Default::Str("quadtree"),
            doc: "`quadtree`: ORB-SLAM's spread over the whole image (weak texture too); `harris`: OpenCV's ORB, the strongest Harris corners (more repeatable between two views, no spreading)",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let c: Config = p.parse()?;
        let config = OrbConfig {
            features: c.features as usize,
            scale_factor: c.scale_factor as f32,
            levels: c.levels as usize,
            ini_threshold: c.ini_threshold.min(254) as u8,
            min_threshold: c.min_threshold.min(254) as u8,
            distribution: if c.distribution == "harris" { Distribution::Harris } else { Distribution::Quadtree },
            ..OrbConfig::default()
        };
        Ok(Instance::Transform(Box::new(OrbOp(OrbExtractor::new(config)))))
    },
};

struct OrbOp(OrbExtractor);

impl Operator for OrbOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("image")?;
        let img = super::gray(msg)?;
        let mask = match inputs.get("mask").map(|m| &m.body) {
            Some(Body::Mask(m)) => {
                if (m.width as usize, m.height as usize) != (img.width, img.height) {
                    return Err(OpError::Input(format!(
                        "`mask` is {}x{} but `image` is {}x{}: a mask must cover the image pixel for pixel",
                        m.width, m.height, img.width, img.height
                    )));
                }
                let data = m.classes.iter().map(|&c| u8::from(c != 0)).collect();
                GrayImage::from_vec(m.width as usize, m.height as usize, data)
            }
            _ => None,
        };
        let f = self.0.extract(&img, mask.as_ref());
        let points = f
            .keypoints
            .iter()
            .map(|k| Keypoint { x: k.x, y: k.y, size: k.size, angle: k.angle, response: k.response, octave: k.octave })
            .collect();
        let descriptors = Descriptors { bytes_per: 32, data: f.descriptors.concat() };
        let body = Body::Keypoints(Keypoints { points, descriptors: Some(descriptors) });
        Ok(Outputs::new().with("keypoints", msg.header.clone(), body))
    }
}
