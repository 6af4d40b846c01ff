//! `box_to_mask`.

use std::sync::Arc;

use dynaflow_engine::msg::{Body, PortType, SegmentationMask};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};

use crate::culling::rules::box_depth_mask;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    classes: String,
    tolerance: f64,
    bin: f64,
}

pub const BOX_TO_MASK: OpSpec = OpSpec {
    name: "box_to_mask",
    family: "inference",
    doc: "A segmentation mask from detector boxes and depth, so mask-based culling rules run with a detector: inside each box of a listed class, the pixels near the object's dominant foreground depth (the nearest depth-histogram bin holding at least half as many pixels as the fullest) are the object's. Class 1 is every masked pixel; instances are the boxes.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("detections", PortType::Detections, "boxes"),
        PortSpec::input("depth", PortType::Depth, "depth in metres, same image"),
    ],
    outputs: &[PortSpec::output(
        "mask",
        PortType::Mask,
        "class 0 static, k the k-th class of `classes` (named in the mask); instance = box index + 1",
    )],
    params: &[
        ParamSpec {
            name: "classes",
            ty: ParamType::Str,
            default: Default::Str("person"),
            doc: "comma-separated class names to mask (the seed papers' dynamic priors start with people)",
        },
        ParamSpec {
            name: "tolerance",
            ty: ParamType::Float { min: 0.01, max: 10.0 },
            default: Default::Float(0.4),
            doc: "metres around the foreground depth that belong to the object (a person is about 0.3-0.5 m deep)",
        },
        ParamSpec {
            name: "bin",
            ty: ParamType::Float { min: 0.005, max: 1.0 },
            default: Default::Float(0.1),
            doc: "depth histogram bin, metres",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let config: Config = p.parse()?;
        super::known_classes("classes", &config.classes)?;
        Ok(Instance::Transform(Box::new(BoxToMask { config })))
    },
};

struct BoxToMask {
    config: Config,
}

impl Operator for BoxToMask {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("detections")?;
        let Body::Detections(d) = &msg.body else {
            return Err(OpError::Input("`detections` is not detections".into()));
        };
        let Body::Depth(depth) = &inputs.require("depth")?.body else {
            return Err(OpError::Input("`depth` is not a depth image".into()));
        };
        // One class id per listed class (1, 2, ... in the order given; 0 is static).
        let wanted: Vec<&str> = self.config.classes.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
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
        Ok(Outputs::new().with("mask", msg.header.clone(), Body::Mask(mask)))
    }
}
