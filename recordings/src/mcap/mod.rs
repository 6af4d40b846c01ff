//! The MCAP recorder: one channel per recorded port (`/<node>/<port>`), Foxglove schemas
//! (protobuf for images, depth and masks; JSON for the rest), zstd chunks of bounded size,
//! provenance as a metadata record, and the bytes each port took.
//!
//! Crash safety: a chunk is written when it reaches `chunk_size` bytes or has been open for
//! `flush_interval`, whichever comes first, so a killed run loses at most that much; every
//! complete chunk before the cut reads back (see `docs/recordings.md`).
//!
//! Submodules: `schemas` (message → Foxglove JSON and the JSON Schemas), `proto` (the
//! protobuf image schemas and wire format).

pub(crate) mod proto;
pub(crate) mod scan;
pub(crate) mod schemas;

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use dynaflow_engine::msg::Message;
use dynaflow_engine::sink::{PortReport, RunInfo, Sink, SinkError, SinkReport};

use crate::encode::{EncodeCache, ImageCodec};

/// Default chunk size bound (bytes before compression): about three frames of the default
/// graph (640x480 `32FC1` depth, masks, JPEG colour, keypoints). The writer keeps an index entry
/// per chunk (with an offset per channel in it) until the file closes, for the summary section
/// readers seek with: 1 MiB chunks made 2.5 a frame, 8 MiB 0.37 (1.6 MB less peak memory at
/// 10 000 frames). A reader decompresses at most this much to reach a message (zstd: a few ms);
/// the one-second bound still limits what a crash loses.
pub const DEFAULT_CHUNK_SIZE: u64 = 8 << 20;
/// Default longest time a chunk stays open.
pub const DEFAULT_FLUSH_INTERVAL: Duration = Duration::from_secs(1);

/// Writes `<out>/<graph>.mcap`.
pub struct McapSink {
    path: PathBuf,
    writer: Option<mcap::Writer<BufWriter<File>>>,
    channels: HashMap<(String, String), u16>,
    schemas: HashMap<&'static str, u16>,
    codec: ImageCodec,
    chunk_size: u64,
    flush_interval: Duration,
    last_flush: Instant,
    cache: EncodeCache,
    /// Messages and their bytes (before chunk compression) per channel.
    bytes: HashMap<u16, (u64, u64)>,
    /// `node/port` of the ports that carry ground truth (their channels say so).
    ground_truth: std::collections::BTreeSet<String>,
}

impl McapSink {
    /// A recorder writing to `path` with default chunking and JPEG (q 90) colour images.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            writer: None,
            channels: HashMap::new(),
            schemas: HashMap::new(),
            codec: ImageCodec::Jpeg(90),
            chunk_size: DEFAULT_CHUNK_SIZE,
            flush_interval: DEFAULT_FLUSH_INTERVAL,
            last_flush: Instant::now(),
            ground_truth: std::collections::BTreeSet::new(),
            cache: EncodeCache::default(),
            bytes: HashMap::new(),
        }
    }

    /// Share image encodings with other recorders (the rerun recorder).
    #[must_use]
    pub fn with_cache(mut self, cache: EncodeCache) -> Self {
        self.cache = cache;
        self
    }

    /// Bound chunk size and age (how much a crash can lose).
    #[must_use]
    pub fn with_chunking(mut self, chunk_size: u64, flush_interval: Duration) -> Self {
        self.chunk_size = chunk_size.max(1024);
        self.flush_interval = flush_interval;
        self
    }

    /// How colour images are stored.
    #[must_use]
    pub fn with_codec(mut self, codec: ImageCodec) -> Self {
        self.codec = codec;
        self
    }

    fn err(&self, e: impl std::fmt::Display) -> SinkError {
        SinkError::new("mcap", format!("{}: {e}", self.path.display()))
    }

    fn channel(&mut self, node: &str, port: &str, msg: &Message) -> Result<u16, SinkError> {
        if let Some(id) = self.channels.get(&(node.to_owned(), port.to_owned())) {
            return Ok(*id);
        }
        let ty = msg.body.port_type();
        let name = schemas::schema_name(ty, self.codec);
        let protobuf = schemas::is_protobuf(ty);
        let err = |e: mcap::McapError| writer_error("mcap", &self.path, &e);
        let writer = self.writer.as_mut().ok_or_else(|| SinkError::new("mcap", "not open"))?;
        let schema = match self.schemas.get(name) {
            Some(id) => *id,
            None => {
                let id = match proto::descriptor_set(name).filter(|_| protobuf) {
                    Some(set) => writer.add_schema(name, "protobuf", &set),
                    None => writer.add_schema(name, "jsonschema", schemas::schema_text(name).as_bytes()),
                }
                .map_err(err)?;
                self.schemas.insert(name, id);
                id
            }
        };
        let mut meta = BTreeMap::from([("dynaflow.type".to_owned(), ty.name().to_owned())]);
        if self.ground_truth.contains(&format!("{node}/{port}")) {
            meta.insert("dynaflow.ground_truth".to_owned(), "true".to_owned());
        }
        let encoding = if protobuf { "protobuf" } else { "json" };
        let id = writer.add_channel(schema, &format!("/{node}/{port}"), encoding, &meta).map_err(err)?;
        self.channels.insert((node.to_owned(), port.to_owned()), id);
        self.bytes.insert(id, (0, 0));
        Ok(id)
    }
}

