//! `testing.test_pattern`: a moving colour gradient and a frame counter.

use std::sync::Arc;

use dynaflow_engine::msg::{Header, Image, PixelFormat, Scalars};
use dynaflow_engine::op::{Context, Instance, OpError, OpKind, OpSpec, Out, Outputs, Params, Source};
use dynaflow_engine::params;

params! {
    /// `testing.test_pattern` configuration.
    struct Config {
        /// number of frames
        frames: u64 [1, 100_000_000] = 300,
        /// image width in pixels
        width: u32 [1, 8192] = 64,
        /// image height in pixels
        height: u32 [1, 8192] = 48,
        /// frame rate that sets the stamps (and pacing with --realtime)
        rate_hz: f64 [0.001, 10_000.0] = 30.0,
    }
}

const IMAGE: Out<Image> = Out::new("image", "RGB8 gradient shifted by one pixel per frame");
const TICK: Out<Scalars> = Out::new("tick", "`frame` = sequence number, `time` = stamp in seconds");

pub(super) const TEST_PATTERN: OpSpec = OpSpec {
    name: "testing.test_pattern",
    family: "testing",
    doc: "Testing only (engine tests and benchmarks; the `testing.` prefix marks it): A moving RGB gradient and a frame counter at a fixed rate. For engine tests and smoke runs; it is not a camera model and feeds no SLAM result.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: &[IMAGE.spec, TICK.spec],
    params: Config::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: build_test_pattern,
};

fn build_test_pattern(params: &Params) -> Result<Instance, OpError> {
    let config = Config::from_params(params)?;
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
        Ok(Some(Outputs::new().send(&IMAGE, header.clone(), img).send(&TICK, header, tick)))
    }

    fn len_hint(&self) -> Option<u64> {
        Some(self.config.frames)
    }
}
