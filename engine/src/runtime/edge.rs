//! A single-producer single-consumer queue with an explicit overflow policy and counters.
//!
//! tokio's channels cannot drop the *oldest* element or report their peak depth, and every
//! dropped message must be counted, so edges get their own small queue: a `VecDeque` under a
//! `std` mutex (never held across an await) and two `Notify`s.
//!
//! # Messages, watermarks and the delay's reservation
//! An envelope is a message or a watermark ("nothing for frame `seq`; the producer has moved
//! past it"). A watermark carries no data, and any later envelope moves the consumer's
//! frontier at least as far, so:
//! - `block` queues keep every envelope in order (a lockstep consumer then sees every frame,
//!   which keeps offline runs exactly reproducible);
//! - dropping queues keep at most `capacity` *messages*, and a new watermark replaces a
//!   watermark at the back of the queue (so a fast gate cannot fill a queue with them). Only
//!   messages are ever counted as dropped.
//!
//! A `delay: d` edge starts with `d` watermarks (frames `0..d` have no predecessor) and, in a
//! feedback loop, always holds the `d` envelopes in flight between the producer's frame and
//! the consumer's. Those `d` slots are reserved: they count neither against the capacity
//! (so a `latest` queue on a delayed edge never drops in a loop that keeps up) nor in
//! `max_depth`.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use tokio::sync::Notify;

use crate::msg::Message;
use crate::spec::QueuePolicy;

/// What travels on an edge: the message of frame `seq`, or `None` meaning "nothing for frame
/// `seq`" (a watermark: the producer's frontier has passed `seq`).
#[derive(Clone, Debug)]
pub(crate) struct Envelope {
    pub seq: u64,
    pub msg: Option<Arc<Message>>,
    /// When the source emitted this frame (for end-to-end age).
    pub born: Instant,
}

impl Envelope {
    fn is_message(&self) -> bool {
        self.msg.is_some()
    }
}

/// Which leftover messages count as discarded when the consumer stops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Closed {
    Open,
    /// The consumer finished every frame up to and including this one (or none: `None`);
    /// messages for later frames belong to frames that never ran (a delay's tail) and are not
    /// lost.
    Completed(Option<u64>),
    /// The consumer stopped early (error, lost task): every message left or sent is lost.
    Abandoned,
}

#[derive(Debug)]
struct State {
    buf: VecDeque<Envelope>,
    /// Messages (not watermarks) in `buf`.
    messages: usize,
    sender_closed: bool,
    closed: Closed,
    stats: EdgeStats,
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    policy: QueuePolicy,
    delay: u64,
    data: Notify,
    space: Notify,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// Counters of one edge, read after (or during) a run. All counts are of messages;
/// watermarks are never counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct EdgeStats {
    /// Messages the producer sent.
    pub sent: u64,
    /// Largest number of envelopes queued beyond the delay's reserved slots.
    pub max_depth: usize,
    /// Messages dropped by a `drop_oldest`/`latest` policy.
    pub dropped: u64,
    /// Messages for frames the consumer should have processed but never did, because it
    /// stopped early (after an error) or ended before they arrived (`--realtime`).
    pub discarded: u64,
    /// Messages handed to the consumer.
    pub delivered: u64,
}

/// Read-only handle on an edge's counters.
#[derive(Clone, Debug)]
pub(crate) struct EdgeProbe(Arc<Shared>);

impl EdgeProbe {
    pub fn stats(&self) -> EdgeStats {
        self.0.lock().stats
    }
    /// Messages queued now (watermarks not counted).
    pub fn depth(&self) -> usize {
        self.0.lock().messages
    }
}

/// Producer end.
#[derive(Debug)]
pub(crate) struct EdgeTx(Arc<Shared>);
/// Consumer end.
#[derive(Debug)]
pub(crate) struct EdgeRx(Arc<Shared>);

/// A new edge. With `delay = d`, frame `k` of the producer arrives as frame `k + d` and the
/// consumer first sees `d` watermarks (frames `0..d` have no predecessor).
pub(crate) fn edge(policy: QueuePolicy, delay: u32) -> (EdgeTx, EdgeRx, EdgeProbe) {
    let now = Instant::now();
    let buf: VecDeque<Envelope> = (0..u64::from(delay)).map(|seq| Envelope { seq, msg: None, born: now }).collect();
    let shared = Arc::new(Shared {
        state: Mutex::new(State {
            buf,
            messages: 0,
            sender_closed: false,
            closed: Closed::Open,
            stats: EdgeStats::default(),
        }),
        policy,
        delay: u64::from(delay),
        data: Notify::new(),
        space: Notify::new(),
    });
    (EdgeTx(shared.clone()), EdgeRx(shared.clone()), EdgeProbe(shared))
}

