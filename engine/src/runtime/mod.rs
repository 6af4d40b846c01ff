//! Executes a [`ResolvedGraph`] on tokio: one task per node, one bounded queue per edge.
//!
//! # Frame semantics
//! Sources number their frames `0, 1, 2, …`. For every frame, every node emits on every
//! output port exactly one envelope: the message, or a watermark "nothing for frame k". A
//! node fires frame `k` once each lockstep input has delivered its envelope for `k` (or has
//! moved past it, when a dropping queue lost it), so gated and optional inputs never leave a
//! join waiting and lockstep runs are exactly reproducible.
//!
//! - `join: lockstep`: the input's message of frame `k`, or absent.
//! - `join: latest`: the newest message at or before `k`. In lockstep (offline) runs the node
//!   waits until the producer's frontier reaches `k`, so the result is deterministic; with
//!   `--realtime` it takes whatever has arrived, so a slow detector never stalls tracking.
//! - `delay: d`: frame `k` of the producer is frame `k + d` of the consumer (feedback).
//!
//! A node whose required input is absent skips the frame (counted) and emits watermarks.
//!
//! Submodules: `edge` (the queue), `node` (the per-node task), `metrics` (the report).

mod edge;
mod metrics;
mod monitor;
mod node;
mod recorders;
pub mod remote;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use rand_core::SeedableRng;
use tokio::sync::Notify;

pub use edge::EdgeStats;
pub use metrics::{EdgeReport, Failure, LatencyStats, NodeReport, ParameterChange, RunReport, RunStatus};
pub use monitor::{AppliedSet, Echo, EchoListener, LiveSet, LiveState, Monitor, NodeSnapshot, Snapshot};
pub use node::ScheduledSet;

use crate::op::{Context, Instance, OpError};
use crate::sink::{RunInfo, Sink, SinkError};
use crate::spec::{RecordPolicy, ResolvedGraph};
use recorders::sink_threads;

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Pace sources at sensor rate and let `latest` joins take what has arrived.
    pub realtime: bool,
    /// Stop sources after this many frames.
    pub max_frames: Option<u64>,
    /// Output folder handed to operators.
    pub out_dir: Option<PathBuf>,
    /// Requests a graceful stop (Ctrl-C).
    pub stop: StopHandle,
    /// Frames produced so far (max over sources), for progress display.
    pub progress: Arc<AtomicU64>,
    /// Length of the longest source, if known, set once sources are built.
    pub total_frames: Arc<AtomicU64>,
    /// After a stop request, how long nodes may take to finish their in-flight frames before
    /// they are cancelled (default [`DEFAULT_STOP_GRACE`]). Recordings are closed either way.
    pub stop_grace: Option<Duration>,
    /// Run only this machine's share of a graph that spans machines (`None`: every node
    /// here, `machines:` or not).
    pub placement: Option<remote::Placement>,
    /// Parameter changes from a frame on (`run --set-at`), validated against the graph.
    pub schedule: Vec<ScheduledSet>,
    /// The live view (`dynaflow top`, `set`, `echo`): the run registers its nodes with it.
    pub monitor: Monitor,
}

/// How long a stopped run waits for in-flight frames before cancelling the nodes.
pub const DEFAULT_STOP_GRACE: Duration = Duration::from_secs(10);

/// Shared flag to stop a run gracefully: sources stop producing, in-flight frames finish,
/// sinks close.
#[derive(Clone, Debug, Default)]
pub struct StopHandle(Arc<(AtomicBool, Notify)>);

impl StopHandle {
    /// Ask the run to stop.
    pub fn request(&self) {
        self.0.0.store(true, Ordering::SeqCst);
        self.0.1.notify_waiters();
    }
    /// Whether a stop was requested.
    pub fn requested(&self) -> bool {
        self.0.0.load(Ordering::SeqCst)
    }
    /// Resolves once a stop is requested.
    pub async fn wait(&self) {
        loop {
            let notified = self.0.1.notified();
            if self.requested() {
                return;
            }
            notified.await;
        }
    }
}

/// Why a run could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunError {
    /// An operator could not be constructed (bad config, missing file, …).
    #[error("node `{node}`: {source}")]
    Build {
        /// Node id.
        node: String,
        /// Cause.
        #[source]
        source: OpError,
    },
    /// A sink could not open its output.
    #[error(transparent)]
    Sink(#[from] SinkError),
    /// The machines of a split graph could not be joined up.
    #[error("{0}")]
    Remote(String),
}

