//! The live stream: every recorded port streamed to a running rerun viewer or server over
//! gRPC while the graph runs, with the entity tree, timelines, blueprint and provenance of the
//! `.rrd` file (the same [`RrdSink`] code, aimed at a URL).
//!
//! A viewer must never hold up the graph or the file recorders, so the stream has its own
//! bounded queue ([`LIVE_QUEUE`] messages) in front of a worker thread that logs into the
//! rerun SDK: when the viewer cannot keep up (the SDK's gRPC client applies backpressure),
//! the queue fills and further messages are dropped, counted per port. The worker checks
//! every [`PROBE_EVERY`] that the viewer still accepts connections; once it does not, the
//! stream stops with one warning and every later message is counted as dropped. The files are
//! recorders of their own and receive everything regardless.

use crate::Error;
use std::collections::BTreeMap;
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use dynaflow_engine::msg::Message;
use dynaflow_engine::sink::{PortReport, RunInfo, Sink, SinkError, SinkReport};

use crate::encode::{EncodeCache, ImageCodec};
use crate::rrd::{RrdSink, Target};

/// rerun's usual local viewer address (`rerun` listens on 9876).
pub const DEFAULT_URL: &str = "rerun+http://127.0.0.1:9876/proxy";

/// Messages waiting for the viewer before new ones are dropped (about two frames of the
/// default graph: a viewer that falls behind loses frames, not seconds of latency).
pub const LIVE_QUEUE: usize = 64;

/// How often the worker checks that the viewer is still there.
pub const PROBE_EVERY: Duration = Duration::from_millis(500);

/// How long closing waits for the viewer to take what is queued.
const CLOSE_WAIT: Duration = Duration::from_secs(5);

/// The `host:port` of a `rerun+http://host:port/proxy` URL.
pub fn address(url: &str) -> Result<SocketAddr, Error> {
    address_msg(url).map_err(Error::Viewer)
}

fn address_msg(url: &str) -> Result<SocketAddr, String> {
    let rest = url
        .strip_prefix("rerun+http://")
        .or_else(|| url.strip_prefix("rerun+https://"))
        .or_else(|| url.strip_prefix("rerun://"))
        .ok_or_else(|| format!("`{url}` is not a rerun URL (expected `rerun+http://HOST:PORT/proxy`)"))?;
    let authority = rest.split('/').next().unwrap_or_default();
    authority
        .to_socket_addrs()
        .map_err(|e| format!("`{url}`: cannot resolve `{authority}`: {e}"))?
        .next()
        .ok_or_else(|| format!("`{url}`: `{authority}` resolves to no address"))
}

/// Whether a viewer accepts connections at `url`; the error says why not.
pub fn probe(url: &str) -> Result<(), Error> {
    let addr = address(url)?;
    TcpStream::connect_timeout(&addr, Duration::from_secs(1))
        .map(drop)
        .map_err(|e| Error::Viewer(format!("{addr}: {e}")))
}

/// Start a local rerun viewer (the `rerun` on `PATH`) listening on rerun's usual port, or
/// find the one already there; returns its URL. The error says how to install one.
pub fn spawn_viewer() -> Result<String, Error> {
    if probe(DEFAULT_URL).is_ok() {
        return Ok(DEFAULT_URL.to_owned());
    }
    let opts = rerun::SpawnOptions { wait_for_bind: true, ..rerun::SpawnOptions::default() };
    rerun::spawn(&opts).map_err(|e| {
        Error::Viewer(format!(
            "cannot start the rerun viewer: {e}\n  install it with `pip install rerun-sdk==0.36.3` (or `cargo install rerun-cli@0.36.3 --locked`)"
        ))
    })?;
    Ok(DEFAULT_URL.to_owned())
}

type Item = (String, String, Arc<Message>);

/// Counts shared by the queueing side and the worker.
#[derive(Default)]
struct Shared {
    ports: Mutex<BTreeMap<String, PortReport>>,
    gone: AtomicBool,
}

impl Shared {
    fn count(&self, key: &str, f: impl FnOnce(&mut PortReport)) {
        f(self.ports.lock().unwrap_or_else(PoisonError::into_inner).entry(key.to_owned()).or_default());
    }
}

/// Streams every recorded port to a rerun viewer (`dynaflow run --connect`/`--spawn`).
pub struct LiveSink {
    url: String,
    codec: ImageCodec,
    cache: EncodeCache,
    queue: Option<SyncSender<Item>>,
    worker: Option<std::thread::JoinHandle<()>>,
    shared: Arc<Shared>,
}

impl LiveSink {
    /// A stream to the viewer at `url`.
    pub fn new(url: impl Into<String>) -> Self {
        Self {
            url: url.into(),
            codec: ImageCodec::Jpeg(90),
            cache: EncodeCache::default(),
            queue: None,
            worker: None,
            shared: Arc::default(),
        }
    }

    /// Share image encodings with the file recorders.
    #[must_use]
    pub fn with_cache(mut self, cache: EncodeCache) -> Self {
        self.cache = cache;
        self
    }

