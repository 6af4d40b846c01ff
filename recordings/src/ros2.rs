//! The ROS 2 recorder (`--record ros2`): a rosbag2 bag (`<stem>.ros2/` with `metadata.yaml`
//! and one MCAP file in the `ros2` profile: `ros2msg` schemas, CDR payloads) that `ros2 bag
//! play`, rviz2, the `rosbags` package, rerun and Foxglove open as a robot's recording.
//!
//! Each recorded port is a topic `/<node>/<port>` of the ROS 2 type that fits (the CDR bytes
//! come from `dynaflow_ros::encode`):
//!
//! | dynaflow | ROS 2 |
//! |---|---|
//! | colour image | `sensor_msgs/msg/CompressedImage` on `/<node>/<port>/compressed` (JPEG or PNG), or `sensor_msgs/msg/Image` (`rgb8`/`mono8`) with `--image-format raw` |
//! | depth | `sensor_msgs/msg/Image`, `32FC1` metres |
//! | mask | `sensor_msgs/msg/Image`, `mono8`/`16UC1` class ids |
//! | camera info | `sensor_msgs/msg/CameraInfo` (`plumb_bob`) |
//! | pose | `geometry_msgs/msg/PoseStamped` (estimates in `map`, ground truth in `world`), and at the end of the run the whole stream as one `nav_msgs/msg/Path` on `/<node>/<port>/path` |
//! | the camera's pose (the graph's first estimated pose output) | also `tf2_msgs/msg/TFMessage` on `/tf`: `map` -> the images' frame (`camera`) |
//! | trajectory | `nav_msgs/msg/Path` |
//! | point cloud, map | `sensor_msgs/msg/PointCloud2` (`x y z` float32, PCL's packed `rgb`) in `map` |
//! | keypoints, tracks, point labels, detections | `visualization_msgs/msg/ImageMarker` (points; track segments and box edges as a line list; labels red dynamic / green static) |
//! | IMU batch | one `sensor_msgs/msg/Imu` per sample |
//! | anything else (scalars, stereo rig, octree updates) | `std_msgs/msg/String`, the MCAP recorder's JSON |
//!
//! `metadata.yaml` (rosbag2's format version 5, what Humble writes and every later release
//! reads) is written when the recorder closes; a run killed before that leaves the MCAP file,
//! which `ros2 bag reindex` turns back into a bag.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::Instant;

use dynaflow_engine::msg::{Body, Message};
use dynaflow_engine::sink::{PortReport, RunInfo, Sink, SinkError, SinkReport};
use dynaflow_ros::encode::{self as ros, MarkerKind, Transform};
use nalgebra::Isometry3;

use crate::encode::{self, EncodeCache, ImageCodec};
use crate::mcap::{DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_INTERVAL, open_writer, schemas, writer_error};

/// The fixed frame of estimated poses and the map (REP 105's `map`).
pub const MAP_FRAME: &str = "map";
/// The frame of ground-truth poses (not aligned with `map`: no transform joins them).
pub const WORLD_FRAME: &str = "world";

