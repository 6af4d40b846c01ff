//! `keyframe_gate`.

use dynaflow_engine::msg::{Body, PortType, Scalars};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    dynamic_below: u64,
    max_gap: u64,
}

/// Why a frame went to inference (the `rule` scalar); 0: it did not.
const RULES: [&str; 6] = ["skipped", "first", "relocalised", "few_dynamic", "keyframe", "gap"];

pub const KEYFRAME_GATE: OpSpec = OpSpec {
    name: "keyframe_gate",
    family: "inference",
    doc: "MG-SLAM's key segmentation frames: passes `image` on (to a detector or segmenter) only when the frame is the first, the previous frame was relocalised or was a tracking key frame (`tracking`, `delay: 1`), the previous frame's dynamic-point count fell below `dynamic_below` (`counts`, `delay: 1`: the dynamic objects may have left or changed), or `max_gap` frames passed without inference. Consumers of the inference result join it with `join: latest`. `stats.rule` says which rule fired; the summary counts them.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("image", PortType::Image, "this frame"),
        PortSpec::optional("tracking", PortType::Scalars, "`pnp_track.stats` of the previous frame (`delay: 1`)"),
        PortSpec::optional(
            "counts",
            PortType::Scalars,
            "culling counts (`dynamic`) of the previous frame (`delay: 1`)",
        ),
    ],
    outputs: &[
        PortSpec::output("image", PortType::Image, "the frame, on key segmentation frames only"),
        PortSpec::output(
            "stats",
            PortType::Scalars,
            "`infer` (0/1), `rule` (0 skipped, 1 first, 2 relocalised, 3 few_dynamic, 4 keyframe, 5 gap)",
        ),
    ],
    params: &[
        ParamSpec {
            name: "dynamic_below",
            ty: ParamType::Int { min: 0, max: 1_000_000 },
            default: Default::Int(10),
            doc: "re-segment when the previous frame had fewer dynamic points than this (0: never)",
        },
        ParamSpec {
            name: "max_gap",
            ty: ParamType::Int { min: 1, max: 1_000_000 },
            default: Default::Int(4),
            doc: "re-segment at least every this many frames (MG-SLAM: four)",
        },
    ],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| {
        Ok(Instance::Transform(Box::new(KeyframeGate { config: p.parse()?, since: None, fired: [0; 6], frames: 0 })))
    },
};

struct KeyframeGate {
    config: Config,
    /// Frames since the last inference (`None` before the first).
    since: Option<u64>,
    fired: [u64; 6],
    frames: u64,
}

fn scalar(inputs: &Inputs, port: &str, key: &str) -> Option<f64> {
    match inputs.get(port).map(|m| &m.body) {
        Some(Body::Scalars(s)) => s.values.iter().find(|(k, _)| &**k == key).map(|(_, v)| *v),
        _ => None,
    }
}

impl Operator for KeyframeGate {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("image")?;
        self.frames += 1;
        let relocalised = scalar(inputs, "tracking", "state") == Some(3.0);
        let keyframe = scalar(inputs, "tracking", "keyframe") == Some(1.0);
        let few_dynamic = scalar(inputs, "counts", "dynamic").is_some_and(|d| d < self.config.dynamic_below as f64);
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
        let mut out = Outputs::new().with("stats", msg.header.clone(), Body::Scalars(Scalars { values: stats }));
        if rule != 0 {
            out = out.with("image", msg.header.clone(), msg.body.clone());
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let inferred: u64 = self.fired[1..].iter().sum();
        let rules: serde_json::Map<String, serde_json::Value> =
            RULES.iter().zip(self.fired).map(|(k, v)| ((*k).to_string(), serde_json::json!(v))).collect();
        ctx.report = Some(serde_json::json!({
            "frames": self.frames,
            "inferred": inferred,
            "inferred_share": if self.frames > 0 { inferred as f64 / self.frames as f64 } else { 0.0 },
            "rules": rules,
        }));
        Ok(())
    }
}
