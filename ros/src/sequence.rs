//! A bag as a run's sequence of frames ([`BagSequence`]): the topic for each role chosen (the
//! only candidate, or named in [`Topics`]), colour and depth paired by header stamp with the
//! rule TUM folders use (nearest first, one to one, within a tolerance; never by record time),
//! intrinsics from `CameraInfo`, ground truth from a pose topic or the tf tree, an IMU's
//! samples in one batch per frame (`imu`), and every message the pairing leaves out counted by
//! reason ([`BagSequence::report`]).
//!
//! Opening reads the bag once (the inventory, every image's stamp, the calibration, the poses);
//! the frames are then read in one more pass, holding only the images whose partner has not
//! come yet. Errors name the bag, and the topic and stamp where there is one.

use std::collections::{BTreeMap, HashMap, HashSet};

use dynaflow_datasets::Error;
use dynaflow_datasets::intrinsics::Intrinsics;
use dynaflow_datasets::tum::{GT_MAX_DIFF_S, associate_stamps, nearest_pose};
use dynaflow_msg::{CameraInfo, DepthImage, Image, ImuBatch};
use dynaflow_vision::camera::Pinhole;
use nalgebra::Isometry3;

use crate::decode::Message;
use crate::inspect::scan;
use crate::sensor::{self, Picture, seconds, stamp_text};
use crate::tf::TfTree;
use crate::{Bag, Messages};

mod collect;
mod imu;
mod topics;

use collect::{Collected, POSE_TYPES, collect};
pub use imu::ImuOptions;
pub use topics::{GroundTruth, TOPIC_ROLES, Topics};
use topics::{none_for, pick, pick_camera_info};

/// How [`BagSequence::open`] reads a bag.
#[derive(Clone, Debug)]
pub struct BagOptions {
    /// The topic of each role.
    pub topics: Topics,
    /// Largest colour/depth header-stamp difference to pair, seconds.
    pub max_difference: f64,
    /// 16-bit depth value per metre (REP 118: millimetres, 1000).
    pub depth_factor: f64,
    /// At most this many frames (0: all).
    pub frames: usize,
    /// Intrinsics to use instead of the bag's `CameraInfo`.
    pub intrinsics: Option<Intrinsics>,
    /// The IMU's noise and mounting, which a bag does not hold.
    pub imu: ImuOptions,
}

/// What a run read from a bag and what it left out (the source's entry in the run summary).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BagReport {
    /// The bag's path.
    pub bag: String,
    /// The topic of each role (`rgb`, `depth`, `camera_info`, `gt`).
    pub topics: BTreeMap<String, String>,
    /// Frames the run was given.
    pub frames: u64,
    /// Messages of the read topics left out, by `topic: reason`.
    pub dropped: BTreeMap<String, u64>,
    /// Frames without a ground-truth pose (left out of the ATE).
    pub frames_without_ground_truth: u64,
    /// Topics no role reads, with their message counts.
    pub topics_not_read: BTreeMap<String, u64>,
}

/// One frame of a [`BagSequence`].
#[derive(Clone, Debug)]
pub struct BagFrame {
    /// The colour image's header stamp, seconds.
    pub stamp: f64,
    /// Colour image (RGB8 or Gray8).
    pub rgb: Image,
    /// Depth in metres, when the run has a depth topic.
    pub depth: Option<DepthImage>,
    /// The intrinsics at the image's size.
    pub camera: CameraInfo,
    /// Ground-truth `world_from_cam`, where the bag has one for this frame.
    pub gt_pose: Option<Isometry3<f64>>,
    /// The IMU samples since the previous frame, when the run reads an IMU topic.
    pub imu: Option<ImuBatch>,
}

/// A colour stamp and its depth partner's, nanoseconds.
#[derive(Clone, Copy, Debug)]
struct Planned {
    rgb: i64,
    depth: Option<i64>,
}

/// The second pass: the messages from where it stands, and the images read ahead of their frame.
struct Stream {
    messages: Messages,
    /// The frame `read` will be asked for next.
    next: usize,
    /// (is depth, stamp) of the images still to come.
    wanted: HashSet<(bool, i64)>,
    pending: HashMap<(bool, i64), Message>,
}

