//! Recorders observe every recorded port without operators knowing.
//!
//! The runtime forwards each recorded message to a dedicated sink thread through a bounded
//! channel; sinks (rerun, MCAP, message log, …) implement [`Sink`]. A sink that fails is
//! reported once, closed, and the run is marked failed; the others keep recording.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, PoisonError};

use crate::msg::{Message, PortType};
use crate::spec::ResolvedGraph;

/// Why a sink failed.
#[derive(Debug, thiserror::Error)]
#[error("{sink}: {message}")]
pub struct SinkError {
    /// The sink's name.
    pub sink: String,
    /// What went wrong (file named where there is one).
    pub message: String,
}

impl SinkError {
    /// A new error.
    pub fn new(sink: impl Into<String>, message: impl Into<String>) -> Self {
        Self { sink: sink.into(), message: message.into() }
    }
}

/// Provenance of a run, handed to sinks when they open.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunInfo {
    /// Graph name.
    pub graph: String,
    /// Variant, if any.
    pub variant: Option<String>,
    /// `Some` for an oracle run (decisions that read ground truth: `node/port <- producer.port`).
    pub oracle: Option<Vec<String>>,
    /// Effective seed.
    pub seed: u64,
    /// The graph file text.
    pub graph_yaml: String,
    /// Resolved parameters per node.
    pub params: BTreeMap<String, serde_json::Value>,
    /// dynaflow version.
    pub version: String,
    /// git commit dynaflow was built from (`-dirty` if the tree had changes).
    pub git_commit: String,
    /// Realtime or lockstep.
    pub realtime: bool,
    /// Recorded ports: `node/port` → type.
    pub ports: BTreeMap<String, PortType>,
    /// The ports that carry ground truth (`node/port`): emitted by a ground-truth output or
    /// derived from one.
    pub ground_truth_ports: std::collections::BTreeSet<String>,
    /// The camera each pose stream is seen through: pose port (`node/port`) -> camera-info
    /// port, the node's own camera-info output (a source's ground truth) or what feeds its
    /// camera-info input (a tracker's estimate). Poses of a node with neither have none.
    pub cameras: BTreeMap<String, String>,
    /// The machine this process ran, in a graph split over machines (`machines:`); its
    /// recordings hold that machine's nodes only (`dynaflow merge` joins them).
    pub machine: Option<String>,
    /// The resolved graph's digest ([`ResolvedGraph::digest`]): recordings of one run's
    /// machines share it.
    pub graph_digest: String,
    /// The point labels tracking decides with (`node/port` of each point-labels output that
    /// feeds a node with a pose output): what a viewer draws on the camera image.
    pub decisions: Vec<String>,
    /// The estimated (not ground-truth) pose outputs, `node/port` in graph order: the first is
    /// the trajectory a run reports first, and the camera a ROS recording puts in its tf tree.
    pub estimates: Vec<String>,
}

/// The point-labels outputs that feed a tracker (a node with a pose output).
fn decisions(graph: &ResolvedGraph) -> Vec<String> {
    let mut out = Vec::new();
    for e in &graph.edges {
        let (Some(from), Some(to)) = (graph.nodes.get(e.from_node), graph.nodes.get(e.to_node)) else { continue };
        let Some(port) = from.outputs.get(e.from_port) else { continue };
        if port.ty == PortType::PointLabels && !to.disabled && to.outputs.iter().any(|o| o.ty == PortType::Pose) {
            let name = format!("{}/{}", from.id, port.name);
            if !out.contains(&name) {
                out.push(name);
            }
        }
    }
    out
}

/// For each pose output of `graph`, the camera-info port it is seen through (see
/// [`RunInfo::cameras`]).
fn pose_cameras(graph: &ResolvedGraph) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for n in &graph.nodes {
        let own = n.outputs.iter().find(|o| o.ty == PortType::CameraInfo).map(|o| format!("{}/{}", n.id, o.name));
        let fed = n.inputs.iter().filter(|i| i.ty == PortType::CameraInfo).find_map(|i| {
            let e = graph.edges.get(i.edge?)?;
            let from = graph.nodes.get(e.from_node)?;
            Some(format!("{}/{}", from.id, from.outputs.get(e.from_port)?.name))
        });
        let Some(camera) = own.or(fed) else { continue };
        for o in n.outputs.iter().filter(|o| o.ty == PortType::Pose) {
            out.insert(format!("{}/{}", n.id, o.name), camera.clone());
        }
    }
    out
}

