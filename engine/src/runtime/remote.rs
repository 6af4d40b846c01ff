//! Edges between machines: a graph whose nodes name `machine:`s runs as one
//! process per machine, and an edge between two of them travels over a [`Wire`] (zenoh in
//! `dynaflow-net`; an in-process loopback for tests).
//!
//! What crosses is the edge's envelope stream itself, so joins, delays and feedback keep their
//! meaning: for each frame the producer's message ([`crate::msg::codec`]: exact, the digest
//! survives) or its watermark, then an end-of-stream mark. The consumer's side puts them into
//! an ordinary local edge with the consumer's queue policy and delay, so a `latest` join waits
//! for the producer's frontier in lockstep runs exactly as in one process, and a dropping
//! queue drops (and counts) on the consumer's machine. The producer's side queues with
//! `block` in lockstep runs (nothing is lost before the wire) and with the consumer edge's
//! policy in real time.
//!
//! A frame on the wire: a kind byte ([`KIND_MESSAGE`], [`KIND_WATERMARK`], [`KIND_END`]),
//! the frame number (u64, little-endian), and for a message its encoding.

use std::sync::Arc;

use futures::future::BoxFuture;

use crate::msg::{Message, codec};

/// A message of frame `seq`.
pub const KIND_MESSAGE: u8 = 1;
/// Nothing for frame `seq`.
pub const KIND_WATERMARK: u8 = 2;
/// The producer has ended: no more frames.
pub const KIND_END: u8 = 3;

/// The transport between the machines of a graph.
pub trait Wire: Send + Sync {
    /// A publication of the stream `key` (`node/port` of a producer on this machine), read
    /// by the machines `to`.
    fn publisher<'a>(&'a self, key: &'a str, to: &'a [Arc<str>]) -> BoxFuture<'a, Result<Box<dyn WireTx>, String>>;
    /// A subscription to the stream `key`, produced on machine `from`. Declared before
    /// [`Wire::ready`], so nothing published after every machine is ready is missed.
    fn subscriber<'a>(&'a self, key: &'a str, from: &'a str) -> BoxFuture<'a, Result<Box<dyn WireRx>, String>>;
    /// Declare this machine ready (its subscriptions are in place) and wait until every
    /// other machine of the graph is: an error names a machine that did not come, or one that
    /// runs another graph.
    fn ready(&self) -> BoxFuture<'_, Result<(), String>>;
}

/// The sending end of one stream.
pub trait WireTx: Send + Sync {
    /// Send one frame (waits while the receivers cannot take more: backpressure); an error
    /// when a receiving machine is gone.
    fn send(&self, frame: Vec<u8>) -> BoxFuture<'_, Result<(), String>>;
}

/// The receiving end of one stream.
pub trait WireRx: Send {
    /// The next frame; an error when the producing machine is gone before the stream ended.
    fn recv(&mut self) -> BoxFuture<'_, Result<Vec<u8>, String>>;
}

/// Where this process stands in a graph that spans machines.
#[derive(Clone)]
pub struct Placement {
    /// This process's machine (a name of the graph's `machines:`).
    pub machine: Arc<str>,
    /// The transport.
    pub wire: Arc<dyn Wire>,
}

impl std::fmt::Debug for Placement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Placement").field("machine", &self.machine).finish_non_exhaustive()
    }
}

/// One frame's bytes.
pub fn encode_frame(seq: u64, msg: Option<&Message>) -> Vec<u8> {
    let mut out = Vec::with_capacity(9);
    out.push(if msg.is_some() { KIND_MESSAGE } else { KIND_WATERMARK });
    out.extend_from_slice(&seq.to_le_bytes());
    if let Some(m) = msg {
        out.extend_from_slice(&codec::encode(m));
    }
    out
}

/// The end-of-stream frame.
pub fn end_frame() -> Vec<u8> {
    vec![KIND_END]
}

/// A decoded frame.
#[derive(Debug)]
pub enum Frame {
    /// Frame `seq`'s message, or its watermark.
    Envelope(u64, Option<Box<Message>>),
    /// The producer has ended.
    End,
}

/// Decode a frame.
pub fn decode_frame(bytes: &[u8]) -> Result<Frame, String> {
    let (&kind, rest) = bytes.split_first().ok_or("an empty frame")?;
    if kind == KIND_END {
        return Ok(Frame::End);
    }
    let seq = rest.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes).ok_or("a truncated frame")?;
    match kind {
        KIND_WATERMARK => Ok(Frame::Envelope(seq, None)),
        KIND_MESSAGE => {
            codec::decode(&rest[8..]).map(|m| Frame::Envelope(seq, Some(Box::new(m)))).map_err(|e| e.to_string())
        }
        k => Err(format!("unknown frame kind {k}")),
    }
}

/// A [`Wire`] inside one process (every "machine" a task of it): the engine's tests of split
/// graphs, and a reference for transports.
pub mod loopback {
    use std::collections::HashMap;
    use std::sync::{Arc, Mutex, PoisonError};

    use futures::FutureExt;
    use futures::future::BoxFuture;
    use tokio::sync::mpsc;

    use super::{Wire, WireRx, WireTx};

    type Streams = HashMap<String, Vec<mpsc::Sender<Vec<u8>>>>;

    /// The shared "network": subscriptions by key.
    #[derive(Clone)]
    pub struct Hub {
        streams: Arc<Mutex<Streams>>,
        ready: Arc<tokio::sync::Barrier>,
    }

    impl Hub {
        /// A hub for `machines` processes.
        pub fn new(machines: usize) -> Self {
            Self { streams: Arc::default(), ready: Arc::new(tokio::sync::Barrier::new(machines)) }
        }
        /// One machine's wire.
        pub fn wire(&self) -> Arc<dyn Wire> {
            Arc::new(self.clone())
        }
    }

    struct Tx(Vec<mpsc::Sender<Vec<u8>>>);
    struct Rx(mpsc::Receiver<Vec<u8>>);

    impl Wire for Hub {
        fn publisher<'a>(
            &'a self,
            key: &'a str,
            _to: &'a [Arc<str>],
        ) -> BoxFuture<'a, Result<Box<dyn WireTx>, String>> {
            let subs =
                self.streams.lock().unwrap_or_else(PoisonError::into_inner).get(key).cloned().unwrap_or_default();
            async move { Ok(Box::new(Tx(subs)) as Box<dyn WireTx>) }.boxed()
        }
        fn subscriber<'a>(&'a self, key: &'a str, _from: &'a str) -> BoxFuture<'a, Result<Box<dyn WireRx>, String>> {
            let (tx, rx) = mpsc::channel(4);
            self.streams.lock().unwrap_or_else(PoisonError::into_inner).entry(key.to_owned()).or_default().push(tx);
            async move { Ok(Box::new(Rx(rx)) as Box<dyn WireRx>) }.boxed()
        }
        fn ready(&self) -> BoxFuture<'_, Result<(), String>> {
            async move {
                self.ready.wait().await;
                Ok(())
            }
            .boxed()
        }
    }

    impl WireTx for Tx {
        fn send(&self, frame: Vec<u8>) -> BoxFuture<'_, Result<(), String>> {
            async move {
                for s in &self.0 {
                    s.send(frame.clone()).await.map_err(|_| "the receiving machine is gone".to_owned())?;
                }
                Ok(())
            }
            .boxed()
        }
    }

    impl WireRx for Rx {
        fn recv(&mut self) -> BoxFuture<'_, Result<Vec<u8>, String>> {
            async move { self.0.recv().await.ok_or_else(|| "the producing machine is gone".to_owned()) }.boxed()
        }
    }
}
