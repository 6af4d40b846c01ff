//! The sparse map's plain data: a frame's keypoint as tracking sees it; the map itself
//! ([`SparseMap`] and its parts) is the message type of `dynaflow-msg`, re-exported here, so
//! tracking, local mapping and loop closing exchange exactly what a graph edge carries.

pub use dynaflow_msg::{CulledKeyFrame, MapFeature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, SparseMap};

/// One keypoint of a frame as tracking sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feature {
    /// Pixel (level-0 coordinates).
    pub uv: [f64; 2],
    /// Pyramid level it was detected on (sets its sigma: `scale^octave`).
    pub octave: u8,
    /// Orientation in degrees, `[0, 360)`; negative if not computed (ORB's intensity centroid:
    /// the motion model's search checks that matches turn alike).
    pub angle: f32,
    /// Measured depth in metres, `None` without a valid measurement.
    pub depth: Option<f64>,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
    /// Left out of tracking (labelled dynamic by culling, or on a masked pixel).
    pub dynamic: bool,
}

/// Sigma of an observation on pyramid level `octave` with scale factor `scale` (ORB-SLAM).
pub fn sigma(scale: f64, octave: u8) -> f64 {
    scale.powi(i32::from(octave))
}
