//! What operators put in the run summary, as types: written by the operators, read back by
//! `run`, `bench`, `compare` and the tests through `dynaflow::summary` (never by JSON key).
//! Each report carries its `kind`, so a reader knows its type without knowing the operator.

use std::collections::BTreeMap;

use dynaflow_slam::memory::MapMemory;
use serde::{Deserialize, Serialize};

pub use dynaflow_ros::sequence::BagReport;

/// A node's report, by kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NodeReport {
    /// `track_rgbd`, `track_stereo`, `track_mono`.
    Tracker(Box<TrackerReport>),
    /// `local_map`.
    LocalMapping(LocalMappingReport),
    /// `loop_close`.
    LoopClosing(Box<LoopClosingReport>),
    /// `label_accuracy`.
    LabelAccuracy(LabelAccuracyReport),
    /// `mask_iou`.
    MaskAccuracy(MaskAccuracyReport),
    /// `keyframe_gate`.
    Gate(GateReport),
    /// `octomap`.
    Octomap(OctomapReport),
    /// `detect`, `segment`: the executor that ran the model.
    Inference(InferenceReport),
    /// A source that skipped frames (`on_error: skip`) or read a bag.
    Source(SourceReport),
}

/// Typed access to one kind of report: `Summary::report_as::<LoopClosingReport>("closing")`.
pub trait ReportKind: Sized {
    /// This kind's report, if `r` is one.
    fn from_report(r: NodeReport) -> Option<Self>;
}

macro_rules! report_kinds {
    ($($variant:ident($ty:ty) $(boxed $boxed:tt)?),* $(,)?) => {$(
        impl ReportKind for $ty {
            fn from_report(r: NodeReport) -> Option<Self> {
                match r {
                    NodeReport::$variant(x) => Some(report_kinds!(@unbox x $($boxed)?)),
                    _ => None,
                }
            }
        }
        impl From<$ty> for NodeReport {
            fn from(x: $ty) -> Self {
                NodeReport::$variant(report_kinds!(@box x $($boxed)?))
            }
        }
    )*};
    (@unbox $x:ident) => { $x };
    (@unbox $x:ident $b:tt) => { *$x };
    (@box $x:ident) => { $x };
    (@box $x:ident $b:tt) => { Box::new($x) };
}

report_kinds! {
    Tracker(TrackerReport) boxed _,
    LocalMapping(LocalMappingReport),
    LoopClosing(LoopClosingReport) boxed _,
    LabelAccuracy(LabelAccuracyReport),
    MaskAccuracy(MaskAccuracyReport),
    Gate(GateReport),
    Octomap(OctomapReport),
    Inference(InferenceReport),
    Source(SourceReport),
}

impl NodeReport {
    /// As the summary's JSON (with its `kind`).
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    /// A typed report from a summary's JSON; `None` for a report of no known kind.
    pub fn from_json(v: &serde_json::Value) -> Option<Self> {
        serde_json::from_value(v.clone()).ok()
    }
}

/// Wall times of one step, milliseconds: count, mean, median, p95, max (nearest rank).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Samples.
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest.
    pub max: f64,
}

impl Timing {
    /// The statistics of `ms`.
    pub fn of(ms: &[f64]) -> Self {
        let mut t = ms.to_vec();
        t.sort_by(f64::total_cmp);
        let q = |p: f64| t.get(((t.len() as f64 - 1.0) * p).round() as usize).copied().unwrap_or(0.0);
        let mean = if t.is_empty() { 0.0 } else { t.iter().sum::<f64>() / t.len() as f64 };
        Self { count: t.len(), mean, median: q(0.5), p95: q(0.95), max: q(1.0) }
    }
}