impl State {
    fn lost_after_close(&self, seq: u64) -> bool {
        match self.closed {
            Closed::Open => false,
            Closed::Completed(last) => last.is_some_and(|l| seq <= l),
            Closed::Abandoned => true,
        }
    }

    fn push(&mut self, env: Envelope, reserved: usize) {
        if env.is_message() {
            self.messages += 1;
        }
        self.buf.push_back(env);
        self.stats.max_depth = self.stats.max_depth.max(self.buf.len().saturating_sub(reserved));
    }

    /// Push under a dropping policy: at most `capacity` messages beyond the reservation, with
    /// no two watermarks in a row.
    fn push_dropping(&mut self, env: Envelope, capacity: usize, reserved: usize) {
        if !env.is_message() && self.buf.back().is_some_and(|b| !b.is_message()) {
            // Consecutive watermarks coalesce: the newer one moves the frontier further.
            self.buf.pop_back();
        }
        if env.is_message() {
            while self.messages >= capacity + reserved {
                match self.buf.pop_front() {
                    Some(old) if old.is_message() => {
                        self.messages -= 1;
                        self.stats.dropped += 1;
                    }
                    Some(_) => {}
                    None => break,
                }
            }
        }
        self.push(env, reserved);
    }
}

impl EdgeTx {
    /// Enqueue, waiting for space under `block`, dropping the oldest under `drop_oldest`.
    pub async fn send(&self, mut env: Envelope) {
        env.seq += self.0.delay;
        let reserved = usize::try_from(self.0.delay).unwrap_or(usize::MAX);
        if env.is_message() {
            self.0.lock().stats.sent += 1;
        }
        loop {
            {
                let mut s = self.0.lock();
                if s.closed != Closed::Open {
                    if env.is_message() && s.lost_after_close(env.seq) {
                        s.stats.discarded += 1;
                    }
                    return;
                }
                match self.0.policy {
                    QueuePolicy::Block { capacity } if s.buf.len() >= capacity.saturating_add(reserved) => {}
                    QueuePolicy::Block { .. } => {
                        s.push(env, reserved);
                        drop(s);
                        self.0.data.notify_one();
                        return;
                    }
                    QueuePolicy::DropOldest { capacity } => {
                        s.push_dropping(env, capacity, reserved);
                        drop(s);
                        self.0.data.notify_one();
                        return;
                    }
                }
            }
            // Single producer: a permit stored by a pop between the check and this await
            // wakes us immediately, so no wake-up is lost.
            self.0.space.notified().await;
        }
    }
}

impl Drop for EdgeTx {
    fn drop(&mut self) {
        self.0.lock().sender_closed = true;
        self.0.data.notify_one();
    }
}

/// Result of a non-blocking receive.
#[derive(Debug)]
pub(crate) enum TryRecv {
    Item(Envelope),
    Empty,
    Closed,
}

impl EdgeRx {
    /// The next envelope, or `None` once the producer is gone and the queue is empty.
    pub async fn recv(&self) -> Option<Envelope> {
        loop {
            match self.try_recv() {
                TryRecv::Item(e) => return Some(e),
                TryRecv::Closed => return None,
                TryRecv::Empty => self.0.data.notified().await,
            }
        }
    }

    pub fn try_recv(&self) -> TryRecv {
        let mut s = self.0.lock();
        if let Some(e) = s.buf.pop_front() {
            if e.is_message() {
                s.messages -= 1;
                s.stats.delivered += 1;
            }
            drop(s);
            self.0.space.notify_one();
            TryRecv::Item(e)
        } else if s.sender_closed {
            TryRecv::Closed
        } else {
            TryRecv::Empty
        }
    }

    /// Stop consuming after finishing every frame up to `last_frame`: what is still queued,
    /// or sent later, for a frame after it belongs to a frame that never ran and is not lost.
    pub fn complete(self, last_frame: Option<u64>) {
        self.close(Closed::Completed(last_frame));
    }

    fn close(&self, how: Closed) {
        let mut s = self.0.lock();
        if s.closed != Closed::Open {
            return;
        }
        s.closed = how;
        let lost = s.buf.iter().filter(|e| e.is_message() && s.lost_after_close(e.seq)).count() as u64;
        s.stats.discarded += lost;
        s.buf.clear();
        s.messages = 0;
        drop(s);
        self.0.space.notify_one();
    }
}

