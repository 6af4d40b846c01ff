//! One bounded pass over an MCAP file in memory, chunks flattened, for the readers (`diff`'s
//! and `mcap_replay`'s). mcap's `MessageStream` sets no limit on a chunk's claimed sizes, so one
//! flipped bit can make it reserve exabytes and abort the process; this pass caps every
//! record and chunk at [`record_length_limit`] of the file's size.

use mcap::records::{Channel, MessageHeader, Metadata, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// The largest record (or decompressed chunk) a file of `file_len` bytes may hold: 256 times
/// the file (a chunk of zeros compresses far, a flipped length does not), at least 16 MiB, at
/// most 1 GiB (8 MiB is the recorder's default chunk bound).
pub fn record_length_limit(file_len: usize) -> usize {
    const MIB: usize = 1 << 20;
    file_len.saturating_mul(256).clamp(16 * MIB, 1024 * MIB)
}

/// What the pass met, in file order.
pub enum Event<'a> {
    /// A metadata record.
    Metadata(Metadata),
    /// A message on a known channel, with its schema's name (empty if none).
    Message { channel: &'a Channel, schema: &'a str, header: MessageHeader, data: &'a [u8] },
}

/// How the pass ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    /// At the end of the file.
    Complete,
    /// Early, at a cut (a killed run) or at corruption after the first channel: what came
    /// before was delivered.
    Truncated,
}

/// Feed every metadata record and message of `buf` to `f`. Corruption before any channel is
/// an error (the file is not a readable recording); later, the pass stops there
/// ([`End::Truncated`]). A message on an unknown channel is an error; `f`'s own errors stop it.
pub fn scan(buf: &[u8], mut f: impl FnMut(Event<'_>) -> Result<(), String>) -> Result<End, String> {
    if !buf.starts_with(mcap::MAGIC) {
        return Err("not an MCAP file (bad magic)".into());
    }
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_skip_end_magic(true)
            .with_record_length_limit(record_length_limit(buf.len())),
    );
    let mut channels: std::collections::BTreeMap<u16, Channel> = std::collections::BTreeMap::new();
    let mut schemas: std::collections::BTreeMap<u16, String> = std::collections::BTreeMap::new();
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
            Err(mcap::McapError::UnexpectedEof) if rest.is_empty() => return Ok(End::Truncated),
            Err(e) if channels.is_empty() => return Err(format!("corrupt MCAP: {e}")),
            Err(_) => return Ok(End::Truncated),
        };
        match record {
            Record::Metadata(m) => f(Event::Metadata(m))?,
            Record::Schema { header, .. } => {
                schemas.insert(header.id, header.name);
            }
            Record::Channel(c) => {
                channels.insert(c.id, c);
            }
            Record::Message { header, data } => {
                let channel = channels
                    .get(&header.channel_id)
                    .ok_or_else(|| format!("message {} on unknown channel {}", header.sequence, header.channel_id))?;
                let schema = schemas.get(&channel.schema_id).map_or("", String::as_str);
                f(Event::Message { channel, schema, header, data: &data })?;
            }
            _ => {}
        }
    }
    Ok(End::Complete)
}
