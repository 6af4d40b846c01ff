//! ROS 2 bags: a folder with rosbag2's `metadata.yaml` naming its storage (`mcap` or `sqlite3`)
//! and files, or one `.mcap` / `.db3` file on its own.
//!
//! - MCAP: streamed with the `mcap` crate's reader; schemas `ros2msg` (CDR messages) and, for
//!   ROS 1 data converted to MCAP, `ros1msg` (ROS 1 messages).
//! - SQLite: rosbag2's `topics` and `messages` tables, in record-time order, a page of rows at a
//!   time; the `message_definitions` table (rosbag2 since Iron) when present, else the built-in
//!   definitions of the sensor types ([`crate::known`]).

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::decode::Encoding;
use crate::msgdef::Dialect;
use crate::{Connection, Error, RawMessage};

/// rosbag2's storage plugins.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// `mcap`.
    Mcap,
    /// `sqlite3` (`.db3`).
    Sqlite,
}

/// The storage and files of a rosbag2 folder, from its `metadata.yaml`.
pub(crate) fn read_metadata(dir: &Path) -> Result<(Storage, Vec<PathBuf>), Error> {
    let path = dir.join("metadata.yaml");
    let text = std::fs::read_to_string(&path).map_err(|e| Error::io(&path, &e))?;
    let doc = dynaflow_base::yaml::parse(&text).map_err(|e| Error::at(&path, 0, format!("not YAML: {}", e.message)))?;
    let info = doc
        .get("rosbag2_bagfile_information")
        .ok_or_else(|| Error::at(&path, 0, "no `rosbag2_bagfile_information` (not a rosbag2 metadata file)"))?;
    let storage = match info.get("storage_identifier").and_then(|s| s.as_str()) {
        Some("mcap") => Storage::Mcap,
        Some("sqlite3") => Storage::Sqlite,
        Some(other) => return Err(Error::at(&path, 0, format!("storage `{other}` (known: mcap, sqlite3)"))),
        None => return Err(Error::at(&path, 0, "no `storage_identifier`")),
    };
    let files: Vec<PathBuf> = match info.get("relative_file_paths").map(|f| &f.kind) {
        Some(dynaflow_base::yaml::YamlKind::Seq(items)) => {
            items.iter().filter_map(|i| i.as_str()).map(|f| dir.join(f)).collect()
        }
        _ => return Err(Error::at(&path, 0, "no `relative_file_paths` list")),
    };
    if files.is_empty() {
        return Err(Error::at(&path, 0, "`relative_file_paths` is empty"));
    }
    for f in &files {
        if !f.is_file() {
            return Err(Error::at(&path, 0, format!("lists {}, which is missing", f.display())));
        }
    }
    Ok((storage, files))
}

/// Messages of one MCAP file, in file order.
pub(crate) struct McapMessages {
    path: PathBuf,
    reader: mcap::io::MessageReader<BufReader<File>>,
    connections: HashMap<u16, Arc<Connection>>,
}

impl McapMessages {
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        let file = File::open(path).map_err(|e| Error::io(path, &e))?;
        let reader = mcap::io::MessageReader::new(BufReader::with_capacity(1 << 20, file));
        Ok(Self { path: path.to_path_buf(), reader, connections: HashMap::new() })
    }

    fn connection(&mut self, channel: &mcap::Channel<'_>) -> Result<Arc<Connection>, Error> {
        if let Some(c) = self.connections.get(&channel.id) {
            return Ok(c.clone());
        }
        let schema = channel.schema.as_ref();
        let (encoding, dialect) = match (channel.message_encoding.as_str(), schema.map(|s| s.encoding.as_str())) {
            ("cdr", Some("ros2msg") | None) => (Encoding::Cdr, Dialect::Ros2),
            ("ros1", Some("ros1msg") | None) => (Encoding::Ros1, Dialect::Ros1),
            (m, s) => {
                return Err(Error::at(
                    &self.path,
                    0,
                    format!(
                        "topic {}: message encoding `{m}` with schema encoding `{}` is not a ROS bag's (cdr/ros2msg or ros1/ros1msg); is this a dynaflow recording? `mcap_replay` reads those",
                        channel.topic,
                        s.unwrap_or("none")
                    ),
                ));
            }
        };
        let Some(schema) = schema else {
            return Err(Error::at(
                &self.path,
                0,
                format!("topic {}: channel without a schema (its type is unknown)", channel.topic),
            ));
        };
        let definition = String::from_utf8_lossy(&schema.data).into_owned();
        let c = Arc::new(Connection::new(
            channel.topic.clone(),
            schema.name.clone(),
            encoding,
            dialect,
            Some(definition),
            None,
        ));
        self.connections.insert(channel.id, c.clone());
        Ok(c)
    }
}

