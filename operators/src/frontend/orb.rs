//! `orb_extract`.

use dynaflow_engine::msg::{Descriptors, Image, Keypoints, SegmentationMask};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::{param_enum, params};
use dynaflow_vision::GrayImage;
use dynaflow_vision::orb::{Distribution, OrbConfig, OrbExtractor};

param_enum! {
    /// How keypoints are chosen among the FAST corners.
    enum Spread { Quadtree = "quadtree", Harris = "harris" }
}

params! {
    pub(super) struct Config {
        /// keypoints wanted over all levels
        features: u64 [1, 100_000] = 1000,
        /// scale between pyramid levels
        scale_factor: f64 [1.01, 4.0] = 1.2,
        /// pyramid levels
        levels: u64 [1, 16] = 8,
        /// FAST threshold tried first in each cell (ORB-SLAM's iniThFAST)
        ini_threshold: u64 [1, 254] = 20,
        /// FAST threshold for cells with no corner at the first (minThFAST)
        min_threshold: u64 [1, 254] = 7,
        /// `quadtree`: ORB-SLAM's spread over the whole image (weak texture too); `harris`: OpenCV's ORB, the strongest Harris corners (more repeatable between two views, no spreading)
        distribution: Spread = Spread::Quadtree,
    }
}

const IMAGE: In<Image> = In::required("image", "RGB8 or grey image");
const MASK: In<SegmentationMask> = In::optional("mask", "pixels of a non-zero class get no keypoint (e.g. people)");
const KEYPOINTS: Out<Keypoints> = Out::new(
    "keypoints",
    "keypoints (level-0 pixels, octave, angle in degrees, FAST response) with 32-byte descriptors",
);

/// The `orb_extract` operator (its doc: `dynaflow ops orb_extract`).
pub const ORB_EXTRACT: OpSpec = OpSpec::transform(
    "orb_extract",
    "orb",
    dynaflow_engine::op::doc_line(include_str!("docs/orb_extract.md")),
    |p: &Params| Ok(Instance::Transform(Box::new(OrbOp(OrbExtractor::new(orb_config(&Config::from_params(p)?)))))),
)
.inputs(&[IMAGE.spec, MASK.spec])
.outputs(&[KEYPOINTS.spec])
.params(Config::PARAMS)
.cpu_heavy();

/// The extractor's settings from the operator's parameters (`stereo_match` extracts its right
/// image with the same ones).
pub(super) fn orb_config(c: &Config) -> OrbConfig {
    OrbConfig {
        features: c.features as usize,
        scale_factor: c.scale_factor as f32,
        levels: c.levels as usize,
        ini_threshold: c.ini_threshold.min(254) as u8,
        min_threshold: c.min_threshold.min(254) as u8,
        distribution: match c.distribution {
            Spread::Quadtree => Distribution::Quadtree,
            Spread::Harris => Distribution::Harris,
        },
        ..OrbConfig::default()
    }
}

struct OrbOp(OrbExtractor);

impl Operator for OrbOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, image) = IMAGE.require(inputs)?;
        let img = super::gray(image)?;
        let mask = match MASK.get(inputs)? {
            Some(m) => {
                if (m.width as usize, m.height as usize) != (img.width, img.height) {
                    return Err(OpError::Input(format!(
                        "`mask` is {}x{} but `image` is {}x{}: a mask must cover the image pixel for pixel",
                        m.width, m.height, img.width, img.height
                    )));
                }
                let data = m.classes.iter().map(|&c| u8::from(c != 0)).collect();
                GrayImage::from_vec(m.width as usize, m.height as usize, data)
            }
            None => None,
        };
        let f = self.0.extract(&img, mask.as_ref());
        let points = f.keypoints;
        let descriptors = Descriptors { bytes_per: 32, data: f.descriptors.concat() };
        let keypoints = Keypoints { points, descriptors: Some(descriptors) };
        Ok(Outputs::new().send(&KEYPOINTS, msg.header.clone(), keypoints))
    }
}
