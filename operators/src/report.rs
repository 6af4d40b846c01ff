//! What operators put in the run summary, as types: written by the operators, read back by
//! `run`, `bench`, `compare` and the tests through `dynaflow::summary` (never by JSON key).
//! Each report carries its `kind`, so a reader knows its type without knowing the operator.

use serde::{Deserialize, Serialize};

/// A node's report, by kind.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum NodeReport {
    /// `track_rgbd`, `track_stereo`, `track_mono`.
    Tracker(Box<TrackerReport>),
    /// `label_accuracy`.
    LabelAccuracy(LabelAccuracyReport),
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
}

/// Absolute trajectory error, metres.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Ate {
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
}
