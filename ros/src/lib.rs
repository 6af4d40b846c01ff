//! ROS 1 and ROS 2 bags as a plain library, with no ROS installation: open a bag, stream its
//! messages in order, decode them with the definitions the bag itself stores, and read the
//! sensor messages a SLAM run needs.
//!
//! - [`msgdef`]: message definitions (`.msg` text with its `MSG:` sections) into a registry.
//! - [`decode`]: ROS 1 and CDR bytes into value trees, every length checked.
//! - [`encode`]: ROS 2 messages out (CDR), for recordings ROS tools replay.
//! - [`inspect`]: a bag's topics, counts and rates, and the topic each role of a run would take.
//! - [`known`]: the ROS 2 sensor types' definitions, for `.db3` bags that do not store theirs.
//! - [`sequence`]: a bag as a run's frames: topics chosen, colour and depth paired by header
//!   stamp, calibration and ground truth, every message left out counted.
//! - [`tf`]: the transform tree of `/tf` and `/tf_static`, looked up at a time as tf2 does.
//! - [`Bag`]: `.bag` (format 2.0; bz2 and lz4 chunks), a rosbag2 folder (`metadata.yaml` with
//!   MCAP or SQLite storage), or a bare `.mcap` / `.db3` file.
//!
//! Every error names the bag file (and byte offset, topic or field where one applies): [`Error`].

#![warn(missing_docs)]

mod bag1;
mod bag2;
pub mod decode;
pub mod encode;
pub mod inspect;
pub mod known;
pub mod msgdef;
pub mod sensor;
pub mod sequence;
pub mod tf;

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

pub use bag2::Storage;
use decode::Encoding;
use msgdef::{Dialect, Registry};

/// What reading a bag can fail with.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A file is missing, unreadable, truncated or malformed; `offset` is a byte offset where
    /// one is known.
    #[error("{}{}: {message}", path.display(), offset.map(|o| format!(" (byte {o})")).unwrap_or_default())]
    File {
        /// The file.
        path: PathBuf,
        /// Byte offset.
        offset: Option<u64>,
        /// What is wrong.
        message: String,
    },
    /// A topic's messages cannot be decoded (definition or bytes).
    #[error("{bag}: topic {topic}: {message}")]
    Topic {
        /// The bag.
        bag: PathBuf,
        /// The topic.
        topic: String,
        /// What is wrong.
        message: String,
    },
}

impl Error {
    pub(crate) fn io(path: &Path, e: &std::io::Error) -> Self {
        Error::File { path: path.to_path_buf(), offset: None, message: e.to_string() }
    }
    pub(crate) fn at(path: &Path, offset: u64, message: impl Into<String>) -> Self {
        Error::File { path: path.to_path_buf(), offset: (offset > 0).then_some(offset), message: message.into() }
    }
}

/// A topic as the bag declares it.
#[derive(Debug)]
pub struct Connection {
    /// Topic name.
    pub topic: String,
    /// Message type as stored (`sensor_msgs/Image`, `sensor_msgs/msg/Image`).
    pub ty: String,
    /// Wire format of its messages.
    pub encoding: Encoding,
    /// Which ROS's definitions.
    pub dialect: Dialect,
    /// The stored definition (with its `MSG:` sections), if the bag has one.
    pub definition: Option<String>,
    /// ROS 1's md5sum of the definition.
    pub md5sum: Option<String>,
    registry: OnceLock<Result<Arc<Registry>, String>>,
}

impl Connection {
    pub(crate) fn new(
        topic: String,
        ty: String,
        encoding: Encoding,
        dialect: Dialect,
        definition: Option<String>,
        md5sum: Option<String>,
    ) -> Self {
        Self { topic, ty, encoding, dialect, definition, md5sum, registry: OnceLock::new() }
    }

    /// `pkg/Type` (ROS 2's `msg/` dropped).
    pub fn type_name(&self) -> String {
        msgdef::normalize_type(&self.ty)
    }

