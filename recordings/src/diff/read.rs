//! Reading a dynaflow MCAP recording back: per topic, the `dynaflow` payload of each frame.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::Error;

/// One recorded topic.
#[derive(Clone, Debug, Default)]
pub struct Topic {
    /// Schema name (e.g. `foxglove.PoseInFrame`).
    pub schema: String,
    /// dynaflow port type (`pose`, `keypoints`, …).
    pub ty: String,
    /// Frame number → the message's `dynaflow` object.
    pub frames: BTreeMap<u64, Value>,
}

/// A recording read back.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// The file.
    pub path: PathBuf,
    /// Topic name → topic.
    pub topics: BTreeMap<String, Topic>,
    /// The `dynaflow` metadata record (provenance).
    pub metadata: BTreeMap<String, String>,
    /// Whether the file ended early (a killed run); everything before the cut was read.
    pub truncated: bool,
}

impl Recording {
    /// Whether the run was an oracle's (its decisions read ground truth): the provenance's
    /// `oracle` entry, `true: ...` with the decisions (recordings made before it have none).
    pub fn is_oracle(&self) -> bool {
        self.metadata.get("oracle").is_some_and(|o| o.starts_with("true"))
    }
}

/// Read a dynaflow MCAP file. A truncated file (killed run) is read up to its last complete
/// record and flagged; a file that is not MCAP at all, or corrupt, is an error naming it.
pub fn read_mcap(path: &Path) -> Result<Recording, Error> {
    let bad = |message: String| Error::BadInput { path: path.to_path_buf(), message };
    if path.extension().is_some_and(|e| e == "rrd") {
        return Err(bad("`dynaflow diff` reads MCAP recordings; diff the `.mcap` written next to this `.rrd`".into()));
    }
    let buf = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    read_mcap_bytes(path, &buf)
}

/// [`read_mcap`] on bytes already in memory; `path` names them in errors.
pub fn read_mcap_bytes(path: &Path, buf: &[u8]) -> Result<Recording, Error> {
    use crate::mcap::scan::{End, Event, scan};
    let bad = |message: String| Error::BadInput { path: path.to_path_buf(), message };
    let mut rec = Recording { path: path.to_path_buf(), ..Recording::default() };
    let mut metadata = BTreeMap::new();
    let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
    let end = scan(buf, |event| {
        match event {
            Event::Metadata(m) if m.name == "dynaflow" => metadata = m.metadata,
            Event::Metadata(_) => {}
            Event::Message { channel, schema, header, data } => {
                let topic = topics.entry(channel.topic.clone()).or_insert_with(|| Topic {
                    schema: schema.to_owned(),
                    ty: channel.metadata.get("dynaflow.type").cloned().unwrap_or_default(),
                    frames: BTreeMap::new(),
                });
                let payload = if channel.message_encoding == "protobuf" {
                    // Images, depth and masks: the payload rides in an undeclared field.
                    let bytes = crate::mcap::proto::payload_of(data).map_err(|e| {
                        format!("message {} on {} is not protobuf: {e}", header.sequence, channel.topic)
                    })?;
                    serde_json::from_slice(bytes).unwrap_or(Value::Null)
                } else {
                    let value: Value = serde_json::from_slice(data)
                        .map_err(|e| format!("message {} on {} is not JSON: {e}", header.sequence, channel.topic))?;
                    value.get("dynaflow").cloned().unwrap_or(Value::Null)
                };
                let seq = payload.get("seq").and_then(Value::as_u64).unwrap_or(u64::from(header.sequence));
                topic.frames.insert(seq, payload);
            }
        }
        Ok(())
    })
    .map_err(bad)?;
    rec.truncated = end == End::Truncated;
    rec.metadata = metadata;
    rec.topics = topics;
    Ok(rec)
}
