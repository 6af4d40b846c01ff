//! The validated graph the runtime executes.

use std::sync::Arc;

use super::{Join, QueuePolicy, RecordPolicy};
use crate::msg::PortType;
use crate::op::{OpSpec, Params};

/// A graph that passed validation: every op known, params typed, every input wired to an
/// existing output of a compatible type, every cycle broken by a delay.
#[derive(Clone, Debug)]
pub struct ResolvedGraph {
    /// Graph name.
    pub name: String,
    /// Effective seed (after `--seed`).
    pub seed: u64,
    /// Variant applied, if any.
    pub variant: Option<String>,
    /// The graph file's text, for provenance in recordings.
    pub source_text: Arc<str>,
    /// The graph file's path as given.
    pub source_name: String,
    /// `Some` when the graph (with its variant) is an oracle, one that decides with ground
    /// truth: the decisions that read it (`node/port <- producer.port`); every result of such a
    /// run is marked "(oracle)".
    pub oracle: Option<Vec<String>>,
    /// Nodes in file order (disabled ones included, marked).
    pub nodes: Vec<ResolvedNode>,
    /// Edges, one per wired input.
    pub edges: Vec<ResolvedEdge>,
    /// `machines:` (name, zenoh endpoint) in file order; empty for a one-process graph.
    pub machines: Vec<(Arc<str>, String)>,
}

/// A validated node.
#[derive(Clone, Debug)]
pub struct ResolvedNode {
    /// Node id.
    pub id: Arc<str>,
    /// Its operator.
    pub op: OpSpec,
    /// Parameters with defaults filled in.
    pub params: Params,
    /// Inputs in the operator's declaration order (unwired optional ones included).
    pub inputs: Vec<ResolvedInput>,
    /// Outputs in declaration order.
    pub outputs: Vec<ResolvedOutput>,
    /// Whether the node is disabled (emits nothing).
    pub disabled: bool,
    /// The machine that runs it (`None` when the graph has no `machines:`).
    pub machine: Option<Arc<str>>,
}

/// An input port of a node.
#[derive(Clone, Debug)]
pub struct ResolvedInput {
    /// Port name.
    pub name: &'static str,
    /// Declared type.
    pub ty: PortType,
    /// Whether the node is skipped for frames where it is absent.
    pub required: bool,
    /// Index into [`ResolvedGraph::edges`], if wired.
    pub edge: Option<usize>,
}

/// An output port of a node.
#[derive(Clone, Debug)]
pub struct ResolvedOutput {
    /// Port name.
    pub name: &'static str,
    /// Concrete type (`Any` only if fed by an untyped chain).
    pub ty: PortType,
    /// What the recorders get.
    pub record: RecordPolicy,
    /// Whether it carries ground truth (emits it, or derives from it); recorded as such, so
    /// a replay of the recording keeps the mark.
    pub ground_truth: bool,
}

/// A wired input.
#[derive(Clone, Debug)]
pub struct ResolvedEdge {
    /// Producer node index.
    pub from_node: usize,
    /// Producer output index.
    pub from_port: usize,
    /// Consumer node index.
    pub to_node: usize,
    /// Consumer input index.
    pub to_port: usize,
    /// Join mode.
    pub join: Join,
    /// Frames of delay.
    pub delay: u32,
    /// Queue policy as written (or the default, `block`).
    pub queue: QueuePolicy,
    /// Whether the queue policy was written; if not, `--realtime` runs use `latest`.
    pub queue_explicit: bool,
}

impl ResolvedEdge {
    /// The queue policy in effect: an input without a written policy blocks offline (nothing
    /// is lost, runs are reproducible) and keeps only the newest message in real time (a slow
    /// consumer drops, and counts, what it cannot keep up with instead of stalling the
    /// sensor).
    pub fn effective_queue(&self, realtime: bool) -> QueuePolicy {
        if realtime && !self.queue_explicit { QueuePolicy::DropOldest { capacity: 1 } } else { self.queue }
    }
}

impl ResolvedGraph {
    /// A digest of what every machine of a split run must agree on: the nodes (op, machine,
    /// every parameter), the edges (ends, join, delay, queue), the seed and the variant. Two
    /// processes of one run compare it at start-up, so mismatched graph files are refused.
    pub fn digest(&self) -> u64 {
        let mut d = crate::msg::Digest::new();
        d.str(&self.name);
        d.u64(self.seed);
        d.str(self.variant.as_deref().unwrap_or(""));
        for n in &self.nodes {
            d.str(&n.id);
            d.str(n.op.name);
            d.str(n.machine.as_deref().unwrap_or(""));
            d.str(&format!("{:?}|{}", n.params, n.disabled));
        }
        for e in &self.edges {
            d.str(&format!(
                "{}:{}>{}:{} {:?} {} {:?}",
                e.from_node, e.from_port, e.to_node, e.to_port, e.join, e.delay, e.queue
            ));
        }
        for (m, endpoint) in &self.machines {
            d.str(m);
            d.str(endpoint);
        }
        d.finish()
    }

    /// Index of a node by id.
    pub fn node_index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| &*n.id == id)
    }

    /// `node.port` label of an edge's producer and `node/port` of its consumer.
    pub fn edge_label(&self, e: &ResolvedEdge) -> String {
        let from = self.nodes.get(e.from_node);
        let to = self.nodes.get(e.to_node);
        format!(
            "{}.{} -> {}/{}",
            from.map_or("?", |n| &*n.id),
            from.and_then(|n| n.outputs.get(e.from_port)).map_or("?", |p| p.name),
            to.map_or("?", |n| &*n.id),
            to.and_then(|n| n.inputs.get(e.to_port)).map_or("?", |p| p.name),
        )
    }
}
