//! `testing.test_pattern`: a moving colour gradient and a frame counter.

use std::sync::Arc;

use dynaflow_engine::msg::{Body, Header, Image, PixelFormat, PortType, Scalars};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};

/// `testing.test_pattern` configuration.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    frames: u64,
    width: u32,
    height: u32,
    rate_hz: f64,
}

pub(super) const TEST_PATTERN: OpSpec = OpSpec {
    name: "testing.test_pattern",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): A moving RGB gradient and a frame counter at a fixed rate. For engine tests and smoke runs; it is not a camera model and feeds no SLAM result.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[
        PortSpec::output("image", PortType::Image, "RGB8 gradient shifted by one pixel per frame"),
        PortSpec::output("tick", PortType::Scalars, "`frame` = sequence number, `time` = stamp in seconds"),
    ],
    params: &[
        ParamSpec {
            name: "frames",
            ty: ParamType::Int { min: 1, max: 100_000_000 },
            default: Default::Int(300),
            doc: "number of frames",
        },
        ParamSpec {
            name: "width",
            ty: ParamType::Int { min: 1, max: 8192 },
            default: Default::Int(64),
            doc: "image width in pixels",
        },
        ParamSpec {
            name: "height",
            ty: ParamType::Int { min: 1, max: 8192 },
            default: Default::Int(48),
            doc: "image height in pixels",
        },
        ParamSpec {
            name: "rate_hz",
            ty: ParamType::Float { min: 0.001, max: 10_000.0 },
            default: Default::Float(30.0),
            doc: "frame rate that sets the stamps (and pacing with --realtime)",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: build_test_pattern,
};

fn build_test_pattern(params: &Params) -> Result<Instance, OpError> {
    let config: Config = params.parse()?;
    Ok(Instance::Source(Box::new(TestPattern { config, frame_id: "camera".into() })))
}

struct TestPattern {
    config: Config,
    frame_id: Arc<str>,
}

impl Source for TestPattern {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        if seq >= self.config.frames {
            return Ok(None);
        }
        let (w, h) = (self.config.width, self.config.height);
        let mut img = Image::zeros(w, h, PixelFormat::Rgb8);
        for (i, px) in img.data.chunks_exact_mut(3).enumerate() {
            let x = (i as u64 % u64::from(w) + seq) as u8;
            let y = (i as u64 / u64::from(w)) as u8;
            px.copy_from_slice(&[x, y, x ^ y]);
        }
        let stamp = seq as f64 / self.config.rate_hz;
        let header = Header { seq, stamp, frame_id: self.frame_id.clone() };
        let tick = Scalars { values: vec![("frame".into(), seq as f64), ("time".into(), stamp)] };
        Ok(Some(Outputs::new().with("image", header.clone(), Body::Image(img)).with(
            "tick",
            header,
            Body::Scalars(tick),
        )))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.config.frames)
    }
}
