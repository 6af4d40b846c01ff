#![warn(missing_docs)]
//! Every message type that travels on a dynaflow edge, in one place (the engine re-exports
//! this crate as `dynaflow_engine::msg`; libraries such as the dataset readers use it
//! without the engine).
//!
//! Operators import payloads from here and never define their own wire types, so the
//! validator, the recorders and the diff tool all agree on what a port carries.
//! A [`Message`] is a [`Header`] plus a [`Body`]; edges carry `Arc<Message>`, so fan-out
//! shares the payload instead of copying it.
//!
//! Submodules group payloads by domain: `image` (pixels and intrinsics), `features`
//! (keypoints, tracks, per-point labels), `semantic` (detections, masks), `geometry`
//! (poses, trajectories, clouds, octree updates), `inertial` (IMU samples and calibration) and
//! `scalar` (metrics).

pub mod codec;
mod digest;
mod features;
mod geometry;
mod image;
mod inertial;
mod scalar;
mod semantic;

use std::fmt;
use std::sync::Arc;

pub use digest::{DIGEST_SCHEME, Digest};
pub use features::{Descriptors, Keypoint, Keypoints, LabelReason, PointLabel, PointLabels, Track, Tracks};
pub use geometry::{
    CulledKeyFrame, Isometry3, MapFeature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, OctreeUpdate, Point3,
    PointCloud, Pose, SparseMap, StampedPose, Trajectory,
};
pub use image::{CameraInfo, DepthImage, Image, LensModel, PixelFormat, StereoRig};
pub use inertial::{ImuBatch, ImuCalibration, ImuSample, STANDARD_GRAVITY};
pub use scalar::Scalars;
pub use semantic::{Detection, Detections, SegmentationMask, class_rgb};

/// Where and when a message's data was observed.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Header {
    /// Frame sequence number: the index of the source frame this message derives from.
    pub seq: u64,
    /// Sensor timestamp in seconds (dataset time, not wall-clock).
    pub stamp: f64,
    /// Coordinate frame or sensor name, e.g. `camera` or `world`.
    pub frame_id: Arc<str>,
}

/// A message: header plus typed payload.
///
/// Its [`digest`](Message::digest) is computed once and kept: a published message is shared
/// read-only (`Arc<Message>`) by the consumers, the digest sink and every recorder, each of
/// which asks for it. Change `header` or `body` only before the first call (a clone starts
/// without the kept value; [`Message::touch`] drops it).
pub struct Message {
    /// Provenance of the payload.
    pub header: Header,
    /// The payload.
    pub body: Body,
    digest: std::sync::OnceLock<u64>,
}

impl Clone for Message {
    fn clone(&self) -> Self {
        Self::new(self.header.clone(), self.body.clone())
    }
}

impl PartialEq for Message {
    fn eq(&self, other: &Self) -> bool {
        self.header == other.header && self.body == other.body
    }
}

impl std::fmt::Debug for Message {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Message").field("header", &self.header).field("body", &self.body).finish()
    }
}