/// Local mapping at the end of the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LocalMappingReport {
    /// Key frames in the map (0 when mapping is off).
    pub keyframes: usize,
    /// Map points.
    pub points: usize,
    /// Key frames culled as redundant (ORB-SLAM2's `KeyFrameCulling`).
    #[serde(default)]
    pub culled_keyframes: usize,
    /// Points culled (the recent-observation test, or left unobserved by a culled key frame).
    #[serde(default)]
    pub culled_points: usize,
    /// Bytes its window holds at the end, per component (an estimate from the containers).
    #[serde(default)]
    pub memory_bytes: MapMemory,
    /// Local BA per key frame.
    pub local_ba_ms: Timing,
}

/// The place-recognition vocabulary loop closing ran with.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VocabularyReport {
    /// Its file (`embedded default` for the built-in one).
    pub file: String,
    /// Its content id.
    pub id: String,
    /// Its words.
    pub words: usize,
    /// Loading time.
    pub load_ms: f64,
}

/// The global BA after a loop correction.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GlobalBaReport {
    /// Levenberg-Marquardt iterations.
    pub iterations: usize,
    /// Cost before.
    pub cost_before: f64,
    /// Cost after.
    pub cost_after: f64,
    /// Wall time.
    pub ms: f64,
}

/// One closed loop.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopReport {
    /// Whether the two key frames' views overlap in the ground truth (`None` without it).
    /// An oracle: scored after the fact, never used for a decision.
    pub ground_truth_overlap: Option<bool>,
    /// The key frame that closed the loop.
    pub keyframe: u64,
    /// The key frame it closed with.
    pub loop_keyframe: u64,
    /// The current key frame's stamp, seconds.
    pub stamp: f64,
    /// The loop key frame's stamp.
    pub loop_stamp: f64,
    /// Bag-of-words matches of the candidate.
    pub bow_matches: usize,
    /// RANSAC inliers (SE(3); Sim(3) for a single camera).
    pub inliers: usize,
    /// Matches after guided search.
    pub matches: usize,
    /// Translation of the correction at the current key frame, metres.
    pub correction_m: f64,
    /// Its rotation, degrees.
    pub correction_deg: f64,
    /// The current key frame's map units in the loop key frame's: 1 with depth; a single
    /// camera's scale drift along the loop (the Sim(3) scale; a missing field reads 1).
    #[serde(default = "one")]
    pub scale: f64,
    /// A merge (ORB-SLAM3's atlas): the older map (its number) the loop key frame belonged to,
    /// taken into the current map; `None` for a loop within one map.
    #[serde(default)]
    pub merged_map: Option<u32>,
    /// Map points fused.
    pub fused: usize,
    /// Key frames in the essential graph.
    pub keyframes: usize,
    /// Its edges.
    pub edges: usize,
    /// Pose-graph cost before.
    pub graph_cost_before: f64,
    /// Pose-graph cost after.
    pub graph_cost_after: f64,
    /// The global BA that followed.
    pub global_ba: GlobalBaReport,
}

/// A scale of 1, the default of [`LoopReport::scale`] (summaries written before it).
fn one() -> f64 {
    1.0
}

/// Loop closing over the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopClosingReport {
    /// The vocabulary.
    pub vocabulary: VocabularyReport,
    /// Key frames in the map.
    pub keyframes: usize,
    /// Maps held at the end: the current one and the older ones (tracking lost for good) that
    /// no merge took in.
    #[serde(default)]
    pub maps: usize,
    /// Loops that merged an older map into the current one.
    #[serde(default)]
    pub merges: usize,
    /// Bytes the whole map holds at the end, per component (an estimate from the containers).
    #[serde(default)]
    pub memory_bytes: MapMemory,
    /// The loops closed, in order.
    pub loops: Vec<LoopReport>,
    /// Loops whose views do not overlap in the ground truth (`None` without it; an oracle).
    pub false_loops: Option<usize>,
    /// Candidates rejected, by reason (`None` before the first key frame).
    pub rejected_candidates: Option<BTreeMap<String, usize>>,
    /// Detection per key frame.
    pub detection_ms: Timing,
    /// Each loop correction.
    pub loop_correction_ms: Timing,
}

