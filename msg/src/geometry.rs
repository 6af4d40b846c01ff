//! Poses, trajectories, point clouds and octree updates. Transforms are named
//! `world_from_cam`: applied to a point in the camera frame they give it in the world frame.

pub use nalgebra::{Isometry3, Point3};

use super::Digest;

fn digest_iso(d: &mut Digest, iso: &Isometry3<f64>) {
    let t = iso.translation.vector;
    let q = iso.rotation.coords;
    for v in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
        d.f64(v);
    }
}

/// A camera pose in the world frame (SE(3), `f64`).
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    /// Camera-to-world transform.
    pub world_from_cam: Isometry3<f64>,
}

impl Pose {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        digest_iso(d, &self.world_from_cam);
    }
}

/// A pose with its timestamp (TUM trajectory line).
#[derive(Clone, Debug, PartialEq)]
pub struct StampedPose {
    /// Seconds.
    pub stamp: f64,
    /// Camera-to-world transform.
    pub world_from_cam: Isometry3<f64>,
}

/// A trajectory, oldest first.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Trajectory {
    /// The poses.
    pub poses: Vec<StampedPose>,
}

impl Trajectory {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.poses.len() as u64);
        for p in &self.poses {
            d.f64(p.stamp);
            digest_iso(d, &p.world_from_cam);
        }
    }
}

/// 3-D points (world frame unless the header says otherwise), optional colours.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PointCloud {
    /// Positions in metres.
    pub points: Vec<[f32; 3]>,
    /// RGB per point, if known.
    pub colors: Option<Vec<[u8; 3]>>,
}

impl PointCloud {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.points.len() as u64);
        for p in &self.points {
            for v in p {
                d.f32(*v);
            }
        }
        if let Some(colors) = &self.colors {
            for c in colors {
                d.bytes(c);
            }
        }
    }
}

/// Voxels of an occupancy octree that changed state in this frame.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct OctreeUpdate {
    /// Leaf edge length in metres.
    pub resolution: f32,
    /// Centres of voxels that became occupied, with a class id.
    pub occupied: Vec<([f32; 3], u16)>,
    /// Centres of voxels that became free.
    pub freed: Vec<[f32; 3]>,
}

impl OctreeUpdate {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.f32(self.resolution);
        d.u64(self.occupied.len() as u64);
        for (p, c) in &self.occupied {
            for v in p {
                d.f32(*v);
            }
            d.bytes(&c.to_le_bytes());
        }
        d.u64(self.freed.len() as u64);
        for p in &self.freed {
            for v in p {
                d.f32(*v);
            }
        }
    }
}

/// A key frame of a sparse SLAM map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapKeyFrame {
    /// Unique within a run.
    pub id: u64,
    /// Sensor time stamp, seconds.
    pub stamp: f64,
    /// Camera-to-world transform.
    pub world_from_cam: Isometry3<f64>,
}

/// A point of a sparse SLAM map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapPoint {
    /// Unique within a run.
    pub id: u64,
    /// World position, metres.
    pub position: Point3<f64>,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
    /// Key frames observing it.
    pub observations: u32,
    /// The key frame that created it.
    pub first_keyframe: u64,
}

/// A key frame's observation of a map point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapObservation {
    /// Key frame id.
    pub keyframe: u64,
    /// Map point id.
    pub point: u64,
    /// Pixel (level-0 coordinates).
    pub uv: [f64; 2],
    /// Measured depth in metres (RGB-D or stereo), if any.
    pub depth: Option<f64>,
    /// Pyramid level (sets its sigma: `scale^octave`).
    pub octave: u8,
}

/// A key frame's keypoint no map point explains yet (monocular: triangulated by mapping).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapFeature {
    /// Key frame id.
    pub keyframe: u64,
    /// Pixel.
    pub uv: [f64; 2],
    /// Pyramid level.
    pub octave: u8,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
}

