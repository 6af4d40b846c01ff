//! A single-producer single-consumer queue with an explicit overflow policy and counters.
//!
//! tokio's channels cannot drop the *oldest* element or report their peak depth, and every
//! dropped message must be counted, so edges get their own small queue: a `VecDeque` under a
//! `std` mutex (never held across an await) and two `Notify`s.

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

#[derive(Debug, Default)]
struct State {
    buf: VecDeque<Envelope>,
    sender_closed: bool,
    receiver_closed: bool,
    max_depth: usize,
    dropped: u64,
    discarded: u64,
    delivered: u64,
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

/// Counters of one edge, read after (or during) a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct EdgeStats {
    /// Largest number of queued messages seen.
    pub max_depth: usize,
    /// Messages dropped by a `drop_oldest`/`latest` policy.
    pub dropped: u64,
    /// Messages sent after the consumer had stopped (only after an error or interrupt).
    pub discarded: u64,
    /// Messages handed to the consumer.
    pub delivered: u64,
}

/// Read-only handle on an edge's counters.
#[derive(Clone, Debug)]
pub(crate) struct EdgeProbe(Arc<Shared>);

impl EdgeProbe {
    pub fn stats(&self) -> EdgeStats {
        let s = self.0.lock();
        EdgeStats { max_depth: s.max_depth, dropped: s.dropped, discarded: s.discarded, delivered: s.delivered }
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
        state: Mutex::new(State { max_depth: buf.len(), buf, ..State::default() }),
        policy,
        delay: u64::from(delay),
        data: Notify::new(),
        space: Notify::new(),
    });
    (EdgeTx(shared.clone()), EdgeRx(shared.clone()), EdgeProbe(shared))
}

impl EdgeTx {
    /// Enqueue, waiting for space under `block`, dropping the oldest under `drop_oldest`.
    pub async fn send(&self, mut env: Envelope) {
        env.seq += self.0.delay;
        loop {
            {
                let mut s = self.0.lock();
                if s.receiver_closed {
                    s.discarded += 1;
                    return;
                }
                match self.0.policy {
                    // The delay's initial watermarks do not count against the capacity.
                    QueuePolicy::Block { capacity } if s.buf.len() >= capacity + self.0.delay as usize => {}
                    QueuePolicy::Block { .. } => {
                        push(&mut s, env);
                        drop(s);
                        self.0.data.notify_one();
                        return;
                    }
                    QueuePolicy::DropOldest { capacity } => {
                        while s.buf.len() >= capacity {
                            s.buf.pop_front();
                            s.dropped += 1;
                        }
                        push(&mut s, env);
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

fn push(s: &mut State, env: Envelope) {
    s.buf.push_back(env);
    s.max_depth = s.max_depth.max(s.buf.len());
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
            s.delivered += 1;
            drop(s);
            self.0.space.notify_one();
            TryRecv::Item(e)
        } else if s.sender_closed {
            TryRecv::Closed
        } else {
            TryRecv::Empty
        }
    }
}

impl Drop for EdgeRx {
    fn drop(&mut self) {
        let mut s = self.0.lock();
        s.receiver_closed = true;
        let left = s.buf.len() as u64;
        s.discarded += left;
        s.buf.clear();
        drop(s);
        self.0.space.notify_one();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(seq: u64) -> Envelope {
        Envelope { seq, msg: None, born: Instant::now() }
    }

    #[tokio::test]
    async fn drop_oldest_counts_every_drop() {
        let (tx, rx, probe) = edge(QueuePolicy::DropOldest { capacity: 2 }, 0);
        for k in 0..5 {
            tx.send(env(k)).await;
        }
        drop(tx);
        let mut got = Vec::new();
        while let Some(e) = rx.recv().await {
            got.push(e.seq);
        }
        assert_eq!(got, vec![3, 4]);
        let stats = probe.stats();
        assert_eq!(stats.dropped, 3);
        assert_eq!(stats.delivered, 2);
    }

    #[tokio::test]
    async fn delay_shifts_and_seeds_watermarks() {
        let (tx, rx, _) = edge(QueuePolicy::Block { capacity: 1 }, 2);
        tx.send(env(0)).await;
        drop(tx);
        let mut got = Vec::new();
        while let Some(e) = rx.recv().await {
            got.push(e.seq);
        }
        assert_eq!(got, vec![0, 1, 2]);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn block_applies_backpressure_without_loss() {
        let (tx, rx, probe) = edge(QueuePolicy::Block { capacity: 2 }, 0);
        let producer = tokio::spawn(async move {
            for k in 0..1000 {
                tx.send(env(k)).await;
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