/// Mask IoU against a reference, pooled over the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MaskAccuracyReport {
    /// Frames scored.
    pub frames: u64,
    /// Pooled intersection over union.
    pub iou: f64,
    /// Pooled precision.
    pub precision: f64,
    /// Pooled recall.
    pub recall: f64,
    /// Mean of the per-frame IoUs.
    pub mean_frame_iou: f64,
}

/// The key-frame gate: how often each rule let the detector run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GateReport {
    /// Frames seen.
    pub frames: u64,
    /// Frames passed to inference.
    pub inferred: u64,
    /// `inferred / frames`.
    pub inferred_share: f64,
    /// Frames per deciding rule (the first is "skipped").
    pub rules: BTreeMap<String, u64>,
}

/// A source's report: frames it skipped, and for a bag what the run read and left out.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SourceReport {
    /// Frames skipped as unreadable (`on_error: skip`).
    pub frames_skipped: u64,
    /// A bag's topics and the messages its pairing left out.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bag: Option<BagReport>,
}

/// The occupancy map at the end of the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OctomapReport {
    /// Frames inserted.
    pub frames: u64,
    /// Insertion per frame.
    pub insert_ms: Timing,
    /// Tree nodes.
    pub nodes: usize,
    /// Leaves.
    pub leaves: usize,
    /// Occupied leaves.
    pub occupied_leaves: usize,
    /// Memory of the tree.
    pub memory_bytes: usize,
    /// Depth pixels left out as dynamic.
    pub dynamic_pixels_skipped: u64,
    /// The `.ot` and `.bt` files written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<String>,
}

/// The executor that ran a model (`rten`, `reference`, `gpu`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InferenceReport {
    /// The backend.
    pub backend: String,
}

/// Precision and recall of culling labels against a reference mask, pooled over the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LabelAccuracyReport {
    /// Frames scored.
    pub frames: u64,
    /// tp / (tp + fp).
    pub precision: f64,
    /// tp / (tp + fn).
    pub recall: f64,
    /// Their harmonic mean.
    pub f1: f64,
    /// Dynamic labels on dynamic pixels.
    pub tp: u64,
    /// Dynamic labels on static pixels.
    pub fp: u64,
    /// Static labels on dynamic pixels.
    #[serde(rename = "fn")]
    pub fn_: u64,
    /// Static labels on static pixels.
    pub tn: u64,
    /// Labels at points the reference does not cover.
    pub outside: u64,
}

/// Frames per tracking state.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameStates {
    /// Before the first map.
    pub not_initialised: u64,
    /// A new map started here.
    pub new_map: u64,
    /// Tracked against the local map.
    pub tracked: u64,
    /// Relocalised after a loss.
    pub relocalised: u64,
    /// Lost (no pose).
    pub lost: u64,
    /// Not tracked by vision, the pose propagated by the IMU.
    #[serde(default)]
    pub inertial: u64,
}

/// A visual-inertial tracker's part of its report.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct InertialReport {
    /// `static`, `map`, or `map_gravity_at_rest` (a single camera that rested first: gravity
    /// from the rest); absent: the IMU was never initialised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_method: Option<String>,
    /// Seconds from the first frame to the initialisation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_after_s: Option<f64>,
    /// Key frames the initialisation used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_keyframes: Option<usize>,
    /// The biases at the end: gyroscope (rad/s), accelerometer (m/s²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gyro_bias: Option<[f64; 3]>,
    /// See `gyro_bias`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accel_bias: Option<[f64; 3]>,
    /// Gravity in the map's world (the first key frame's camera frame), m/s², as the
    /// initialisation found it: with the final trajectory it gives each camera's roll and pitch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<[f64; 3]>,
    /// Why the last MAP initialisation failed (when it never succeeded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_failure: Option<String>,
    /// Visual-inertial windows optimised (key-frame velocities, poses and biases).
    #[serde(default)]
    pub windows: u64,
    /// Frames whose visual-inertial fit failed the chi-square test against the IMU (vision's
    /// pose kept).
    #[serde(default)]
    pub inconsistent: u64,
    /// A single camera's scale refinements: seconds from the first frame, and the factor the
    /// map was scaled by.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scale_refinements: Vec<ScaleRefinement>,
}

