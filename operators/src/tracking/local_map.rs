//! `local_map`.

use std::sync::Arc;
use std::time::Instant;

use crate::report::{LocalMappingReport, NodeReport, Timing};
use dynaflow_engine::msg::{CameraInfo, Header, Message, PointCloud, Scalars, SparseMap};
use dynaflow_engine::op::{Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use dynaflow_slam::{LocalMapConfig, LocalMapper};
use dynaflow_vision::camera::Pinhole;

params! {
    struct Config {
        /// key frames refined by local BA: the new one and its best covisible neighbours
        window: u64 [2, 100] = 10,
        /// key frames kept at most (the oldest are forgotten: `loop_close` keeps the whole map)
        keep_keyframes: u64 [2, 100_000] = 60,
        /// ORB-SLAM2's `Camera.bf`, pixels (as `track_rgbd`'s): the depth residual's weight and the close depth of key-frame culling (40 x bf / fx); a stereo rig's own replaces it
        bf: f64 [0.0, 10000.0] = 40.0,
        /// cull redundant key frames (ORB-SLAM2's `KeyFrameCulling`: 90 % of a key frame's close points seen by three other key frames at the same or a finer scale); tracking and `loop_close` drop them too
        cull_keyframes: bool = true,
    }
}

const KEYFRAME: In<SparseMap> = In::required("keyframe", "a key frame from `pnp_track`");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "intrinsics");
use super::STEREO_RIG as STEREO;
const LOOP: In<SparseMap> = In::optional(
    "loop",
    "`loop_close`'s corrected map (`delay: 1`, `join: latest`): applied before the next key frame",
);
const MAP: Out<SparseMap> = Out::new("map", "the refined local window: key frames, points, removed point ids");
const POINTS: Out<PointCloud> = Out::new("points", "every map point held (on key frames)");
const STATS: Out<Scalars> = Out::new(
    "stats",
    "`keyframes`, `points`, `window`, `removed`, `triangulated`, `fused` (monocular), `culled_keyframes` (by this key frame's insertion), `ba_iterations`, `ba_cost_before`, `ba_cost_after` (insertion times: the summary's `report.local_ba_ms`)",
);

/// The `local_map` operator (its doc: `dynaflow ops local_map`).
pub const LOCAL_MAP: OpSpec = OpSpec::transform(
    "local_map",
    "pnp_ba",
    dynaflow_engine::op::doc_line(include_str!("docs/local_map.md")),
    |p: &Params| {
        Ok(Instance::Transform(Box::new(LocalMap {
            config: Config::from_params(p)?,
            mapper: None,
            ba_ms: Vec::new(),
            last_loop: None,
        })))
    },
)
.inputs(&[KEYFRAME.spec, CAMERA_INFO.spec, STEREO.spec, LOOP.spec])
.outputs(&[MAP.spec, POINTS.spec, STATS.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct LocalMap {
    config: Config,
    mapper: Option<LocalMapper>,
    /// Milliseconds per key-frame insertion (local BA and culling).
    ba_ms: Vec<f64>,
    /// The loop correction last applied (a `latest` join repeats it).
    last_loop: Option<Arc<Message>>,
}

impl Operator for LocalMap {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, batch) = KEYFRAME.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        let rig = STEREO.get(inputs)?.map(crate::frontend::stereo_baseline).transpose()?;
        let mapper = self.mapper.get_or_insert_with(|| {
            // A monocular tracker's key frames carry their unmatched keypoints: triangulate
            // them, with ORB-SLAM2's monocular settings.
            let mut c =
                if batch.features.is_empty() { LocalMapConfig::rgbd(k.fx) } else { LocalMapConfig::monocular(k.fx) };
            c.window = self.config.window as usize;
            c.keep_keyframes = self.config.keep_keyframes as usize;
            c.cull_keyframes = self.config.cull_keyframes;
            if batch.features.is_empty() {
                c.bf = rig.map_or(self.config.bf, |b| k.fx * b);
                c.close_depth = dynaflow_slam::tracker::CLOSE_BASELINES * c.bf / k.fx;
            }
            LocalMapper::new(c, Pinhole::from(k))
        });
        if let Some(correction) = super::fresh(LOOP.find(inputs)?, &mut self.last_loop) {
            mapper.apply_correction(correction);
        }
        let t0 = Instant::now();
        let update = mapper.insert(batch);
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
            ("triangulated".into(), mapper.last_triangulated() as f64),
            ("fused".into(), mapper.last_fused() as f64),
            ("culled_keyframes".into(), update.culled.len() as f64),
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
        Ok(Outputs::new().send(&MAP, header.clone(), update).send(&POINTS, header.clone(), cloud).send(
            &STATS,
            header,
            Scalars { values: stats },
        ))
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let report = LocalMappingReport {
            keyframes: self.mapper.as_ref().map_or(0, LocalMapper::keyframes),
            points: self.mapper.as_ref().map_or(0, LocalMapper::points),
            culled_keyframes: self.mapper.as_ref().map_or(0, LocalMapper::culled_keyframes),
            culled_points: self.mapper.as_ref().map_or(0, LocalMapper::culled_points),
            memory_bytes: self.mapper.as_ref().map(LocalMapper::memory).unwrap_or_default(),
            local_ba_ms: Timing::of(&self.ba_ms),
        };
        ctx.report = Some(NodeReport::from(report).to_json());
        Ok(())
    }
}