/// A bag read frame by frame. See the module documentation.
pub struct BagSequence {
    bag: Bag,
    rgb: String,
    depth: Option<String>,
    camera_info: Option<String>,
    gt_from: GroundTruth,
    frames: Vec<Planned>,
    intrinsics: Intrinsics,
    /// The `CameraInfo`'s image size, which every frame must have.
    info_size: Option<(u32, u32)>,
    depth_factor: f64,
    gt: Vec<(f64, Isometry3<f64>)>,
    tf: TfTree,
    stream: Option<Stream>,
    /// Messages left out, by reason.
    dropped: BTreeMap<String, u64>,
    /// Frames without a ground-truth pose.
    frames_without_pose: u64,
    /// Topics no role reads, with their message counts.
    unused: BTreeMap<String, u64>,
    imu: Option<imu::Plan>,
}

impl std::fmt::Debug for BagSequence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagSequence").field("bag", &self.bag.path()).field("frames", &self.frames.len()).finish()
    }
}

impl BagSequence {
    /// Opens `bag` for a run: reads it once, chooses the topics, pairs colour with depth. An
    /// error names the bag and says which `topics` entry would settle it.
    pub fn open(bag: Bag, options: &BagOptions) -> Result<Self, Error> {
        let path = bag.path().to_path_buf();
        let fail = |message: String| Error::file(&path, message);
        let mut c = Collected::default();
        let inventory = scan(&bag, |raw, decoded, stamp| collect(raw, decoded, stamp, &mut c))
            .map_err(|e| Error::Data(e.to_string()))?;
        let t = &options.topics;
        let rgb = pick(&inventory, "rgb", t.rgb.as_deref(), &["sensor_msgs/Image", "sensor_msgs/CompressedImage"])
            .map_err(fail)?
            .ok_or_else(|| fail(none_for(&inventory, "rgb", "colour images")))?;
        let depth = match t.depth.as_deref() {
            Some("none") => None,
            given => {
                pick(&inventory, "depth", given, &["sensor_msgs/Image", "sensor_msgs/CompressedImage"]).map_err(fail)?
            }
        };
        if depth.is_none() && t.depth.is_none() {
            tracing::warn!("{}: no depth topic; the run is monocular", path.display());
        }
        for (role, topic, want) in [("rgb", Some(&rgb), "colour"), ("depth", depth.as_ref(), "depth")] {
            let Some(topic) = topic else { continue };
            let content = inventory.topics.iter().find(|i| &i.topic == topic).and_then(|i| i.content.as_deref());
            if content != Some(want) {
                return Err(fail(format!(
                    "topic {topic} (`{role}`) does not hold {want} images: its first message is {}",
                    content.unwrap_or("not an image")
                )));
            }
        }
        // Calibration: given, or the bag's CameraInfo for the colour camera.
        let (intrinsics, info_size, camera_info) = match options.intrinsics {
            Some(k) => (k, None, None),
            None => {
                let topic = pick_camera_info(&inventory, &rgb, t.camera_info.as_deref())
                    .map_err(fail)?
                    .ok_or_else(|| {
                        fail(format!(
                            "no sensor_msgs/CameraInfo topic for {rgb}: name one with `topics: camera_info=TOPIC`, or give the intrinsics (`intrinsics: fx,fy,cx,cy`, `--intrinsics`)"
                        ))
                    })?;
                let (info, changed) = c.infos.remove(&topic).unwrap_or_else(|| (Err("no message".into()), None));
                let info = info.map_err(|e| fail(format!("topic {topic}: {e}")))?;
                if let Some(at) = changed {
                    return Err(fail(format!(
                        "topic {topic}: the calibration changes at {} s; a run takes one calibration (give `intrinsics` to choose)",
                        stamp_text(at)
                    )));
                }
                let k = Intrinsics {
                    pinhole: Pinhole::new(info.fx, info.fy, info.cx, info.cy),
                    distortion: info.distortion,
                    model: info.model,
                };
                let size = (info.width > 0 && info.height > 0).then_some((info.width, info.height));
                (k, size, Some(topic))
            }
        };
        // Ground truth.
        let gt_from = match &t.gt {
            Some(g) => g.clone(),
            None => match pick(&inventory, "gt", None, &POSE_TYPES) {
                Ok(Some(topic)) => {
                    tracing::info!(
                        "{}: ground truth from {topic} (the only pose topic; `topics: gt=none` if it is not ground truth)",
                        path.display()
                    );
                    GroundTruth::Topic(topic)
                }
                Ok(None) => GroundTruth::Off,
                Err(e) => return Err(fail(e)),
            },
        };
        let gt = match &gt_from {
            GroundTruth::Topic(topic) => {
                if let Err(e) = pick(&inventory, "gt", Some(topic), &POSE_TYPES) {
                    return Err(fail(e));
                }
                let mut poses =
                    c.poses.remove(topic).unwrap_or(Ok(Vec::new())).map_err(|e| fail(format!("topic {topic}: {e}")))?;
                poses.sort_by_key(|p| p.0);
                poses.into_iter().map(|(ns, p)| (seconds(ns), p)).collect()
            }
            GroundTruth::Tf { .. } => {
                if let Some(e) = c.tf_error.take() {
                    return Err(fail(e));
                }
                Vec::new()
            }
            GroundTruth::Off => Vec::new(),
        };
        // Pairing, by header stamp.
        let mut dropped = BTreeMap::new();
        let stamps = |topic: &str, dropped: &mut BTreeMap<String, u64>| {
            let mut s = c.image_stamps.get(topic).cloned().unwrap_or_default();
            s.sort_unstable();
            let before = s.len();
            s.dedup();
            if s.len() < before {
                dropped.insert(format!("{topic}: repeats a header stamp"), (before - s.len()) as u64);
            }
            s
        };
        let rgb_ns = stamps(&rgb, &mut dropped);
        let mut frames: Vec<Planned> = match &depth {
            None => rgb_ns.iter().map(|&r| Planned { rgb: r, depth: None }).collect(),
            Some(depth_topic) => {
                let depth_ns = stamps(depth_topic, &mut dropped);
                let to_s = |v: &[i64]| v.iter().map(|&n| seconds(n)).collect::<Vec<f64>>();
                let pairs = associate_stamps(&to_s(&rgb_ns), &to_s(&depth_ns), options.max_difference);
                if pairs.is_empty() {
                    let first = rgb_ns.first().copied().unwrap_or_default();
                    let nearest = depth_ns.iter().min_by_key(|d| (*d - first).abs()).copied();
                    return Err(fail(format!(
                        "no colour image of {rgb} has a depth image of {depth_topic} within {} s of its header stamp: the first colour stamp, {} s, is nearest depth {}; raise `max_difference`, or check that both cameras stamp on one clock",
                        options.max_difference,
                        stamp_text(first),
                        nearest.map_or("(none)".to_string(), |d| format!(
                            "{} s, {:.3} s away",
                            stamp_text(d),
                            (d - first) as f64 * 1e-9
                        ))
                    )));
                }
                let unpaired_rgb = rgb_ns.len() - pairs.len();
                let unpaired_depth = depth_ns.len() - pairs.len();
                if unpaired_rgb > 0 {
                    dropped.insert(format!("{rgb}: no depth within {} s", options.max_difference), unpaired_rgb as u64);
                }
                if unpaired_depth > 0 {
                    dropped.insert(
                        format!("{depth_topic}: no colour within {} s", options.max_difference),
                        unpaired_depth as u64,
                    );
                }
                pairs.into_iter().map(|(i, j)| Planned { rgb: rgb_ns[i], depth: Some(depth_ns[j]) }).collect()
            }
        };
        if options.frames > 0 {
            frames.truncate(options.frames);
        }
        // The IMU: named, or the only one when its noise is given.
        let imu_topic = match t.imu.as_deref() {
            Some("none") => None,
            Some(given) => pick(&inventory, "imu", Some(given), &["sensor_msgs/Imu"]).map_err(fail)?,
            None if options.imu.noise.is_some() => pick(&inventory, "imu", None, &["sensor_msgs/Imu"]).map_err(fail)?,
            None => {
                if inventory.candidates.get("imu").is_some_and(|c| !c.is_empty()) {
                    tracing::info!(
                        "{}: the IMU is not read without its noise figures (`imu_noise`); a visual-inertial graph needs them",
                        path.display()
                    );
                }
                None
            }
        };
        let imu = match imu_topic {
            None => None,
            Some(topic) => {
                let stamps: Vec<(f64, i64)> = frames.iter().map(|f| (seconds(f.rgb), f.rgb)).collect();
                let camera_frame = c.image_frames.get(&rgb).cloned().unwrap_or_default();
                let plan =
                    imu::plan(&path, &topic, &mut c.imu, &camera_frame, &c.tf, &options.imu, &stamps).map_err(fail)?;
                if plan.after_last > 0 {
                    dropped.insert(format!("{topic}: after the last frame"), plan.after_last);
                }
                if plan.repeats > 0 {
                    dropped.insert(format!("{topic}: repeats a sample"), plan.repeats);
                }
                Some(plan)
            }
        };
        let used: Vec<Option<&str>> = vec![
            Some(rgb.as_str()),
            depth.as_deref(),
            camera_info.as_deref(),
            match &gt_from {
                GroundTruth::Topic(t) => Some(t.as_str()),
                _ => None,
            },
            imu.as_ref().map(|p| p.topic.as_str()),
        ];
        let tf_used = matches!(gt_from, GroundTruth::Tf { .. });
        let unused = inventory
            .topics
            .iter()
            .filter(|i| !used.contains(&Some(i.topic.as_str())))
            .filter(|i| !(tf_used && i.ty == "tf2_msgs/TFMessage"))
            .map(|i| (i.topic.clone(), i.count))
            .collect();
        let mut seq = Self {
            bag,
            rgb,
            depth,
            camera_info,
            gt_from,
            frames,
            intrinsics,
            info_size,
            depth_factor: options.depth_factor,
            gt,
            tf: c.tf,
            stream: None,
            dropped,
            frames_without_pose: 0,
            unused,
            imu,
        };
        seq.frames_without_pose = (0..seq.frames.len()).filter(|&i| seq.gt_pose(i).is_none()).count() as u64;
        if seq.frames_without_pose as usize == seq.frames.len() && seq.gt_from != GroundTruth::Off {
            return Err(fail(format!(
                "{}: no ground-truth pose for any frame (frames {:.6}..{:.6} s); `topics: gt=none` runs without",
                seq.gt_name(),
                seconds(seq.frames.first().map_or(0, |f| f.rgb)),
                seconds(seq.frames.last().map_or(0, |f| f.rgb)),
            )));
        }
        Ok(seq)
    }

