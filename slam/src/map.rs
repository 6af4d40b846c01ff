//! The sparse map's plain data.

use nalgebra::{Isometry3, Point3};

/// One keypoint of a frame as tracking sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feature {
    /// Pixel (level-0 coordinates).
    pub uv: [f64; 2],
    /// Pyramid level it was detected on (sets its sigma: `scale^octave`).
    pub octave: u8,
    /// Measured depth in metres, `None` without a valid measurement.
    pub depth: Option<f64>,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
    /// Left out of tracking (labelled dynamic by culling, or on a masked pixel).
    pub dynamic: bool,
}

/// A map point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapPoint {
    /// Unique within a run.
    pub id: u64,
    /// World position, metres.
    pub position: Point3<f64>,
    /// Representative descriptor (of the observation that created it).
    pub descriptor: [u8; 32],
    /// Key frames observing it.
    pub observations: u32,
    /// The key frame that created it.
    pub first_keyframe: u64,
}

/// A key frame's identity and pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyFrameInfo {
    /// Unique within a run.
    pub id: u64,
    /// Sensor time stamp, seconds.
    pub stamp: f64,
    /// `world_from_cam`.
    pub world_from_cam: Isometry3<f64>,
}

/// A key frame's observation of a map point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Observation {
    /// Key frame id.
    pub keyframe: u64,
    /// Map point id.
    pub point: u64,
    /// Pixel.
    pub uv: [f64; 2],
    /// Measured depth, metres (RGB-D), if any.
    pub depth: Option<f64>,
    /// Pyramid level.
    pub octave: u8,
}

/// A key frame's keypoint that no map point explains yet: what monocular local mapping
/// triangulates new points from (ORB-SLAM2's key frames keep all their keypoints).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyFrameFeature {
    /// Key frame id.
    pub keyframe: u64,
    /// Pixel (level-0 coordinates).
    pub uv: [f64; 2],
    /// Pyramid level.
    pub octave: u8,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
}

/// One static keypoint of a new key frame, with its depth and the map point it observes:
/// what place recognition and loop closing see of a key frame (ORB-SLAM2's key frames keep all
/// their keypoints).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyFrameKeypoint {
    /// Key frame id.
    pub keyframe: u64,
    /// Pixel (level-0 coordinates).
    pub uv: [f64; 2],
    /// Pyramid level.
    pub octave: u8,
    /// Measured depth, metres.
    pub depth: Option<f64>,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
    /// The map point it observes.
    pub point: Option<u64>,
}

/// What tracking and local mapping exchange. Tracking sends one new key frame with its
/// observations and the points it created; local mapping answers with its window's refined
/// key-frame poses, the refined local points and the ids of points it removed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseMap {
    /// Map number: a new map starts (and local mapping forgets the old one) after tracking
    /// was lost for good.
    pub map_id: u32,
    /// Key frames (their refined poses, from local mapping).
    pub keyframes: Vec<KeyFrameInfo>,
    /// Points (new ones from tracking; refined ones from local mapping).
    pub points: Vec<MapPoint>,
    /// Observations (from tracking: the new key frame's).
    pub observations: Vec<Observation>,
    /// Point ids removed by local mapping.
    pub removed: Vec<u64>,
    /// From monocular tracking: the new key frame's unmatched static keypoints, which local
    /// mapping triangulates against its neighbours (empty with depth, which creates points).
    pub features: Vec<KeyFrameFeature>,
    /// From tracking, forwarded by local mapping: every static keypoint of the new key frame
    /// (place recognition and loop closing). A loop correction leaves it empty.
    pub keypoints: Vec<KeyFrameKeypoint>,
}

/// Sigma of an observation on pyramid level `octave` with scale factor `scale` (ORB-SLAM).
pub fn sigma(scale: f64, octave: u8) -> f64 {
    scale.powi(i32::from(octave))
}
