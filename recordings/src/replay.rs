//! `mcap_replay`: replays topics of a dynaflow MCAP recording as ports, so the late part of a
//! graph can be re-run on recorded intermediates.
//!
//! Messages are rebuilt from the Foxglove messages and the `dynaflow` payload: exact for
//! camera info, keypoints (with descriptors), tracks, labels, detections, poses, trajectories,
//! scalars, IMU batches and depth (`32FC1`); images exact when recorded with `--image-format png` or `raw`
//! (JPEG otherwise); masks without instance ids. Recordings made before images became
//! protobuf (JSON `foxglove.CompressedImage`, depth as millimetre PNG) replay too, depth to the
//! millimetre. Frame numbers are kept: a topic recorded only on key frames replays only on
//! those frames.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use base64::Engine as _;
use dynaflow_engine::msg::{
    Body, CameraInfo, DepthImage, Descriptors, Detection, Detections, Header, Image, ImuBatch, ImuCalibration,
    ImuSample, Isometry3, Keypoint, Keypoints, LabelReason, LensModel, Message, PixelFormat, PointLabel, PointLabels,
    PortType, Pose, Scalars, SegmentationMask, StampedPose, StereoRig, Track, Tracks, Trajectory,
};
use dynaflow_engine::op::{
    Context, Instance, OpError, OpSpec, Outputs, Param, ParamMap, ParamType, Params, PortSpec, Source,
};
use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};
use serde_json::Value;

const OUTPUTS: &[PortSpec] = &[
    PortSpec::output("rgb", PortType::Image, "image topic"),
    PortSpec::output(
        "depth",
        PortType::Depth,
        "depth topic (bit-exact; to the millimetre from recordings made before protobuf images)",
    ),
    PortSpec::output("camera_info", PortType::CameraInfo, "camera calibration topic"),
    PortSpec::output("mask", PortType::Mask, "segmentation mask topic (classes only)"),
    PortSpec::output("keypoints", PortType::Keypoints, "keypoints topic"),
    PortSpec::output("tracks", PortType::Tracks, "tracks topic"),
    PortSpec::output("detections", PortType::Detections, "detections topic"),
    PortSpec::output("point_labels", PortType::PointLabels, "point labels topic"),
    PortSpec::output("pose", PortType::Pose, "pose topic"),
    PortSpec::output("trajectory", PortType::Trajectory, "trajectory topic"),
    PortSpec::output("scalars", PortType::Scalars, "scalars topic"),
    PortSpec::output("stereo", PortType::StereoRig, "stereo rig topic"),
    PortSpec::output("imu", PortType::Imu, "IMU topic (a frame's samples and the calibration)"),
];

const MCAP_REPLAY_DOC: &str = "Replays topics of a dynaflow MCAP recording as ports, keeping frame numbers and stamps, so a user re-runs only the late part of a graph on recorded intermediates. `topics` maps ports to topics, e.g. `{ pose: /track/pose, keypoints: /orb/keypoints }`.";

/// The `mcap_replay` operator.
pub const MCAP_REPLAY: OpSpec = OpSpec::source("mcap_replay", "recordings", MCAP_REPLAY_DOC, build)
    .outputs(OUTPUTS)
    .params(Config::PARAMS)
    .cpu_heavy()
    .ground_truth_outputs(replayed_ground_truth);

/// The ports that replay a topic the recorded run marked as ground truth (its provenance's
/// `ground_truth_topics`), so validation follows them as it followed the original ports. A
/// file that cannot be read marks nothing here; building the operator then reports it.
fn replayed_ground_truth(params: &Params) -> Vec<&'static str> {
    let Ok(c) = Config::from_params(params) else { return Vec::new() };
    let Some(marked) = ground_truth_topics(&c.path) else { return Vec::new() };
    c.topics.0.into_iter().filter(|(_, topic)| marked.contains(topic)).map(|(port, _)| port.0).collect()
}

