//! The `dynaflow` object stored with every MCAP message: header, content digest and the
//! numeric payload (never pixels) that `dynaflow diff` compares and `mcap_replay` restores:
//! complete for every non-image type, so a replayed message equals the recorded one.
//!
//! ```json
//! {"seq": 12, "stamp": 0.4, "frame_id": "camera", "type": "keypoints", "digest": "9f…",
//!  "data": {"xy": [[10.5, 20.0], …], "octave": [0, …]}}
//! ```

use base64::Engine as _;
use dynaflow_engine::msg::{Body, Message};
use serde_json::{Value, json};

/// The `dynaflow` object of a message.
pub fn payload(msg: &Message) -> Value {
    json!({
        "seq": msg.header.seq,
        "stamp": msg.header.stamp,
        "frame_id": &*msg.header.frame_id,
        "type": msg.body.port_type(),
        "digest": format!("{:016x}", msg.digest()),
        "data": data(&msg.body),
    })
}

fn data(body: &Body) -> Value {
    match body {
        Body::Keypoints(k) => json!({
            "xy": k.points.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>(),
            "octave": k.points.iter().map(|p| p.octave).collect::<Vec<_>>(),
            "size": k.points.iter().map(|p| p.size).collect::<Vec<_>>(),
            "angle": k.points.iter().map(|p| p.angle).collect::<Vec<_>>(),
            "response": k.points.iter().map(|p| p.response).collect::<Vec<_>>(),
            "descriptor_bytes": k.descriptors.as_ref().map(|d| d.bytes_per),
            "descriptors": k.descriptors.as_ref().map(|d| base64::engine::general_purpose::STANDARD.encode(&d.data)),
        }),
        Body::Tracks(t) => json!({
            "prev_seq": t.prev_seq,
            "id": t.tracks.iter().map(|t| t.id).collect::<Vec<_>>(),
            "prev": t.tracks.iter().map(|t| t.prev).collect::<Vec<_>>(),
            "cur": t.tracks.iter().map(|t| t.cur).collect::<Vec<_>>(),
            "error": t.tracks.iter().map(|t| t.error).collect::<Vec<_>>(),
        }),
        Body::PointLabels(l) => json!({
            "index": l.labels.iter().map(|l| l.index).collect::<Vec<_>>(),
            "dynamic": l.labels.iter().map(|l| l.dynamic).collect::<Vec<_>>(),
            "reason": l.labels.iter().map(|l| l.reason).collect::<Vec<_>>(),
            "score": l.labels.iter().map(|l| l.score).collect::<Vec<_>>(),
        }),
        Body::Detections(d) => json!({
            "bbox": d.detections.iter().map(|d| d.bbox).collect::<Vec<_>>(),
            "class_id": d.detections.iter().map(|d| d.class_id).collect::<Vec<_>>(),
            "label": d.detections.iter().map(|d| &*d.label).collect::<Vec<_>>(),
            "score": d.detections.iter().map(|d| d.score).collect::<Vec<_>>(),
        }),
        Body::Pose(p) => {
            let t = p.world_from_cam.translation.vector;
            let q = p.world_from_cam.rotation.coords;
            json!({"t": [t.x, t.y, t.z], "q": [q.x, q.y, q.z, q.w]})
        }
        Body::Trajectory(tr) => json!({
            "stamp": tr.poses.iter().map(|p| p.stamp).collect::<Vec<_>>(),
            "t": tr.poses.iter().map(|p| { let t = p.world_from_cam.translation.vector; [t.x, t.y, t.z] }).collect::<Vec<_>>(),
            "q": tr.poses.iter().map(|p| { let q = p.world_from_cam.rotation.coords; [q.x, q.y, q.z, q.w] }).collect::<Vec<_>>(),
        }),
        Body::Scalars(s) => Value::Object(s.values.iter().map(|(k, v)| (k.to_string(), json!(v))).collect()),
        Body::PointCloud(c) => json!({"count": c.points.len()}),
        Body::Map(m) => json!({
            "map_id": m.map_id,
            "keyframes": m.keyframes.iter().map(|k| k.id).collect::<Vec<_>>(),
            "points": m.points.len(),
            "observations": m.observations.len(),
            "removed": m.removed.len(),
        }),
        Body::OctreeUpdate(o) => {
            json!({"occupied": o.occupied.len(), "freed": o.freed.len(), "resolution": o.resolution})
        }
        Body::CameraInfo(c) => {
            json!({"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "width": c.width, "height": c.height})
        }
        Body::Image(i) => json!({"width": i.width, "height": i.height}),
        Body::Depth(d) => json!({"width": d.width, "height": d.height}),
        Body::Mask(m) => {
            json!({"width": m.width, "height": m.height, "class_names": m.class_names.iter().map(|n| &**n).collect::<Vec<_>>()})
        }
        _ => Value::Null,
    }
}
