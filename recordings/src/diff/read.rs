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

impl Recording {
    /// Whether the run was an oracle's (its decisions read ground truth): the provenance's
    /// `oracle` entry, `true: ...` with the decisions (recordings made before it have none).
    pub fn is_oracle(&self) -> bool {
        self.metadata.get("oracle").is_some_and(|o| o.starts_with("true"))
    }
}

/// Largest record the reader accepts, inside chunks too: a record (or a decompressed chunk)
/// may exceed its file through compression, but never absurdly. A corrupt length field then
/// fails as "record too large" instead of asking the allocator for exabytes.
fn record_length_limit(file_len: usize) -> usize {
    const MIB: usize = 1 << 20;
    file_len.saturating_mul(256).clamp(16 * MIB, 1024 * MIB)
}

/// Read a dynaflow MCAP file. A truncated file (killed run) is read up to its last complete
/// record and flagged; a file that is not MCAP at all, or corrupt, is an error naming it.
pub fn read_mcap(path: &Path) -> Result<Recording, DiffError> {
    let bad = |message: String| DiffError::BadInput { path: path.to_path_buf(), message };
    if path.extension().is_some_and(|e| e == "rrd") {
        return Err(bad("`dynaflow diff` reads MCAP recordings; diff the `.mcap` written next to this `.rrd`".into()));
    }
    let buf = std::fs::read(path).map_err(|e| bad(e.to_string()))?;
    read_mcap_bytes(path, &buf)
}

/// [`read_mcap`] on bytes already in memory; `path` names them in errors.
pub fn read_mcap_bytes(path: &Path, buf: &[u8]) -> Result<Recording, DiffError> {
    use mcap::records::Record;
    use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

    let bad = |message: String| DiffError::BadInput { path: path.to_path_buf(), message };
    if !buf.starts_with(mcap::MAGIC) {
        return Err(bad("not an MCAP file (bad magic)".into()));
    }
    let mut rec = Recording { path: path.to_path_buf(), ..Recording::default() };
    // One bounded pass over every record, chunks flattened (mcap's `MessageStream` sets no
    // record length limit inside chunks, so one flipped bit could abort the process).
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_record_length_limit(record_length_limit(buf.len())),
    );
    let mut channels: BTreeMap<u16, mcap::records::Channel> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, String> = BTreeMap::new();
    let mut rest: &[u8] = buf;
    while let Some(event) = reader.next_event() {
        let record = match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(rest.get(..n).unwrap_or_default());
                reader.notify_read(n);
                rest = rest.get(n..).unwrap_or_default();
                continue;
            }
            Ok(LinearReadEvent::Record { data, opcode }) => mcap::parse_record(opcode, data),
            Err(e) => Err(e),
        };
        let record = match record {
            Ok(r) => r,
            // A killed run ends mid-record: everything before is good.
            Err(mcap::McapError::UnexpectedEof) if rest.is_empty() => {
                rec.truncated = true;
                break;
            }
            Err(e) if rec.topics.is_empty() && channels.is_empty() => return Err(bad(format!("corrupt MCAP: {e}"))),
            // Corrupt further in: keep what came before, flagged like a cut-off file.
            Err(_) => {
                rec.truncated = true;
                break;
            }
        };
        match record {
            Record::Metadata(m) if m.name == "dynaflow" => rec.metadata = m.metadata,
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                channels.insert(c.id, c);
            }
            Record::Message { header, data } => {
                let channel = channels.get(&header.channel_id).ok_or_else(|| {
                    bad(format!("message {} on unknown channel {}", header.sequence, header.channel_id))
                })?;
                let topic = rec.topics.entry(channel.topic.clone()).or_insert_with(|| Topic {
                    schema: schemas.get(&channel.schema_id).cloned().unwrap_or_default(),
                    ty: channel.metadata.get("dynaflow.type").cloned().unwrap_or_default(),
                    frames: BTreeMap::new(),
                });
                let payload = if channel.message_encoding == "protobuf" {
                    // Images, depth and masks: the payload rides in an undeclared field.
                    let bytes = crate::mcap::proto::payload_of(&data).map_err(|e| {
                        bad(format!("message {} on {} is not protobuf: {e}", header.sequence, channel.topic))
                    })?;
                    serde_json::from_slice(bytes).unwrap_or(Value::Null)
                } else {
                    let value: Value = serde_json::from_slice(&data).map_err(|e| {
                        bad(format!("message {} on {} is not JSON: {e}", header.sequence, channel.topic))
                    })?;
                    value.get("dynaflow").cloned().unwrap_or(Value::Null)
                };
                let seq = payload.get("seq").and_then(Value::as_u64).unwrap_or(u64::from(header.sequence));
                topic.frames.insert(seq, payload);
            }
            _ => {}
        }
    }
    Ok(rec)
}