    /// How colour images are sent.
    #[must_use]
    pub fn with_codec(mut self, codec: ImageCodec) -> Self {
        self.codec = codec;
        self
    }
}

fn worker(mut rrd: RrdSink, rx: &Receiver<Item>, shared: &Shared, url: &str) {
    let mut last_probe = Instant::now();
    let went_away = |seq: u64, why: &dyn std::fmt::Display| {
        tracing::warn!(
            "the rerun viewer at {url} went away at frame {seq} ({why}); the run goes on and the files get everything, the live stream stops (its drops are counted in the summary)"
        );
        shared.gone.store(true, Ordering::Relaxed);
    };
    while let Ok((node, port, msg)) = rx.recv() {
        let key = format!("{node}/{port}");
        if !shared.gone.load(Ordering::Relaxed) && last_probe.elapsed() >= PROBE_EVERY {
            last_probe = Instant::now();
            if let Err(e) = probe(url) {
                went_away(msg.header.seq, &e);
            }
        }
        if shared.gone.load(Ordering::Relaxed) {
            shared.count(&key, |p| p.dropped += 1);
            continue;
        }
        match rrd.record(&node, &port, &msg) {
            Ok(()) => shared.count(&key, |p| p.messages += 1),
            Err(e) => {
                went_away(msg.header.seq, &e);
                shared.count(&key, |p| p.dropped += 1);
            }
        }
    }
    if let Err(e) = rrd.close() {
        tracing::warn!("live stream to {url}: {e}");
    }
}

impl Sink for LiveSink {
    fn name(&self) -> &str {
        "live"
    }

    fn open(&mut self, info: &RunInfo) -> Result<(), SinkError> {
        probe(&self.url).map_err(|e| {
            SinkError::new(
                "live",
                format!("no rerun viewer at {}: {e} (start one with `rerun`, or use --spawn)", self.url),
            )
        })?;
        let mut rrd = RrdSink::to(Target::Grpc(self.url.clone())).with_codec(self.codec).with_cache(self.cache.clone());
        rrd.open(info)?;
        let (tx, rx) = std::sync::mpsc::sync_channel::<Item>(LIVE_QUEUE);
        let (shared, url) = (self.shared.clone(), self.url.clone());
        let handle = std::thread::Builder::new()
            .name("dynaflow-live".into())
            .spawn(move || worker(rrd, &rx, &shared, &url))
            .map_err(|e| SinkError::new("live", format!("cannot start the live stream thread: {e}")))?;
        self.queue = Some(tx);
        self.worker = Some(handle);
        Ok(())
    }

    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let shared = Arc::new(msg.clone());
        self.enqueue(node, port, &shared)
    }

    fn record_shared(&mut self, node: &str, port: &str, msg: &Arc<Message>) -> Result<(), SinkError> {
        self.enqueue(node, port, msg)
    }

    fn close(&mut self) -> Result<(), SinkError> {
        drop(self.queue.take());
        let Some(handle) = self.worker.take() else { return Ok(()) };
        // Wait for the worker to hand over what is queued, but not for a stuck viewer.
        let started = Instant::now();
        while !handle.is_finished() && started.elapsed() < CLOSE_WAIT {
            std::thread::sleep(Duration::from_millis(20));
        }
        if handle.is_finished() {
            let _ = handle.join();
        } else {
            tracing::warn!("the rerun viewer at {} did not take the last messages within {CLOSE_WAIT:?}", self.url);
        }
        Ok(())
    }

    fn report(&self) -> SinkReport {
        SinkReport {
            ports: self.shared.ports.lock().unwrap_or_else(PoisonError::into_inner).clone(),
            ..SinkReport::default()
        }
    }
}

impl LiveSink {
    fn enqueue(&mut self, node: &str, port: &str, msg: &Arc<Message>) -> Result<(), SinkError> {
        let Some(queue) = &self.queue else { return Err(SinkError::new("live", "not open")) };
        let sent = !self.shared.gone.load(Ordering::Relaxed)
            && match queue.try_send((node.to_owned(), port.to_owned(), msg.clone())) {
                Ok(()) => true,
                Err(TrySendError::Full(_)) => false,
                Err(TrySendError::Disconnected(_)) => {
                    self.shared.gone.store(true, Ordering::Relaxed);
                    false
                }
            };
        if !sent {
            self.shared.count(&format!("{node}/{port}"), |p| p.dropped += 1);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_name_their_address_and_bad_ones_say_why() {
        assert_eq!(address("rerun+http://127.0.0.1:9876/proxy").unwrap().port(), 9876);
        assert!(address("http://127.0.0.1:9876").unwrap_err().to_string().contains("not a rerun URL"));
        assert!(address("rerun+http://127.0.0.1/proxy").is_err());
        // Nothing listens on port 1.
        assert!(probe("rerun+http://127.0.0.1:1/proxy").is_err());
    }
}
