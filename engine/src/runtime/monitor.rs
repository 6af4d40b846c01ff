//! The live view of a running graph, off the data path: what `dynaflow top` shows, where
//! `dynaflow set` changes a parameter and where `dynaflow echo` and `hz` listen.
//!
//! A [`Monitor`] is handed to [`super::run`] in [`super::RunOptions`]; the run registers its
//! nodes with it once the graph is wired. Each node task keeps its counters under a mutex the
//! monitor can read (locked once per frame by the task, uncontended unless a snapshot is being
//! taken), so a [`Snapshot`] needs nothing from the data path and attaching a viewer changes
//! nothing a node computes. A parameter change travels to its node on its own channel and is
//! applied between two frames, at the first frame the node computes after it arrived; the
//! frame it took effect at is recorded (the summary's `parameter_changes`), so `run --set-at`
//! replays the run exactly. A port is summarised for `echo` only while someone listens.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use tokio::sync::{broadcast, mpsc, oneshot, watch};

use super::edge::EdgeProbe;
use super::metrics::{LatencyStats, NodeMetrics, RunStatus};
use crate::spec::ResolvedGraph;

/// A parameter change on its way to a running node: applied before the next frame the node
/// computes; `applied` answers the frame it took effect at.
#[derive(Debug)]
pub struct LiveSet {
    /// The parameter (validated as tunable by the caller).
    pub param: String,
    /// The value, as validation resolved it.
    pub value: serde_json::Value,
    /// The frame the node first computed with it, or why it did not take it.
    pub applied: oneshot::Sender<Result<AppliedSet, String>>,
}

/// A change a node took.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AppliedSet {
    /// The first frame computed with the new value.
    pub frame: u64,
    /// The value before.
    pub old: serde_json::Value,
    /// And after.
    pub new: serde_json::Value,
}

/// One message of a port someone listens to (`dynaflow echo`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Echo {
    /// Node id.
    pub node: String,
    /// Output port.
    pub port: String,
    /// Frame.
    pub seq: u64,
    /// Sensor time, seconds.
    pub stamp: f64,
    /// Seconds since the run started when the node emitted it.
    pub at_s: f64,
    /// Sizes and small values ([`crate::msg::Message::summary`]).
    pub summary: serde_json::Value,
}

/// How many echoed messages wait for a slow listener before it misses some (and is told how
/// many).
const ECHO_CAPACITY: usize = 1024;

/// The handle a run and its viewers share (cheap to clone; `Default` is a monitor no run has
/// attached yet).
#[derive(Clone, Debug, Default)]
pub struct Monitor(Arc<Inner>);

#[derive(Debug, Default)]
struct Inner {
    live: Mutex<Option<Live>>,
    /// The other machines' latest snapshots in a split run, by machine (shared over the wire).
    peers: Mutex<std::collections::BTreeMap<String, Snapshot>>,
    /// `Some(status)` once the run has ended.
    ended: Mutex<Option<watch::Sender<Option<RunStatus>>>>,
}

#[derive(Debug)]
struct Live {
    graph: String,
    variant: Option<String>,
    machine: Option<String>,
    started: Instant,
    progress: Arc<AtomicU64>,
    total: Arc<AtomicU64>,
    nodes: Vec<LiveNode>,
    echo: broadcast::Sender<Echo>,
    status: Option<RunStatus>,
}

