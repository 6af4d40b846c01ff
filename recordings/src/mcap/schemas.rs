//! Messages as Foxglove JSON (`message_encoding: json`, `schema encoding: jsonschema`), except
//! images, depth and masks, which are protobuf (`proto`).
//!
//! Foxglove's well-known schema names are used where one fits (images, annotations, poses,
//! point clouds, calibration, scene updates); `dynaflow.PointLabels`, `dynaflow.Scalars`,
//! `dynaflow.StereoRig` and `dynaflow.ImuBatch` (a frame's samples, named as ROS's
//! `sensor_msgs/Imu` names its fields) are ours. Every message also carries a `dynaflow` object (see `payload`) that Foxglove
//! ignores and `dynaflow diff` reads. The schemas below list the fields we write.

use base64::Engine as _;
use dynaflow_engine::msg::{Body, LensModel, Message, PointCloud, PortType, SparseMap};
use serde::Serialize;
use serde_json::{Value, json};

use super::proto;
use crate::encode::{self, EncodeCache, ImageCodec};
use crate::payload::{Payload, payload};

/// Whether a port type's messages are protobuf-encoded (pixels), not JSON.
pub fn is_protobuf(ty: PortType) -> bool {
    matches!(ty, PortType::Image | PortType::Depth | PortType::Mask)
}

/// The schema name used for a port type (colour images depend on the codec).
pub fn schema_name(ty: PortType, codec: ImageCodec) -> &'static str {
    match ty {
        PortType::Image if codec == ImageCodec::Raw => "foxglove.RawImage",
        PortType::Image => "foxglove.CompressedImage",
        PortType::Depth | PortType::Mask => "foxglove.RawImage",
        PortType::CameraInfo => "foxglove.CameraCalibration",
        PortType::Keypoints | PortType::Tracks | PortType::Detections => "foxglove.ImageAnnotations",
        PortType::Pose => "foxglove.PoseInFrame",
        PortType::Trajectory => "foxglove.PosesInFrame",
        PortType::PointCloud | PortType::Map => "foxglove.PointCloud",
        PortType::OctreeUpdate => "foxglove.SceneUpdate",
        PortType::PointLabels => "dynaflow.PointLabels",
        PortType::StereoRig => "dynaflow.StereoRig",
        PortType::Imu => "dynaflow.ImuBatch",
        PortType::Scalars | PortType::Any => "dynaflow.Scalars",
    }
}

const TIME: &str =
    r#"{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0}}}"#;
const VEC3: &str =
    r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}}"#;
const QUAT: &str = r#"{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}"#;
const COLOR: &str = r#"{"type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}"#;
const DYNAFLOW: &str = r#"{"type":"object","description":"dynaflow header, content digest and numeric payload (see docs/recordings.md)","properties":{"seq":{"type":"integer"},"stamp":{"type":"number"},"frame_id":{"type":"string"},"type":{"type":"string"},"digest":{"type":"string"},"data":{}}}"#;

