//! `local_map`.

use std::sync::Arc;
use std::time::Instant;

use dynaflow_engine::msg::{Body, Header, PointCloud, PortType, Scalars};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_slam::{LocalMapConfig, LocalMapper};
use dynaflow_vision::geometry::Camera;

use super::convert;

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    window: u64,
    keep_keyframes: u64,
    baseline: f64,
}

pub const LOCAL_MAP: OpSpec = OpSpec {
    name: "local_map",
    family: "pnp_ba",
    doc: "ORB-SLAM's local mapping: each key frame from `pnp_track` joins the map with its observations and new points; it and its best covisible key frames (the window) are refined with their points by local BA (sparse LM, Schur complement on the points, Huber; two stages with outliers dropped between), key frames outside the window that see its points held fixed; bad observations are erased and points seen by fewer than two key frames two key frames after their creation are culled. The refined window goes back to `pnp_track` on `map` (connect it with `delay: 1` and `join: latest`, so tracking never waits on it in `--realtime`).",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("keyframe", PortType::Map, "a key frame from `pnp_track`"),
        PortSpec::input("camera_info", PortType::CameraInfo, "intrinsics"),
    ],
    outputs: &[
        PortSpec::output("map", PortType::Map, "the refined local window: key frames, points, removed point ids"),
        PortSpec::output("points", PortType::PointCloud, "every map point held (on key frames)"),
        PortSpec::output(
            "stats",
            PortType::Scalars,
            "`keyframes`, `points`, `window`, `removed`, `ba_iterations`, `ba_cost_before`, `ba_cost_after` (insertion times: the summary's `report.local_ba_ms`)",
        ),
    ],
    params: &[
        ParamSpec {
            name: "window",
            ty: ParamType::Int { min: 2, max: 100 },
            default: Default::Int(10),
            doc: "key frames refined by local BA: the new one and its best covisible neighbours",
        },
        ParamSpec {
            name: "keep_keyframes",
            ty: ParamType::Int { min: 2, max: 100_000 },
            default: Default::Int(60),
            doc: "key frames kept at most (the oldest are forgotten; no loop closing needs them)",
        },
        ParamSpec {
            name: "baseline",
            ty: ParamType::Float { min: 0.0, max: 10.0 },
            default: Default::Float(0.08),
            doc: "virtual baseline, metres (as `pnp_track`'s)",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        Ok(Instance::Transform(Box::new(LocalMap { config: p.parse()?, mapper: None, ba_ms: Vec::new() })))
    },
};

struct LocalMap {
    config: Config,
    mapper: Option<LocalMapper>,
    /// Milliseconds per key-frame insertion (local BA and culling).
    ba_ms: Vec<f64>,
}

impl Operator for LocalMap {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("keyframe")?;
        let Body::Map(batch) = &msg.body else { return Err(OpError::Input("`keyframe` is not a map".into())) };
        let Body::CameraInfo(k) = &inputs.require("camera_info")?.body else {
            return Err(OpError::Input("`camera_info` is not camera info".into()));
        };
        let mapper = self.mapper.get_or_insert_with(|| {
            let mut c = LocalMapConfig::rgbd(k.fx);
            c.window = self.config.window as usize;
            c.keep_keyframes = self.config.keep_keyframes as usize;
            c.bf = k.fx * self.config.baseline;
            LocalMapper::new(c, Camera { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy })
        });
        let t0 = Instant::now();
        let update = mapper.insert(&convert::from_msg(batch));
        // Wall time stays out of the messages (they must be identical run to run); it goes
        // to the summary at the end.
        self.ba_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let ba = mapper.last_ba();
        let header = Header { frame_id: Arc::from("world"), ..msg.header.clone() };
        let stats = vec![
            ("keyframes".into(), mapper.keyframes() as f64),
            ("points".into(), mapper.points() as f64),
            ("window".into(), update.keyframes.len() as f64),
            ("removed".into(), update.removed.len() as f64),
            ("ba_iterations".into(), ba.iterations as f64),
            ("ba_cost_before".into(), ba.initial_cost),
            ("ba_cost_after".into(), ba.final_cost),
        ];
        let cloud = PointCloud {
            points: mapper
                .all_points()
                .map(|p| [p.position.x as f32, p.position.y as f32, p.position.z as f32])
                .collect(),
            colors: None,
        };
        Ok(Outputs::new()
            .with("map", header.clone(), Body::Map(convert::to_msg(&update)))
            .with("points", header.clone(), Body::PointCloud(cloud))
            .with("stats", header, Body::Scalars(Scalars { values: stats })))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let mut t = self.ba_ms.clone();
        t.sort_by(f64::total_cmp);
        let q = |p: f64| t.get(((t.len() as f64 - 1.0) * p).round() as usize).copied().unwrap_or(0.0);
        let mean = if t.is_empty() { 0.0 } else { t.iter().sum::<f64>() / t.len() as f64 };
        ctx.report = Some(serde_json::json!({
            "keyframes": self.mapper.as_ref().map_or(0, LocalMapper::keyframes),
            "points": self.mapper.as_ref().map_or(0, LocalMapper::points),
            "local_ba_ms": { "count": t.len(), "mean": mean, "median": q(0.5), "p95": q(0.95), "max": q(1.0) },
        }));
        Ok(())
    }
}
