//! `keyframe_gate`.

use dynaflow_engine::msg::{Image, Scalars};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;

params! {
    struct Config {
        /// re-segment when the previous frame had fewer dynamic points than this (0: never)
        dynamic_below: u64 [0, 1_000_000] = 10,
        /// re-segment at least every this many frames (MG-SLAM: four)
        max_gap: u64 [1, 1_000_000] = 4,
    }
}

/// Why a frame went to inference (the `rule` scalar); 0: it did not.
const RULES: [&str; 6] = ["skipped", "first", "relocalised", "few_dynamic", "keyframe", "gap"];

const IMAGE: In<Image> = In::required("image", "this frame");
const TRACKING: In<Scalars> = In::optional("tracking", "`pnp_track.stats` of the previous frame (`delay: 1`)");
const COUNTS: In<Scalars> = In::optional("counts", "culling counts (`dynamic`) of the previous frame (`delay: 1`)");
const IMAGE_OUT: Out<Image> = Out::new("image", "the frame, on key segmentation frames only");
const STATS: Out<Scalars> =
    Out::new("stats", "`infer` (0/1), `rule` (0 skipped, 1 first, 2 relocalised, 3 few_dynamic, 4 keyframe, 5 gap)");

/// The `keyframe_gate` operator (its doc: `dynaflow ops keyframe_gate`).
pub const KEYFRAME_GATE: OpSpec = OpSpec::transform(
    "keyframe_gate",
    "inference",
    dynaflow_engine::op::doc_line(include_str!("docs/keyframe_gate.md")),
    |p: &Params| {
        Ok(Instance::Transform(Box::new(KeyframeGate {
            config: Config::from_params(p)?,
            since: None,
            fired: [0; 6],
            frames: 0,
        })))
    },
)
.inputs(&[IMAGE.spec, TRACKING.spec, COUNTS.spec])
.outputs(&[IMAGE_OUT.spec, STATS.spec])
.params(Config::PARAMS);

struct KeyframeGate {
    config: Config,
    /// Frames since the last inference (`None` before the first).
    since: Option<u64>,
    fired: [u64; 6],
    frames: u64,
}

fn scalar(inputs: &Inputs, port: &In<Scalars>, key: &str) -> Result<Option<f64>, OpError> {
    Ok(port.get(inputs)?.and_then(|s| s.values.iter().find(|(k, _)| &**k == key).map(|(_, v)| *v)))
}

impl Operator for KeyframeGate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, image) = IMAGE.require(inputs)?;
        self.frames += 1;
        let relocalised = scalar(inputs, &TRACKING, "state")? == Some(3.0);
        let keyframe = scalar(inputs, &TRACKING, "keyframe")? == Some(1.0);
        let few_dynamic = scalar(inputs, &COUNTS, "dynamic")?.is_some_and(|d| d < self.config.dynamic_below as f64);
        let rule = match self.since {
            None => 1,
            Some(_) if relocalised => 2,
            Some(_) if few_dynamic => 3,
            Some(_) if keyframe => 4,
            Some(n) if n + 1 >= self.config.max_gap => 5,
            Some(_) => 0,
        };
        self.fired[rule] += 1;
        self.since = if rule == 0 { self.since.map(|n| n + 1) } else { Some(0) };
        let stats = vec![("infer".into(), f64::from(u8::from(rule != 0))), ("rule".into(), rule as f64)];
        let mut out = Outputs::new().send(&STATS, msg.header.clone(), Scalars { values: stats });
        if rule != 0 {
            out = out.send(&IMAGE_OUT, msg.header.clone(), image.clone());
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let inferred: u64 = self.fired[1..].iter().sum();
        let report = crate::report::GateReport {
            frames: self.frames,
            inferred,
            inferred_share: if self.frames > 0 { inferred as f64 / self.frames as f64 } else { 0.0 },
            rules: RULES.iter().zip(self.fired).map(|(k, v)| ((*k).to_string(), v)).collect(),
        };
        ctx.report = Some(crate::report::NodeReport::from(report).to_json());
        Ok(())
    }
}