/// A parameter changed while running, as a `foxglove.Log` (level INFO, `name` the node) with
/// the change itself under `dynaflow`: `{"node", "frame", "param", "old", "new"}`.
pub fn parameter_log(node: &str, change: &dynaflow_engine::runtime::ParameterChange, ns: u64) -> String {
    serde_json::json!({
        "timestamp": {"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000},
        "level": 2,
        "message": format!("frame {}: {node}.{} {} -> {}", change.frame, change.param, change.old, change.new),
        "name": node,
        "file": "",
        "line": 0,
        "dynaflow": {"node": node, "frame": change.frame, "param": change.param, "old": change.old, "new": change.new},
    })
    .to_string()
}

/// The JSON Schema text of a schema name.
pub fn schema_text(name: &str) -> String {
    let pose = format!(r#"{{"type":"object","properties":{{"position":{VEC3},"orientation":{QUAT}}}}}"#);
    let body = match name {
        "foxglove.CameraCalibration" => format!(
            r#""timestamp":{TIME},"frame_id":{{"type":"string"}},"width":{{"type":"integer"}},"height":{{"type":"integer"}},"distortion_model":{{"type":"string"}},"D":{{"type":"array","items":{{"type":"number"}}}},"K":{{"type":"array","items":{{"type":"number"}},"minItems":9,"maxItems":9}},"R":{{"type":"array","items":{{"type":"number"}},"minItems":9,"maxItems":9}},"P":{{"type":"array","items":{{"type":"number"}},"minItems":12,"maxItems":12}}"#
        ),
        "foxglove.ImageAnnotations" => format!(
            r#""circles":{{"type":"array"}},"points":{{"type":"array","items":{{"type":"object","properties":{{"timestamp":{TIME},"type":{{"type":"integer","description":"0 UNKNOWN, 1 POINTS, 2 LINE_LOOP, 3 LINE_STRIP, 4 LINE_LIST"}},"points":{{"type":"array","items":{{"type":"object","properties":{{"x":{{"type":"number"}},"y":{{"type":"number"}}}}}}}},"outline_color":{COLOR},"outline_colors":{{"type":"array","items":{COLOR}}},"fill_color":{COLOR},"thickness":{{"type":"number"}}}}}}}},"texts":{{"type":"array","items":{{"type":"object","properties":{{"timestamp":{TIME},"position":{{"type":"object","properties":{{"x":{{"type":"number"}},"y":{{"type":"number"}}}}}},"text":{{"type":"string"}},"font_size":{{"type":"number"}},"text_color":{COLOR},"background_color":{COLOR}}}}}}}"#
        ),
        "foxglove.PoseInFrame" => format!(r#""timestamp":{TIME},"frame_id":{{"type":"string"}},"pose":{pose}"#),
        "foxglove.PosesInFrame" => {
            format!(r#""timestamp":{TIME},"frame_id":{{"type":"string"}},"poses":{{"type":"array","items":{pose}}}"#)
        }
        "foxglove.PointCloud" => format!(
            r#""timestamp":{TIME},"frame_id":{{"type":"string"}},"pose":{pose},"point_stride":{{"type":"integer"}},"fields":{{"type":"array","items":{{"type":"object","properties":{{"name":{{"type":"string"}},"offset":{{"type":"integer"}},"type":{{"type":"integer","description":"7 FLOAT32, 1 UINT8"}}}}}}}},"data":{{"type":"string","contentEncoding":"base64"}}"#
        ),
        "foxglove.SceneUpdate" => format!(
            r#""deletions":{{"type":"array"}},"entities":{{"type":"array","items":{{"type":"object","properties":{{"timestamp":{TIME},"frame_id":{{"type":"string"}},"id":{{"type":"string"}},"lifetime":{TIME},"frame_locked":{{"type":"boolean"}},"cubes":{{"type":"array","items":{{"type":"object","properties":{{"pose":{pose},"size":{VEC3},"color":{COLOR}}}}}}}}}}}}}"#
        ),
        "dynaflow.PointLabels" => r#""timestamp":{"type":"object"},"index":{"type":"array","items":{"type":"integer"}},"dynamic":{"type":"array","items":{"type":"boolean"}},"reason":{"type":"array","items":{"type":"string","enum":["static","epipolar","semantic","flow","depth"]}},"score":{"type":"array","items":{"type":"number"}},"at":{"type":"array","items":{"type":"array","items":{"type":"number"}}}"#.replace(r#"{"type":"object"}"#, TIME),
        "foxglove.Log" => format!(
            r#""timestamp":{TIME},"level":{{"type":"integer","description":"1 DEBUG, 2 INFO, 3 WARNING, 4 ERROR, 5 FATAL"}},"message":{{"type":"string"}},"name":{{"type":"string"}},"file":{{"type":"string"}},"line":{{"type":"integer"}}"#
        ),
        "dynaflow.StereoRig" => format!(
            r#""timestamp":{TIME},"baseline_m":{{"type":"number","description":"distance between the optical centres, metres"}}"#
        ),
        "dynaflow.ImuBatch" => format!(
            r#""timestamp":{TIME},"stamp":{{"type":"array","items":{{"type":"number"}},"description":"each sample's time, seconds"}},"angular_velocity":{{"type":"array","items":{VEC3},"description":"rad/s, IMU frame"}},"linear_acceleration":{{"type":"array","items":{VEC3},"description":"specific force, m/s^2, IMU frame"}}"#
        ),
        _ => format!(r#""timestamp":{TIME},"values":{{"type":"object","additionalProperties":{{"type":"number"}}}}"#),
    };
    format!(r#"{{"title":"{name}","type":"object","properties":{{{body},"dynaflow":{DYNAFLOW}}}}}"#)
}

fn time(stamp: f64) -> Value {
    let stamp = if stamp.is_finite() && stamp > 0.0 { stamp } else { 0.0 };
    let sec = stamp.floor();
    json!({"sec": sec as u64, "nsec": ((stamp - sec) * 1e9).round().min(999_999_999.0) as u64})
}

fn b64(bytes: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

/// An image coordinate for display, to 1/100 px: `123.46` instead of the 17 digits of the
/// widened `f32` (the exact values are in the `dynaflow` payload).
fn px(v: f32) -> f64 {
    (f64::from(v) * 100.0).round() / 100.0
}

fn color(r: f32, g: f32, b: f32, a: f32) -> Value {
    json!({"r": r, "g": g, "b": b, "a": a})
}

fn pose_json(iso: &nalgebra::Isometry3<f64>) -> Value {
    let t = iso.translation.vector;
    let q = iso.rotation.coords;
    json!({"position": {"x": t.x, "y": t.y, "z": t.z}, "orientation": {"x": q.x, "y": q.y, "z": q.z, "w": q.w}})
}

/// Encode an image, depth or mask message as its protobuf Foxglove message (`None` for
/// other types): depth as `32FC1` metres (bit-exact), masks as `mono8`/`16UC1` class ids,
/// colour as JPEG/PNG (`CompressedImage`) or raw `rgb8`/`mono8`.
pub fn to_protobuf(msg: &Message, codec: ImageCodec, cache: &EncodeCache) -> Option<Result<Vec<u8>, String>> {
    let (stamp, frame_id) = (msg.header.stamp, &*msg.header.frame_id);
    let payload = || serde_json::to_vec(&payload(msg)).map_err(|e| e.to_string());
    let out = match &msg.body {
        Body::Image(img) if codec == ImageCodec::Raw => {
            let (encoding, step) = encode::raw_image_encoding(img);
            let layout = proto::RawLayout { width: img.width, height: img.height, encoding, step };
            payload().map(|p| proto::raw_image(stamp, frame_id, layout, |b| b.extend_from_slice(&img.data), &p))
        }
        Body::Image(img) => cache
            .get_or_encode(msg, 0, || encode::image(img, codec))
            .map_err(|e| e.to_string())
            .and_then(|e| Ok(proto::compressed_image(stamp, frame_id, &e.bytes, e.format, &payload()?))),
        Body::Depth(d) => {
            let layout = proto::RawLayout { width: d.width, height: d.height, encoding: "32FC1", step: d.width * 4 };
            payload().map(|p| proto::raw_image(stamp, frame_id, layout, |b| encode::depth_f32_le_into(d, b), &p))
        }
        Body::Mask(m) => {
            let (encoding, step) = encode::mask_encoding(m);
            let layout = proto::RawLayout { width: m.width, height: m.height, encoding, step };
            payload().map(|p| proto::raw_image(stamp, frame_id, layout, |b| encode::mask_raw_into(m, encoding, b), &p))
        }
        _ => return None,
    };
    Some(out)
}

/// Encode a non-image message as its Foxglove JSON object.
pub fn to_json(msg: &Message) -> Result<Vec<u8>, String> {
    let ts = time(msg.header.stamp);
    let frame_id = &*msg.header.frame_id;
    let mut v = match &msg.body {
        Body::CameraInfo(c) => json!({
            "timestamp": ts, "frame_id": frame_id, "width": c.width, "height": c.height,
            // Foxglove's names; a Kannala-Brandt lens has four coefficients.
            "distortion_model": if c.model == LensModel::KannalaBrandt { "kannala_brandt" } else { "plumb_bob" },
            "D": if c.model == LensModel::KannalaBrandt { &c.distortion[..4] } else { &c.distortion[..] },
            "K": [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0],
            "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "P": [c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        }),
        Body::Keypoints(k) => {
            let points = k.points.iter().map(|p| Xy { x: px(p.x), y: px(p.y) }).collect();
            let style = (1, 3.0, color(0.1, 0.9, 0.2, 1.0), color(0.1, 0.9, 0.2, 1.0));
            return points_annotation(msg, &ts, style, points);
        }
        Body::Tracks(t) => {
            let xy = |v: [f32; 2]| Xy { x: px(v[0]), y: px(v[1]) };
            let points = t.tracks.iter().flat_map(|t| [xy(t.prev), xy(t.cur)]).collect();
            let style = (4, 1.0, color(1.0, 0.8, 0.0, 1.0), color(0.0, 0.0, 0.0, 0.0));
            return points_annotation(msg, &ts, style, points);
        }
        Body::Detections(d) => json!({
            "circles": [],
            "points": d.detections.iter().map(|det| {
                let [x0, y0, x1, y1] = det.bbox;
                json!({"timestamp": ts, "type": 2, "thickness": 2.0,
                       "points": [{"x": x0, "y": y0}, {"x": x1, "y": y0}, {"x": x1, "y": y1}, {"x": x0, "y": y1}],
                       "outline_color": color(1.0, 0.2, 0.2, 1.0), "outline_colors": [], "fill_color": color(0.0, 0.0, 0.0, 0.0)})
            }).collect::<Vec<_>>(),
            "texts": d.detections.iter().map(|det| json!({
                "timestamp": ts, "position": {"x": det.bbox[0], "y": det.bbox[1]},
                "text": format!("{} {:.2}", det.label, det.score), "font_size": 12.0,
                "text_color": color(1.0, 1.0, 1.0, 1.0), "background_color": color(0.8, 0.1, 0.1, 0.7)})).collect::<Vec<_>>(),
        }),
        Body::PointLabels(l) => json!({
            "timestamp": ts,
            "index": l.labels.iter().map(|l| l.index).collect::<Vec<_>>(),
            "dynamic": l.labels.iter().map(|l| l.dynamic).collect::<Vec<_>>(),
            "reason": l.labels.iter().map(|l| l.reason).collect::<Vec<_>>(),
            "score": l.labels.iter().map(|l| l.score).collect::<Vec<_>>(),
            "at": l.labels.iter().map(|l| l.at).collect::<Vec<_>>(),
        }),
        Body::Pose(p) => json!({"timestamp": ts, "frame_id": "world", "pose": pose_json(&p.world_from_cam)}),
        Body::Trajectory(t) => json!({
            "timestamp": ts, "frame_id": "world",
            "poses": t.poses.iter().map(|p| pose_json(&p.world_from_cam)).collect::<Vec<_>>(),
        }),
        Body::PointCloud(c) => point_cloud_json(c, &ts),
        Body::Map(m) => point_cloud_json(&map_cloud(m), &ts),
        Body::OctreeUpdate(o) => {
            let size = json!({"x": o.resolution, "y": o.resolution, "z": o.resolution});
            let cubes: Vec<Value> = o
                .occupied
                .iter()
                .map(|(p, class)| {
                    let [r, g, b] = dynaflow_engine::msg::class_rgb(*class).map(|v| f32::from(v) / 255.0);
                    json!({"pose": {"position": {"x": p[0], "y": p[1], "z": p[2]}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
                           "size": size, "color": color(r, g, b, 0.8)})
                })
                .collect();
            json!({"deletions": [], "entities": [{"timestamp": ts, "frame_id": "world", "id": format!("octree-{}", msg.header.seq),
                   "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": false, "cubes": cubes}]})
        }
        Body::Scalars(s) => json!({
            "timestamp": ts,
            "values": Value::Object(s.values.iter().map(|(k, v)| (k.to_string(), json!(v))).collect()),
        }),
        Body::StereoRig(r) => json!({"timestamp": ts, "baseline_m": r.baseline}),
        Body::Imu(b) => json!({
            "timestamp": ts,
            "stamp": b.samples.iter().map(|s| s.stamp).collect::<Vec<_>>(),
            "angular_velocity": b.samples.iter().map(|s| json!({"x": s.gyro.x, "y": s.gyro.y, "z": s.gyro.z})).collect::<Vec<_>>(),
            "linear_acceleration": b.samples.iter().map(|s| json!({"x": s.accel.x, "y": s.accel.y, "z": s.accel.z})).collect::<Vec<_>>(),
        }),
        _ => json!({"timestamp": ts}),
    };
    if let Some(obj) = v.as_object_mut() {
        obj.insert("dynaflow".into(), serde_json::to_value(payload(msg)).map_err(|e| e.to_string())?);
    }
    serde_json::to_vec(&v).map_err(|e| e.to_string())
}

/// `foxglove.ImageAnnotations` with one `PointsAnnotation`, serialized as it is: keypoints and
/// tracks are hundreds of points a frame, and a `Value` tree cost a map per point. Fields are
/// in alphabetical order, as a `Value` object writes them, so the bytes are unchanged.
#[derive(Serialize)]
struct ImageAnnotations<'a> {
    circles: [Value; 0],
    dynaflow: Payload<'a>,
    points: [PointsAnnotation<'a>; 1],
    texts: [Value; 0],
}

#[derive(Serialize)]
struct PointsAnnotation<'a> {
    fill_color: Value,
    outline_color: Value,
    outline_colors: [Value; 0],
    points: Vec<Xy>,
    thickness: f64,
    timestamp: &'a Value,
    #[serde(rename = "type")]
    ty: u8,
}

#[derive(Serialize)]
struct Xy {
    x: f64,
    y: f64,
}

/// `(type, thickness, outline colour, fill colour)` of a points annotation.
type PointsStyle = (u8, f64, Value, Value);

fn points_annotation(msg: &Message, ts: &Value, style: PointsStyle, points: Vec<Xy>) -> Result<Vec<u8>, String> {
    let (ty, thickness, outline_color, fill_color) = style;
    let annotation =
        PointsAnnotation { fill_color, outline_color, outline_colors: [], points, thickness, timestamp: ts, ty };
    let out = ImageAnnotations { circles: [], dynaflow: payload(msg), points: [annotation], texts: [] };
    serde_json::to_vec(&out).map_err(|e| e.to_string())
}

/// A point cloud as `foxglove.PointCloud` (x, y, z float32, optional RGBA bytes).
fn point_cloud_json(c: &PointCloud, ts: &Value) -> Value {
    let with_color = c.colors.is_some();
    let stride = if with_color { 16 } else { 12 };
    let mut data = Vec::with_capacity(c.points.len() * stride);
    for (i, p) in c.points.iter().enumerate() {
        for v in p {
            data.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(colors) = &c.colors {
            let [r, g, b] = colors.get(i).copied().unwrap_or([255, 255, 255]);
            data.extend_from_slice(&[r, g, b, 255]);
        }
    }
    let mut fields = vec![
        json!({"name": "x", "offset": 0, "type": 7}),
        json!({"name": "y", "offset": 4, "type": 7}),
        json!({"name": "z", "offset": 8, "type": 7}),
    ];
    if with_color {
        for (i, n) in ["red", "green", "blue", "alpha"].iter().enumerate() {
            fields.push(json!({"name": n, "offset": 12 + i, "type": 1}));
        }
    }
    json!({"timestamp": ts, "frame_id": "world", "pose": pose_json(&nalgebra::Isometry3::identity()),
               "point_stride": stride, "fields": fields, "data": b64(&data)})
}

/// A sparse map's points as a cloud (what the recorders show of a map batch).
pub fn map_cloud(m: &SparseMap) -> PointCloud {
    PointCloud {
        points: m.points.iter().map(|p| [p.position.x as f32, p.position.y as f32, p.position.z as f32]).collect(),
        colors: None,
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use dynaflow_engine::msg::{Body, Descriptors, Header, Keypoint, Keypoints, Message, Track, Tracks};
    use serde_json::Value;

    use super::to_json;

    fn message(body: Body) -> Message {
        Message::new(Header { seq: 7, stamp: 1.25, frame_id: Arc::from("camera") }, body)
    }

    /// Keypoints and tracks are serialized without a `Value` tree; their bytes must be what
    /// the tree wrote (keys in alphabetical order, `f32` widened to `f64`), and the payload
    /// must give back every `f32` exactly.
    #[test]
    fn keypoints_and_tracks_json_is_the_value_trees_and_restores_every_float() {
        let kp = |i: u8| Keypoint {
            x: 0.1 + f32::from(i) * 97.3,
            y: 1.0 / 3.0 + f32::from(i),
            size: 31.0,
            angle: -1.0 + f32::from(i) * 1e-3,
            response: 1e-7 * f32::from(i + 1),
            octave: i % 8,
        };
        let points: Vec<Keypoint> = (0..9).map(kp).collect();
        let descriptors = Some(Descriptors { bytes_per: 32, data: (0..9 * 32).map(|v| v as u8).collect() });
        let keypoints = message(Body::Keypoints(Keypoints { points: points.clone(), descriptors }));
        let tracks = message(Body::Tracks(Tracks {
            prev_seq: 6,
            tracks: (0..5u8)
                .map(|i| Track {
                    id: u64::from(i) * 11,
                    prev: [kp(i).x, kp(i).y],
                    cur: [kp(i + 1).x, kp(i).y],
                    error: 0.3,
                })
                .collect(),
        }));
        for msg in [&keypoints, &tracks] {
            let bytes = to_json(msg).unwrap();
            let tree: Value = serde_json::from_slice(&bytes).unwrap();
            assert_eq!(serde_json::to_vec(&tree).unwrap(), bytes, "{}", String::from_utf8_lossy(&bytes));
            assert_eq!(tree["dynaflow"]["seq"], 7);
            assert_eq!(tree["points"][0]["timestamp"]["nsec"], 250_000_000);
        }
        let tree: Value = serde_json::from_slice(&to_json(&keypoints).unwrap()).unwrap();
        let data = &tree["dynaflow"]["data"];
        for (i, p) in points.iter().enumerate() {
            let f = |v: &Value| v.as_f64().unwrap() as f32;
            assert_eq!(f(&data["xy"][i][0]).to_bits(), p.x.to_bits());
            assert_eq!(f(&data["xy"][i][1]).to_bits(), p.y.to_bits());
            assert_eq!(f(&data["response"][i]).to_bits(), p.response.to_bits());
            assert_eq!(f(&data["angle"][i]).to_bits(), p.angle.to_bits());
            assert_eq!(data["octave"][i], p.octave);
            // The annotation's points are rounded to a hundredth of a pixel.
            assert!((tree["points"][0]["points"][i]["x"].as_f64().unwrap() - f64::from(p.x)).abs() <= 0.005);
        }
        assert_eq!(tree["points"][0]["points"].as_array().unwrap().len(), 9);
        let tree: Value = serde_json::from_slice(&to_json(&tracks).unwrap()).unwrap();
        assert_eq!(tree["points"][0]["points"].as_array().unwrap().len(), 10);
        assert_eq!(tree["dynaflow"]["data"]["prev_seq"], 6);
        assert_eq!(tree["dynaflow"]["data"]["id"][4], 44);
    }
}