/// One refinement of a single camera's map scale by the IMU.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ScaleRefinement {
    /// Seconds from the first frame.
    pub after_s: f64,
    /// The factor applied to the map.
    pub scale: f64,
}

/// Absolute trajectory error, metres.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Ate {
    /// The tracker node (on the summary's ATEs; a tracker's own report leaves it out).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    /// Root mean square error.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// Standard deviation.
    pub std: f64,
    /// Largest.
    pub max: f64,
    /// The alignment (`se3`, `sim3`).
    pub align: String,
    /// Poses matched with ground truth.
    pub pairs: u64,
    /// The Sim(3) scale (1 for SE(3)).
    pub scale: f64,
}

impl Ate {
    /// From an evaluation.
    pub fn of(e: &dynaflow_slam::eval::Evaluation, align: &str) -> Self {
        Self {
            node: None,
            rmse: e.ate.rmse,
            mean: e.ate.mean,
            median: e.ate.median,
            std: e.ate.std,
            max: e.ate.max,
            align: align.to_owned(),
            pairs: e.matched as u64,
            scale: e.scale,
        }
    }
}

/// Relative pose error over `delta_frames`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Rpe {
    /// Frames between the pose pairs.
    pub delta_frames: u64,
    /// Translation RMSE, metres.
    pub translation_rmse: f64,
    /// Rotation RMSE, degrees.
    pub rotation_rmse_deg: f64,
}

impl Rpe {
    /// From an evaluation.
    pub fn of(e: &dynaflow_slam::eval::Evaluation) -> Self {
        Self {
            delta_frames: e.rpe_delta as u64,
            translation_rmse: e.rpe_translation.rmse,
            rotation_rmse_deg: e.rpe_rotation_deg.rmse,
        }
    }
}

/// A map written with `save_map`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapSaved {
    /// The file.
    pub file: String,
    /// Key frames in it.
    pub keyframes: usize,
    /// Map points in it.
    pub points: usize,
}

/// A tracker's report (`track_rgbd`, `track_stereo`, `track_mono`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackerReport {
    /// Frames per state.
    pub frames: FrameStates,
    /// Maps started.
    pub maps: u32,
    /// Bytes it holds at the end, per component (key-frame poses and frame anchors, the local
    /// map, the whole map kept for relocalisation; an estimate from the containers).
    #[serde(default)]
    pub memory_bytes: MapMemory,
    /// Relocalisations in the whole map.
    pub map_relocalisations: usize,
    /// `rgbd`, `stereo` or `mono`.
    pub sensor: String,
    /// The first frame with a pose.
    pub first_pose_frame: Option<u64>,
    /// `false` when no frame ever had a pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initialised: Option<bool>,
    /// Why no frame ever had a pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_initialised_because: Option<String>,
    /// The online estimate's ATE (each pose as it was sent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ate: Option<Ate>,
    /// Its RPE.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpe: Option<Rpe>,
    /// Why the online estimate could not be scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ate_error: Option<String>,
    /// The final estimate's ATE (rebuilt from the key frames at the end).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ate_final: Option<Ate>,
    /// Its RPE.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rpe_final: Option<Rpe>,
    /// Why the final estimate could not be scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ate_final_error: Option<String>,
    /// The map written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_saved: Option<MapSaved>,
    /// Why the map could not be written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_saved_error: Option<String>,
    /// The map started in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map_loaded: Option<String>,
    /// With an IMU: its initialisation and final biases.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertial: Option<InertialReport>,
}
