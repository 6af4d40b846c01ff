//! Reading a dynaflow MCAP recording back: per topic, the `dynaflow` payload of each frame.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::DiffError;

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

/// Read a dynaflow MCAP file. A truncated file (killed run) is read up to its last complete
/// record and flagged; a file that is not MCAP at all is an error naming it.
pub fn read_mcap(path: &Path) -> Result<Recording, DiffError> {
    let bad = |message: String| DiffError::BadInput { path: path.to_path_buf(), message };
    if path.extension().is_some_and(|e| e == "rrd") {
        return Err(bad("`dynaflow diff` reads MCAP recordings; diff the `.mcap` written next to this `.rrd`".into()));
    }
    let buf = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    if !buf.starts_with(mcap::MAGIC) {
        return Err(bad("not an MCAP file (bad magic)".into()));
    }
    let opts = enumset::EnumSet::only(mcap::read::Options::IgnoreEndMagic);
    let mut rec = Recording { path: path.to_path_buf(), ..Recording::default() };
    let reader = mcap::read::LinearReader::new_with_options(&buf, opts).map_err(|e| bad(e.to_string()))?;
    for record in reader {
        match record {
            Ok(mcap::records::Record::Metadata(m)) if m.name == "dynaflow" => rec.metadata = m.metadata,
            Ok(_) => {}
            Err(_) => {
                rec.truncated = true;
                break;
            }
        }
    }
    let stream = mcap::MessageStream::new_with_options(&buf, opts).map_err(|e| bad(e.to_string()))?;
    for message in stream {
        let message = match message {
            Ok(m) => m,
            Err(_) => {
                rec.truncated = true;
                break;
            }
        };
        let topic = rec.topics.entry(message.channel.topic.clone()).or_insert_with(|| Topic {
            schema: message.channel.schema.as_ref().map(|s| s.name.clone()).unwrap_or_default(),
            ty: message.channel.metadata.get("dynaflow.type").cloned().unwrap_or_default(),
            frames: BTreeMap::new(),
        });
        let value: Value = serde_json::from_slice(&message.data)
            .map_err(|e| bad(format!("message {} on {} is not JSON: {e}", message.sequence, message.channel.topic)))?;
        let payload = value.get("dynaflow").cloned().unwrap_or(Value::Null);
        let seq = payload.get("seq").and_then(Value::as_u64).unwrap_or(u64::from(message.sequence));
        topic.frames.insert(seq, payload);
    }
    Ok(rec)
}