    /// The bag.
    pub fn bag(&self) -> &Bag {
        &self.bag
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether there is no frame (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The topics the run reads, by role.
    pub fn topics(&self) -> Vec<(&'static str, String)> {
        let mut out = vec![("rgb", self.rgb.clone())];
        if let Some(d) = &self.depth {
            out.push(("depth", d.clone()));
        }
        if let Some(c) = &self.camera_info {
            out.push(("camera_info", c.clone()));
        }
        if self.gt_from != GroundTruth::Off {
            out.push(("gt", self.gt_name()));
        }
        if let Some(p) = &self.imu {
            out.push(("imu", p.topic.clone()));
        }
        out
    }

    fn gt_name(&self) -> String {
        match &self.gt_from {
            GroundTruth::Topic(t) => t.clone(),
            GroundTruth::Tf { parent, child } => format!("tf:{parent}:{child}"),
            GroundTruth::Off => "none".into(),
        }
    }

    fn gt_pose(&self, index: usize) -> Option<Isometry3<f64>> {
        let ns = self.frames.get(index)?.rgb;
        match &self.gt_from {
            GroundTruth::Topic(_) => nearest_pose(&self.gt, seconds(ns), GT_MAX_DIFF_S),
            GroundTruth::Tf { parent, child } => self.tf.lookup(parent, child, ns).ok(),
            GroundTruth::Off => None,
        }
    }

    /// Frames without a ground-truth pose (left out of the ATE).
    pub fn frames_without_pose(&self) -> u64 {
        self.frames_without_pose
    }

    /// What the run's summary says of the bag: its topics, the messages left out by reason,
    /// frames without ground truth, and the topics no role reads.
    pub fn report(&self) -> BagReport {
        BagReport {
            bag: self.bag.path().display().to_string(),
            topics: self.topics().into_iter().map(|(role, t)| (role.to_string(), t)).collect(),
            frames: self.frames.len() as u64,
            dropped: self.dropped.clone(),
            frames_without_ground_truth: self.frames_without_pose,
            topics_not_read: self.unused.clone(),
        }
    }

    fn topic_error(&self, topic: &str, ns: i64, message: impl std::fmt::Display) -> Error {
        Error::file(self.bag.path(), format!("topic {topic} at {} s: {message}", stamp_text(ns)))
    }

    /// Frame `index`, `None` past the end. Read in order, each message is decoded once; going
    /// back starts the pass again.
    pub fn frame(&mut self, index: usize) -> Result<Option<BagFrame>, Error> {
        let Some(plan) = self.frames.get(index).copied() else { return Ok(None) };
        if self.stream.as_ref().is_none_or(|s| s.next != index) {
            let wanted = self.frames[index..]
                .iter()
                .flat_map(|p| std::iter::once((false, p.rgb)).chain(p.depth.map(|d| (true, d))))
                .collect();
            let messages = self.bag.messages().map_err(|e| Error::Data(e.to_string()))?;
            self.stream = Some(Stream { messages, next: index, wanted, pending: HashMap::new() });
        }
        let keys = [Some((false, plan.rgb)), plan.depth.map(|d| (true, d))];
        while let Some(stream) = self.stream.as_mut() {
            if keys.iter().flatten().all(|k| stream.pending.contains_key(k)) {
                break;
            }
            let raw = match stream.messages.next() {
                Some(r) => r.map_err(|e| Error::Data(e.to_string()))?,
                None => {
                    self.stream = None;
                    return Err(Error::file(
                        self.bag.path(),
                        format!("the bag ended before the images of the frame at {} s", stamp_text(plan.rgb)),
                    ));
                }
            };
            let is_depth = if raw.connection.topic == self.rgb {
                false
            } else if self.depth.as_deref() == Some(raw.connection.topic.as_str()) {
                true
            } else {
                continue;
            };
            let bad = |e: String| Error::file(self.bag.path(), format!("topic {}: {e}", raw.connection.topic));
            let m = raw.decode().map_err(bad)?;
            let ns = sensor::header(&m).map_err(bad)?.stamp_ns;
            if stream.wanted.remove(&(is_depth, ns)) {
                stream.pending.insert((is_depth, ns), m);
            }
        }
        let Some(stream) = self.stream.as_mut() else { return Ok(None) };
        stream.next = index + 1;
        let rgb_msg = stream.pending.remove(&(false, plan.rgb));
        let depth_msg = plan.depth.and_then(|d| stream.pending.remove(&(true, d)));
        let rgb = match rgb_msg.map(|m| self.picture(&m)) {
            Some(Ok(Picture::Colour(img))) => img,
            Some(Ok(Picture::Depth(_))) => {
                return Err(self.topic_error(&self.rgb, plan.rgb, "a depth image on the colour topic"));
            }
            Some(Err(e)) => return Err(self.topic_error(&self.rgb, plan.rgb, e)),
            None => return Err(self.topic_error(&self.rgb, plan.rgb, "the message went missing")),
        };
        let depth = match (depth_msg.map(|m| self.picture(&m)), &self.depth, plan.depth) {
            (Some(Ok(Picture::Depth(d))), Some(topic), Some(ns)) => {
                if (d.width, d.height) != (rgb.width, rgb.height) {
                    return Err(self.topic_error(
                        topic,
                        ns,
                        format!(
                            "depth of {}x{} beside colour of {}x{} ({}); the depth must be registered to the colour camera",
                            d.width, d.height, rgb.width, rgb.height, self.rgb
                        ),
                    ));
                }
                Some(d)
            }
            (Some(Ok(Picture::Colour(_))), Some(topic), Some(ns)) => {
                return Err(self.topic_error(topic, ns, "a colour image on the depth topic"));
            }
            (Some(Err(e)), Some(topic), Some(ns)) => return Err(self.topic_error(topic, ns, e)),
            _ => None,
        };
        if let Some((w, h)) = self.info_size
            && (w, h) != (rgb.width, rgb.height)
        {
            return Err(self.topic_error(
                &self.rgb,
                plan.rgb,
                format!(
                    "an image of {}x{}, but {} calibrates {w}x{h}",
                    rgb.width,
                    rgb.height,
                    self.camera_info.as_deref().unwrap_or("the CameraInfo")
                ),
            ));
        }
        Ok(Some(BagFrame {
            stamp: seconds(plan.rgb),
            camera: self.intrinsics.camera_info(rgb.width, rgb.height),
            rgb,
            depth,
            gt_pose: self.gt_pose(index),
            imu: self.imu.as_ref().map(|p| ImuBatch {
                samples: p.batches.get(index).cloned().unwrap_or_default(),
                calibration: p.calibration,
            }),
        }))
    }

    fn picture(&self, m: &Message) -> Result<Picture, String> {
        if m.get("format").is_some() && m.get("encoding").is_none() {
            sensor::compressed_image(m, self.depth_factor)
        } else {
            sensor::image(m, self.depth_factor)
        }
    }
}

impl dynaflow_datasets::Sequence for BagSequence {
    type Frame = BagFrame;
    fn len(&self) -> usize {
        self.frames.len()
    }
    fn read(&mut self, index: usize) -> Result<Option<BagFrame>, Error> {
        self.frame(index)
    }
    fn stamp(frame: &BagFrame) -> f64 {
        frame.stamp
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seconds_are_the_decimal_stamp() {
        for text in ["1305031102.175304", "0.033333", "1700000000.999999999", "3.000000001"] {
            let (s, f) = text.split_once('.').unwrap();
            let ns: i64 = s.parse::<i64>().unwrap() * 1_000_000_000 + format!("{f:0<9}").parse::<i64>().unwrap();
            assert_eq!(seconds(ns), text.parse::<f64>().unwrap(), "{text}");
        }
        assert_eq!(seconds(-1_500_000_000), -1.5);
    }
}
