//! The engine's map message and `dynaflow-slam`'s map batch carry the same fields.

use dynaflow_engine::msg as m;
use dynaflow_slam as s;
use nalgebra::Point3;

pub fn to_msg(b: &s::SparseMap) -> m::SparseMap {
    m::SparseMap {
        map_id: b.map_id,
        keyframes: b
            .keyframes
            .iter()
            .map(|k| m::MapKeyFrame { id: k.id, stamp: k.stamp, world_from_cam: k.world_from_cam })
            .collect(),
        points: b
            .points
            .iter()
            .map(|p| m::MapPoint {
                id: p.id,
                position: [p.position.x, p.position.y, p.position.z],
                descriptor: p.descriptor,
                observations: p.observations,
                first_keyframe: p.first_keyframe,
            })
            .collect(),
        observations: b
            .observations
            .iter()
            .map(|o| m::MapObservation {
                keyframe: o.keyframe,
                point: o.point,
                uv: o.uv,
                depth: o.depth.unwrap_or(0.0),
                octave: o.octave,
            })
            .collect(),
        removed: b.removed.clone(),
        features: b
            .features
            .iter()
            .map(|f| m::MapFeature { keyframe: f.keyframe, uv: f.uv, octave: f.octave, descriptor: f.descriptor })
            .collect(),
        keypoints: b
            .keypoints
            .iter()
            .map(|k| m::MapKeypoint {
                keyframe: k.keyframe,
                uv: k.uv,
                octave: k.octave,
                depth: k.depth.unwrap_or(0.0),
                descriptor: k.descriptor,
                point: k.point,
            })
            .collect(),
    }
}

pub fn from_msg(b: &m::SparseMap) -> s::SparseMap {
    s::SparseMap {
        map_id: b.map_id,
        keyframes: b
            .keyframes
            .iter()
            .map(|k| s::KeyFrameInfo { id: k.id, stamp: k.stamp, world_from_cam: k.world_from_cam })
            .collect(),
        points: b
            .points
            .iter()
            .map(|p| s::MapPoint {
                id: p.id,
                position: Point3::from(p.position),
                descriptor: p.descriptor,
                observations: p.observations,
                first_keyframe: p.first_keyframe,
            })
            .collect(),
        observations: b
            .observations
            .iter()
            .map(|o| s::Observation {
                keyframe: o.keyframe,
                point: o.point,
                uv: o.uv,
                depth: (o.depth > 0.0).then_some(o.depth),
                octave: o.octave,
            })
            .collect(),
        removed: b.removed.clone(),
        features: b
            .features
            .iter()
            .map(|f| s::KeyFrameFeature { keyframe: f.keyframe, uv: f.uv, octave: f.octave, descriptor: f.descriptor })
            .collect(),
        keypoints: b
            .keypoints
            .iter()
            .map(|k| s::KeyFrameKeypoint {
                keyframe: k.keyframe,
                uv: k.uv,
                octave: k.octave,
                depth: (k.depth > 0.0).then_some(k.depth),
                descriptor: k.descriptor,
                point: k.point,
            })
            .collect(),
    }
}
