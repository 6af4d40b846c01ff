//! What a bag holds, as `dynaflow inspect` prints it: per topic its type, message count, the
//! span and rate of its header stamps (record times where a message has no header), and which
//! topic a run would take for each role (colour, depth, camera info, IMU, ground truth). A role
//! is filled only when one topic fits it; otherwise the candidates are listed and the user names
//! one with `--topics`.

use std::collections::BTreeMap;

use crate::sensor::{self, Picture};
use crate::{Bag, Error};

/// One topic.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// `pkg/Type`.
    pub ty: String,
    /// Messages.
    pub count: u64,
    /// First and last header stamp (record time without a header), seconds.
    pub span_s: [f64; 2],
    /// `(count - 1) / span`, Hz (0 for one message).
    pub rate_hz: f64,
    /// What the first message is, for images: `colour`, `depth`, or why it cannot be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub content: Option<String>,
}

/// The roles a run fills from a bag.
pub const ROLES: [&str; 5] = ["rgb", "depth", "camera_info", "imu", "gt"];

/// A bag's topics and the topic each role would take.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Inventory {
    /// Topics by name.
    pub topics: Vec<TopicInfo>,
    /// Per role: the topics that fit it (a run takes it when there is exactly one).
    pub candidates: BTreeMap<String, Vec<String>>,
}

impl Inventory {
    /// The topic a run would take for `role`: the only candidate.
    pub fn chosen(&self, role: &str) -> Option<&str> {
        match self.candidates.get(role).map(Vec::as_slice) {
            Some([one]) => Some(one),
            _ => None,
        }
    }
}

/// Reads the whole bag once (every message's stamp; the first image of each topic decoded).
pub fn inspect(bag: &Bag) -> Result<Inventory, Error> {
    scan(bag, |_, _, _| {})
}

/// The `CameraInfo` topics of `infos` beside image topic `image`: in its namespace, where
/// image_transport puts them (`/cam/color/camera_info` beside `/cam/color/image_raw` and its
/// `/cam/color/image_raw/compressed`).
pub(crate) fn beside(image: &str, infos: &[String]) -> Vec<String> {
    let base = ["/compressed", "/compressedDepth", "/theora", "/zstd"]
        .iter()
        .find_map(|t| image.strip_suffix(t))
        .unwrap_or(image);
    let Some((ns, _)) = base.rsplit_once('/') else { return Vec::new() };
    infos.iter().filter(|i| i.rsplit_once('/').is_some_and(|(n, _)| n == ns)).cloned().collect()
}

/// [`inspect`], handing each message to `each` as it goes: the message, its decoding, and its
/// header stamp (record time without a header), nanoseconds. A run's source reads what it needs
/// (image stamps, calibration, poses) in the same pass.
pub(crate) fn scan(
    bag: &Bag,
    mut each: impl FnMut(&crate::RawMessage, &Result<crate::decode::Message, String>, i64),
) -> Result<Inventory, Error> {
    struct Acc {
        ty: String,
        count: u64,
        first: i64,
        last: i64,
        content: Option<String>,
    }
    let mut acc: BTreeMap<String, Acc> = BTreeMap::new();
    // Where a cut or corrupt bag stops: after the last message read.
    let mut last: Option<(String, i64)> = None;
    for raw in bag.messages()? {
        let raw = raw.map_err(|e| match (e, &last) {
            (Error::File { path, offset, message }, Some((topic, ns))) => Error::File {
                path,
                offset,
                message: format!("{message} (after topic {topic} at {} s)", sensor::stamp_text(*ns)),
            },
            (e, _) => e,
        })?;
        let ty = raw.connection.type_name();
        let decoded = raw.decode();
        let stamp =
            decoded.as_ref().ok().and_then(|m| sensor::header(m).ok()).map_or(raw.log_time as i64, |h| h.stamp_ns);
        let a = acc.entry(raw.connection.topic.clone()).or_insert_with(|| Acc {
            ty: ty.clone(),
            count: 0,
            first: stamp,
            last: stamp,
            content: None,
        });
        if a.count == 0 && matches!(ty.as_str(), "sensor_msgs/Image" | "sensor_msgs/CompressedImage") {
            a.content = Some(match &decoded {
                Err(e) => format!("undecodable: {e}"),
                Ok(m) => {
                    let picture = if ty == "sensor_msgs/Image" {
                        sensor::image(m, 1000.0)
                    } else {
                        sensor::compressed_image(m, 1000.0)
                    };
                    match picture {
                        Ok(Picture::Colour(_)) => "colour".into(),
                        Ok(Picture::Depth(_)) => "depth".into(),
                        Err(e) => format!("unreadable: {e}"),
                    }
                }
            });
        }
        each(&raw, &decoded, stamp);
        last = Some((raw.connection.topic.clone(), stamp));
        a.count += 1;
        a.first = a.first.min(stamp);
        a.last = a.last.max(stamp);
    }
    let topics: Vec<TopicInfo> = acc
        .into_iter()
        .map(|(topic, a)| TopicInfo {
            topic,
            ty: a.ty,
            count: a.count,
            span_s: [a.first as f64 * 1e-9, a.last as f64 * 1e-9],
            // From the integer nanoseconds: seconds since 1970 in an f64 keep only ~0.2 us.
            rate_hz: if a.count > 1 && a.last > a.first {
                (a.count - 1) as f64 * 1e9 / (a.last - a.first) as f64
            } else {
                0.0
            },
            content: a.content,
        })
        .collect();
    let of = |pred: &dyn Fn(&TopicInfo) -> bool| topics.iter().filter(|t| pred(t)).map(|t| t.topic.clone()).collect();
    let mut candidates = BTreeMap::new();
    candidates.insert("rgb".to_string(), of(&|t| t.content.as_deref() == Some("colour")));
    candidates.insert("depth".to_string(), of(&|t| t.content.as_deref() == Some("depth")));
    candidates.insert("imu".to_string(), of(&|t| t.ty == "sensor_msgs/Imu"));
    // Ground truth: a pose topic; odometry is an estimate, never taken as ground truth unless
    // named (`gt=/odom`).
    candidates.insert(
        "gt".to_string(),
        of(&|t| {
            matches!(
                t.ty.as_str(),
                "geometry_msgs/PoseStamped"
                    | "geometry_msgs/TransformStamped"
                    | "geometry_msgs/PoseWithCovarianceStamped"
            )
        }),
    );
    // Camera info: the one topic, or the one beside the only colour topic.
    let infos: Vec<String> = of(&|t| t.ty == "sensor_msgs/CameraInfo");
    let near = match candidates["rgb"].as_slice() {
        [one] => beside(one, &infos),
        _ => Vec::new(),
    };
    candidates.insert("camera_info".to_string(), if near.len() == 1 { near } else { infos });
    Ok(Inventory { topics, candidates })
}