    /// The parsed definition (parsed once). An error says why the topic cannot be decoded.
    pub fn registry(&self) -> Result<Arc<Registry>, String> {
        self.registry
            .get_or_init(|| {
                let text = self.definition.clone().or_else(|| known::bundle(&self.type_name())).ok_or_else(|| {
                    format!("the bag stores no definition of `{}` and it is not a known sensor type", self.ty)
                })?;
                Registry::parse(&self.ty, &text, self.dialect).map(Arc::new).map_err(|e| e.to_string())
            })
            .clone()
    }
}

/// One serialised message.
#[derive(Clone, Debug)]
pub struct RawMessage {
    /// Its topic.
    pub connection: Arc<Connection>,
    /// When it was recorded, nanoseconds (the bag's time, not the header stamp).
    pub log_time: u64,
    /// The serialised bytes.
    pub data: Vec<u8>,
}

impl RawMessage {
    /// Decodes it with its topic's definition.
    pub fn decode(&self) -> Result<decode::Message, String> {
        let registry = self.connection.registry()?;
        decode::decode(&registry, self.connection.encoding, &self.data).map_err(|e| e.to_string())
    }
}

/// Which kind of bag.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// ROS 1 `.bag`, format 2.0.
    Ros1,
    /// ROS 2, in MCAP or SQLite storage.
    Ros2(Storage),
}

/// An opened bag: its files, read again from the start by each [`Bag::messages`].
#[derive(Clone, Debug)]
pub struct Bag {
    path: PathBuf,
    format: Format,
    files: Vec<PathBuf>,
}

/// Messages in order, one file after another.
pub type Messages = Box<dyn Iterator<Item = Result<RawMessage, Error>> + Send>;

impl Bag {
    /// Opens a ROS 1 `.bag`, a rosbag2 folder, or a bare `.mcap` / `.db3`, told apart by their
    /// contents (the first bytes; `metadata.yaml` for a folder).
    pub fn open(path: &Path) -> Result<Self, Error> {
        if path.is_dir() {
            let (storage, files) = bag2::read_metadata(path)?;
            return Ok(Bag { path: path.to_path_buf(), format: Format::Ros2(storage), files });
        }
        let format = sniff(path)?
            .ok_or_else(|| Error::at(path, 0, "not a ROS bag (neither `#ROSBAG V2.0`, MCAP nor SQLite)"))?;
        Ok(Bag { path: path.to_path_buf(), format, files: vec![path.to_path_buf()] })
    }

    /// The path it was opened from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Its kind.
    pub fn format(&self) -> Format {
        self.format
    }

    /// Its storage files.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Streams every message from the start: file order for `.bag` and MCAP (record order),
    /// record-time order for SQLite.
    pub fn messages(&self) -> Result<Messages, Error> {
        let mut parts: Vec<Messages> = Vec::new();
        for f in &self.files {
            parts.push(match self.format {
                Format::Ros1 => Box::new(bag1::Bag1Messages::open(f)?),
                Format::Ros2(Storage::Mcap) => Box::new(bag2::McapMessages::open(f)?),
                Format::Ros2(Storage::Sqlite) => Box::new(bag2::SqliteMessages::open(f)?),
            });
        }
        Ok(Box::new(parts.into_iter().flatten()))
    }
}

/// The format told by a file's first bytes.
fn sniff(path: &Path) -> Result<Option<Format>, Error> {
    use std::io::Read;
    let mut head = [0u8; 16];
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, &e))?;
    let n = f.read(&mut head).map_err(|e| Error::io(path, &e))?;
    let head = &head[..n];
    Ok(if head.starts_with(bag1::MAGIC) {
        Some(Format::Ros1)
    } else if head.starts_with(b"\x89MCAP0\r\n") {
        Some(Format::Ros2(Storage::Mcap))
    } else if head.starts_with(b"SQLite format 3\0") {
        Some(Format::Ros2(Storage::Sqlite))
    } else {
        None
    })
}