/// The one list of payload types: each line declares a [`Body`] variant, its payload type, the
/// [`PortType`] of the same name and that type's name in graph files. Everything that must
/// name every payload (the two enums, [`PortType::ALL`], [`PortType::name`], [`Payload`], the
/// digest) is generated from it, so a new payload is one line here plus its codec and
/// recorders (whose matches the compiler checks for exhaustiveness).
macro_rules! payloads {
    ($($(#[doc = $doc:literal])* $variant:ident($ty:ty) = $name:literal,)*) => {
        /// The payload of a [`Message`]; one variant per [`PortType`].
        #[derive(Clone, Debug, PartialEq)]
        #[non_exhaustive]
        pub enum Body {
            $( $(#[doc = $doc])* $variant($ty), )*
        }

        /// The type of a port, checked when edges are validated.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
        #[serde(rename_all = "snake_case")]
        pub enum PortType {
            $( #[doc = concat!("[`", stringify!($ty), "`].")] $variant, )*
            /// Accepts any message (inputs of generic operators only).
            Any,
        }

        impl PortType {
            /// Every concrete type (not `Any`), in declaration order (the wire codec's tags:
            /// append, never reorder).
            pub const ALL: [PortType; [$(stringify!($variant)),*].len()] = [$(PortType::$variant),*];

            /// The name used in graph files and docs.
            pub fn name(self) -> &'static str {
                match self {
                    $( PortType::$variant => $name, )*
                    PortType::Any => "any",
                }
            }
        }

        impl Body {
            /// The port type this payload travels on.
            pub fn port_type(&self) -> PortType {
                match self { $( Body::$variant(_) => PortType::$variant, )* }
            }

            fn digest_into(&self, d: &mut Digest) {
                match self { $( Body::$variant(m) => m.digest_into(d), )* }
            }
        }

        $(
        impl Payload for $ty {
            const PORT: PortType = PortType::$variant;
            fn of(body: &Body) -> Option<&Self> {
                match body {
                    Body::$variant(v) => Some(v),
                    _ => None,
                }
            }
            fn into_body(self) -> Body {
                Body::$variant(self)
            }
        }
        )*
    };
}

payloads! {
    /// An RGB8 or Gray8 image.
    Image(Image) = "image",
    /// A depth image in metres.
    Depth(DepthImage) = "depth",
    /// Pinhole intrinsics and distortion.
    CameraInfo(CameraInfo) = "camera_info",
    /// Keypoints with optional binary descriptors.
    Keypoints(Keypoints) = "keypoints",
    /// Point correspondences between two frames (optical flow tracks or matches).
    Tracks(Tracks) = "tracks",
    /// Object detections.
    Detections(Detections) = "detections",
    /// A per-pixel class (and instance) mask.
    Mask(SegmentationMask) = "mask",
    /// Static/dynamic decision per point, with the reason.
    PointLabels(PointLabels) = "point_labels",
    /// A camera pose.
    Pose(Pose) = "pose",
    /// A sequence of stamped poses.
    Trajectory(Trajectory) = "trajectory",
    /// A 3-D point cloud.
    PointCloud(PointCloud) = "point_cloud",
    /// Changed voxels of an occupancy octree.
    OctreeUpdate(OctreeUpdate) = "octree_update",
    /// A batch of a sparse SLAM map (key frames, points, observations).
    Map(SparseMap) = "map",
    /// Named scalar metrics.
    Scalars(Scalars) = "scalars",
    /// A rectified stereo pair's baseline.
    StereoRig(StereoRig) = "stereo_rig",
    /// The IMU samples since the previous frame, with the IMU's calibration.
    Imu(ImuBatch) = "imu",
}

impl PortType {
    /// Whether an output of type `self` may feed an input of type `input`.
    pub fn feeds(self, input: PortType) -> bool {
        input == PortType::Any || self == input
    }
}

impl fmt::Display for PortType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A payload type: what a typed port handle (the engine's `op::In`, `op::Out`) carries.
pub trait Payload: Sized {
    /// The port type it travels on.
    const PORT: PortType;
    /// The payload of `body`, if it is of this type.
    fn of(body: &Body) -> Option<&Self>;
    /// As a message body.
    fn into_body(self) -> Body;
}

/// Any message (ports of type `any`).
impl Payload for Body {
    const PORT: PortType = PortType::Any;
    fn of(body: &Body) -> Option<&Self> {
        Some(body)
    }
    fn into_body(self) -> Body {
        self
    }
}

impl Message {
    /// A new message.
    pub fn new(header: Header, body: Body) -> Self {
        Self { header, body, digest: std::sync::OnceLock::new() }
    }

    /// Drop the kept digest (after changing `header` or `body` of a message whose digest was
    /// asked for).
    pub fn touch(&mut self) {
        self.digest = std::sync::OnceLock::new();
    }

    /// A deterministic 64-bit content hash of header and payload (bit-exact floats).
    /// Two runs are identical on a port iff the sequences of digests are. Computed on the
    /// first call and kept (see [`Message`]).
    pub fn digest(&self) -> u64 {
        *self.digest.get_or_init(|| self.compute_digest())
    }

    fn compute_digest(&self) -> u64 {
        let mut d = Digest::new();
        d.u64(self.header.seq);
        d.f64(self.header.stamp);
        d.str(&self.header.frame_id);
        d.str(self.body.port_type().name());
        self.body.digest_into(&mut d);
        d.finish()
    }

    /// A short JSON summary for logs (sizes and small values, never pixel data).
    pub fn summary(&self) -> serde_json::Value {
        use serde_json::json;
        match &self.body {
            Body::Image(m) => json!({"width": m.width, "height": m.height, "format": m.format.name()}),
            Body::Depth(m) => json!({"width": m.width, "height": m.height}),
            Body::CameraInfo(m) => json!({"fx": m.fx, "fy": m.fy, "cx": m.cx, "cy": m.cy}),
            Body::Keypoints(m) => json!({"count": m.points.len()}),
            Body::Tracks(m) => json!({"count": m.tracks.len()}),
            Body::Detections(m) => json!({"count": m.detections.len()}),
            Body::Mask(m) => json!({"width": m.width, "height": m.height, "classes": m.class_names.len()}),
            Body::PointLabels(m) => {
                // Dynamic points by the rule that decided.
                let mut reasons = serde_json::Map::new();
                for l in m.labels.iter().filter(|l| l.dynamic) {
                    let name = serde_json::to_value(l.reason).ok().and_then(|v| v.as_str().map(str::to_owned));
                    let n = reasons.entry(name.unwrap_or_default()).or_insert(json!(0));
                    *n = json!(n.as_u64().unwrap_or(0) + 1);
                }
                json!({"count": m.labels.len(), "dynamic": m.dynamic_count(), "reasons": reasons})
            }
            Body::Pose(m) => {
                let t = m.world_from_cam.translation.vector;
                let q = m.world_from_cam.rotation.coords;
                json!({"t": [t.x, t.y, t.z], "q_xyzw": [q.x, q.y, q.z, q.w]})
            }
            Body::Trajectory(m) => json!({"poses": m.poses.len()}),
            Body::PointCloud(m) => json!({"points": m.points.len()}),
            Body::OctreeUpdate(m) => json!({"occupied": m.occupied.len(), "resolution": m.resolution}),
            Body::Map(m) => json!({
                "map_id": m.map_id,
                "keyframes": m.keyframes.len(),
                "points": m.points.len(),
                "observations": m.observations.len(),
                "removed": m.removed.len(),
            }),
            Body::Scalars(m) => {
                serde_json::Value::Object(m.values.iter().map(|(k, v)| (k.to_string(), json!(v))).collect())
            }
            Body::StereoRig(m) => json!({"baseline_m": m.baseline}),
            Body::Imu(m) => json!({"samples": m.samples.len(), "rate_hz": m.calibration.rate_hz}),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(v: f64) -> Message {
        Message::new(Header { seq: 1, stamp: 0.5, frame_id: Arc::from("camera") }, Body::Scalars(Scalars::one("x", v)))
    }

    #[test]
    fn the_kept_digest_follows_a_clone_or_a_touch_and_never_goes_stale() {
        let mut m = message(1.0);
        let first = m.digest();
        assert_eq!(first, m.compute_digest());
        assert_eq!(m.digest(), first, "asked twice: the same value");
        // A clone starts afresh, so changing it cannot keep the original's digest.
        let mut c = m.clone();
        c.body = Body::Scalars(Scalars::one("x", 2.0));
        assert_ne!(c.digest(), first);
        assert_eq!(c.digest(), c.compute_digest());
        // Changed in place after the first call: `touch` drops the kept value.
        m.header.seq = 2;
        m.touch();
        assert_ne!(m.digest(), first);
        assert_eq!(m.digest(), m.compute_digest());
        assert_eq!(message(1.0), message(1.0), "equality ignores whether a digest was kept");
    }
}
