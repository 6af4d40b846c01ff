//! The `synth` source operator: streams generated frames straight into a graph.

use std::sync::Arc;

use dynaflow_engine::msg::{Body, DepthImage, Header, Image, PixelFormat, PortType, Pose, SegmentationMask};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};

use super::{Generator, Motion, PeopleMode, SynthConfig, scaled_fr3};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    motion: String,
    people: u64,
    sitting: bool,
    frames: u64,
    width: u32,
    height: u32,
    rate_hz: f64,
    #[serde(default)]
    seed: Option<u64>,
    depth_noise: bool,
    image_noise: f64,
    blur: bool,
}

pub(crate) const SYNTH: OpSpec = OpSpec {
    name: "synth",
    family: "synth",
    doc: "Semi-synthetic dynamic RGB-D scene with exact ground truth: a textured room with furniture, people walking across the view (or sitting), a TUM-fr3-like camera motion, Kinect-like depth noise/holes/quantisation, image noise and blur. Deterministic by `seed`. `dynaflow synth` writes the same frames as a TUM folder.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[
        PortSpec::output("rgb", PortType::Image, "RGB8 camera image"),
        PortSpec::output("depth", PortType::Depth, "depth in metres (0 = no measurement)"),
        PortSpec::output("camera_info", PortType::CameraInfo, "pinhole intrinsics (TUM fr3, scaled to the resolution)"),
        PortSpec::ground_truth("gt_pose", PortType::Pose, "ground-truth world_from_cam"),
        PortSpec::ground_truth("gt_mask", PortType::Mask, "ground-truth class (0 static, 1 person) and instance masks"),
    ],
    params: &[
        ParamSpec {
            name: "motion",
            ty: ParamType::Enum { values: Motion::NAMES },
            default: Default::Str("xyz"),
            doc: "camera motion, like the TUM fr3 sequences",
        },
        ParamSpec {
            name: "people",
            ty: ParamType::Int { min: 0, max: 16 },
            default: Default::Int(2),
            doc: "number of people",
        },
        ParamSpec {
            name: "sitting",
            ty: ParamType::Bool,
            default: Default::Bool(false),
            doc: "people sit and move little (TUM `sitting`)",
        },
        ParamSpec {
            name: "frames",
            ty: ParamType::Int { min: 1, max: 1_000_000 },
            default: Default::Int(300),
            doc: "number of frames",
        },
        ParamSpec {
            name: "width",
            ty: ParamType::Int { min: 16, max: 4096 },
            default: Default::Int(640),
            doc: "image width (intrinsics scale with it)",
        },
        ParamSpec {
            name: "height",
            ty: ParamType::Int { min: 16, max: 4096 },
            default: Default::Int(480),
            doc: "image height",
        },
        ParamSpec {
            name: "rate_hz",
            ty: ParamType::Float { min: 0.1, max: 1000.0 },
            default: Default::Float(30.0),
            doc: "frame rate",
        },
        ParamSpec {
            name: "seed",
            ty: ParamType::Int { min: 0, max: i64::MAX },
            default: Default::FromGraphSeed,
            doc: "scene and noise seed; unset, it derives from the graph seed (`--seed`) and the node id",
        },
        ParamSpec {
            name: "depth_noise",
            ty: ParamType::Bool,
            default: Default::Bool(true),
            doc: "Kinect depth noise, holes and quantisation",
        },
        ParamSpec {
            name: "image_noise",
            ty: ParamType::Float { min: 0.0, max: 50.0 },
            default: Default::Float(2.0),
            doc: "image noise σ in grey levels",
        },
        ParamSpec { name: "blur", ty: ParamType::Bool, default: Default::Bool(true), doc: "3×3 image blur" },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build,
};

fn build(params: &Params) -> Result<Instance, OpError> {
    let c: Config = params.parse()?;
    let motion = Motion::from_name(&c.motion)
        .ok_or_else(|| OpError::Config { key: "motion".into(), message: format!("unknown motion `{}`", c.motion) })?;
    let config = SynthConfig {
        motion,
        people: c.people as usize,
        mode: if c.sitting { PeopleMode::Sitting } else { PeopleMode::Walking },
        // Replaced in `start` by the node's seed when the graph sets none.
        seed: c.seed.unwrap_or(0),
        rate_hz: c.rate_hz,
        intrinsics: scaled_fr3(c.width, c.height),
        depth_noise: c.depth_noise,
        image_noise: c.image_noise as f32,
        blur: c.blur,
    };
    Ok(Instance::Source(Box::new(SynthSource {
        generator: Generator::new(config),
        seeded: c.seed.is_some(),
        frames: c.frames,
        frame_id: "camera".into(),
    })))
}

struct SynthSource {
    generator: Generator,
    /// Whether the graph gave `seed`; otherwise the node's seed is used.
    seeded: bool,
    frames: u64,
    frame_id: Arc<str>,
}

impl Source for SynthSource {
    fn start(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        if !self.seeded {
            let mut config = self.generator.config().clone();
            config.seed = ctx.seed;
            self.generator = Generator::new(config);
        }
        Ok(())
    }

    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        if seq >= self.frames {
            return Ok(None);
        }
        let f = self.generator.frame(seq, false);
        let k = &self.generator.config().intrinsics;
        let header = Header { seq, stamp: f.stamp, frame_id: self.frame_id.clone() };
        let world = Header { frame_id: "world".into(), ..header.clone() };
        let info = k.clone();
        let mask = SegmentationMask {
            width: k.width,
            height: k.height,
            classes: f.class,
            instances: Some(f.instance),
            class_names: vec!["static".into(), "person".into()],
        };
        Ok(Some(
            Outputs::new()
                .with(
                    "rgb",
                    header.clone(),
                    Body::Image(Image { width: k.width, height: k.height, format: PixelFormat::Rgb8, data: f.rgb }),
                )
                .with(
                    "depth",
                    header.clone(),
                    Body::Depth(DepthImage { width: k.width, height: k.height, data: f.depth }),
                )
                .with("camera_info", header.clone(), Body::CameraInfo(info))
                .with("gt_pose", world, Body::Pose(Pose { world_from_cam: f.world_from_cam }))
                .with("gt_mask", header, Body::Mask(mask)),
        ))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.frames)
    }
}
