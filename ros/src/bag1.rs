//! ROS 1 bags, format 2.0 (rosbag's `.bag`): a `#ROSBAG V2.0` line, then records of a header
//! (`name=value` fields, each with a `uint32` length) and a data part. Messages sit in chunks
//! (uncompressed, `bz2` or `lz4`, the LZ4 frame format roslz4 writes) together with the
//! connection records that define their topics; an index section follows the chunks.
//!
//! Read front to back, chunk by chunk, so a bag that was never closed (no index) reads as far as
//! it was written; one decompressed chunk is held at a time. A record cut short is an error
//! naming the byte offset.

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::decode::Encoding;
use crate::msgdef::Dialect;
use crate::{Connection, Error, RawMessage};

/// The first line of every ROS 1 bag.
pub const MAGIC: &[u8] = b"#ROSBAG V2.0\n";

const OP_MSG_DATA: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_INDEX_DATA: u8 = 0x04;
const OP_CHUNK: u8 = 0x05;
const OP_CHUNK_INFO: u8 = 0x06;
const OP_CONNECTION: u8 = 0x07;

/// Records larger than this are refused as corrupt (rosbag's chunks are ~768 KiB; one image
/// message can be tens of MiB, never gigabytes).
const MAX_RECORD: usize = 1 << 30;

/// A record's header fields, name to raw value.
struct Fields(Vec<(String, Vec<u8>)>);

impl Fields {
    fn parse(bytes: &[u8]) -> Option<Self> {
        let mut out = Vec::new();
        let mut rest = bytes;
        while !rest.is_empty() {
            let len = u32::from_le_bytes(rest.get(..4)?.try_into().ok()?) as usize;
            let field = rest.get(4..4 + len)?;
            let eq = field.iter().position(|&b| b == b'=')?;
            out.push((String::from_utf8_lossy(&field[..eq]).into_owned(), field[eq + 1..].to_vec()));
            rest = &rest[4 + len..];
        }
        Some(Fields(out))
    }
    fn get(&self, name: &str) -> Option<&[u8]> {
        self.0.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_slice())
    }
    fn u32(&self, name: &str) -> Option<u32> {
        Some(u32::from_le_bytes(self.get(name)?.try_into().ok()?))
    }
    fn u8(&self, name: &str) -> Option<u8> {
        self.get(name)?.first().copied()
    }
    fn string(&self, name: &str) -> Option<String> {
        Some(String::from_utf8_lossy(self.get(name)?).into_owned())
    }
    /// rosbag's `time`: `uint32` seconds then `uint32` nanoseconds, as nanoseconds.
    fn time(&self, name: &str) -> Option<u64> {
        let v = self.get(name)?;
        let sec = u32::from_le_bytes(v.get(..4)?.try_into().ok()?) as u64;
        let nsec = u32::from_le_bytes(v.get(4..8)?.try_into().ok()?) as u64;
        Some(sec * 1_000_000_000 + nsec)
    }
}

/// Streams the messages of one ROS 1 bag in file order.
pub(crate) struct Bag1Messages {
    path: PathBuf,
    file: BufReader<File>,
    /// Offset of the next top-level record.
    offset: u64,
    connections: HashMap<u32, Arc<Connection>>,
    /// The chunk being read: its bytes, the cursor in them, and its file offset.
    chunk: Option<(Vec<u8>, usize, u64)>,
    /// What the bag header promises: the index's offset (0 for a bag never closed), and the
    /// connection and chunk-info records of that index.
    promised: Option<(u64, u32, u32)>,
    /// Connection and chunk-info records seen at or after the index offset.
    indexed: (u32, u32),
    done: bool,
}