#[derive(Debug)]
struct LiveNode {
    id: Arc<str>,
    op: &'static str,
    metrics: Arc<Mutex<NodeMetrics>>,
    /// The node's input edges (queue depth now, drops).
    inputs: Vec<EdgeProbe>,
    /// `None`: a source, a disabled node, or one on another machine.
    sets: Option<mpsc::UnboundedSender<LiveSet>>,
    /// Per output port: its name and how many listeners it has.
    outputs: Vec<(&'static str, Arc<AtomicUsize>)>,
}

/// What a node task takes from the monitor.
pub(crate) struct NodeHooks {
    pub metrics: Arc<Mutex<NodeMetrics>>,
    pub sets: Option<mpsc::UnboundedReceiver<LiveSet>>,
    pub echo: EchoTap,
}

/// The node's side of `echo`: per output port a listener count, and the channel.
#[derive(Clone, Debug)]
pub(crate) struct EchoTap {
    pub listeners: Vec<Arc<AtomicUsize>>,
    pub tx: broadcast::Sender<Echo>,
    pub started: Instant,
}

impl EchoTap {
    /// Whether port `j` has a listener (one relaxed load: what an unwatched port pays).
    pub fn watched(&self, j: usize) -> bool {
        self.listeners.get(j).is_some_and(|l| l.load(Ordering::Relaxed) > 0)
    }
}

/// Lock, whatever a panicking holder left: counters stay readable.
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Where the run is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LiveState {
    /// Not wired yet (operators being built).
    Starting,
    /// Frames flowing.
    Running,
    /// Every node has finished; the counts are final (the summary's).
    Completed,
    /// Stopped by a signal; the counts are final.
    Interrupted,
    /// A node or a recorder failed; the counts are final.
    Failed,
}

/// One look at a running graph (`dynaflow top --json`).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct Snapshot {
    /// Graph name.
    pub graph: String,
    /// Variant.
    pub variant: Option<String>,
    /// This machine, in a run split over machines.
    pub machine: Option<String>,
    /// Where the run is.
    pub state: LiveState,
    /// Seconds since the run started.
    pub elapsed_s: f64,
    /// Frames the sources have produced (max over sources).
    pub frames: u64,
    /// The longest source's length, if known.
    pub total_frames: Option<u64>,
    /// Resident memory of the process, bytes (Linux).
    pub rss_bytes: Option<u64>,
    /// Per node on this machine, in graph order.
    pub nodes: Vec<NodeSnapshot>,
}

/// One node in a [`Snapshot`].
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct NodeSnapshot {
    /// Node id.
    pub node: String,
    /// Operator.
    pub op: String,
    /// Frames processed (sources: produced), as in the summary.
    pub frames: u64,
    /// Frames skipped, as in the summary.
    pub skipped: u64,
    /// Frames handled (processed or skipped) per second, as the summary's `rate_hz`.
    pub rate_hz: f64,
    /// Processing latency per frame.
    pub latency: LatencyStats,
    /// Time from the source's emission to this node's output.
    pub age: LatencyStats,
    /// Share of the elapsed time spent inside the operator, percent.
    pub busy_pct: f64,
    /// Messages queued on the node's inputs now.
    pub queue: usize,
    /// Largest queue depth so far over its inputs.
    pub max_queue: usize,
    /// Messages dropped on its inputs by queue policies.
    pub dropped: u64,
    /// The newest frame it handled.
    pub last_frame: Option<u64>,
    /// How many frames it is behind the sources (frames produced minus frames handled).
    pub lag_frames: u64,
    /// Parameters changed while running, so far.
    pub parameter_changes: usize,
}

impl Monitor {
    /// A monitor for one run.
    pub fn new() -> Self {
        Self::default()
    }