/// The `ground_truth_topics` of a dynaflow MCAP recording's provenance, read from the start
/// of the file (the recorder writes the record first; no chunk is decompressed). `None` when
/// the file cannot be read or has no such record (a recording made before the mark existed).
pub fn ground_truth_topics(path: &Path) -> Option<Vec<String>> {
    use mcap::records::Record;
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
    use std::io::Read as _;
    let mut file = std::fs::File::open(path).ok()?;
    let len = usize::try_from(file.metadata().ok()?.len()).unwrap_or(usize::MAX);
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_record_length_limit(crate::mcap::scan::record_length_limit(len)),
    );
    while let Some(event) = reader.next_event() {
        match event.ok()? {
            LinearReadEvent::ReadRequest(need) => {
                let n = file.read(reader.insert(need)).ok()?;
                reader.notify_read(n);
                if n == 0 {
                    return None;
                }
            }
            LinearReadEvent::Record { data, opcode } => match mcap::parse_record(opcode, data).ok()? {
                Record::Metadata(m) if m.name == "dynaflow" => {
                    let list = m.metadata.get("ground_truth_topics")?;
                    return Some(list.split(',').filter(|t| !t.is_empty()).map(str::to_owned).collect());
                }
                // The recorder writes its provenance before any message.
                Record::Chunk { .. } | Record::Message { .. } => return None,
                _ => {}
            },
        }
    }
    None
}

/// The names of [`OUTPUTS`].
const PORT_NAMES: [&str; OUTPUTS.len()] = {
    let mut names = [""; OUTPUTS.len()];
    let mut i = 0;
    while i < OUTPUTS.len() {
        names[i] = OUTPUTS[i].name;
        i += 1;
    }
    names
};

/// One of the replay ports, as a `topics` key.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ReplayPort(&'static str);

impl Param for ReplayPort {
    const TYPE: ParamType = ParamType::Enum { values: &PORT_NAMES };
    fn from_json(value: &Value, _: &Params) -> Result<Self, String> {
        let name = value.as_str().unwrap_or_default();
        PORT_NAMES
            .iter()
            .find(|p| **p == name)
            .map(|p| ReplayPort(p))
            .ok_or_else(|| format!("no output port {value}; ports: {}", PORT_NAMES.join(", ")))
    }
    fn to_json(&self) -> Value {
        self.0.into()
    }
}

dynaflow_engine::params! {
    struct Config {
        /// the `.mcap` recording
        path: std::path::PathBuf,
        /// the topic each port replays, e.g. `{ pose: /track/pose, keypoints: /orb/keypoints }` (or the older `pose=/track/pose,keypoints=/orb/keypoints`)
        topics: ParamMap<ReplayPort, String>,
    }
}