impl Drop for EdgeRx {
    fn drop(&mut self) {
        self.close(Closed::Abandoned);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Body, Header, Scalars};

    fn wm(seq: u64) -> Envelope {
        Envelope { seq, msg: None, born: Instant::now() }
    }

    fn msg(seq: u64) -> Envelope {
        let header = Header { seq, stamp: 0.0, frame_id: "t".into() };
        Envelope {
            seq,
            msg: Some(Arc::new(Message::new(header, Body::Scalars(Scalars::one("v", 0.0))))),
            born: Instant::now(),
        }
    }

    async fn drain(rx: &EdgeRx) -> Vec<(u64, bool)> {
        let mut got = Vec::new();
        while let Some(e) = rx.recv().await {
            got.push((e.seq, e.is_message()));
        }
        got
    }

    #[tokio::test]
    async fn drop_oldest_counts_every_dropped_message() {
        let (tx, rx, probe) = edge(QueuePolicy::DropOldest { capacity: 2 }, 0);
        for k in 0..5 {
            tx.send(msg(k)).await;
        }
        drop(tx);
        assert_eq!(drain(&rx).await, vec![(3, true), (4, true)]);
        let stats = probe.stats();
        assert_eq!((stats.sent, stats.dropped, stats.delivered), (5, 3, 2));
    }

    #[tokio::test]
    async fn dropping_queue_coalesces_watermarks_and_never_counts_them() {
        // A gate's pattern: one message, then four watermarks, into a consumer that is away.
        let (tx, rx, probe) = edge(QueuePolicy::DropOldest { capacity: 1 }, 0);
        for k in 0..10 {
            tx.send(if k % 5 == 0 { msg(k) } else { wm(k) }).await;
        }
        drop(tx);
        // Message 0 was displaced by message 5; watermarks 1..=3 and 6..=8 were coalesced.
        assert_eq!(drain(&rx).await, vec![(4, false), (5, true), (9, false)]);
        let stats = probe.stats();
        assert_eq!((stats.sent, stats.dropped, stats.delivered), (2, 1, 1));
    }

    #[tokio::test]
    async fn a_delay_reserves_its_slots_in_a_dropping_queue() {
        // Feedback with `delay: 3, queue: latest`: the consumer takes one frame for each the
        // producer sends, three behind. Nothing may drop.
        let (tx, rx, probe) = edge(QueuePolicy::DropOldest { capacity: 1 }, 3);
        let mut got = Vec::new();
        for k in 0..12 {
            let e = rx.recv().await.unwrap();
            got.push((e.seq, e.is_message()));
            tx.send(msg(k)).await;
        }
        let expected: Vec<(u64, bool)> = (0..12).map(|k| (k, k >= 3)).collect();
        assert_eq!(got, expected);
        let stats = probe.stats();
        assert_eq!((stats.dropped, stats.max_depth), (0, 0));
        // The run ends after frame 11: frames 12..=14 never run, so nothing was lost.
        rx.complete(Some(11));
        assert_eq!(probe.stats().discarded, 0);
    }

    #[tokio::test]
    async fn abandoned_consumer_discards_what_is_left() {
        let (tx, rx, probe) = edge(QueuePolicy::Block { capacity: 4 }, 0);
        tx.send(msg(0)).await;
        tx.send(wm(1)).await;
        tx.send(msg(2)).await;
        drop(rx);
        tx.send(msg(3)).await;
        let stats = probe.stats();
        assert_eq!((stats.sent, stats.discarded, stats.delivered), (3, 3, 0));
    }

    #[tokio::test]
    async fn delay_shifts_and_seeds_watermarks() {
        let (tx, rx, _) = edge(QueuePolicy::Block { capacity: 1 }, 2);
        tx.send(msg(0)).await;
        drop(tx);
        assert_eq!(drain(&rx).await, vec![(0, false), (1, false), (2, true)]);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn block_applies_backpressure_without_loss() {
        let (tx, rx, probe) = edge(QueuePolicy::Block { capacity: 2 }, 0);
        let producer = tokio::spawn(async move {
            for k in 0..1000 {
                tx.send(msg(k)).await;
            }
        });
        let mut expected = 0;
        while let Some(e) = rx.recv().await {
            assert_eq!(e.seq, expected);
            expected += 1;
        }
        producer.await.unwrap();
        assert_eq!(expected, 1000);
        assert!(probe.stats().max_depth <= 2);
        assert_eq!(probe.stats().dropped, 0);
    }
}
