//! `loop_close`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use crate::report::{GlobalBaReport, LoopClosingReport, LoopReport, NodeReport, Timing, VocabularyReport};
use dynaflow_engine::msg::{CameraInfo, Header, Pose, Scalars, SparseMap, StampedPose, Trajectory};
use dynaflow_engine::op::{Context, In, InputRole, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Params};
use dynaflow_engine::params;
use dynaflow_slam::bow::Vocabulary;
use dynaflow_slam::loop_closing::{LoopCloser, LoopConfig, Rejection};
use dynaflow_vision::camera::Pinhole;
use rand_core::Rng;

params! {
    struct Config {
        /// vocabulary file (`dynaflow vocab train`); empty: the embedded default (k 10, L 5, trained on synthetic frames of seed 31 and nine real frames: slam/vocabulary/SOURCE.md)
        vocabulary: PathBuf = PathBuf::new(),
        /// ORB-SLAM2's `Camera.bf`, pixels (fx x a virtual baseline; as `track_rgbd`'s): weighs the depth term of the loop pose's refinement; a stereo rig's own replaces it
        bf: f64 [0.0, 10000.0] = 40.0,
        /// keep the maps tracking lost for good (the atlas) and merge one into the current map when its place comes back (ORB-SLAM3); off, each new map stays in its own frame
        merge: bool = true,
    }
}

const MAP: In<SparseMap> =
    In::required("map", "`local_map`'s output: the refined window and the new key frame's keypoints");
const CAMERA_INFO: In<CameraInfo> = In::required("camera_info", "intrinsics");
use super::STEREO_RIG as STEREO;
const GT_POSE: In<Pose> = In::optional(
    "gt_pose",
    "ground truth: each loop is checked against it (do the two key frames' views overlap?) for the summary's `false_loops`; never used to decide",
)
.with_role(InputRole::Evaluation);
const INERTIAL: In<Scalars> = In::optional(
    "inertial",
    "the visual-inertial tracker's `stats`: once its IMU is initialised they carry `gravity_x/y/z`, and loops correct yaw and position only (4 DoF: gravity fixes roll and pitch; ORB-SLAM3, VINS-Fusion), a loop whose correction would tilt gravity by more than 0.008 rad refused",
);
const CORRECTION: Out<SparseMap> = Out::new(
    "correction",
    "after a loop: the whole corrected map (every key frame's pose, every point, fusion's observations and removed points), for `pnp_track` and `local_map` (`delay: 1`, `join: latest`)",
);
const KEYFRAMES: Out<Trajectory> =
    Out::new("keyframes", "after a loop: every key frame's corrected pose (the corrected trajectory)");
const LOOP_EDGE: Out<Trajectory> =
    Out::new("loop_edge", "after a loop: the key frame that closed it and the one it revisits (a line in the viewer)");
const STATS: Out<Scalars> = Out::new(
    "stats",
    "per key frame: `keyframes`, `points`, `loops`, `maps` (the current one and the older ones not merged), `loop` (1 when this key frame closed one), `merge` (1 when that was a merge of an older map), `loop_keyframe`, `matches`, `correction_m`, `correction_deg`, `fused` (times: the summary's `report`)",
);

/// The `loop_close` operator (its doc: `dynaflow ops loop_close`).
pub const LOOP_CLOSE: OpSpec = OpSpec::transform(
    "loop_close",
    "pnp_ba",
    dynaflow_engine::op::doc_line(include_str!("docs/loop_close.md")),
    |p: &Params| {
        let config = Config::from_params(p)?;
        let (vocabulary, name, load_ms) = super::load_vocabulary(&config.vocabulary)?;
        Ok(Instance::Transform(Box::new(LoopClose {
            config,
            vocabulary,
            vocabulary_name: name,
            load_ms,
            closer: None,
            insert_ms: Vec::new(),
            loop_ms: Vec::new(),
            ground_truth: Vec::new(),
        })))
    },
)
.inputs(&[MAP.spec, CAMERA_INFO.spec, STEREO.spec, GT_POSE.spec, INERTIAL.spec])
.outputs(&[CORRECTION.spec, KEYFRAMES.spec, LOOP_EDGE.spec, STATS.spec])
.params(Config::PARAMS)
.cpu_heavy();

