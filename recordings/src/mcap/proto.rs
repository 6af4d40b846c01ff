//! Foxglove's image schemas in protobuf (`message_encoding: protobuf`): `foxglove.RawImage`
//! for depth and masks (raw samples, compressed by the MCAP chunk's zstd) and
//! `foxglove.CompressedImage` for colour. Pixels stay bytes instead of base64 text inside
//! JSON, so zstd sees the samples themselves.
//!
//! The schema records carry a `FileDescriptorSet` (what Foxglove and `mcap-protobuf-support`
//! read) describing the published `foxglove/RawImage.proto` and `foxglove/CompressedImage.proto`
//! with their `google/protobuf/timestamp.proto` import. Every message also carries the
//! `dynaflow` JSON payload (see `payload`) in field [`PAYLOAD_FIELD`], which the schema does
//! not declare: protobuf readers skip unknown fields, `dynaflow diff` and `mcap_replay` read it.
//!
//! A writer and a reader of the protobuf wire format (varints, fixed32, length-delimited)
//! are all this needs; no code generator.

/// Field number of the `dynaflow` payload (JSON bytes) appended to every image message.
pub const PAYLOAD_FIELD: u32 = 1000;

const VARINT: u32 = 0;
const LEN: u32 = 2;
const FIXED32: u32 = 5;

/// A protobuf message being written.
#[derive(Default)]
pub struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    /// An empty message with room for `capacity` bytes.
    pub fn with_capacity(capacity: usize) -> Self {
        Self { buf: Vec::with_capacity(capacity) }
    }

    fn varint(&mut self, mut v: u64) {
        while v >= 0x80 {
            self.buf.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.buf.push(v as u8);
    }

    fn tag(&mut self, field: u32, wire: u32) {
        self.varint(u64::from(field << 3 | wire));
    }

    /// An integer field (int32/int64/enum), omitted when 0 as proto3 does.
    pub fn int(&mut self, field: u32, v: i64) -> &mut Self {
        if v != 0 {
            self.tag(field, VARINT);
            self.varint(v as u64);
        }
        self
    }

    /// A `fixed32` field, omitted when 0.
    pub fn fixed32(&mut self, field: u32, v: u32) -> &mut Self {
        if v != 0 {
            self.tag(field, FIXED32);
            self.buf.extend_from_slice(&v.to_le_bytes());
        }
        self
    }

    /// A `bytes`, `string` or embedded-message field (always written).
    pub fn bytes(&mut self, field: u32, v: &[u8]) -> &mut Self {
        self.tag(field, LEN);
        self.varint(v.len() as u64);
        self.buf.extend_from_slice(v);
        self
    }

    /// A `bytes` field of `len` bytes that `fill` appends (pixels written in place, no copy).
    pub fn bytes_with(&mut self, field: u32, len: usize, fill: impl FnOnce(&mut Vec<u8>)) -> &mut Self {
        self.tag(field, LEN);
        self.varint(len as u64);
        let start = self.buf.len();
        fill(&mut self.buf);
        debug_assert_eq!(self.buf.len() - start, len, "field {field}");
        self
    }

    /// A `string` field, omitted when empty.
    pub fn string(&mut self, field: u32, v: &str) -> &mut Self {
        if !v.is_empty() {
            self.bytes(field, v.as_bytes());
        }
        self
    }

    /// An embedded message field.
    pub fn message(&mut self, field: u32, m: &Writer) -> &mut Self {
        self.bytes(field, &m.buf)
    }

    /// The encoded message.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// One field as read: its number and value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Field<'a> {
    /// A varint (any integer type).
    Varint(u32, u64),
    /// A `fixed64`/`double`.
    Fixed64(u32, u64),
    /// A `fixed32`/`float`.
    Fixed32(u32, u32),
    /// Bytes, a string or an embedded message.
    Bytes(u32, &'a [u8]),
}

/// The fields of an encoded message, in order (the workspace's one wire reader,
/// `dynaflow_base::wire`); `Err` names the first malformed byte.
pub fn fields(data: &[u8]) -> Result<Vec<Field<'_>>, String> {
    use dynaflow_base::wire::Value;
    let read = dynaflow_base::wire::fields(data).map_err(|e| e.0)?;
    Ok(read
        .into_iter()
        .map(|(n, v)| match v {
            Value::Varint(x) => Field::Varint(n, x),
            Value::Fixed64(x) => Field::Fixed64(n, x),
            Value::Fixed32(x) => Field::Fixed32(n, x),
            Value::Bytes(b) => Field::Bytes(n, b),
        })
        .collect())
}