impl RunInfo {
    /// Provenance of `graph`.
    pub fn new(graph: &ResolvedGraph, realtime: bool) -> Self {
        Self {
            graph: graph.name.clone(),
            variant: graph.variant.clone(),
            oracle: graph.oracle.clone(),
            seed: graph.seed,
            graph_yaml: graph.source_text.to_string(),
            params: graph
                .nodes
                .iter()
                .map(|n| (n.id.to_string(), serde_json::Value::Object(n.params.as_map().clone())))
                .collect(),
            version: env!("CARGO_PKG_VERSION").to_owned(),
            git_commit: env!("DYNAFLOW_GIT_COMMIT").to_owned(),
            realtime,
            ports: graph
                .nodes
                .iter()
                .flat_map(|n| n.outputs.iter().map(move |o| (format!("{}/{}", n.id, o.name), o.ty)))
                .collect(),
            ground_truth_ports: graph
                .nodes
                .iter()
                .flat_map(|n| n.outputs.iter().filter(|o| o.ground_truth).map(move |o| format!("{}/{}", n.id, o.name)))
                .collect(),
            cameras: pose_cameras(graph),
            machine: None,
            graph_digest: format!("{:016x}", graph.digest()),
            decisions: decisions(graph),
            estimates: graph
                .nodes
                .iter()
                .flat_map(|n| {
                    n.outputs
                        .iter()
                        .filter(|o| o.ty == PortType::Pose && !o.ground_truth)
                        .map(move |o| format!("{}/{}", n.id, o.name))
                })
                .collect(),
        }
    }
}

impl RunInfo {
    /// Provenance as string pairs (MCAP metadata).
    pub fn to_strings(&self) -> BTreeMap<String, String> {
        BTreeMap::from([
            ("graph".to_owned(), self.graph.clone()),
            ("variant".to_owned(), self.variant.clone().unwrap_or_default()),
            // `true` with the decisions that read ground truth, else `false`.
            (
                "oracle".to_owned(),
                self.oracle.as_ref().map_or_else(|| "false".to_owned(), |u| format!("true: {}", u.join("; "))),
            ),
            ("seed".to_owned(), self.seed.to_string()),
            ("graph_yaml".to_owned(), self.graph_yaml.clone()),
            ("params".to_owned(), serde_json::to_string(&self.params).unwrap_or_default()),
            ("dynaflow_version".to_owned(), self.version.clone()),
            ("git_commit".to_owned(), self.git_commit.clone()),
            ("realtime".to_owned(), self.realtime.to_string()),
            ("digest".to_owned(), crate::msg::DIGEST_SCHEME.to_owned()),
            ("machine".to_owned(), self.machine.clone().unwrap_or_default()),
            ("graph_digest".to_owned(), self.graph_digest.clone()),
            // Comma-separated `node/port`: the point labels tracking decides with.
            ("decisions".to_owned(), self.decisions.join(",")),
            // Comma-separated `/node/port` topics that carry ground truth (`mcap_replay` keeps
            // the mark on them).
            (
                "ground_truth_topics".to_owned(),
                self.ground_truth_ports.iter().map(|p| format!("/{p}")).collect::<Vec<_>>().join(","),
            ),
        ])
    }
}

/// A recorder.
pub trait Sink: Send {
    /// Short name for messages ("jsonl", "rerun", "mcap").
    fn name(&self) -> &str;
    /// Called once before the first message.
    fn open(&mut self, _info: &RunInfo) -> Result<(), SinkError> {
        Ok(())
    }
    /// One recorded message of `node.port`.
    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError>;
    /// The same, given the shared message: a sink that hands messages to another thread
    /// (the live viewer stream) keeps the `Arc` instead of copying pixels. Defaults to `record`.
    fn record_shared(&mut self, node: &str, port: &str, msg: &Arc<Message>) -> Result<(), SinkError> {
        self.record(node, port, msg)
    }
    /// A parameter of `node` changed while running (`run --set-at`, `dynaflow set`), from frame
    /// `change.frame` on, at sensor time `stamp`: a marker on the recording's timeline. Ignored
    /// by default.
    fn parameter_change(
        &mut self,
        _node: &str,
        _change: &crate::runtime::ParameterChange,
        _stamp: f64,
    ) -> Result<(), SinkError> {
        Ok(())
    }
    /// Called once at the end, also after an interrupt or an operator failure. Must leave a
    /// complete, valid file.
    fn close(&mut self) -> Result<(), SinkError>;
    /// What the recording cost (after `close`): file size, bytes and drops per port.
    fn report(&self) -> SinkReport {
        SinkReport::default()
    }
}

