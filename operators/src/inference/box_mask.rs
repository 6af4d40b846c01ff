//! `box_to_mask`.

use std::sync::Arc;

use dynaflow_engine::msg::{DepthImage, Detections, SegmentationMask};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;

use super::{ClassName, class_list};
use crate::culling::rules::box_depth_mask;

params! {
    struct Config {
        /// class names to mask (the seed papers' dynamic priors start with people)
        classes: Vec<ClassName> = class_list(&["person"]),
        /// metres around the foreground depth that belong to the object (a person is about 0.3-0.5 m deep)
        tolerance: f64 [0.01, 10.0] = 0.4,
        /// depth histogram bin, metres
        bin: f64 [0.005, 1.0] = 0.1,
    }
}

const DETECTIONS: In<Detections> = In::required("detections", "boxes");
const DEPTH: In<DepthImage> = In::required("depth", "depth in metres, same image");
const MASK: Out<SegmentationMask> =
    Out::new("mask", "class 0 static, k the k-th class of `classes` (named in the mask); instance = box index + 1");

/// The `box_to_mask` operator (its doc: `dynaflow ops box_to_mask`).
pub const BOX_TO_MASK: OpSpec = OpSpec::transform(
    "box_to_mask",
    "inference",
    dynaflow_engine::op::doc_line(include_str!("docs/box_to_mask.md")),
    |p: &Params| Ok(Instance::Transform(Box::new(BoxToMask { config: Config::from_params(p)? }))),
)
.inputs(&[DETECTIONS.spec, DEPTH.spec])
.outputs(&[MASK.spec])
.params(Config::PARAMS);

struct BoxToMask {
    config: Config,
}

impl Operator for BoxToMask {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, d) = DETECTIONS.require(inputs)?;
        let (_, depth) = DEPTH.require(inputs)?;
        // One class id per listed class (1, 2, ... in the order given; 0 is static).
        let wanted: Vec<&str> = self.config.classes.iter().map(ClassName::as_str).collect();
        let mut boxes: Vec<(f32, [f32; 4], u16)> = d
            .detections
            .iter()
            .filter_map(|x| {
                let class = wanted.iter().position(|w| *w == &*x.label)?;
                Some((x.score, x.bbox, u16::try_from(class + 1).unwrap_or(u16::MAX)))
            })
            .collect();
        // Ascending score: the best box is drawn last and wins overlaps.
        boxes.sort_by(|a, b| a.0.total_cmp(&b.0));
        let rects: Vec<[f32; 4]> = boxes.iter().map(|b| b.1).collect();
        let (w, h) = (depth.width as usize, depth.height as usize);
        let instances = box_depth_mask(&rects, &depth.data, w, h, self.config.bin as f32, self.config.tolerance as f32);
        // Instance k + 1 is box k's.
        let classes = instances
            .iter()
            .map(|&i| if i == 0 { 0 } else { boxes.get(usize::from(i) - 1).map_or(0, |b| b.2) })
            .collect();
        let class_names = std::iter::once("static").chain(wanted.iter().copied()).map(Arc::from).collect();
        let mask = SegmentationMask {
            width: depth.width,
            height: depth.height,
            classes,
            instances: Some(instances),
            class_names,
        };
        Ok(Outputs::new().send(&MASK, msg.header.clone(), mask))
    }
}
