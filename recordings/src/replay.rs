//! `mcap_replay`: replays topics of a dynaflow MCAP recording as ports, so the late part of a
//! graph can be re-run on recorded intermediates.
//!
//! Messages are rebuilt from the Foxglove JSON and the `dynaflow` payload: exact for camera
//! info, keypoints (with descriptors), tracks, labels, detections, poses, trajectories and
//! scalars; images exact when recorded with `--image-format png` (JPEG otherwise); depth to
//! the millimetre; masks without instance ids. Frame numbers are kept: a topic recorded only
//! on key frames replays only on those frames.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use base64::Engine as _;
use dynaflow_engine::msg::{
    Body, CameraInfo, DepthImage, Descriptors, Detection, Detections, Header, Image, Isometry3, Keypoint, Keypoints,
    LabelReason, Message, PixelFormat, PointLabel, PointLabels, PortType, Pose, Scalars, SegmentationMask, StampedPose,
    Track, Tracks, Trajectory,
};
use dynaflow_engine::op::{
    Context, Default, Instance, OpError, OpKind, OpSpec, Outputs, ParamSpec, ParamType, Params, PortSpec, Source,
};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};
use serde_json::Value;

const OUTPUTS: &[PortSpec] = &[
    PortSpec::output("rgb", PortType::Image, "image topic"),
    PortSpec::output("depth", PortType::Depth, "depth topic (millimetre resolution)"),
    PortSpec::output("camera_info", PortType::CameraInfo, "camera calibration topic"),
    PortSpec::output("mask", PortType::Mask, "segmentation mask topic (classes only)"),
    PortSpec::output("keypoints", PortType::Keypoints, "keypoints topic"),
    PortSpec::output("tracks", PortType::Tracks, "tracks topic"),
    PortSpec::output("detections", PortType::Detections, "detections topic"),
    PortSpec::output("point_labels", PortType::PointLabels, "point labels topic"),
    PortSpec::output("pose", PortType::Pose, "pose topic"),
    PortSpec::output("trajectory", PortType::Trajectory, "trajectory topic"),
    PortSpec::output("scalars", PortType::Scalars, "scalars topic"),
];

/// The `mcap_replay` operator.
pub const MCAP_REPLAY: OpSpec = OpSpec {
    name: "mcap_replay",
    family: "recordings",
    doc: "Replays topics of a dynaflow MCAP recording as ports, keeping frame numbers and stamps, so a user re-runs only the late part of a graph on recorded intermediates. `topics` maps ports to topics, e.g. `pose=/track/pose,keypoints=/orb/keypoints`.",
    kind: OpKind::Source,
    inputs: &[],
    outputs: OUTPUTS,
    params: &[
        ParamSpec { name: "path", ty: ParamType::Path, default: Default::Required, doc: "the `.mcap` recording" },
        ParamSpec {
            name: "topics",
            ty: ParamType::Str,
            default: Default::Required,
            doc: "`port=/node/port` pairs, comma-separated",
        },
    ],
    cpu_heavy: true,
    build,
};

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct Config {
    path: String,
    topics: String,
}

fn build(params: &Params) -> Result<Instance, OpError> {
    let c: Config = params.parse()?;
    let path = params.resolve_path(&c.path);
    let mut wanted: Vec<(&'static str, String)> = Vec::new();
    for pair in c.topics.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (port, topic) = pair.split_once('=').ok_or_else(|| OpError::Config {
            key: "topics".into(),
            message: format!("`{pair}` is not `port=/topic`"),
        })?;
        let spec = OUTPUTS.iter().find(|p| p.name == port.trim()).ok_or_else(|| OpError::Config {
            key: "topics".into(),
            message: format!(
                "no output port `{}`; ports: {}",
                port.trim(),
                OUTPUTS.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
            ),
        })?;
        wanted.push((spec.name, topic.trim().to_owned()));
    }
    let frames = read(&path, &wanted)?;
    Ok(Instance::Source(Box::new(Replay { frames, wanted })))
}

/// Frame → port → the message's full JSON.
type Frames = BTreeMap<u64, BTreeMap<&'static str, Value>>;

fn read(path: &Path, wanted: &[(&'static str, String)]) -> Result<Frames, OpError> {
    let buf = std::fs::read(path).map_err(|source| OpError::Io { path: path.to_path_buf(), source })?;
    let opts = enumset::EnumSet::only(mcap::read::Options::IgnoreEndMagic);
    let stream = mcap::MessageStream::new_with_options(&buf, opts)
        .map_err(|e| OpError::Input(format!("{}: {e}", path.display())))?;
    let mut frames = Frames::new();
    let mut seen: Vec<String> = Vec::new();
    for message in stream {
        // A killed run's recording ends mid-chunk: replay what is complete.
        let Ok(message) = message else { break };
        let topic = &message.channel.topic;
        if !seen.contains(topic) {
            seen.push(topic.clone());
        }
        for (port, _) in wanted.iter().filter(|(_, t)| t == topic) {
            let v: Value = serde_json::from_slice(&message.data)
                .map_err(|e| OpError::Input(format!("{}: {topic}: {e}", path.display())))?;
            let seq = v["dynaflow"]["seq"].as_u64().unwrap_or(u64::from(message.sequence));
            frames.entry(seq).or_default().insert(port, v);
        }
    }
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

fn decode_png_or_jpeg(v: &Value) -> Result<image::DynamicImage, String> {
    let data = base64::engine::general_purpose::STANDARD
        .decode(v["data"].as_str().unwrap_or_default())
        .map_err(|e| e.to_string())?;
    image::load_from_memory(&data).map_err(|e| e.to_string())
}

/// Rebuild a message of port type `ty` from its recorded JSON.
fn decode(ty: PortType, v: &Value) -> Result<Body, String> {
    let d = &v["dynaflow"]["data"];
    Ok(match ty {
        PortType::Image => match decode_png_or_jpeg(v)? {
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
        PortType::Depth => {
            let img = decode_png_or_jpeg(v)?.into_luma16();
            Body::Depth(DepthImage {
                width: img.width(),
                height: img.height(),
                data: img.into_raw().into_iter().map(|mm| f32::from(mm) / 1000.0).collect(),
            })
        }
        PortType::Mask => {
            let img = decode_png_or_jpeg(v)?.into_luma16();
            let names = d["class_names"]
                .as_array()
                .map(|a| a.iter().map(|n| Arc::from(n.as_str().unwrap_or(""))).collect())
                .unwrap_or_default();
            Body::Mask(SegmentationMask {
                width: img.width(),
                height: img.height(),
                classes: img.into_raw(),
                instances: None,
                class_names: names,
            })
        }
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
            for (port, v) in ports {
                let ty = OUTPUTS.iter().find(|p| p.name == *port).map_or(PortType::Any, |p| p.ty);
                let topic = self.wanted.iter().find(|(p, _)| p == port).map_or("", |(_, t)| t.as_str());
                let body = decode(ty, v).map_err(|e| OpError::Input(format!("{topic} frame {seq}: {e}")))?;
                let p = &v["dynaflow"];
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

/// Check a replayed message against its recorded digest (tests, `--verify`).
pub fn same_as_recorded(msg: &Message, v: &Value) -> bool {
    v["dynaflow"]["digest"].as_str() == Some(format!("{:016x}", msg.digest()).as_str())
}