impl McapSink {
    /// Write `data` on `channel_id` as frame `seq` at sensor time `stamp`: counted for the
    /// report, and the chunk flushed when it has been open for the flush interval.
    fn write(&mut self, channel_id: u16, seq: u64, stamp: f64, data: &[u8]) -> Result<(), SinkError> {
        if let Some((n, b)) = self.bytes.get_mut(&channel_id) {
            *n += 1;
            *b += data.len() as u64;
        }
        let ns = (stamp.max(0.0) * 1e9) as u64;
        let header = mcap::records::MessageHeader { channel_id, sequence: seq as u32, log_time: ns, publish_time: ns };
        let flush_due = self.last_flush.elapsed() >= self.flush_interval;
        let err = |e: mcap::McapError| writer_error("mcap", &self.path, &e);
        let writer = self.writer.as_mut().ok_or_else(|| SinkError::new("mcap", "not open"))?;
        writer.write_to_known_channel(&header, data).map_err(err)?;
        if flush_due {
            writer.flush().map_err(err)?;
            self.last_flush = Instant::now();
        }
        Ok(())
    }
}

/// A new MCAP file at `path` for recorder `sink` (never over an existing file), in `profile`
/// (`""`, or `ros2` for a rosbag2 bag): zstd chunks of `chunk_size`, the run's provenance as a
/// metadata record.
pub(crate) fn open_writer(
    sink: &str,
    path: &std::path::Path,
    profile: &str,
    chunk_size: u64,
    info: &RunInfo,
) -> Result<mcap::Writer<BufWriter<File>>, SinkError> {
    let file = dynaflow_engine::files::create_new(path)
        .map_err(|e| SinkError::new(sink, format!("{}: {e}", path.display())))?;
    let options = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        // Level 1: 0.68x the CPU of the default 3 for 1.13x the bytes on the default
        // graph's frames (docs/benchmarks.md); recording has to keep up with the graph.
        .compression_level(1)
        .chunk_size(Some(chunk_size))
        .profile(profile)
        .library(format!("dynaflow {}", info.version));
    let mut writer = options.create(BufWriter::new(file)).map_err(|e| writer_error(sink, path, &e))?;
    let metadata = mcap::records::Metadata { name: "dynaflow".into(), metadata: info.to_strings() };
    writer.write_metadata(&metadata).map_err(|e| writer_error(sink, path, &e))?;
    Ok(writer)
}

/// The MCAP writer's error for the file at `path`, with what caused it: the writer's own
/// message for an I/O failure names no cause ("I/O error from writing ..."), the
/// `std::io::Error` under it does ("No space left on device").
pub(crate) fn writer_error(sink: &str, path: &std::path::Path, e: &mcap::McapError) -> SinkError {
    SinkError::new(sink, format!("{}: {}", path.display(), with_causes(e)))
}

/// An error's message followed by those of its sources not already in it.
fn with_causes(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !text.contains(&cause_text) {
            text = format!("{text}: {cause_text}");
        }
        source = cause.source();
    }
    text
}

impl Sink for McapSink {
    fn name(&self) -> &str {
        "mcap"
    }

    fn open(&mut self, info: &RunInfo) -> Result<(), SinkError> {
        let writer = open_writer("mcap", &self.path, "", self.chunk_size, info)?;
        self.ground_truth.clone_from(&info.ground_truth_ports);
        self.writer = Some(writer);
        self.last_flush = Instant::now();
        Ok(())
    }

    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let channel_id = self.channel(node, port, msg)?;
        let data = match schemas::to_protobuf(msg, self.codec, &self.cache) {
            Some(pb) => pb,
            None => schemas::to_json(msg),
        }
        .map_err(|e| self.err(format!("encoding {node}/{port}: {e}")))?;
        self.write(channel_id, msg.header.seq, msg.header.stamp, &data)
    }

    /// A `foxglove.Log` message on `/parameters` (the node, the parameter, old and new value,
    /// and the frame in `dynaflow`), at the frame's sensor time.
    fn parameter_change(
        &mut self,
        node: &str,
        change: &dynaflow_engine::runtime::ParameterChange,
        stamp: f64,
    ) -> Result<(), SinkError> {
        let err = |e: mcap::McapError| writer_error("mcap", &self.path, &e);
        let key = (String::new(), "parameters".to_owned());
        let channel_id = match self.channels.get(&key) {
            Some(id) => *id,
            None => {
                let writer = self.writer.as_mut().ok_or_else(|| SinkError::new("mcap", "not open"))?;
                let schema = writer
                    .add_schema("foxglove.Log", "jsonschema", schemas::schema_text("foxglove.Log").as_bytes())
                    .map_err(err)?;
                let id = writer.add_channel(schema, "/parameters", "json", &BTreeMap::new()).map_err(err)?;
                self.channels.insert(key, id);
                self.bytes.insert(id, (0, 0));
                id
            }
        };
        let ns = (stamp.max(0.0) * 1e9) as u64;
        let data = schemas::parameter_log(node, change, ns).into_bytes();
        self.write(channel_id, change.frame, stamp, &data)
    }

    fn close(&mut self) -> Result<(), SinkError> {
        let Some(mut writer) = self.writer.take() else { return Ok(()) };
        writer.finish().map_err(|e| writer_error("mcap", &self.path, &e))?;
        let mut inner = writer.into_inner();
        inner.flush().map_err(|e| self.err(e))?;
        inner.get_ref().sync_all().map_err(|e| self.err(e))
    }

    fn report(&self) -> SinkReport {
        let ports = self
            .channels
            .iter()
            .map(|((node, port), id)| {
                let (messages, bytes) = self.bytes.get(id).copied().unwrap_or_default();
                (format!("{node}/{port}"), PortReport { messages, bytes, ..PortReport::default() })
            })
            .collect();
        SinkReport {
            path: Some(self.path.display().to_string()),
            file_bytes: std::fs::metadata(&self.path).ok().map(|m| m.len()),
            ports,
            ..SinkReport::default()
        }
    }
}