/// A `google.protobuf.Timestamp` from seconds (negative or non-finite → 0).
pub fn timestamp(stamp: f64) -> Writer {
    let stamp = if stamp.is_finite() && stamp > 0.0 { stamp } else { 0.0 };
    let sec = stamp.floor();
    let nsec = ((stamp - sec) * 1e9).round().min(999_999_999.0);
    let mut w = Writer::default();
    w.int(1, sec as i64).int(2, nsec as i64);
    w
}

/// The layout of a `foxglove.RawImage`: `encoding` as in ROS (`32FC1`, `16UC1`, `mono8`,
/// `rgb8`), rows of `step` bytes of little-endian samples.
#[derive(Clone, Copy, Debug)]
pub struct RawLayout<'a> {
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// ROS encoding name.
    pub encoding: &'a str,
    /// Bytes per row.
    pub step: u32,
}

/// `foxglove.RawImage`; `fill` appends the `step * height` sample bytes in place.
pub fn raw_image(
    stamp: f64,
    frame_id: &str,
    layout: RawLayout<'_>,
    fill: impl FnOnce(&mut Vec<u8>),
    payload: &[u8],
) -> Vec<u8> {
    let len = layout.step as usize * layout.height as usize;
    let mut w = Writer::with_capacity(len + payload.len() + 64);
    w.message(1, &timestamp(stamp))
        .fixed32(2, layout.width)
        .fixed32(3, layout.height)
        .string(4, layout.encoding)
        .fixed32(5, layout.step)
        .bytes_with(6, len, fill)
        .string(7, frame_id)
        .bytes(PAYLOAD_FIELD, payload);
    w.finish()
}

/// `foxglove.CompressedImage`: `format` `jpeg` or `png`.
pub fn compressed_image(stamp: f64, frame_id: &str, data: &[u8], format: &str, payload: &[u8]) -> Vec<u8> {
    let mut w = Writer::with_capacity(data.len() + payload.len() + 64);
    w.message(1, &timestamp(stamp)).bytes(2, data).string(3, format).string(4, frame_id).bytes(PAYLOAD_FIELD, payload);
    w.finish()
}

// Descriptor field numbers (google/protobuf/descriptor.proto).
const FIELD_LABEL_OPTIONAL: i64 = 1;
const TYPE_INT64: i64 = 3;
const TYPE_INT32: i64 = 5;
const TYPE_FIXED32: i64 = 7;
const TYPE_STRING: i64 = 9;
const TYPE_MESSAGE: i64 = 11;
const TYPE_BYTES: i64 = 12;

/// `(name, number, type, json name)`; a message type names `.google.protobuf.Timestamp`.
type FieldDef = (&'static str, i64, i64, &'static str);

fn file_descriptor(name: &str, package: &str, deps: &[&str], message: &str, defs: &[FieldDef]) -> Writer {
    let mut msg = Writer::default();
    msg.string(1, message);
    for &(field, number, ty, json) in defs {
        let mut f = Writer::default();
        f.string(1, field).int(3, number).int(4, FIELD_LABEL_OPTIONAL).int(5, ty);
        if ty == TYPE_MESSAGE {
            f.string(6, ".google.protobuf.Timestamp");
        }
        f.string(10, json);
        msg.message(2, &f);
    }
    let mut file = Writer::default();
    file.string(1, name).string(2, package);
    for d in deps {
        file.string(3, d);
    }
    file.message(4, &msg).string(12, "proto3");
    file
}

fn timestamp_file() -> Writer {
    file_descriptor(
        "google/protobuf/timestamp.proto",
        "google.protobuf",
        &[],
        "Timestamp",
        &[("seconds", 1, TYPE_INT64, "seconds"), ("nanos", 2, TYPE_INT32, "nanos")],
    )
}

