//! `topics`: which topic fills each role of a run, as a user writes it
//! (`rgb=/camera/color/image_raw,depth=...,gt=tf:world:camera`).

use crate::inspect::{Inventory, beside};

/// Where a run's ground truth comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GroundTruth {
    /// A `PoseStamped`, `Odometry`, `TransformStamped` or `PoseWithCovarianceStamped` topic:
    /// the nearest pose within 10 ms of each frame, as a TUM folder's `groundtruth.txt`.
    Topic(String),
    /// `parent_from_child` through `/tf` and `/tf_static`, interpolated at each frame's stamp.
    Tf {
        /// The fixed frame (`world`, `map`).
        parent: String,
        /// The camera's frame.
        child: String,
    },
    /// None, even if the bag has a pose topic.
    Off,
}

/// The topic for each role: `None` takes the only candidate ([`Inventory::chosen`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Topics {
    /// Colour (or grey) images.
    pub rgb: Option<String>,
    /// Depth images; `Some("none")` is a monocular run of a bag that has depth.
    pub depth: Option<String>,
    /// The colour camera's `CameraInfo`.
    pub camera_info: Option<String>,
    /// Ground truth.
    pub gt: Option<GroundTruth>,
    /// The IMU (`Some("none")`: not read).
    pub imu: Option<String>,
}

/// The roles [`Topics::parse`] reads.
pub const TOPIC_ROLES: &str = "rgb, depth, camera_info, gt, imu";

impl Topics {
    /// `rgb=/camera/color/image_raw,depth=/camera/depth/image_raw,gt=/mocap/pose`: each role at
    /// most once; `depth=none`, `gt=none` and `imu=none` leave a role out; `gt=tf:PARENT:CHILD` takes the
    /// ground truth from the transform tree. Empty text names nothing.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut t = Topics::default();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let Some((role, topic)) = part.split_once('=').map(|(r, v)| (r.trim(), v.trim())) else {
                return Err(format!("`{part}`: expected ROLE=TOPIC (roles: {TOPIC_ROLES})"));
            };
            if topic.is_empty() {
                return Err(format!("`{part}`: no topic after `=`"));
            }
            let slot_taken = match role {
                "rgb" => t.rgb.replace(topic.to_string()).is_some(),
                "depth" => t.depth.replace(topic.to_string()).is_some(),
                "camera_info" => t.camera_info.replace(topic.to_string()).is_some(),
                "gt" => {
                    let gt = if topic == "none" {
                        GroundTruth::Off
                    } else if let Some(pair) = topic.strip_prefix("tf:") {
                        let Some((parent, child)) =
                            pair.split_once(':').filter(|(p, c)| !p.is_empty() && !c.is_empty())
                        else {
                            return Err(format!("`{part}`: expected gt=tf:PARENT:CHILD, e.g. gt=tf:world:camera"));
                        };
                        GroundTruth::Tf { parent: parent.to_string(), child: child.to_string() }
                    } else {
                        GroundTruth::Topic(topic.to_string())
                    };
                    t.gt.replace(gt).is_some()
                }
                "imu" => t.imu.replace(topic.to_string()).is_some(),
                other => return Err(format!("`{part}`: unknown role `{other}` (roles: {TOPIC_ROLES})")),
            };
            if slot_taken {
                return Err(format!("role `{role}` is named twice"));
            }
        }
        Ok(t)
    }
}

/// The topic for `role`: `given` (which must be in the bag with one of `types`), or the only
/// candidate. `Ok(None)`: no candidate; an error for several, naming them.
pub(super) fn pick(
    inventory: &Inventory,
    role: &str,
    given: Option<&str>,
    types: &[&str],
) -> Result<Option<String>, String> {
    if let Some(topic) = given {
        let Some(info) = inventory.topics.iter().find(|t| t.topic == topic) else {
            let like: Vec<&str> =
                inventory.topics.iter().filter(|t| types.contains(&t.ty.as_str())).map(|t| t.topic.as_str()).collect();
            return Err(format!(
                "topic {topic} (`{role}`) is not in the bag; its {} topics: {}",
                types.join(" / "),
                if like.is_empty() { "none".to_string() } else { like.join(", ") }
            ));
        };
        if !types.contains(&info.ty.as_str()) {
            return Err(format!("topic {topic} (`{role}`) is {}, not {}", info.ty, types.join(" or ")));
        }
        return Ok(Some(topic.to_string()));
    }
    match inventory.candidates.get(role).map(Vec::as_slice) {
        None | Some([]) => Ok(None),
        Some([one]) => Ok(Some(one.clone())),
        Some(many) => Err(format!(
            "{} topics could be `{role}` ({}); name one with `topics: {role}=TOPIC` (`--topics {role}=TOPIC`)",
            many.len(),
            many.join(", ")
        )),
    }
}

/// The `CameraInfo` topic for colour topic `rgb`: `given`, the only one, or the only one
/// beside `rgb`.
pub(super) fn pick_camera_info(
    inventory: &Inventory,
    rgb: &str,
    given: Option<&str>,
) -> Result<Option<String>, String> {
    match pick(inventory, "camera_info", given, &["sensor_msgs/CameraInfo"]) {
        Err(many) => {
            match beside(rgb, &inventory.candidates.get("camera_info").cloned().unwrap_or_default()).as_slice() {
                [one] => Ok(Some(one.clone())),
                _ => Err(many),
            }
        }
        other => other,
    }
}

/// The error for a role no topic fills: the bag's topics, and why each image topic that
/// might have been one cannot be read (its first message's stamp and the reason).
pub(super) fn none_for(inventory: &Inventory, role: &str, what: &str) -> String {
    let all: Vec<String> = inventory.topics.iter().map(|t| format!("{} ({})", t.topic, t.ty)).collect();
    let unreadable: Vec<String> = inventory
        .topics
        .iter()
        .filter_map(|t| {
            let why = t.content.as_deref().filter(|c| *c != "colour" && *c != "depth")?;
            Some(format!("topic {} at {:.6} s: {why}", t.topic, t.span_s[0]))
        })
        .collect();
    let mut text = format!(
        "no topic holds {what} (`{role}`); the bag's topics: {}",
        if all.is_empty() { "none".to_string() } else { all.join(", ") }
    );
    for u in unreadable {
        text.push_str("; ");
        text.push_str(&u);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_parse_each_role_once() {
        let t = Topics::parse("rgb=/a/image, depth=none,gt=tf:world:cam").unwrap();
        assert_eq!(t.rgb.as_deref(), Some("/a/image"));
        assert_eq!(t.depth.as_deref(), Some("none"));
        assert_eq!(t.gt, Some(GroundTruth::Tf { parent: "world".into(), child: "cam".into() }));
        assert_eq!(Topics::parse("").unwrap(), Topics::default());
        assert_eq!(Topics::parse("gt=none").unwrap().gt, Some(GroundTruth::Off));
        assert_eq!(Topics::parse("imu=/camera/imu").unwrap().imu.as_deref(), Some("/camera/imu"));
        for (bad, says) in [
            ("rgb=/a,rgb=/b", "named twice"),
            ("colour=/a", "unknown role `colour`"),
            ("rgb", "expected ROLE=TOPIC"),
            ("gt=tf:world", "gt=tf:PARENT:CHILD"),
            ("depth=", "no topic"),
            ("imu=/a,imu=/b", "named twice"),
        ] {
            let e = Topics::parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
