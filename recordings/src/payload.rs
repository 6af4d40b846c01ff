//! The `dynaflow` object stored with every MCAP message: header, content digest and the
//! numeric payload (never pixels) that `dynaflow diff` compares and `mcap_replay` restores:
//! complete for every non-image type, so a replayed message equals the recorded one.
//!
//! ```json
//! {"seq": 12, "stamp": 0.4, "frame_id": "camera", "type": "keypoints", "digest": "9f…",
//!  "data": {"xy": [[10.5, 20.0], …], "octave": [0, …]}}
//! ```

use base64::Engine as _;
use dynaflow_engine::msg::{Body, Keypoints, Message, PortType, Tracks};
use serde::Serialize;
use serde_json::{Value, json};

/// The `dynaflow` object of a message, serialized as it is (no `serde_json::Value` tree for
/// the per-frame keypoints and tracks: building one cost a map per point). Fields are in
/// alphabetical order, the order a `Value` object writes them in, so the bytes are those of
/// the `Value` tree this replaced (tested).
#[derive(Serialize)]
pub struct Payload<'a> {
    data: Data,
    digest: String,
    frame_id: &'a str,
    seq: u64,
    stamp: f64,
    #[serde(rename = "type")]
    ty: PortType,
}

#[derive(Serialize)]
#[serde(untagged)]
enum Data {
    Keypoints(KeypointsData),
    Tracks(TracksData),
    Other(Value),
}

/// Keypoints' numbers, `f32` widened to `f64` as a `Value` stores them.
#[derive(Serialize)]
struct KeypointsData {
    angle: Vec<f64>,
    descriptor_bytes: Option<usize>,
    descriptors: Option<String>,
    octave: Vec<u8>,
    response: Vec<f64>,
    size: Vec<f64>,
    xy: Vec<[f64; 2]>,
}

#[derive(Serialize)]
struct TracksData {
    cur: Vec<[f64; 2]>,
    error: Vec<f64>,
    id: Vec<u64>,
    prev: Vec<[f64; 2]>,
    prev_seq: u64,
}

/// The `dynaflow` object of a message.
pub fn payload(msg: &Message) -> Payload<'_> {
    Payload {
        data: match &msg.body {
            Body::Keypoints(k) => Data::Keypoints(keypoints(k)),
            Body::Tracks(t) => Data::Tracks(tracks(t)),
            body => Data::Other(data(body)),
        },
        digest: format!("{:016x}", msg.digest()),
        frame_id: &msg.header.frame_id,
        seq: msg.header.seq,
        stamp: msg.header.stamp,
        ty: msg.body.port_type(),
    }
}

fn keypoints(k: &Keypoints) -> KeypointsData {
    let wide = |f: fn(&dynaflow_engine::msg::Keypoint) -> f32| k.points.iter().map(|p| f64::from(f(p))).collect();
    KeypointsData {
        angle: wide(|p| p.angle),
        descriptor_bytes: k.descriptors.as_ref().map(|d| d.bytes_per),
        descriptors: k.descriptors.as_ref().map(|d| base64::engine::general_purpose::STANDARD.encode(&d.data)),
        octave: k.points.iter().map(|p| p.octave).collect(),
        response: wide(|p| p.response),
        size: wide(|p| p.size),
        xy: k.points.iter().map(|p| [f64::from(p.x), f64::from(p.y)]).collect(),
    }
}

fn tracks(t: &Tracks) -> TracksData {
    let wide = |v: [f32; 2]| [f64::from(v[0]), f64::from(v[1])];
    TracksData {
        cur: t.tracks.iter().map(|t| wide(t.cur)).collect(),
        error: t.tracks.iter().map(|t| f64::from(t.error)).collect(),
        id: t.tracks.iter().map(|t| t.id).collect(),
        prev: t.tracks.iter().map(|t| wide(t.prev)).collect(),
        prev_seq: t.prev_seq,
    }
}

fn data(body: &Body) -> Value {
    match body {
        Body::PointLabels(l) => json!({
            "index": l.labels.iter().map(|l| l.index).collect::<Vec<_>>(),
            "dynamic": l.labels.iter().map(|l| l.dynamic).collect::<Vec<_>>(),
            "reason": l.labels.iter().map(|l| l.reason).collect::<Vec<_>>(),
            "score": l.labels.iter().map(|l| l.score).collect::<Vec<_>>(),
            "at": l.labels.iter().map(|l| l.at).collect::<Vec<_>>(),
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
        Body::StereoRig(r) => json!({"baseline_m": r.baseline}),
        Body::Imu(b) => {
            let c = &b.calibration;
            let t = c.body_from_cam.translation.vector;
            let q = c.body_from_cam.rotation.coords;
            json!({
                "stamp": b.samples.iter().map(|s| s.stamp).collect::<Vec<_>>(),
                "gyro": b.samples.iter().map(|s| [s.gyro.x, s.gyro.y, s.gyro.z]).collect::<Vec<_>>(),
                "accel": b.samples.iter().map(|s| [s.accel.x, s.accel.y, s.accel.z]).collect::<Vec<_>>(),
                "calibration": {
                    "gyro_noise_density": c.gyro_noise_density,
                    "accel_noise_density": c.accel_noise_density,
                    "gyro_random_walk": c.gyro_random_walk,
                    "accel_random_walk": c.accel_random_walk,
                    "rate_hz": c.rate_hz,
                    "gravity": c.gravity,
                    "body_from_cam": {"t": [t.x, t.y, t.z], "q": [q.x, q.y, q.z, q.w]},
                },
            })
        }
        Body::PointCloud(c) => json!({"count": c.points.len()}),
        Body::Map(m) => json!({
            "map_id": m.map_id,
            "keyframes": m.keyframes.iter().map(|k| k.id).collect::<Vec<_>>(),
            "points": m.points.len(),
            "observations": m.observations.len(),
            "removed": m.removed.len(),
            "culled_keyframes": m.culled.iter().map(|c| c.id).collect::<Vec<_>>(),
        }),
        Body::OctreeUpdate(o) => {
            json!({"occupied": o.occupied.len(), "freed": o.freed.len(), "resolution": o.resolution})
        }
        Body::CameraInfo(c) => {
            let mut v = json!({"fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy, "width": c.width, "height": c.height});
            // The lens, where there is one (`mcap_replay` reads both back).
            if c.distortion != [0.0; 5] {
                v["distortion"] = json!(c.distortion);
            }
            if c.model != dynaflow_engine::msg::LensModel::BrownConrady {
                v["model"] = json!(c.model);
            }
            v
        }
        Body::Image(i) => json!({"width": i.width, "height": i.height}),
        Body::Depth(d) => json!({"width": d.width, "height": d.height}),
        Body::Mask(m) => {
            json!({"width": m.width, "height": m.height, "class_names": m.class_names.iter().map(|n| &**n).collect::<Vec<_>>()})
        }
        _ => Value::Null,
    }
}