impl Bag1Messages {
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        let file = File::open(path).map_err(|e| Error::io(path, &e))?;
        let mut file = BufReader::with_capacity(1 << 20, file);
        let mut magic = [0u8; 13];
        file.read_exact(&mut magic).map_err(|_| Error::at(path, 0, "too short for a ROS 1 bag"))?;
        if magic != MAGIC {
            return Err(Error::at(
                path,
                0,
                "not a ROS 1 bag 2.0 (no `#ROSBAG V2.0` line); ROS 1 bags of format 1.2 are not read",
            ));
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            offset: MAGIC.len() as u64,
            connections: HashMap::new(),
            chunk: None,
            promised: None,
            indexed: (0, 0),
            done: false,
        })
    }

    /// The next top-level record, or `None` at a clean end of file.
    fn read_record(&mut self) -> Result<Option<(Fields, Vec<u8>)>, Error> {
        let start = self.offset;
        let Some(header) = self.read_part(start, "record header")? else { return Ok(None) };
        let fields = Fields::parse(&header).ok_or_else(|| Error::at(&self.path, start, "malformed record header"))?;
        let data = self
            .read_part(start, "record data")?
            .ok_or_else(|| Error::at(&self.path, start, "truncated: the file ends before the record's data"))?;
        Ok(Some((fields, data)))
    }

    /// One length-prefixed part of the record at `start`; `None` when the file ends before its
    /// first byte.
    fn read_part(&mut self, start: u64, what: &str) -> Result<Option<Vec<u8>>, Error> {
        let mut len = [0u8; 4];
        match read_full(&mut self.file, &mut len).map_err(|e| Error::io(&self.path, &e))? {
            0 => return Ok(None),
            4 => {}
            n => {
                return Err(Error::at(
                    &self.path,
                    start,
                    format!("truncated: the file ends {n} bytes into the {what}'s length"),
                ));
            }
        }
        let len = u32::from_le_bytes(len) as usize;
        if len > MAX_RECORD {
            return Err(Error::at(&self.path, start, format!("{what} of {len} bytes: corrupt length")));
        }
        let mut buf = vec![0u8; len];
        let got = read_full(&mut self.file, &mut buf).map_err(|e| Error::io(&self.path, &e))?;
        if got != len {
            return Err(Error::at(
                &self.path,
                start,
                format!("truncated: {what} of {len} bytes, the file ends after {got}"),
            ));
        }
        self.offset += 4 + len as u64;
        Ok(Some(buf))
    }

    fn connection(&mut self, fields: &Fields, data: &[u8], at: u64) -> Result<(), Error> {
        let id = fields.u32("conn").ok_or_else(|| Error::at(&self.path, at, "connection record without `conn`"))?;
        let info = Fields::parse(data).ok_or_else(|| Error::at(&self.path, at, "malformed connection header"))?;
        let topic = fields.string("topic").or_else(|| info.string("topic")).unwrap_or_default();
        let ty = info
            .string("type")
            .ok_or_else(|| Error::at(&self.path, at, format!("connection {id} ({topic}) has no `type`")))?;
        let conn = Connection::new(
            topic,
            ty,
            Encoding::Ros1,
            Dialect::Ros1,
            info.string("message_definition"),
            info.string("md5sum"),
        );
        self.connections.entry(id).or_insert_with(|| Arc::new(conn));
        Ok(())
    }

    fn message(&self, fields: &Fields, data: Vec<u8>, at: u64) -> Result<RawMessage, Error> {
        let id = fields.u32("conn").ok_or_else(|| Error::at(&self.path, at, "message record without `conn`"))?;
        let connection = self.connections.get(&id).cloned().ok_or_else(|| {
            Error::at(
                &self.path,
                at,
                format!("message on connection {id}, which no connection record defined before it"),
            )
        })?;
        let log_time = fields.time("time").ok_or_else(|| Error::at(&self.path, at, "message record without `time`"))?;
        Ok(RawMessage { connection, log_time, data })
    }

    fn decompress(&self, fields: &Fields, data: Vec<u8>, at: u64) -> Result<Vec<u8>, Error> {
        let size = fields.u32("size").ok_or_else(|| Error::at(&self.path, at, "chunk without `size`"))? as usize;
        let compression = fields.string("compression").unwrap_or_else(|| "none".into());
        if size > MAX_RECORD {
            return Err(Error::at(&self.path, at, format!("chunk of {size} bytes: corrupt size")));
        }
        let out = match compression.as_str() {
            "none" => data,
            "bz2" | "lz4" => {
                let mut decoder: Box<dyn Read + '_> = if compression == "bz2" {
                    Box::new(bzip2::read::BzDecoder::new(data.as_slice()))
                } else {
                    Box::new(lz4_flex::frame::FrameDecoder::new(data.as_slice()))
                };
                let mut out = Vec::with_capacity(size);
                decoder
                    .read_to_end(&mut out)
                    .map_err(|e| Error::at(&self.path, at, format!("{compression} chunk: {e}")))?;
                out
            }
            other => {
                return Err(Error::at(&self.path, at, format!("chunk compression `{other}` (known: none, bz2, lz4)")));
            }
        };
        if out.len() != size {
            return Err(Error::at(
                &self.path,
                at,
                format!("chunk holds {} bytes once decompressed, its header says {size}", out.len()),
            ));
        }
        Ok(out)
    }

    /// At the end of the file: a closed bag (its header names where its index starts) must hold
    /// that whole index, else it was cut short. A bag never closed (index offset 0) is read as far
    /// as it goes.
    fn check_complete(&self) -> Result<(), Error> {
        let Some((index, conns, chunks)) = self.promised else {
            return Err(Error::at(&self.path, self.offset, "truncated: the file ends before the bag header record"));
        };
        if index == 0 {
            tracing::warn!(
                "{}: the bag was never closed (no index); read up to byte {}",
                self.path.display(),
                self.offset
            );
            return Ok(());
        }
        if self.offset < index || self.indexed != (conns, chunks) {
            return Err(Error::at(
                &self.path,
                self.offset,
                format!(
                    "truncated: the file ends at byte {} where its header promises an index at byte {index} with {conns} connections and {chunks} chunks ({} and {} read)",
                    self.offset, self.indexed.0, self.indexed.1
                ),
            ));
        }
        Ok(())
    }

    /// The next record inside the current chunk, with the chunk's file offset (errors name it).
    fn chunk_record(&mut self) -> Result<Option<(Fields, Vec<u8>, u64)>, Error> {
        let Some((buf, pos, at)) = self.chunk.as_mut() else { return Ok(None) };
        if *pos >= buf.len() {
            self.chunk = None;
            return Ok(None);
        }
        let at = *at;
        let part = |buf: &[u8], pos: usize| -> Option<(usize, usize)> {
            let len = u32::from_le_bytes(buf.get(pos..pos + 4)?.try_into().ok()?) as usize;
            (pos + 4 + len <= buf.len()).then_some((pos + 4, len))
        };
        let bad = || Error::at(&self.path, at, "a record inside the chunk runs past the chunk's end");
        let (h, hl) = part(buf, *pos).ok_or_else(bad)?;
        let (d, dl) = part(buf, h + hl).ok_or_else(bad)?;
        let fields = Fields::parse(&buf[h..h + hl]).ok_or_else(bad)?;
        let data = buf[d..d + dl].to_vec();
        *pos = d + dl;
        Ok(Some((fields, data, at)))
    }

    fn next_message(&mut self) -> Result<Option<RawMessage>, Error> {
        loop {
            if let Some((fields, data, at)) = self.chunk_record()? {
                match fields.u8("op") {
                    Some(OP_CONNECTION) => self.connection(&fields, &data, at)?,
                    Some(OP_MSG_DATA) => return self.message(&fields, data, at).map(Some),
                    _ => {} // anything else inside a chunk carries nothing to read
                }
                continue;
            }
            let at = self.offset;
            let Some((fields, data)) = self.read_record()? else {
                self.check_complete()?;
                return Ok(None);
            };
            // Records at or after the index offset are the index `check_complete` counts.
            let in_index = self.promised.is_some_and(|(index, _, _)| index > 0 && at >= index);
            match fields.u8("op") {
                Some(OP_CHUNK) => {
                    let bytes = self.decompress(&fields, data, at)?;
                    self.chunk = Some((bytes, 0, at));
                }
                Some(OP_CONNECTION) => {
                    self.indexed.0 += u32::from(in_index);
                    self.connection(&fields, &data, at)?;
                }
                Some(OP_MSG_DATA) => return self.message(&fields, data, at).map(Some),
                Some(OP_BAG_HEADER) => {
                    let index = fields.get("index_pos").and_then(|v| Some(u64::from_le_bytes(v.try_into().ok()?)));
                    match (index, fields.u32("conn_count"), fields.u32("chunk_count")) {
                        (Some(i), Some(c), Some(k)) => self.promised = Some((i, c, k)),
                        _ => {
                            return Err(Error::at(
                                &self.path,
                                at,
                                "bag header without index_pos, conn_count or chunk_count",
                            ));
                        }
                    }
                }
                Some(OP_CHUNK_INFO) => self.indexed.1 += u32::from(in_index),
                Some(OP_INDEX_DATA) => {}
                Some(op) => return Err(Error::at(&self.path, at, format!("unknown record op {op:#04x}"))),
                None => return Err(Error::at(&self.path, at, "record without `op`")),
            }
        }
    }
}

impl Iterator for Bag1Messages {
    type Item = Result<RawMessage, Error>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let item = self.next_message().transpose();
        if !matches!(item, Some(Ok(_))) {
            self.done = true;
        }
        item
    }
}

/// Reads until `buf` is full or the file ends; the bytes read.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}
