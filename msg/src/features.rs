//! Sparse features: keypoints, tracks and per-point static/dynamic labels.

use super::Digest;

/// One keypoint (OpenCV `KeyPoint` semantics: `angle` in degrees, `octave` pyramid level).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Keypoint {
    /// Column in level-0 pixels.
    pub x: f32,
    /// Row in level-0 pixels.
    pub y: f32,
    /// Diameter of the meaningful neighbourhood.
    pub size: f32,
    /// Orientation in degrees, `[0, 360)`; `-1` if not computed.
    pub angle: f32,
    /// Detector response.
    pub response: f32,
    /// Pyramid level.
    pub octave: u8,
}

/// Binary descriptors, `bytes_per` bytes each, one per keypoint.
#[derive(Clone, Debug, PartialEq)]
pub struct Descriptors {
    /// Bytes per descriptor (32 for ORB).
    pub bytes_per: usize,
    /// `len * bytes_per` bytes.
    pub data: Vec<u8>,
}

/// Keypoints of one image.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Keypoints {
    /// The points.
    pub points: Vec<Keypoint>,
    /// Descriptors aligned with `points`, if computed.
    pub descriptors: Option<Descriptors>,
}

impl Keypoints {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.points.len() as u64);
        for p in &self.points {
            for v in [p.x, p.y, p.size, p.angle, p.response] {
                d.f32(v);
            }
            d.bytes(&[p.octave]);
        }
        if let Some(desc) = &self.descriptors {
            d.u64(desc.bytes_per as u64);
            d.bytes(&desc.data);
        }
    }
}

/// A correspondence of one point between the previous and the current frame.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Track {
    /// Stable id of the tracked point.
    pub id: u64,
    /// Position in the previous frame.
    pub prev: [f32; 2],
    /// Position in the current frame.
    pub cur: [f32; 2],
    /// Tracking residual (LK error or descriptor distance).
    pub error: f32,
}

/// Tracks or matches between two frames.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Tracks {
    /// Sequence number of the frame `prev` positions refer to.
    pub prev_seq: u64,
    /// The correspondences.
    pub tracks: Vec<Track>,
}

impl Tracks {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.prev_seq);
        d.u64(self.tracks.len() as u64);
        for t in &self.tracks {
            d.u64(t.id);
            for v in [t.prev[0], t.prev[1], t.cur[0], t.cur[1], t.error] {
                d.f32(v);
            }
        }
    }
}

/// Why a point was labelled dynamic (or kept static).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum LabelReason {
    /// No rule fired.
    Static,
    /// Distance to the epipolar line above threshold.
    Epipolar,
    /// Inside a detection box / mask of a movable class.
    Semantic,
    /// Optical flow inconsistent with camera motion.
    Flow,
    /// Depth inconsistent with the key frame.
    Depth,
}

/// The label of one point, indexing into the keypoints/tracks it was computed from.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct PointLabel {
    /// Index into the source keypoints/tracks.
    pub index: u32,
    /// Whether the point is considered dynamic.
    pub dynamic: bool,
    /// The rule that decided.
    pub reason: LabelReason,
    /// The rule's measure for this point, in the rule's unit (epipolar distance in pixels,
    /// a class's dynamic value, a flow or depth residual, ...), compared with its threshold.
    pub score: f32,
    /// Where the point is in this frame's image (pixels; a track's current position), so a
    /// label is drawn at its own point whatever else the frame carries (NaN: unknown, e.g.
    /// replayed from a recording made before labels carried it).
    pub at: [f32; 2],
}

/// Labels of all points of a frame.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PointLabels {
    /// One per point.
    pub labels: Vec<PointLabel>,
}

impl PointLabels {
    /// Number of dynamic points.
    pub fn dynamic_count(&self) -> usize {
        self.labels.iter().filter(|l| l.dynamic).count()
    }
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.labels.len() as u64);
        for l in &self.labels {
            d.u64(u64::from(l.index));
            d.bytes(&[u8::from(l.dynamic), l.reason as u8]);
            d.f32(l.score);
            d.f32(l.at[0]);
            d.f32(l.at[1]);
        }
    }
}
