//! Poses, trajectories, point clouds and octree updates. Transforms are named
//! `world_from_cam`: applied to a point in the camera frame they give it in the world frame.

pub use nalgebra::Isometry3;

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