fn build(params: &Params) -> Result<Instance, OpError> {
    let c = Config::from_params(params)?;
    let path = c.path;
    let wanted: Vec<(&'static str, String)> = c.topics.0.into_iter().map(|(port, topic)| (port.0, topic)).collect();
    let frames = read(&path, &wanted)?;
    Ok(Instance::Source(Box::new(Replay { path, frames, wanted })))
}

/// A recorded message: Foxglove JSON (with its `dynaflow` payload), or a protobuf image
/// message (`raw`: `foxglove.RawImage`, else `foxglove.CompressedImage`).
enum Stored {
    Json(Value),
    Proto { raw: bool, data: Vec<u8> },
}

/// Frame → port → the recorded message.
type Frames = BTreeMap<u64, BTreeMap<&'static str, Stored>>;

fn read(path: &Path, wanted: &[(&'static str, String)]) -> Result<Frames, OpError> {
    let buf = std::fs::read(path).map_err(|source| OpError::Io { path: path.to_path_buf(), source })?;
    let mut frames = Frames::new();
    let mut seen: Vec<String> = Vec::new();
    // A killed run's recording ends mid-chunk, corruption later in the file ends it too:
    // replay what is complete before (the bounded pass never reserves what a corrupt size
    // claims).
    crate::mcap::scan::scan(&buf, |event| {
        let crate::mcap::scan::Event::Message { channel, schema, header, data } = event else { return Ok(()) };
        let topic = &channel.topic;
        if !seen.contains(topic) {
            seen.push(topic.clone());
        }
        for (port, _) in wanted.iter().filter(|(_, t)| t == topic) {
            let (seq, stored) = if channel.message_encoding == "protobuf" {
                let payload: Value = crate::mcap::proto::payload_of(data)
                    .and_then(|p| serde_json::from_slice(p).map_err(|e| e.to_string()))
                    .map_err(|e| format!("{topic}: {e}"))?;
                let raw = schema == "foxglove.RawImage";
                (payload["seq"].as_u64(), Stored::Proto { raw, data: data.to_vec() })
            } else {
                let v: Value = serde_json::from_slice(data).map_err(|e| format!("{topic}: {e}"))?;
                (v["dynaflow"]["seq"].as_u64(), Stored::Json(v))
            };
            frames.entry(seq.unwrap_or(u64::from(header.sequence))).or_default().insert(port, stored);
        }
        Ok(())
    })
    .map_err(|e| OpError::Input(format!("{}: {e}", path.display())))?;
    for (port, topic) in wanted {
        if !seen.contains(topic) {
            return Err(OpError::Config {
                key: "topics".into(),
                message: format!("{}: no topic `{topic}` (for `{port}`); topics: {}", path.display(), seen.join(", ")),
            });
        }
    }
    Ok(frames)
}

struct Replay {
    /// The recording, for errors.
    path: std::path::PathBuf,
    frames: Frames,
    wanted: Vec<(&'static str, String)>,
}

fn f32s(v: &Value) -> Vec<f32> {
    v.as_array().map(|a| a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN) as f32).collect()).unwrap_or_default()
}

fn pairs(v: &Value) -> Vec<[f32; 2]> {
    v.as_array()
        .map(|a| {
            a.iter()
                .map(|p| [p[0].as_f64().unwrap_or(f64::NAN) as f32, p[1].as_f64().unwrap_or(f64::NAN) as f32])
                .collect()
        })
        .unwrap_or_default()
}

fn iso(t: &Value, q: &Value) -> Isometry3<f64> {
    let g = |v: &Value, i: usize| v[i].as_f64().unwrap_or(0.0);
    let rot = UnitQuaternion::new_unchecked(Quaternion::new(g(q, 3), g(q, 0), g(q, 1), g(q, 2)));
    Isometry3::from_parts(Translation3::new(g(t, 0), g(t, 1), g(t, 2)), rot)
}

/// Recorded pixels: an image file (JPEG/PNG, `CompressedImage`) or raw samples (`RawImage`).
enum Pixels<'a> {
    File(std::borrow::Cow<'a, [u8]>),
    Raw { width: u32, height: u32, encoding: &'a str, step: u32, data: &'a [u8] },
}

impl Pixels<'_> {
    fn file(&self) -> Result<image::DynamicImage, String> {
        match self {
            Self::File(bytes) => image::load_from_memory(bytes).map_err(|e| e.to_string()),
            Self::Raw { encoding, .. } => Err(format!("raw `{encoding}` where an image file was expected")),
        }
    }

    /// Rows of `width * bytes_per` bytes out of `step`-byte rows, checked against the size.
    fn rows(&self, bytes_per: u32) -> Result<(u32, u32, Vec<u8>), String> {
        let Self::Raw { width, height, step, data, encoding } = *self else { return Err("not raw".into()) };
        let row = width as usize * bytes_per as usize;
        if (step as usize) < row || data.len() < step as usize * height as usize {
            return Err(format!("{encoding} {width}x{height}: step {step}, {} bytes", data.len()));
        }
        if row == 0 || height == 0 {
            return Ok((width, height, Vec::new()));
        }
        let out = data.chunks(step as usize).take(height as usize).flat_map(|r| &r[..row]).copied().collect();
        Ok((width, height, out))
    }
}

/// The pixels of a recorded image message.
fn pixels<'a>(stored: &'a Stored, proto: Option<&crate::mcap::proto::ImageMsg<'a>>) -> Result<Pixels<'a>, String> {
    match (stored, proto) {
        (_, Some(m)) if m.encoding.is_empty() => Ok(Pixels::File(std::borrow::Cow::Borrowed(m.data))),
        (_, Some(m)) => {
            Ok(Pixels::Raw { width: m.width, height: m.height, encoding: m.encoding, step: m.step, data: m.data })
        }
        (Stored::Json(v), None) => base64::engine::general_purpose::STANDARD
            .decode(v["data"].as_str().unwrap_or_default())
            .map(|b| Pixels::File(std::borrow::Cow::Owned(b)))
            .map_err(|e| e.to_string()),
        (Stored::Proto { .. }, None) => Err("protobuf message not decoded".into()),
    }
}

/// Rebuild a message of port type `ty` from its recorded form; returns the `dynaflow`
/// payload (header) and the body.
fn decode(ty: PortType, stored: &Stored) -> Result<(Value, Body), String> {
    let proto = match stored {
        Stored::Proto { raw, data } => Some(crate::mcap::proto::read_image(data, *raw)?),
        Stored::Json(_) => None,
    };
    let payload: Value = match (&proto, stored) {
        (Some(m), _) => serde_json::from_slice(m.payload).map_err(|e| e.to_string())?,
        (None, Stored::Json(v)) => v["dynaflow"].clone(),
        (None, Stored::Proto { .. }) => Value::Null,
    };
    let body = match ty {
        PortType::Image | PortType::Depth | PortType::Mask => {
            decode_pixels(ty, &pixels(stored, proto.as_ref())?, &payload)?
        }
        _ => match stored {
            Stored::Json(v) => decode_json(ty, v)?,
            Stored::Proto { .. } => return Err(format!("a protobuf message on a {ty} port")),
        },
    };
    Ok((payload, body))
}

fn decode_pixels(ty: PortType, px: &Pixels<'_>, payload: &Value) -> Result<Body, String> {
    let encoding = match px {
        Pixels::Raw { encoding, .. } => Some(*encoding),
        Pixels::File(_) => None,
    };
    Ok(match (ty, encoding) {
        (PortType::Image, Some("rgb8" | "mono8")) => {
            let gray = encoding == Some("mono8");
            let (width, height, data) = px.rows(if gray { 1 } else { 3 })?;
            let format = if gray { PixelFormat::Gray8 } else { PixelFormat::Rgb8 };
            Body::Image(Image { width, height, format, data })
        }
        (PortType::Image, None) => match px.file()? {
            image::DynamicImage::ImageLuma8(g) => Body::Image(Image {
                width: g.width(),
                height: g.height(),
                format: PixelFormat::Gray8,
                data: g.into_raw(),
            }),
            other => {
                let rgb = other.into_rgb8();
                Body::Image(Image {
                    width: rgb.width(),
                    height: rgb.height(),
                    format: PixelFormat::Rgb8,
                    data: rgb.into_raw(),
                })
            }
        },
        (PortType::Depth, Some("32FC1")) => {
            let (width, height, data) = px.rows(4)?;
            let data = data.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
            Body::Depth(DepthImage { width, height, data })
        }
        (PortType::Depth, Some("16UC1")) => {
            let (width, height, data) = px.rows(2)?;
            let data = data.chunks_exact(2).map(|b| f32::from(u16::from_le_bytes([b[0], b[1]])) / 1000.0).collect();
            Body::Depth(DepthImage { width, height, data })
        }
        // Recordings before protobuf images: 16-bit PNG in millimetres.
        (PortType::Depth, None) => {
            let img = px.file()?.into_luma16();
            Body::Depth(DepthImage {
                width: img.width(),
                height: img.height(),
                data: img.into_raw().into_iter().map(|mm| f32::from(mm) / 1000.0).collect(),
            })
        }
        (PortType::Mask, enc) => {
            let (width, height, classes) = match enc {
                Some("mono8") => {
                    let (w, h, d) = px.rows(1)?;
                    (w, h, d.into_iter().map(u16::from).collect())
                }
                Some("16UC1" | "mono16") => {
                    let (w, h, d) = px.rows(2)?;
                    (w, h, d.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect())
                }
                Some(other) => return Err(format!("mask encoding `{other}` (expected mono8 or 16UC1)")),
                None => {
                    let img = px.file()?.into_luma16();
                    (img.width(), img.height(), img.into_raw())
                }
            };
            let names = payload["data"]["class_names"]
                .as_array()
                .map(|a| a.iter().map(|n| Arc::from(n.as_str().unwrap_or(""))).collect())
                .unwrap_or_default();
            Body::Mask(SegmentationMask { width, height, classes, instances: None, class_names: names })
        }
        (_, enc) => return Err(format!("{ty} with pixel encoding {enc:?}")),
    })
}

/// Rebuild a non-image message from its recorded JSON.
fn decode_json(ty: PortType, v: &Value) -> Result<Body, String> {
    let d = &v["dynaflow"]["data"];
    Ok(match ty {
        PortType::CameraInfo => {
            let g = |k: &str| d[k].as_f64().unwrap_or(f64::NAN);
            let mut distortion = [0.0; 5];
            for (i, x) in distortion.iter_mut().enumerate() {
                *x = d["distortion"][i].as_f64().unwrap_or(0.0);
            }
            Body::CameraInfo(CameraInfo {
                width: g("width") as u32,
                height: g("height") as u32,
                fx: g("fx"),
                fy: g("fy"),
                cx: g("cx"),
                cy: g("cy"),
                distortion,
                // Recordings made before the lens model have none: Brown-Conrady.
                model: match d["model"].as_str() {
                    Some("kannala_brandt") => LensModel::KannalaBrandt,
                    _ => LensModel::BrownConrady,
                },
            })
        }
        PortType::Keypoints => {
            let (xy, size, angle, response) =
                (pairs(&d["xy"]), f32s(&d["size"]), f32s(&d["angle"]), f32s(&d["response"]));
            let octave: Vec<u8> = d["octave"]
                .as_array()
                .map(|a| a.iter().map(|o| o.as_u64().unwrap_or(0) as u8).collect())
                .unwrap_or_default();
            let points = xy
                .iter()
                .enumerate()
                .map(|(i, p)| Keypoint {
                    x: p[0],
                    y: p[1],
                    size: size.get(i).copied().unwrap_or(0.0),
                    angle: angle.get(i).copied().unwrap_or(-1.0),
                    response: response.get(i).copied().unwrap_or(0.0),
                    octave: octave.get(i).copied().unwrap_or(0),
                })
                .collect();
            let descriptors = match (d["descriptor_bytes"].as_u64(), d["descriptors"].as_str()) {
                (Some(n), Some(b)) => Some(Descriptors {
                    bytes_per: n as usize,
                    data: base64::engine::general_purpose::STANDARD.decode(b).map_err(|e| e.to_string())?,
                }),
                _ => None,
            };
            Body::Keypoints(Keypoints { points, descriptors })
        }
        PortType::Tracks => {
            let (prev, cur, error) = (pairs(&d["prev"]), pairs(&d["cur"]), f32s(&d["error"]));
            let ids: Vec<u64> =
                d["id"].as_array().map(|a| a.iter().map(|x| x.as_u64().unwrap_or(0)).collect()).unwrap_or_default();
            let tracks = ids
                .iter()
                .enumerate()
                .map(|(i, id)| Track {
                    id: *id,
                    prev: prev.get(i).copied().unwrap_or_default(),
                    cur: cur.get(i).copied().unwrap_or_default(),
                    error: error.get(i).copied().unwrap_or(0.0),
                })
                .collect();
            Body::Tracks(Tracks { prev_seq: d["prev_seq"].as_u64().unwrap_or(0), tracks })
        }
        PortType::Detections => {
            let bbox = d["bbox"].as_array().cloned().unwrap_or_default();
            let detections = bbox
                .iter()
                .enumerate()
                .map(|(i, b)| Detection {
                    bbox: std::array::from_fn(|k| b[k].as_f64().unwrap_or(0.0) as f32),
                    class_id: d["class_id"][i].as_u64().unwrap_or(0) as u32,
                    label: Arc::from(d["label"][i].as_str().unwrap_or("")),
                    score: d["score"][i].as_f64().unwrap_or(0.0) as f32,
                })
                .collect();
            Body::Detections(Detections { detections })
        }
        PortType::PointLabels => {
            let reason = |r: &Value| match r.as_str() {
                Some("epipolar") => LabelReason::Epipolar,
                Some("semantic") => LabelReason::Semantic,
                Some("flow") => LabelReason::Flow,
                Some("depth") => LabelReason::Depth,
                _ => LabelReason::Static,
            };
            let index = d["index"].as_array().cloned().unwrap_or_default();
            let labels = index
                .iter()
                .enumerate()
                .map(|(i, x)| PointLabel {
                    index: x.as_u64().unwrap_or(0) as u32,
                    dynamic: d["dynamic"][i].as_bool().unwrap_or(false),
                    reason: reason(&d["reason"][i]),
                    score: d["score"][i].as_f64().unwrap_or(0.0) as f32,
                    // Recordings made before labels carried their pixel: unknown.
                    at: std::array::from_fn(|k| d["at"][i][k].as_f64().map_or(f32::NAN, |v| v as f32)),
                })
                .collect();
            Body::PointLabels(PointLabels { labels })
        }
        PortType::Pose => Body::Pose(Pose { world_from_cam: iso(&d["t"], &d["q"]) }),
        PortType::Trajectory => {
            let stamps = d["stamp"].as_array().cloned().unwrap_or_default();
            let poses = stamps
                .iter()
                .enumerate()
                .map(|(i, s)| StampedPose {
                    stamp: s.as_f64().unwrap_or(0.0),
                    world_from_cam: iso(&d["t"][i], &d["q"][i]),
                })
                .collect();
            Body::Trajectory(Trajectory { poses })
        }
        PortType::Scalars => Body::Scalars(Scalars {
            values: d
                .as_object()
                .map(|o| o.iter().map(|(k, x)| (Arc::from(k.as_str()), x.as_f64().unwrap_or(f64::NAN))).collect())
                .unwrap_or_default(),
        }),
        PortType::StereoRig => Body::StereoRig(StereoRig { baseline: d["baseline_m"].as_f64().unwrap_or(f64::NAN) }),
        PortType::Imu => {
            let c = &d["calibration"];
            let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
            let v3 = |v: &Value| Vector3::new(f(&v[0]), f(&v[1]), f(&v[2]));
            let stamps = d["stamp"].as_array().cloned().unwrap_or_default();
            let samples = stamps
                .iter()
                .enumerate()
                .map(|(i, s)| ImuSample { stamp: f(s), gyro: v3(&d["gyro"][i]), accel: v3(&d["accel"][i]) })
                .collect();
            let calibration = ImuCalibration {
                gyro_noise_density: f(&c["gyro_noise_density"]),
                accel_noise_density: f(&c["accel_noise_density"]),
                gyro_random_walk: f(&c["gyro_random_walk"]),
                accel_random_walk: f(&c["accel_random_walk"]),
                rate_hz: f(&c["rate_hz"]),
                gravity: f(&c["gravity"]),
                body_from_cam: iso(&c["body_from_cam"]["t"], &c["body_from_cam"]["q"]),
            };
            Body::Imu(ImuBatch { samples, calibration })
        }
        other => return Err(format!("replaying {other} is not supported")),
    })
}

impl Source for Replay {
    fn next(&mut self, _ctx: &mut Context, seq: u64) -> Result<Option<Outputs>, OpError> {
        let last = self.frames.keys().next_back().copied().unwrap_or(0);
        if seq > last || self.frames.is_empty() {
            return Ok(None);
        }
        let mut out = Outputs::new();
        if let Some(ports) = self.frames.get(&seq) {
            for (port, stored) in ports {
                let ty = OUTPUTS.iter().find(|p| p.name == *port).map_or(PortType::Any, |p| p.ty);
                let topic = self.wanted.iter().find(|(p, _)| p == port).map_or("", |(_, t)| t.as_str());
                let (p, body) = decode(ty, stored)
                    .map_err(|e| OpError::Input(format!("{}: {topic} frame {seq}: {e}", self.path.display())))?;
                let header = Header {
                    seq,
                    stamp: p["stamp"].as_f64().unwrap_or(0.0),
                    frame_id: Arc::from(p["frame_id"].as_str().unwrap_or("")),
                };
                out.push(port, header, body);
            }
        }
        Ok(Some(out))
    }

    fn len_hint(&self) -> Option<u64> {
        self.frames.keys().next_back().map(|k| k + 1)
    }
}

/// Check a replayed message against the digest in its recorded `dynaflow` payload.
pub fn same_as_recorded(msg: &Message, payload: &Value) -> bool {
    payload["digest"].as_str() == Some(format!("{:016x}", msg.digest()).as_str())
}

#[cfg(test)]
mod tests;
