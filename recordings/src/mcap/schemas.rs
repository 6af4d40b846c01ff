//! Messages as Foxglove JSON (`message_encoding: json`, `schema encoding: jsonschema`), except
//! images, depth and masks, which are protobuf (`proto`).
//!
//! Foxglove's well-known schema names are used where one fits (images, annotations, poses,
//! point clouds, calibration, scene updates); `dynaflow.PointLabels` and `dynaflow.Scalars`
//! are ours. Every message also carries a `dynaflow` object (see `payload`) that Foxglove
//! ignores and `dynaflow diff` reads. The schemas below list the fields we write.

use base64::Engine as _;
use dynaflow_engine::msg::{Body, Message, PointCloud, PortType, SparseMap};
use serde_json::{Value, json};

use super::proto;
use crate::encode::{self, EncodeCache, ImageCodec};
use crate::payload::payload;

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
        "dynaflow.PointLabels" => r#""timestamp":{"type":"object"},"index":{"type":"array","items":{"type":"integer"}},"dynamic":{"type":"array","items":{"type":"boolean"}},"reason":{"type":"array","items":{"type":"string","enum":["static","epipolar","semantic","flow","depth"]}},"score":{"type":"array","items":{"type":"number"}}"#.replace(r#"{"type":"object"}"#, TIME),
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
pub fn to_json(msg: &Message) -> Result<Value, String> {
    let ts = time(msg.header.stamp);
    let frame_id = &*msg.header.frame_id;
    let mut v = match &msg.body {
        Body::CameraInfo(c) => json!({
            "timestamp": ts, "frame_id": frame_id, "width": c.width, "height": c.height,
            "distortion_model": "plumb_bob", "D": c.distortion,
            "K": [c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0],
            "R": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            "P": [c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        }),
        Body::Keypoints(k) => json!({
            "circles": [], "texts": [],
            "points": [{
                "timestamp": ts, "type": 1, "thickness": 3.0,
                "points": k.points.iter().map(|p| json!({"x": px(p.x), "y": px(p.y)})).collect::<Vec<_>>(),
                "outline_color": color(0.1, 0.9, 0.2, 1.0), "outline_colors": [], "fill_color": color(0.1, 0.9, 0.2, 1.0),
            }],
        }),
        Body::Tracks(t) => json!({
            "circles": [], "texts": [],
            "points": [{
                "timestamp": ts, "type": 4, "thickness": 1.0,
                "points": t.tracks.iter().flat_map(|t| [json!({"x": px(t.prev[0]), "y": px(t.prev[1])}), json!({"x": px(t.cur[0]), "y": px(t.cur[1])})]).collect::<Vec<_>>(),
                "outline_color": color(1.0, 0.8, 0.0, 1.0), "outline_colors": [], "fill_color": color(0.0, 0.0, 0.0, 0.0),
            }],
        }),
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
        _ => json!({"timestamp": ts}),
    };
    if let Some(obj) = v.as_object_mut() {
        obj.insert("dynaflow".into(), payload(msg));
    }
    Ok(v)
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
        points: m.points.iter().map(|p| [p.position[0] as f32, p.position[1] as f32, p.position[2] as f32]).collect(),
        colors: None,
    }
}