    /// Register the nodes of this process once the run is wired: every node's counters, its
    /// input probes (`probes[i]` is `graph.edges[i]`'s), and a channel for parameter changes
    /// where the node can take them.
    pub(crate) fn attach(
        &self,
        graph: &ResolvedGraph,
        local: &[bool],
        probes: &[EdgeProbe],
        options: &super::RunOptions,
    ) -> Vec<Option<NodeHooks>> {
        let (echo, _) = broadcast::channel(ECHO_CAPACITY);
        let started = Instant::now();
        let mut nodes = Vec::new();
        let mut hooks = Vec::new();
        for (i, node) in graph.nodes.iter().enumerate() {
            if !local.get(i).copied().unwrap_or(false) {
                hooks.push(None);
                continue;
            }
            let metrics: Arc<Mutex<NodeMetrics>> = Arc::default();
            let inputs =
                graph.edges.iter().zip(probes).filter(|(e, _)| e.to_node == i).map(|(_, p)| p.clone()).collect();
            let takes_sets = !node.disabled && !node.op.tunable.is_empty();
            let (tx, rx) = if takes_sets {
                let (tx, rx) = mpsc::unbounded_channel();
                (Some(tx), Some(rx))
            } else {
                (None, None)
            };
            let outputs: Vec<(&'static str, Arc<AtomicUsize>)> =
                node.outputs.iter().map(|o| (o.name, Arc::default())).collect();
            hooks.push(Some(NodeHooks {
                metrics: metrics.clone(),
                sets: rx,
                echo: EchoTap {
                    listeners: outputs.iter().map(|(_, l)| l.clone()).collect(),
                    tx: echo.clone(),
                    started,
                },
            }));
            nodes.push(LiveNode { id: node.id.clone(), op: node.op.name, metrics, inputs, sets: tx, outputs });
        }
        *lock(&self.0.live) = Some(Live {
            graph: graph.name.clone(),
            variant: graph.variant.clone(),
            machine: options.placement.as_ref().map(|p| p.machine.to_string()),
            started,
            progress: options.progress.clone(),
            total: options.total_frames.clone(),
            nodes,
            echo,
            status: None,
        });
        hooks
    }

    /// The run has ended with `status`: snapshots are final from now on, and whoever waits on
    /// [`Monitor::ended`] is woken.
    pub fn finish(&self, status: RunStatus) {
        if let Some(live) = lock(&self.0.live).as_mut() {
            live.status = Some(status);
            // Nobody can change a parameter any more.
            for n in &mut live.nodes {
                n.sets = None;
            }
        }
        // Kept whether or not anyone waits now (`send` would drop it without a receiver).
        self.end_channel().send_replace(Some(status));
    }

    fn end_channel(&self) -> watch::Sender<Option<RunStatus>> {
        lock(&self.0.ended).get_or_insert_with(|| watch::channel(None).0).clone()
    }

    /// Resolves once the run has ended, with how it ended.
    pub async fn ended(&self) -> RunStatus {
        let mut rx = self.end_channel().subscribe();
        loop {
            if let Some(s) = *rx.borrow_and_update() {
                return s;
            }
            if rx.changed().await.is_err() {
                return RunStatus::Failed;
            }
        }
    }

    /// Whether the run has registered its nodes (its operators are built).
    pub fn attached(&self) -> bool {
        lock(&self.0.live).is_some()
    }

    /// What the run looks like now.
    pub fn snapshot(&self) -> Option<Snapshot> {
        let guard = lock(&self.0.live);
        let live = guard.as_ref()?;
        let elapsed = live.started.elapsed().as_secs_f64();
        let produced = live.progress.load(Ordering::Relaxed);
        let nodes = live
            .nodes
            .iter()
            .map(|n| {
                let m = lock(&n.metrics);
                let stats: Vec<_> = n.inputs.iter().map(EdgeProbe::stats).collect();
                NodeSnapshot {
                    node: n.id.to_string(),
                    op: n.op.to_owned(),
                    frames: m.frames,
                    skipped: m.skipped,
                    rate_hz: m.rate_hz(),
                    latency: m.latency.stats(),
                    age: m.age.stats(),
                    busy_pct: if elapsed > 0.0 { 100.0 * m.busy.as_secs_f64() / elapsed } else { 0.0 },
                    queue: n.inputs.iter().map(EdgeProbe::depth).sum(),
                    max_queue: stats.iter().map(|s| s.max_depth).max().unwrap_or(0),
                    dropped: stats.iter().map(|s| s.dropped).sum(),
                    last_frame: m.last_seq,
                    lag_frames: produced.saturating_sub(m.last_seq.map_or(0, |s| s + 1)),
                    parameter_changes: m.parameter_changes.len(),
                }
            })
            .collect();
        let state = match live.status {
            None => LiveState::Running,
            Some(RunStatus::Completed) => LiveState::Completed,
            Some(RunStatus::Interrupted) => LiveState::Interrupted,
            Some(RunStatus::Failed) => LiveState::Failed,
        };
        let total = live.total.load(Ordering::Relaxed);
        Some(Snapshot {
            graph: live.graph.clone(),
            variant: live.variant.clone(),
            machine: live.machine.clone(),
            state,
            elapsed_s: elapsed,
            frames: produced,
            total_frames: (total > 0).then_some(total),
            rss_bytes: resident_bytes(),
            nodes,
        })
    }

    /// Keep another machine's latest snapshot (a split run shares them over the wire), so a
    /// viewer attached here sees every machine.
    pub fn set_peer(&self, snapshot: Snapshot) {
        let Some(machine) = snapshot.machine.clone() else { return };
        lock(&self.0.peers).insert(machine, snapshot);
    }

    /// The other machines' latest snapshots, by machine name.
    pub fn peers(&self) -> Vec<Snapshot> {
        lock(&self.0.peers).values().cloned().collect()
    }

    /// Hand a validated change of `node.param` to the node; it answers with the frame it took
    /// effect at once it has.
    pub fn set(
        &self,
        node: &str,
        param: &str,
        value: serde_json::Value,
    ) -> oneshot::Receiver<Result<AppliedSet, String>> {
        let (tx, rx) = oneshot::channel();
        let guard = lock(&self.0.live);
        let why = match guard.as_ref().map(|l| (l.status, l.nodes.iter().find(|n| &*n.id == node))) {
            None => Some("the run has not started its nodes yet".to_owned()),
            Some((Some(status), _)) => Some(format!("the run has ended ({status:?})")),
            Some((None, None)) => Some(format!("node `{node}` does not run on this machine")),
            Some((None, Some(n))) => match &n.sets {
                None => Some(format!("node `{node}` takes no parameter changes while running (disabled, or a source)")),
                Some(s) => {
                    // A node that has finished dropped its end: answer through the change itself.
                    if let Err(e) = s.send(LiveSet { param: param.to_owned(), value, applied: tx }) {
                        let _ = e.0.applied.send(Err(format!("node `{node}` has finished its frames")));
                    }
                    None
                }
            },
        };
        drop(guard);
        if let Some(why) = why {
            let (tx, rx) = oneshot::channel();
            let _ = tx.send(Err(why));
            return rx;
        }
        rx
    }

    /// Listen to `node.port`: its messages from now on (a listener that falls more than
    /// [`ECHO_CAPACITY`] behind is told how many it missed). `Err` names the ports there are.
    pub fn echo(&self, node: &str, port: &str) -> Result<EchoListener, String> {
        let guard = lock(&self.0.live);
        let Some(live) = guard.as_ref() else { return Err("the run has not started its nodes yet".into()) };
        let Some(n) = live.nodes.iter().find(|n| &*n.id == node) else {
            let names: Vec<&str> = live.nodes.iter().map(|n| &*n.id).collect();
            return Err(format!("no node `{node}` runs here (its nodes: {})", names.join(", ")));
        };
        let Some((_, count)) = n.outputs.iter().find(|(p, _)| *p == port) else {
            let names: Vec<&str> = n.outputs.iter().map(|(p, _)| *p).collect();
            return Err(format!("node `{node}` has no output port `{port}` (its ports: {})", names.join(", ")));
        };
        count.fetch_add(1, Ordering::Relaxed);
        Ok(EchoListener {
            rx: live.echo.subscribe(),
            node: node.to_owned(),
            port: port.to_owned(),
            count: count.clone(),
        })
    }
}

/// A listener on one port (stops the port's summaries when the last one is dropped).
#[derive(Debug)]
pub struct EchoListener {
    rx: broadcast::Receiver<Echo>,
    node: String,
    port: String,
    count: Arc<AtomicUsize>,
}

impl EchoListener {
    /// The next message of the port: `Ok(Some)`, `Ok(None)` once the run is over, `Err(n)` when
    /// `n` messages were missed because the listener fell behind.
    pub async fn next(&mut self) -> Result<Option<Echo>, u64> {
        loop {
            match self.rx.recv().await {
                Ok(e) if e.node == self.node && e.port == self.port => return Ok(Some(e)),
                Ok(_) => {}
                Err(broadcast::error::RecvError::Closed) => return Ok(None),
                Err(broadcast::error::RecvError::Lagged(n)) => return Err(n),
            }
        }
    }
}

impl Drop for EchoListener {
    fn drop(&mut self) {
        self.count.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Resident set size of this process (`VmRSS`), where `/proc` has it.
fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