struct LoopClose {
    config: Config,
    vocabulary: Arc<Vocabulary>,
    vocabulary_name: String,
    load_ms: f64,
    closer: Option<LoopCloser>,
    /// Milliseconds per key frame without a loop (detection), and per closed loop.
    insert_ms: Vec<f64>,
    loop_ms: Vec<f64>,
    /// Ground truth at the key frames' stamps (evaluation only).
    ground_truth: Vec<(f64, nalgebra::Isometry3<f64>)>,
}

/// Two views overlap when their optical axes are within this angle and their centres within
/// [`OVERLAP_DISTANCE`] (chosen on the synthetic scene: with a 62-degree field of view, axes 30
/// degrees apart still share half the image at room depths). Evaluation only.
const OVERLAP_ANGLE_DEG: f64 = 30.0;
const OVERLAP_DISTANCE: f64 = 1.0;

fn views_overlap(a: &nalgebra::Isometry3<f64>, b: &nalgebra::Isometry3<f64>) -> bool {
    let axis = |p: &nalgebra::Isometry3<f64>| p.rotation * nalgebra::Vector3::z();
    let angle = axis(a).angle(&axis(b)).to_degrees();
    angle <= OVERLAP_ANGLE_DEG && (a.translation.vector - b.translation.vector).norm() <= OVERLAP_DISTANCE
}