/// A pose port's fixed frame and its `(stamp, world_from_cam)`, for its `Path`.
type PoseStream = (&'static str, Vec<(f64, Isometry3<f64>)>);

/// One ROS 2 message: topic, type, CDR bytes.
type RosMessage = (String, &'static str, Vec<u8>);

#[derive(Debug)]
struct Topic {
    channel: u16,
    ty: &'static str,
    count: u64,
}

/// Writes `<out>/<stem>.ros2/`.
pub struct Ros2Sink {
    dir: PathBuf,
    file_name: String,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    codec: ImageCodec,
    cache: EncodeCache,
    schemas: HashMap<&'static str, u16>,
    topics: BTreeMap<String, Topic>,
    /// Per port: messages and bytes recorded.
    ports: BTreeMap<String, (u64, u64)>,
    ground_truth: std::collections::BTreeSet<String>,
    /// The pose port whose poses go to `/tf` as `map` -> camera.
    camera_pose: Option<String>,
    /// Every pose port's poses, for its `Path` at the end.
    paths: BTreeMap<String, PoseStream>,
    first_ns: Option<u64>,
    last_ns: u64,
    last_flush: Instant,
}

impl Ros2Sink {
    /// A recorder writing the bag folder `dir` (its MCAP file named after it), colour images
    /// as JPEG (q 90).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        let dir = dir.into();
        let stem = dir.file_name().map_or_else(|| "run".to_string(), |n| n.to_string_lossy().into_owned());
        Self {
            file_name: format!("{stem}_0.mcap"),
            dir,
            writer: None,
            codec: ImageCodec::Jpeg(90),
            cache: EncodeCache::default(),
            schemas: HashMap::new(),
            topics: BTreeMap::new(),
            ports: BTreeMap::new(),
            ground_truth: std::collections::BTreeSet::new(),
            camera_pose: None,
            paths: BTreeMap::new(),
            first_ns: None,
            last_ns: 0,
            last_flush: Instant::now(),
        }
    }

    /// How colour images are stored.
    #[must_use]
    pub fn with_codec(mut self, codec: ImageCodec) -> Self {
        self.codec = codec;
        self
    }

    /// Share image encodings with other recorders.
    #[must_use]
    pub fn with_cache(mut self, cache: EncodeCache) -> Self {
        self.cache = cache;
        self
    }

    fn mcap_path(&self) -> PathBuf {
        self.dir.join(&self.file_name)
    }

    fn err(&self, e: impl std::fmt::Display) -> SinkError {
        SinkError::new("ros2", format!("{}: {e}", self.dir.display()))
    }

    /// Writes one message on `topic` (its channel and schema added on first use).
    fn write(&mut self, topic: &str, ty: &'static str, stamp_ns: u64, seq: u32, data: &[u8]) -> Result<(), SinkError> {
        let path = self.mcap_path();
        let err = |e: mcap::McapError| writer_error("ros2", &path, &e);
        let writer = self.writer.as_mut().ok_or_else(|| SinkError::new("ros2", "not open"))?;
        let channel = match self.topics.get_mut(topic) {
            Some(t) => {
                t.count += 1;
                t.channel
            }
            None => {
                let schema = match self.schemas.get(ty) {
                    Some(id) => *id,
                    None => {
                        let short = ty.replace("/msg/", "/");
                        let text = dynaflow_ros::known::bundle(&short)
                            .ok_or_else(|| SinkError::new("ros2", format!("no definition of {ty}")))?;
                        let id = writer.add_schema(ty, "ros2msg", text.as_bytes()).map_err(err)?;
                        self.schemas.insert(ty, id);
                        id
                    }
                };
                let meta = BTreeMap::from([("offered_qos_profiles".to_string(), String::new())]);
                let channel = writer.add_channel(schema, topic, "cdr", &meta).map_err(err)?;
                self.topics.insert(topic.to_string(), Topic { channel, ty, count: 1 });
                channel
            }
        };
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: seq,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        writer.write_to_known_channel(&header, data).map_err(err)?;
        self.first_ns = Some(self.first_ns.map_or(stamp_ns, |f| f.min(stamp_ns)));
        self.last_ns = self.last_ns.max(stamp_ns);
        Ok(())
    }

    /// The ROS 2 messages of one dynaflow message: `(topic, type, bytes)`.
    fn convert(&mut self, node: &str, port: &str, msg: &Message) -> Result<Vec<RosMessage>, String> {
        let key = format!("{node}/{port}");
        let topic = format!("/{node}/{port}");
        let (stamp, frame) = (msg.header.stamp, &*msg.header.frame_id);
        let one = |ty: &'static str, data: Vec<u8>| vec![(topic.clone(), ty, data)];
        Ok(match &msg.body {
            Body::Image(img) if self.codec == ImageCodec::Raw => {
                one("sensor_msgs/msg/Image", ros::image(stamp, frame, img))
            }
            Body::Image(img) => {
                let e =
                    self.cache.get_or_encode(msg, 0, || encode::image(img, self.codec)).map_err(|e| e.to_string())?;
                vec![(
                    format!("{topic}/compressed"),
                    "sensor_msgs/msg/CompressedImage",
                    ros::compressed_image(stamp, frame, e.format, &e.bytes),
                )]
            }
            Body::Depth(d) => one("sensor_msgs/msg/Image", ros::depth_image(stamp, frame, d)),
            Body::Mask(m) => {
                let (encoding, step) = encode::mask_encoding(m);
                let data = ros::raw_image(stamp, frame, m.width, m.height, encoding, step, |b| {
                    encode::mask_raw_into(m, encoding, b);
                });
                one("sensor_msgs/msg/Image", data)
            }
            Body::CameraInfo(c) => one("sensor_msgs/msg/CameraInfo", ros::camera_info(stamp, frame, c)),
            Body::Pose(p) => {
                let fixed = if self.ground_truth.contains(&key) { WORLD_FRAME } else { MAP_FRAME };
                self.paths.entry(key.clone()).or_insert_with(|| (fixed, Vec::new())).1.push((stamp, p.world_from_cam));
                let mut out = one("geometry_msgs/msg/PoseStamped", ros::pose_stamped(stamp, fixed, &p.world_from_cam));
                if self.camera_pose.as_deref() == Some(key.as_str()) {
                    let edge =
                        Transform { stamp, parent: MAP_FRAME, child: "camera", parent_from_child: p.world_from_cam };
                    out.push(("/tf".to_string(), "tf2_msgs/msg/TFMessage", ros::tf(&[edge])));
                }
                out
            }
            Body::Trajectory(t) => {
                let fixed = if self.ground_truth.contains(&key) { WORLD_FRAME } else { MAP_FRAME };
                let poses: Vec<(f64, Isometry3<f64>)> = t.poses.iter().map(|p| (p.stamp, p.world_from_cam)).collect();
                one("nav_msgs/msg/Path", ros::path(stamp, fixed, &poses))
            }
            Body::PointCloud(c) => {
                one("sensor_msgs/msg/PointCloud2", ros::point_cloud(stamp, MAP_FRAME, &c.points, c.colors.as_deref()))
            }
            Body::Map(m) => {
                let c = schemas::map_cloud(m);
                one("sensor_msgs/msg/PointCloud2", ros::point_cloud(stamp, MAP_FRAME, &c.points, c.colors.as_deref()))
            }
            Body::Keypoints(k) => {
                let points: Vec<[f32; 2]> = k.points.iter().map(|p| [p.x, p.y]).collect();
                let colours = vec![[0.1, 0.9, 0.2, 1.0]; points.len()];
                one(
                    "visualization_msgs/msg/ImageMarker",
                    ros::image_marker(stamp, frame, &key, MarkerKind::Points, 3.0, &points, &colours),
                )
            }
            Body::Tracks(t) => {
                let points: Vec<[f32; 2]> = t.tracks.iter().flat_map(|t| [t.prev, t.cur]).collect();
                let colours = vec![[1.0, 0.8, 0.0, 1.0]; points.len()];
                one(
                    "visualization_msgs/msg/ImageMarker",
                    ros::image_marker(stamp, frame, &key, MarkerKind::LineList, 1.0, &points, &colours),
                )
            }
            Body::PointLabels(l) => {
                let kept: Vec<_> = l.labels.iter().filter(|l| l.at.iter().all(|v| v.is_finite())).collect();
                let points: Vec<[f32; 2]> = kept.iter().map(|l| l.at).collect();
                let colours: Vec<[f32; 4]> =
                    kept.iter().map(|l| if l.dynamic { [0.9, 0.1, 0.1, 1.0] } else { [0.1, 0.9, 0.2, 1.0] }).collect();
                one(
                    "visualization_msgs/msg/ImageMarker",
                    ros::image_marker(stamp, frame, &key, MarkerKind::Points, 4.0, &points, &colours),
                )
            }
            Body::Detections(d) => {
                let points: Vec<[f32; 2]> = d
                    .detections
                    .iter()
                    .flat_map(|det| {
                        let [x0, y0, x1, y1] = det.bbox;
                        [[x0, y0], [x1, y0], [x1, y0], [x1, y1], [x1, y1], [x0, y1], [x0, y1], [x0, y0]]
                    })
                    .collect();
                let colours = vec![[1.0, 0.2, 0.2, 1.0]; points.len()];
                one(
                    "visualization_msgs/msg/ImageMarker",
                    ros::image_marker(stamp, frame, &key, MarkerKind::LineList, 2.0, &points, &colours),
                )
            }
            Body::Imu(batch) => batch
                .samples
                .iter()
                .map(|s| {
                    let (g, a) = (s.gyro, s.accel);
                    (topic.clone(), "sensor_msgs/msg/Imu", ros::imu(s.stamp, "imu", [g.x, g.y, g.z], [a.x, a.y, a.z]))
                })
                .collect(),
            _ => {
                let json = schemas::to_json(msg)?;
                one("std_msgs/msg/String", ros::string(&String::from_utf8_lossy(&json)))
            }
        })
    }

    fn metadata_yaml(&self) -> String {
        let start = self.first_ns.unwrap_or(0);
        let duration = self.last_ns.saturating_sub(start);
        let total: u64 = self.topics.values().map(|t| t.count).sum();
        let mut y = String::from("rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n");
        y += &format!(
            "  duration:\n    nanoseconds: {duration}\n  starting_time:\n    nanoseconds_since_epoch: {start}\n"
        );
        y += &format!("  message_count: {total}\n  topics_with_message_count:\n");
        for (name, t) in &self.topics {
            y += &format!(
                "    - topic_metadata:\n        name: {name}\n        type: {}\n        serialization_format: cdr\n        offered_qos_profiles: \"\"\n      message_count: {}\n",
                t.ty, t.count
            );
        }
        y += "  compression_format: \"\"\n  compression_mode: \"\"\n";
        y += &format!("  relative_file_paths:\n    - {}\n", self.file_name);
        y += &format!(
            "  files:\n    - path: {}\n      starting_time:\n        nanoseconds_since_epoch: {start}\n      duration:\n        nanoseconds: {duration}\n      message_count: {total}\n",
            self.file_name
        );
        y
    }
}

fn stamp_ns(stamp: f64) -> u64 {
    let (sec, nanosec) = ros::time(stamp);
    sec.max(0) as u64 * 1_000_000_000 + u64::from(nanosec)
}

impl Sink for Ros2Sink {
    fn name(&self) -> &str {
        "ros2"
    }

    fn open(&mut self, info: &RunInfo) -> Result<(), SinkError> {
        if self.dir.exists() {
            return Err(self.err("already exists; a bag folder is never overwritten"));
        }
        std::fs::create_dir_all(&self.dir).map_err(|e| self.err(e))?;
        let writer = open_writer("ros2", &self.mcap_path(), "ros2", DEFAULT_CHUNK_SIZE, info)?;
        self.writer = Some(writer);
        self.ground_truth.clone_from(&info.ground_truth_ports);
        self.camera_pose = info.estimates.first().cloned();
        self.last_flush = Instant::now();
        Ok(())
    }

    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let out = self.convert(node, port, msg).map_err(|e| self.err(format!("encoding {node}/{port}: {e}")))?;
        let ns = stamp_ns(msg.header.stamp);
        let entry = self.ports.entry(format!("{node}/{port}")).or_default();
        entry.0 += 1;
        entry.1 += out.iter().map(|(_, _, d)| d.len() as u64).sum::<u64>();
        for (topic, ty, data) in out {
            self.write(&topic, ty, ns, msg.header.seq as u32, &data)?;
        }
        if self.last_flush.elapsed() >= DEFAULT_FLUSH_INTERVAL {
            let path = self.mcap_path();
            let writer = self.writer.as_mut().ok_or_else(|| SinkError::new("ros2", "not open"))?;
            writer.flush().map_err(|e| writer_error("ros2", &path, &e))?;
            self.last_flush = Instant::now();
        }
        Ok(())
    }

    fn close(&mut self) -> Result<(), SinkError> {
        if self.writer.is_none() {
            return Ok(());
        }
        // Each pose stream as one Path, stamped with its last pose.
        for (key, (fixed, poses)) in std::mem::take(&mut self.paths) {
            let Some(last) = poses.last().map(|p| p.0) else { continue };
            let data = ros::path(last, fixed, &poses);
            self.write(&format!("/{key}/path"), "nav_msgs/msg/Path", stamp_ns(last), 0, &data)?;
        }
        let Some(mut writer) = self.writer.take() else { return Ok(()) };
        writer.finish().map_err(|e| writer_error("ros2", &self.mcap_path(), &e))?;
        let mut inner = writer.into_inner();
        inner.flush().map_err(|e| self.err(e))?;
        inner.get_ref().sync_all().map_err(|e| self.err(e))?;
        dynaflow_engine::files::write_atomic(&self.dir.join("metadata.yaml"), self.metadata_yaml().as_bytes())
            .map_err(|e| self.err(e))
    }

    fn report(&self) -> SinkReport {
        let ports = self
            .ports
            .iter()
            .map(|(k, (messages, bytes))| {
                (k.clone(), PortReport { messages: *messages, bytes: *bytes, ..PortReport::default() })
            })
            .collect();
        let file_bytes = std::fs::metadata(self.mcap_path()).ok().map(|m| m.len());
        SinkReport { path: Some(self.dir.display().to_string()), file_bytes, ports, ..SinkReport::default() }
    }
}