/// The `FileDescriptorSet` of a schema name this module writes (`None` for others).
pub fn descriptor_set(schema: &str) -> Option<Vec<u8>> {
    let file = match schema {
        "foxglove.RawImage" => file_descriptor(
            "foxglove/RawImage.proto",
            "foxglove",
            &["google/protobuf/timestamp.proto"],
            "RawImage",
            &[
                ("timestamp", 1, TYPE_MESSAGE, "timestamp"),
                ("frame_id", 7, TYPE_STRING, "frameId"),
                ("width", 2, TYPE_FIXED32, "width"),
                ("height", 3, TYPE_FIXED32, "height"),
                ("encoding", 4, TYPE_STRING, "encoding"),
                ("step", 5, TYPE_FIXED32, "step"),
                ("data", 6, TYPE_BYTES, "data"),
            ],
        ),
        "foxglove.CompressedImage" => file_descriptor(
            "foxglove/CompressedImage.proto",
            "foxglove",
            &["google/protobuf/timestamp.proto"],
            "CompressedImage",
            &[
                ("timestamp", 1, TYPE_MESSAGE, "timestamp"),
                ("frame_id", 4, TYPE_STRING, "frameId"),
                ("data", 2, TYPE_BYTES, "data"),
                ("format", 3, TYPE_STRING, "format"),
            ],
        ),
        _ => return None,
    };
    let mut set = Writer::default();
    set.message(1, &timestamp_file()).message(1, &file);
    Some(set.finish())
}

/// A decoded image message of either schema (fields this module writes).
#[derive(Debug, Default)]
pub struct ImageMsg<'a> {
    /// Pixel width (`RawImage`).
    pub width: u32,
    /// Pixel height (`RawImage`).
    pub height: u32,
    /// `RawImage` encoding.
    pub encoding: &'a str,
    /// `RawImage` row stride in bytes.
    pub step: u32,
    /// Samples (`RawImage`) or file contents (`CompressedImage`).
    pub data: &'a [u8],
    /// `CompressedImage` format.
    pub format: &'a str,
    /// The `dynaflow` payload (JSON).
    pub payload: &'a [u8],
}

/// Decode a `foxglove.RawImage` (`raw = true`) or `foxglove.CompressedImage` message.
pub fn read_image(data: &[u8], raw: bool) -> Result<ImageMsg<'_>, String> {
    fn text(b: &[u8]) -> Result<&str, String> {
        std::str::from_utf8(b).map_err(|e| e.to_string())
    }
    let mut m = ImageMsg::default();
    for f in fields(data)? {
        match (raw, f) {
            (_, Field::Bytes(PAYLOAD_FIELD, b)) => m.payload = b,
            (true, Field::Fixed32(2, v)) => m.width = v,
            (true, Field::Fixed32(3, v)) => m.height = v,
            (true, Field::Bytes(4, b)) => m.encoding = text(b)?,
            (true, Field::Fixed32(5, v)) => m.step = v,
            (true, Field::Bytes(6, b)) | (false, Field::Bytes(2, b)) => m.data = b,
            (false, Field::Bytes(3, b)) => m.format = text(b)?,
            _ => {}
        }
    }
    Ok(m)
}

/// The `dynaflow` payload of a protobuf image message (empty when it has none).
pub fn payload_of(data: &[u8]) -> Result<&[u8], String> {
    Ok(fields(data)?
        .into_iter()
        .find_map(|f| match f {
            Field::Bytes(PAYLOAD_FIELD, b) => Some(b),
            _ => None,
        })
        .unwrap_or_default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_image_round_trips_through_the_reader() {
        let data: Vec<u8> = (0..24u8).collect();
        let layout = RawLayout { width: 3, height: 2, encoding: "32FC1", step: 12 };
        let bytes = raw_image(12.25, "camera", layout, |b| b.extend_from_slice(&data), br#"{"seq":4}"#);
        let m = read_image(&bytes, true).unwrap();
        assert_eq!((m.width, m.height, m.encoding, m.step), (3, 2, "32FC1", 12));
        assert_eq!(m.data, &data[..]);
        assert_eq!(m.payload, br#"{"seq":4}"#);
        assert_eq!(payload_of(&bytes).unwrap(), br#"{"seq":4}"#);
        let ts = fields(&bytes).unwrap().into_iter().find_map(|f| match f {
            Field::Bytes(1, b) => Some(fields(b).unwrap()),
            _ => None,
        });
        assert_eq!(ts, Some(vec![Field::Varint(1, 12), Field::Varint(2, 250_000_000)]));
    }

    #[test]
    fn truncated_messages_are_errors_not_panics() {
        let bytes = compressed_image(1.0, "c", &[1, 2, 3], "jpeg", b"{}");
        for cut in 0..bytes.len() {
            let _ = read_image(&bytes[..cut], false);
        }
        assert!(fields(&bytes[..bytes.len() - 1]).is_err());
        assert!(descriptor_set("foxglove.RawImage").is_some_and(|d| !d.is_empty()));
        assert!(descriptor_set("foxglove.PoseInFrame").is_none());
    }
}
