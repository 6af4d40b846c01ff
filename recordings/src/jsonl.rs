//! `<out>/<graph>.messages.jsonl`: a line per recorded message.
//!
//! Line 1 is `{"kind":"run", ...provenance}`; then `{"kind":"msg","node","port","seq","stamp",
//! "frame_id","type","digest","summary"}`; the last line `{"kind":"end","messages":N}` is
//! written when the sink is closed, so its presence tells a complete log from a cut one.
//! Lines are flushed in batches; a killed run loses at most the unflushed batch and leaves
//! every earlier line intact.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use dynaflow_engine::msg::Message;
use dynaflow_engine::sink::{PortReport, RunInfo, Sink, SinkError, SinkReport};

/// Messages per flush.
const FLUSH_EVERY: u64 = 64;

/// The JSON-lines message log.
#[derive(Debug)]
pub struct MessageLog {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    count: u64,
    /// `node/port` -> messages written.
    ports: std::collections::BTreeMap<String, u64>,
}

impl MessageLog {
    /// A log that will be written to `path` when the run opens it.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into(), out: None, count: 0, ports: std::collections::BTreeMap::new() }
    }

    /// Where the log is written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn err(&self, e: impl std::fmt::Display) -> SinkError {
        SinkError::new("jsonl", format!("{}: {e}", self.path.display()))
    }

    fn line(&mut self, value: &serde_json::Value) -> Result<(), SinkError> {
        let Some(out) = self.out.as_mut() else {
            return Err(SinkError::new("jsonl", format!("{}: not open", self.path.display())));
        };
        let r =
            serde_json::to_writer(&mut *out, value).map_err(std::io::Error::other).and_then(|()| out.write_all(b"\n"));
        r.map_err(|e| self.err(e))
    }
}

impl Sink for MessageLog {
    fn name(&self) -> &str {
        "jsonl"
    }

    fn open(&mut self, info: &RunInfo) -> Result<(), SinkError> {
        let file = dynaflow_engine::files::create_new(&self.path).map_err(|e| self.err(e))?;
        self.out = Some(BufWriter::new(file));
        let mut v = serde_json::to_value(info).map_err(|e| self.err(e))?;
        if let Some(obj) = v.as_object_mut() {
            obj.insert("kind".into(), "run".into());
        }
        self.line(&v)?;
        self.out.as_mut().map_or(Ok(()), Write::flush).map_err(|e| self.err(e))
    }

    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let v = serde_json::json!({
            "kind": "msg",
            "node": node,
            "port": port,
            "seq": msg.header.seq,
            "stamp": msg.header.stamp,
            "frame_id": &*msg.header.frame_id,
            "type": msg.body.port_type(),
            "digest": format!("{:016x}", msg.digest()),
            "summary": msg.summary(),
        });
        self.line(&v)?;
        self.count += 1;
        *self.ports.entry(format!("{node}/{port}")).or_default() += 1;
        if self.count.is_multiple_of(FLUSH_EVERY) {
            self.out.as_mut().map_or(Ok(()), Write::flush).map_err(|e| self.err(e))?;
        }
        Ok(())
    }

    fn close(&mut self) -> Result<(), SinkError> {
        if self.out.is_none() {
            return Ok(());
        }
        let end = serde_json::json!({"kind": "end", "messages": self.count});
        self.line(&end)?;
        let out = self.out.take();
        match out {
            Some(mut w) => w.flush().and_then(|()| w.get_ref().sync_all()).map_err(|e| self.err(e)),
            None => Ok(()),
        }
    }

    fn report(&self) -> SinkReport {
        SinkReport {
            path: Some(self.path.display().to_string()),
            file_bytes: std::fs::metadata(&self.path).ok().map(|m| m.len()),
            ports: self
                .ports
                .iter()
                .map(|(k, &messages)| (k.clone(), PortReport { messages, ..PortReport::default() }))
                .collect(),
            ..SinkReport::default()
        }
    }
}
