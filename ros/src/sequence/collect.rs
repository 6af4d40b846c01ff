//! The first pass over a bag: every image's header stamp and frame, the first calibration of
//! each `CameraInfo` topic (and whether it changes), the poses of each pose topic, the tf tree
//! and the IMU samples.

use std::collections::HashMap;

use dynaflow_msg::CameraInfo;
use nalgebra::Isometry3;

use super::imu;
use crate::decode::Message;
use crate::sensor::{self, stamp_text};
use crate::tf::TfTree;

/// A pose topic's `(stamp ns, world_from_cam)`.
type Poses = Vec<(i64, Isometry3<f64>)>;

/// What the first pass keeps.
#[derive(Default)]
pub(super) struct Collected {
    /// Header stamps per image topic, in record order.
    pub(super) image_stamps: HashMap<String, Vec<i64>>,
    /// Per `CameraInfo` topic: the first calibration, and the stamp of the first that differs.
    pub(super) infos: HashMap<String, (Result<CameraInfo, String>, Option<i64>)>,
    /// Per pose topic: its poses (or the first error).
    pub(super) poses: HashMap<String, Result<Poses, String>>,
    pub(super) tf: TfTree,
    pub(super) tf_error: Option<String>,
    /// The first message's `header.frame_id` per image topic.
    pub(super) image_frames: HashMap<String, String>,
    pub(super) imu: imu::Collected,
}

pub(super) const POSE_TYPES: [&str; 4] = [
    "geometry_msgs/PoseStamped",
    "nav_msgs/Odometry",
    "geometry_msgs/TransformStamped",
    "geometry_msgs/PoseWithCovarianceStamped",
];

pub(super) fn collect(raw: &crate::RawMessage, decoded: &Result<Message, String>, stamp: i64, c: &mut Collected) {
    let Ok(m) = decoded else { return };
    let topic = &raw.connection.topic;
    match raw.connection.type_name().as_str() {
        "sensor_msgs/Image" | "sensor_msgs/CompressedImage" => {
            c.image_stamps.entry(topic.clone()).or_default().push(stamp);
            if !c.image_frames.contains_key(topic)
                && let Ok(h) = sensor::header(m)
            {
                c.image_frames.insert(topic.clone(), h.frame_id);
            }
        }
        "sensor_msgs/Imu" => {
            let sample = sensor::imu(m).and_then(|s| Ok((s, sensor::header(m)?.frame_id)));
            c.imu.add(topic, sample.map_err(|e| format!("at {} s: {e}", stamp_text(stamp))));
        }
        "sensor_msgs/CameraInfo" => {
            let info = sensor::camera_info(m);
            match c.infos.get_mut(topic) {
                None => {
                    c.infos.insert(topic.clone(), (info, None));
                }
                Some((first, changed @ None)) if info.as_ref().ok() != first.as_ref().ok() => *changed = Some(stamp),
                Some(_) => {}
            }
        }
        "tf2_msgs/TFMessage" => match sensor::transforms(m) {
            Ok(list) => {
                let is_static = topic.ends_with("tf_static");
                for (h, child, pose) in list {
                    if let Err(e) = c.tf.insert(&h.frame_id, &child, h.stamp_ns, pose, is_static) {
                        c.tf_error.get_or_insert_with(|| format!("topic {topic} at {} s: {e}", stamp_text(h.stamp_ns)));
                    }
                }
            }
            Err(e) => {
                c.tf_error.get_or_insert_with(|| format!("topic {topic}: {e}"));
            }
        },
        ty if POSE_TYPES.contains(&ty) => {
            let entry = c.poses.entry(topic.clone()).or_insert_with(|| Ok(Vec::new()));
            if let Ok(list) = entry {
                match sensor::stamped_pose(m) {
                    Ok((h, _, pose)) => list.push((h.stamp_ns, pose)),
                    Err(e) => *entry = Err(format!("at {} s: {e}", stamp_text(stamp))),
                }
            }
        }
        _ => {}
    }
}