/// A static keypoint of a new key frame, with its depth and its map point (loop closing).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapKeypoint {
    /// Key frame id.
    pub keyframe: u64,
    /// Pixel.
    pub uv: [f64; 2],
    /// Pyramid level.
    pub octave: u8,
    /// Measured depth in metres, if any.
    pub depth: Option<f64>,
    /// 256-bit ORB descriptor.
    pub descriptor: [u8; 32],
    /// The map point it observes.
    pub point: Option<u64>,
}

/// A batch of a sparse SLAM map, as tracking and local mapping exchange them: a new key frame
/// with its observations and new points (tracking to mapping), or the refined local window
/// and the removed points (mapping to tracking).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct SparseMap {
    /// Map number (a new map starts after tracking is lost for good).
    pub map_id: u32,
    /// Key frames.
    pub keyframes: Vec<MapKeyFrame>,
    /// Points.
    pub points: Vec<MapPoint>,
    /// Observations.
    pub observations: Vec<MapObservation>,
    /// Ids of removed points.
    pub removed: Vec<u64>,
    /// Unmatched keypoints of a new monocular key frame (for triangulation).
    pub features: Vec<MapFeature>,
    /// Every static keypoint of a new key frame (tracking, forwarded by mapping: loop closing).
    pub keypoints: Vec<MapKeypoint>,
    /// Key frames local mapping culled (ORB-SLAM2's `KeyFrameCulling`), each with the key frame
    /// that stands in for it: frames tracked against it, its spanning-tree children and its
    /// loop edges move to that one.
    pub culled: Vec<CulledKeyFrame>,
}

/// A key frame culled as redundant, and the covisible key frame that takes its place.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CulledKeyFrame {
    /// The culled key frame.
    pub id: u64,
    /// Its best covisible key frame when it was culled.
    pub anchor: u64,
    /// The culled key frame's pose in the anchor's frame (`anchor_from_culled`), as local
    /// mapping last refined both.
    pub anchor_from_culled: Isometry3<f64>,
}

impl SparseMap {
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(u64::from(self.map_id));
        d.u64(self.keyframes.len() as u64);
        for k in &self.keyframes {
            d.u64(k.id);
            d.f64(k.stamp);
            digest_iso(d, &k.world_from_cam);
        }
        d.u64(self.points.len() as u64);
        for p in &self.points {
            d.u64(p.id);
            for v in p.position.coords.iter() {
                d.f64(*v);
            }
            d.bytes(&p.descriptor);
            d.u64(u64::from(p.observations));
            d.u64(p.first_keyframe);
        }
        d.u64(self.observations.len() as u64);
        for o in &self.observations {
            d.u64(o.keyframe);
            d.u64(o.point);
            // No depth is digested as 0 (what depth images write for "no measurement").
            for v in [o.uv[0], o.uv[1], o.depth.unwrap_or(0.0)] {
                d.f64(v);
            }
            d.bytes(&[o.octave]);
        }
        d.u64(self.removed.len() as u64);
        for r in &self.removed {
            d.u64(*r);
        }
        d.u64(self.features.len() as u64);
        for f in &self.features {
            d.u64(f.keyframe);
            d.f64(f.uv[0]);
            d.f64(f.uv[1]);
            d.bytes(&[f.octave]);
            d.bytes(&f.descriptor);
        }
        d.u64(self.keypoints.len() as u64);
        for k in &self.keypoints {
            d.u64(k.keyframe);
            for v in [k.uv[0], k.uv[1], k.depth.unwrap_or(0.0)] {
                d.f64(v);
            }
            d.bytes(&[k.octave]);
            d.bytes(&k.descriptor);
            d.u64(k.point.map_or(u64::MAX, |p| p));
        }
        d.u64(self.culled.len() as u64);
        for c in &self.culled {
            d.u64(c.id);
            d.u64(c.anchor);
            digest_iso(d, &c.anchor_from_culled);
        }
    }
}