/// Mix the graph seed and the node id into the node's RNG seed (SplitMix64 finaliser over an
/// FNV-1a hash of the id), so adding a node never changes another node's random stream.
pub fn node_seed(graph_seed: u64, node: &str) -> u64 {
    // Byte-wise FNV-1a of the length-prefixed id (what the content digest was before scheme
    // 2; kept so every node's random stream, and so every documented result, stays the same).
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in (node.len() as u64).to_le_bytes().iter().chain(node.as_bytes()) {
        h = (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    // One SplitMix64 step from `graph_seed ^ h`.
    dynaflow_base::rng::SplitMix64::new(graph_seed ^ h).next_u64()
}

/// A local port read by other machines: the edge the wire drains, its counters, and the
/// machines that consume it.
type Outgoing = (edge::EdgeRx, edge::EdgeProbe, Vec<Arc<str>>);

/// Run `graph` to completion (or stop/failure). Sinks are opened first and always closed.
pub async fn run(graph: &ResolvedGraph, options: RunOptions, sinks: Vec<Box<dyn Sink>>) -> Result<RunReport, RunError> {
    let started = Instant::now();
    // The nodes this process runs: all of them, or this machine's share.
    let local: Vec<bool> = graph
        .nodes
        .iter()
        .map(|n| options.placement.as_ref().is_none_or(|p| n.machine.as_deref() == Some(&*p.machine)))
        .collect();
    if let Some(p) = &options.placement
        && !graph.machines.iter().any(|(m, _)| *m == p.machine)
    {
        let names: Vec<&str> = graph.machines.iter().map(|(m, _)| &**m).collect();
        return Err(RunError::Remote(format!(
            "the graph has no machine `{}` (its machines: {})",
            p.machine,
            if names.is_empty() { "none".to_owned() } else { names.join(", ") }
        )));
    }
    // Build every operator before anything runs: a missing file fails fast, naming the node.
    let mut instances: Vec<Option<Instance>> = Vec::new();
    for (node, here) in graph.nodes.iter().zip(&local) {
        if node.disabled || !here {
            instances.push(None);
            continue;
        }
        let inst =
            (node.op.build)(&node.params).map_err(|source| RunError::Build { node: node.id.to_string(), source })?;
        if let Instance::Source(src) = &inst
            && let Some(len) = src.len_hint()
        {
            let len = options.max_frames.map_or(len, |m| m.min(len));
            options.total_frames.fetch_max(len, Ordering::Relaxed);
        }
        instances.push(Some(inst));
    }

    let mut info = RunInfo::new(graph, options.realtime);
    info.machine = options.placement.as_ref().map(|p| p.machine.to_string());
    // Without sinks nothing is tapped, so an unrecorded run pays nothing for recording.
    let recording = !sinks.is_empty();
    let (tap_tx, sink_handles) = sink_threads(sinks, &info)?;
    let failures: Arc<Mutex<Vec<Failure>>> = Arc::default();

    // Wire edges.
    let mut senders: Vec<Vec<Vec<edge::EdgeTx>>> =
        graph.nodes.iter().map(|n| n.outputs.iter().map(|_| Vec::new()).collect()).collect();
    let mut receivers: Vec<Vec<Option<edge::EdgeRx>>> =
        graph.nodes.iter().map(|n| n.inputs.iter().map(|_| None).collect()).collect();
    let mut probes = Vec::new();
    // Edges to and from other machines, by producer port: the local edges a subscription
    // feeds, and the remote consumers of a local port with the local edge the wire drains.
    let mut incoming: std::collections::BTreeMap<(usize, usize), Vec<edge::EdgeTx>> = Default::default();
    let mut outgoing: std::collections::BTreeMap<(usize, usize), Outgoing> = Default::default();
    for e in &graph.edges {
        let (from_here, to_here) = (local[e.from_node], local[e.to_node]);
        let policy = e.effective_queue(options.realtime);
        if !from_here && to_here {
            let (tx, rx, probe) = edge::edge(policy, e.delay);
            if let Some(slot) = receivers.get_mut(e.to_node).and_then(|r| r.get_mut(e.to_port)) {
                *slot = Some(rx);
            }
            incoming.entry((e.from_node, e.from_port)).or_default().push(tx);
            probes.push(probe);
            continue;
        }
        if from_here && !to_here {
            let machine: Arc<str> = graph.nodes[e.to_node].machine.clone().unwrap_or_else(|| Arc::from(""));
            let entry = outgoing.entry((e.from_node, e.from_port)).or_insert_with(|| {
                // Lockstep: nothing is lost before the wire; real time: the consumer's policy.
                let queue = if options.realtime {
                    policy
                } else {
                    crate::spec::QueuePolicy::Block { capacity: crate::spec::DEFAULT_CAPACITY }
                };
                let (tx, rx, probe) = edge::edge(queue, 0);
                if let Some(slot) = senders.get_mut(e.from_node).and_then(|s| s.get_mut(e.from_port)) {
                    slot.push(tx);
                }
                (rx, probe, Vec::new())
            });
            if !entry.2.contains(&machine) {
                entry.2.push(machine);
            }
            probes.push(entry.1.clone());
            continue;
        }
        let (tx, rx, probe) = edge::edge(policy, e.delay);
        if from_here && to_here {
            if let Some(slot) = senders.get_mut(e.from_node).and_then(|s| s.get_mut(e.from_port)) {
                slot.push(tx);
            }
            if let Some(slot) = receivers.get_mut(e.to_node).and_then(|r| r.get_mut(e.to_port)) {
                *slot = Some(rx);
            }
        }
        probes.push(probe);
    }
    let mut bridges = Vec::new();
    if let Some(p) = &options.placement {
        let key = |(n, o): (usize, usize)| {
            let node = &graph.nodes[n];
            format!("{}/{}", node.id, node.outputs.get(o).map_or("?", |o| o.name))
        };
        let mut subscriptions = Vec::new();
        for &port in incoming.keys() {
            let from = graph.nodes[port.0].machine.clone().unwrap_or_else(|| Arc::from(""));
            let rx = p.wire.subscriber(&key(port), &from).await.map_err(RunError::Remote)?;
            subscriptions.push((key(port), rx));
        }
        p.wire.ready().await.map_err(RunError::Remote)?;
        for ((k, rx), txs) in subscriptions.into_iter().zip(std::mem::take(&mut incoming).into_values()) {
            bridges.push(tokio::spawn(bridge_in(k, rx, txs, failures.clone(), options.clone())));
        }
        for (port, (rx, _, to)) in std::mem::take(&mut outgoing) {
            let tx = p.wire.publisher(&key(port), &to).await.map_err(RunError::Remote)?;
            bridges.push(tokio::spawn(bridge_out(key(port), rx, tx, failures.clone(), options.stop.clone())));
        }
    }

    let stem: Arc<str> = crate::files::RunFiles::stem_of(&graph.name, graph.variant.as_deref()).into();
    let mut hooks = options.monitor.attach(graph, &local, &probes, &options);
    let mut tasks = Vec::new();
    for (i, (node, inst)) in graph.nodes.iter().zip(instances).enumerate() {
        if !local[i] {
            continue;
        }
        let seed = node_seed(graph.seed, &node.id);
        let ctx = Context {
            node: node.id.clone(),
            seed,
            rng: rand_chacha::ChaCha8Rng::seed_from_u64(seed),
            out_dir: options.out_dir.clone(),
            stem: stem.clone(),
            realtime: options.realtime,
            report: None,
        };
        let outputs = node::Outputs {
            ports: node
                .outputs
                .iter()
                .map(|o| (o.name, o.ty, if recording { o.record } else { RecordPolicy::None }))
                .collect(),
            senders: std::mem::take(senders.get_mut(i).unwrap_or(&mut Vec::new())),
            tap: tap_tx.clone(),
        };
        let mut schedule: Vec<ScheduledSet> =
            options.schedule.iter().filter(|s| *s.node == *node.id).cloned().collect();
        schedule.sort_by_key(|s| s.frame);
        let hook = hooks.get_mut(i).and_then(Option::take);
        let task = node::NodeTask {
            schedule,
            live: hook.as_ref().map_or_else(Arc::default, |h| h.metrics.clone()),
            echo: hook.as_ref().map(|h| h.echo.clone()),
            sets: hook.and_then(|h| h.sets),
            node: node.clone(),
            ctx,
            outputs,
            inputs: std::mem::take(receivers.get_mut(i).unwrap_or(&mut Vec::new())),
            joins: node
                .inputs
                .iter()
                .map(|inp| inp.edge.and_then(|e| graph.edges.get(e)).map(|e| (e.join, e.delay)))
                .collect(),
            failures: failures.clone(),
            options: options.clone(),
        };
        tasks.push(tokio::spawn(task.run(inst)));
    }
    drop(tap_tx);

    // A stop request lets sources end and in-flight frames drain. Should a node still not
    // finish (an operator stuck in a long call), cancel the rest after a grace period: the
    // first Ctrl-C always ends the run, and the recorders still close their files.
    let aborts: Vec<tokio::task::AbortHandle> = tasks.iter().map(tokio::task::JoinHandle::abort_handle).collect();
    let all = futures::future::join_all(tasks);
    tokio::pin!(all);
    let grace = options.stop_grace.unwrap_or(DEFAULT_STOP_GRACE);
    let results = tokio::select! {
        r = &mut all => r,
        () = async { options.stop.wait().await; tokio::time::sleep(grace).await } => {
            tracing::warn!("nodes still busy {:.1} s after the stop request: cancelling them", grace.as_secs_f64());
            for a in &aborts {
                a.abort();
            }
            all.await
        }
    };
    // The wire's tasks end once their streams have (or a peer is gone).
    for b in bridges {
        let _ = b.await;
    }
    let here: Vec<&crate::spec::ResolvedNode> =
        graph.nodes.iter().zip(&local).filter(|(_, l)| **l).map(|(n, _)| n).collect();
    let mut node_metrics = Vec::new();
    for (joined, node) in results.into_iter().zip(here.iter().copied()) {
        match joined {
            Ok(m) => node_metrics.push(m),
            Err(e) if e.is_cancelled() => {
                tracing::warn!(node = %node.id, "cancelled before finishing its in-flight frames");
                node_metrics.push(metrics::NodeMetrics::default());
            }
            Err(e) => {
                failures
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(Failure { node: node.id.to_string(), error: format!("task failed: {e}") });
                node_metrics.push(metrics::NodeMetrics::default());
            }
        }
    }
    let (mut sink_failures, mut sink_dropped, mut recorders) = (Vec::new(), 0, std::collections::BTreeMap::new());
    for handle in sink_handles {
        let joined = tokio::task::spawn_blocking(move || handle.join()).await.ok().and_then(Result::ok);
        match joined {
            Some(done) => {
                sink_failures.extend(done.failures);
                sink_dropped += done.lost;
                recorders.insert(done.name, done.report);
            }
            None => sink_failures.push(Failure { node: "sinks".into(), error: "a recorder thread panicked".into() }),
        }
    }

    let mut failures = std::mem::take(&mut *failures.lock().unwrap_or_else(PoisonError::into_inner));
    failures.extend(sink_failures);
    // A machine reports the edges that touch it (one from another machine is counted on the
    // consumer's side, where its queue is).
    let (touching, edge_reports): (Vec<&crate::spec::ResolvedEdge>, Vec<EdgeReport>) = graph
        .edges
        .iter()
        .zip(&probes)
        .filter(|(e, _)| local[e.to_node] || local[e.from_node])
        .map(|(e, p)| (e, EdgeReport { edge: graph.edge_label(e), stats: p.stats() }))
        .unzip();
    let nodes = graph
        .nodes
        .iter()
        .enumerate()
        .filter(|(i, _)| local[*i])
        .zip(node_metrics)
        .map(|((i, n), m)| {
            let inputs = touching.iter().zip(&edge_reports).filter(|(e, _)| e.to_node == i);
            let (max_queue, dropped) =
                inputs.fold((0, 0), |(q, d), (_, r)| (q.max(r.stats.max_depth), d + r.stats.dropped));
            NodeReport {
                node: n.id.to_string(),
                op: n.op.name.to_owned(),
                frames: m.frames,
                skipped: m.skipped,
                latency: m.latency.stats(),
                latency_ends: m.ends.report(m.frames),
                age: m.age.stats(),
                busy_s: m.busy.as_secs_f64(),
                rate_hz: m.rate_hz(),
                max_queue,
                dropped,
                parameter_changes: m.parameter_changes,
                report: m.report,
            }
        })
        .collect();
    let status = if !failures.is_empty() {
        RunStatus::Failed
    } else if options.stop.requested() {
        RunStatus::Interrupted
    } else {
        RunStatus::Completed
    };
    options.monitor.finish(status);
    Ok(RunReport {
        graph: graph.name.clone(),
        variant: graph.variant.clone(),
        oracle: graph.oracle.clone(),
        seed: graph.seed,
        realtime: options.realtime,
        status,
        frames: options.progress.load(Ordering::Relaxed),
        wall_s: started.elapsed().as_secs_f64(),
        dropped: edge_reports.iter().map(|e| e.stats.dropped).sum(),
        edges: edge_reports,
        nodes,
        sink_dropped,
        recorders,
        failures,
    })
}

/// Install SIGINT/SIGTERM handlers: the first signal requests a graceful stop, a second one
/// calls `abort` (the CLI exits with status 130; the engine never ends the process).
pub fn stop_on_signals(stop: StopHandle, abort: impl FnOnce() + Send + 'static) {
    tokio::spawn(async move {
        #[cfg(unix)]
        {
            use tokio::signal::unix::{SignalKind, signal};
            let (Ok(mut int), Ok(mut term)) = (signal(SignalKind::interrupt()), signal(SignalKind::terminate())) else {
                tracing::warn!("cannot install signal handlers; Ctrl-C will kill the run abruptly");
                return;
            };
            for round in 0..2 {
                tokio::select! {
                    _ = int.recv() => {}
                    _ = term.recv() => {}
                }
                if round == 0 {
                    tracing::warn!(
                        "interrupted: finishing in-flight frames and closing recordings (signal again to abort)"
                    );
                    stop.request();
                } else {
                    tracing::error!("aborted");
                    abort();
                    return;
                }
            }
        }
        #[cfg(not(unix))]
        {
            if tokio::signal::ctrl_c().await.is_ok() {
                stop.request();
            }
        }
    });
}

/// A broken stream between machines: a failure of the run (reported as `wire:<key>`), which
/// then stops.
fn wire_failure(failures: &Mutex<Vec<Failure>>, stop: &StopHandle, key: &str, error: String) {
    tracing::error!("{error}");
    failures.lock().unwrap_or_else(PoisonError::into_inner).push(Failure { node: format!("wire:{key}"), error });
    stop.request();
}

/// Feed the local edges of one incoming stream until it ends; a broken stream (the producing
/// machine gone, a frame that does not decode) fails the run and stops it.
async fn bridge_in(
    key: String,
    mut rx: Box<dyn remote::WireRx>,
    txs: Vec<edge::EdgeTx>,
    failures: Arc<Mutex<Vec<Failure>>>,
    options: RunOptions,
) {
    let fail = |error: String| wire_failure(&failures, &options.stop, &key, error);
    loop {
        let frame = match rx.recv().await {
            Ok(f) => f,
            Err(e) => return fail(format!("stream `{key}`: {e}")),
        };
        match remote::decode_frame(&frame) {
            Ok(remote::Frame::End) => return,
            Ok(remote::Frame::Envelope(seq, msg)) => {
                let msg = msg.map(|m| Arc::new(*m));
                // Age is measured from the arrival on this machine (clocks differ).
                let born = Instant::now();
                for tx in &txs {
                    tx.send(edge::Envelope { seq, msg: msg.clone(), born }).await;
                }
                options.progress.fetch_max(seq + 1, Ordering::Relaxed);
            }
            Err(e) => return fail(format!("stream `{key}`: {e}")),
        }
    }
}

/// Send a local port's envelopes to the machines that consume it, then the end mark.
async fn bridge_out(
    key: String,
    rx: edge::EdgeRx,
    tx: Box<dyn remote::WireTx>,
    failures: Arc<Mutex<Vec<Failure>>>,
    stop: StopHandle,
) {
    while let Some(env) = rx.recv().await {
        if let Err(e) = tx.send(remote::encode_frame(env.seq, env.msg.as_deref())).await {
            return wire_failure(&failures, &stop, &key, format!("stream `{key}`: {e}"));
        }
    }
    if let Err(e) = tx.send(remote::end_frame()).await {
        tracing::warn!("stream `{key}`: end mark not delivered: {e}");
    }
}