impl Iterator for McapMessages {
    type Item = Result<RawMessage, Error>;
    fn next(&mut self) -> Option<Self::Item> {
        let m = match self.reader.next()? {
            Ok(m) => m,
            Err(e) => return Some(Err(Error::at(&self.path, 0, format!("MCAP: {e}")))),
        };
        Some(self.connection(&m.channel).map(|connection| RawMessage {
            connection,
            log_time: m.log_time,
            data: m.data.into_owned(),
        }))
    }
}

/// Rows fetched per query.
const PAGE: usize = 32;

/// Messages of one rosbag2 SQLite file, in record-time order.
pub(crate) struct SqliteMessages {
    path: PathBuf,
    db: rusqlite::Connection,
    connections: HashMap<i64, Arc<Connection>>,
    /// The last row returned: (timestamp, id).
    after: (i64, i64),
    page: std::collections::VecDeque<(i64, i64, Vec<u8>)>,
    done: bool,
}

impl SqliteMessages {
    pub(crate) fn open(path: &Path) -> Result<Self, Error> {
        let sql = |e: rusqlite::Error| Error::at(path, 0, format!("SQLite: {e}"));
        let db =
            rusqlite::Connection::open_with_flags(path, rusqlite::OpenFlags::SQLITE_OPEN_READ_ONLY).map_err(sql)?;
        // Definitions stored in the bag (rosbag2 since Iron), by type.
        let mut stored: HashMap<String, String> = HashMap::new();
        let has_defs: bool = db
            .query_row(
                "SELECT count(*) FROM sqlite_master WHERE type='table' AND name='message_definitions'",
                [],
                |r| r.get::<_, i64>(0),
            )
            .map_err(sql)?
            > 0;
        if has_defs {
            let mut q = db
                .prepare("SELECT topic_type, encoding, encoded_message_definition FROM message_definitions")
                .map_err(sql)?;
            let rows = q
                .query_map([], |r| Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?, r.get::<_, String>(2)?)))
                .map_err(sql)?;
            for row in rows {
                let (ty, enc, def) = row.map_err(sql)?;
                if enc == "ros2msg" && !def.is_empty() {
                    stored.insert(crate::msgdef::normalize_type(&ty), def);
                }
            }
        }
        let mut connections = HashMap::new();
        {
            let mut q = db
                .prepare("SELECT id, name, type, serialization_format FROM topics")
                .map_err(|e| Error::at(path, 0, format!("SQLite: {e} (not a rosbag2 `.db3`: no `topics` table?)")))?;
            let rows = q
                .query_map([], |r| {
                    Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?, r.get::<_, String>(2)?, r.get::<_, String>(3)?))
                })
                .map_err(sql)?;
            for row in rows {
                let (id, topic, ty, format) = row.map_err(sql)?;
                if format != "cdr" {
                    return Err(Error::at(
                        path,
                        0,
                        format!("topic {topic}: serialization format `{format}` (only cdr is read)"),
                    ));
                }
                let norm = crate::msgdef::normalize_type(&ty);
                let definition = stored.get(&norm).cloned().or_else(|| crate::known::bundle(&norm));
                connections
                    .insert(id, Arc::new(Connection::new(topic, ty, Encoding::Cdr, Dialect::Ros2, definition, None)));
            }
        }
        Ok(Self {
            path: path.to_path_buf(),
            db,
            connections,
            after: (i64::MIN, i64::MIN),
            page: Default::default(),
            done: false,
        })
    }

    fn fill(&mut self) -> Result<(), Error> {
        let sql = |e: rusqlite::Error| Error::at(&self.path, 0, format!("SQLite: {e}"));
        let mut q = self
            .db
            .prepare_cached(
                "SELECT timestamp, id, topic_id, data FROM messages WHERE (timestamp, id) > (?1, ?2) ORDER BY timestamp, id LIMIT ?3",
            )
            .map_err(sql)?;
        let rows = q
            .query_map(rusqlite::params![self.after.0, self.after.1, PAGE as i64], |r| {
                Ok((r.get::<_, i64>(0)?, r.get::<_, i64>(1)?, r.get::<_, i64>(2)?, r.get::<_, Vec<u8>>(3)?))
            })
            .map_err(sql)?;
        let mut page = std::collections::VecDeque::new();
        for row in rows {
            let (t, id, topic, data) = row.map_err(sql)?;
            self.after = (t, id);
            page.push_back((t, topic, data));
        }
        self.page = page;
        Ok(())
    }
}

impl Iterator for SqliteMessages {
    type Item = Result<RawMessage, Error>;
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        if self.page.is_empty() {
            if let Err(e) = self.fill() {
                self.done = true;
                return Some(Err(e));
            }
            if self.page.is_empty() {
                self.done = true;
                return None;
            }
        }
        let (t, topic, data) = self.page.pop_front()?;
        let Some(connection) = self.connections.get(&topic).cloned() else {
            self.done = true;
            return Some(Err(Error::at(
                &self.path,
                0,
                format!("a message of topic id {topic}, which the `topics` table lacks"),
            )));
        };
        Some(Ok(RawMessage { connection, log_time: t.max(0) as u64, data }))
    }
}