/// What one recorder wrote, in the run summary's `recorders`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SinkReport {
    /// The file written, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<String>,
    /// Its size in bytes (after the container's compression).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file_bytes: Option<u64>,
    /// `file_bytes` per frame of the run (set with the run's frame count).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes_per_frame: Option<f64>,
    /// `node/port` → what the recorder took of it.
    pub ports: BTreeMap<String, PortReport>,
}

/// One port in one recorder.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PortReport {
    /// Messages written.
    pub messages: u64,
    /// Their encoded bytes, before the container's compression (0 where a recorder does not
    /// measure it).
    pub bytes: u64,
    /// Messages this recorder could not deliver (a live viewer that fell behind), counted.
    pub dropped: u64,
    /// `bytes` per frame of the run (set with the run's frame count).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bytes_per_frame: Option<f64>,
}

/// `(node, port, message)`.
pub type Recorded = (String, String, Arc<Message>);

/// Keeps every recorded message in memory (tests, in-process comparisons).
#[derive(Clone, Debug, Default)]
pub struct MemorySink {
    /// `(node, port, message)` in arrival order.
    pub messages: Arc<Mutex<Vec<Recorded>>>,
    /// Whether `close` was called.
    pub closed: Arc<Mutex<bool>>,
}

impl MemorySink {
    /// Messages of `node.port`, in order.
    pub fn port(&self, node: &str, port: &str) -> Vec<Arc<Message>> {
        self.messages
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .iter()
            .filter(|(n, p, _)| n == node && p == port)
            .map(|(_, _, m)| m.clone())
            .collect()
    }
}

impl Sink for MemorySink {
    fn name(&self) -> &str {
        "memory"
    }
    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        self.messages.lock().unwrap_or_else(PoisonError::into_inner).push((
            node.to_owned(),
            port.to_owned(),
            Arc::new(msg.clone()),
        ));
        Ok(())
    }
    fn close(&mut self) -> Result<(), SinkError> {
        *self.closed.lock().unwrap_or_else(PoisonError::into_inner) = true;
        Ok(())
    }
}

/// Per-port message count and order-sensitive content digest: two runs recorded the same
/// data on a port iff both agree.
#[derive(Clone, Debug, Default)]
pub struct DigestSink {
    /// `node/port` → (count, digest).
    pub ports: Arc<Mutex<BTreeMap<String, (u64, u64)>>>,
}

/// One port's messages and their digest, as the run summary's `digests` lists them.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PortDigest {
    /// Messages on the port.
    pub count: u64,
    /// Their order-sensitive content digest, 16 hex digits.
    pub digest: String,
}

impl DigestSink {
    /// A snapshot, by `node/port`.
    pub fn snapshot(&self) -> BTreeMap<String, PortDigest> {
        let ports = self.ports.lock().unwrap_or_else(PoisonError::into_inner);
        ports
            .iter()
            .map(|(k, (count, digest))| (k.clone(), PortDigest { count: *count, digest: format!("{digest:016x}") }))
            .collect()
    }
}

impl Sink for DigestSink {
    fn name(&self) -> &str {
        "digest"
    }
    fn record(&mut self, node: &str, port: &str, msg: &Message) -> Result<(), SinkError> {
        let mut ports = self.ports.lock().unwrap_or_else(PoisonError::into_inner);
        let entry = ports.entry(format!("{node}/{port}")).or_insert((0, 0xcbf2_9ce4_8422_2325));
        entry.0 += 1;
        let mut d = crate::msg::Digest::new();
        d.u64(entry.1);
        d.u64(msg.digest());
        entry.1 = d.finish();
        Ok(())
    }
    fn close(&mut self) -> Result<(), SinkError> {
        Ok(())
    }
    /// Messages per port (no file: the digests go into the summary's `digests`).
    fn report(&self) -> SinkReport {
        let ports = self.ports.lock().unwrap_or_else(PoisonError::into_inner);
        SinkReport {
            ports: ports
                .iter()
                .map(|(k, (count, _))| (k.clone(), PortReport { messages: *count, ..PortReport::default() }))
                .collect(),
            ..SinkReport::default()
        }
    }
}