impl Operator for LoopClose {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, update) = MAP.require(inputs)?;
        let (_, k) = CAMERA_INFO.require(inputs)?;
        let rig = STEREO.get(inputs)?.map(crate::frontend::stereo_baseline).transpose()?;
        let closer = self.closer.get_or_insert_with(|| {
            let bf = rig.map_or(self.config.bf, |b| k.fx * b);
            let cam = Pinhole::from(k);
            LoopCloser::new(
                LoopConfig::new(bf, f64::from(k.width), f64::from(k.height)),
                cam,
                self.vocabulary.clone(),
                ctx.rng.next_u64(),
            )
            .with_merging(self.config.merge)
        });
        // The map's up axis, once the tracker's IMU knows gravity.
        if let Some(stats) = INERTIAL.get(inputs)? {
            let value = |name: &str| stats.values.iter().find(|(n, _)| &**n == name).map(|v| v.1);
            if let (Some(x), Some(y), Some(z)) = (value("gravity_x"), value("gravity_y"), value("gravity_z")) {
                closer.set_up(nalgebra::Unit::try_new(-nalgebra::Vector3::new(x, y, z), 1e-9));
            }
        }
        if let Some(gt) = GT_POSE.get(inputs)? {
            self.ground_truth.push((msg.header.stamp, gt.world_from_cam));
        }
        let t0 = Instant::now();
        let closed = closer.insert(update);
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        if update.keypoints.is_empty() {
            return Ok(Outputs::new());
        }
        if closed.is_some() {
            self.loop_ms.push(ms)
        } else {
            self.insert_ms.push(ms)
        }
        let header = Header { frame_id: Arc::from("world"), ..msg.header.clone() };
        let c = closed.as_ref();
        let stats = vec![
            ("keyframes".into(), closer.keyframes() as f64),
            ("points".into(), closer.points() as f64),
            ("loops".into(), closer.loops().len() as f64),
            ("maps".into(), closer.maps() as f64),
            ("loop".into(), if closed.is_some() { 1.0 } else { 0.0 }),
            ("merge".into(), if c.is_some_and(|c| c.merged_map.is_some()) { 1.0 } else { 0.0 }),
            ("loop_keyframe".into(), c.map_or(-1.0, |c| c.loop_keyframe as f64)),
            ("matches".into(), c.map_or(0.0, |c| c.matches as f64)),
            ("correction_m".into(), c.map_or(0.0, |c| c.correction_m)),
            ("correction_deg".into(), c.map_or(0.0, |c| c.correction_deg)),
            ("fused".into(), c.map_or(0.0, |c| c.fused as f64)),
        ];
        let mut out = Outputs::new().send(&STATS, header.clone(), Scalars { values: stats });
        if let Some(c) = closed {
            tracing::info!(
                "`{}`: {}: key frame {} revisits {} ({} matches), corrected by {:.3} m / {:.2} deg, scale {:.4}",
                ctx.node,
                c.merged_map.map_or_else(|| "loop closed".to_owned(), |m| format!("map {m} merged")),
                c.current,
                c.loop_keyframe,
                c.matches,
                c.correction_m,
                c.correction_deg,
                c.scale
            );
            let poses: Vec<StampedPose> = closer
                .keyframe_poses()
                .map(|k| StampedPose { stamp: k.stamp, world_from_cam: k.world_from_cam })
                .collect();
            let pick = |id: u64| closer.keyframe_poses().find(|k| k.id == id).copied();
            let edge: Vec<StampedPose> = [pick(c.current), pick(c.loop_keyframe)]
                .into_iter()
                .flatten()
                .map(|k| StampedPose { stamp: k.stamp, world_from_cam: k.world_from_cam })
                .collect();
            out = out
                .send(&CORRECTION, header.clone(), closer.correction())
                .send(&KEYFRAMES, header.clone(), Trajectory { poses })
                .send(&LOOP_EDGE, header, Trajectory { poses: edge });
        }
        Ok(out)
    }

    fn stop(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let gt_at = |t: f64| self.ground_truth.iter().find(|g| (g.0 - t).abs() < 1e-6).map(|g| g.1);
        let loops: Vec<LoopReport> = self
            .closer
            .as_ref()
            .map(|c| {
                c.loops()
                    .iter()
                    .map(|l| LoopReport {
                        ground_truth_overlap: gt_at(l.current_stamp)
                            .zip(gt_at(l.loop_stamp))
                            .map(|(a, b)| views_overlap(&a, &b)),
                        keyframe: l.current,
                        loop_keyframe: l.loop_keyframe,
                        stamp: l.current_stamp,
                        loop_stamp: l.loop_stamp,
                        bow_matches: l.bow_matches,
                        inliers: l.inliers,
                        matches: l.matches,
                        correction_m: l.correction_m,
                        correction_deg: l.correction_deg,
                        scale: l.scale,
                        merged_map: l.merged_map,
                        fused: l.fused,
                        keyframes: l.keyframes,
                        edges: l.edges,
                        graph_cost_before: l.cost_before,
                        graph_cost_after: l.cost_after,
                        global_ba: GlobalBaReport {
                            iterations: l.global_ba.iterations,
                            cost_before: l.global_ba.initial_cost,
                            cost_after: l.global_ba.final_cost,
                            ms: l.global_ba_ms,
                        },
                    })
                    .collect()
            })
            .unwrap_or_default();
        let false_loops = loops.iter().filter(|l| l.ground_truth_overlap == Some(false)).count();
        let report = LoopClosingReport {
            vocabulary: VocabularyReport {
                file: self.vocabulary_name.clone(),
                id: self.vocabulary.id(),
                words: self.vocabulary.words(),
                load_ms: self.load_ms,
            },
            keyframes: self.closer.as_ref().map_or(0, LoopCloser::keyframes),
            maps: self.closer.as_ref().map_or(0, LoopCloser::maps),
            merges: loops.iter().filter(|l| l.merged_map.is_some()).count(),
            memory_bytes: self.closer.as_ref().map(LoopCloser::memory).unwrap_or_default(),
            loops,
            false_loops: (!self.ground_truth.is_empty()).then_some(false_loops),
            rejected_candidates: self
                .closer
                .as_ref()
                .map(|c| Rejection::NAMES.iter().zip(c.rejected()).map(|(n, v)| ((*n).to_owned(), v)).collect()),
            detection_ms: Timing::of(&self.insert_ms),
            loop_correction_ms: Timing::of(&self.loop_ms),
        };
        ctx.report = Some(NodeReport::from(report).to_json());
        Ok(())
    }
}
