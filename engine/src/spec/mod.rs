//! Graph files: the YAML syntax, parsed into spanned spec types, then validated into a
//! [`ResolvedGraph`] the runtime can execute.
//!
//! - `parse`: YAML tree → [`GraphSpec`] (structure, ids, value shapes), collecting every error.
//! - `variant`: applies a named variant and `--set` overrides to a spec.
//! - `validate`: checks the spec against the operator registry (ops, params, ports, types,
//!   cycles) and resolves it.
//! - `resolved`: the validated, typed graph.
//!
//! # Syntax
//!
//! ```yaml
//! name: example            # required
//! description: optional text
//! seed: 7                  # graph seed; every node's RNG derives from it and the node id
//! oracle: false            # true when a decision reads ground truth (validation checks it)
//! nodes:                   # node id -> node; ids match [A-Za-z_][A-Za-z0-9_-]*
//!   camera:
//!     op: testing.test_pattern     # operator name (`dynaflow ops` lists them)
//!     params: { frames: 300 }
//!     record: all          # all | none | every N | {port: policy, ...}
//!   blur:
//!     op: passthrough
//!     in:
//!       input: camera.image                # shorthand: lockstep, block, no delay
//!       hint:                              # long form
//!         from: other.scalars              # node.port
//!         join: latest                     # lockstep (default) | latest
//!         delay: 1                         # frames; closes feedback cycles
//!         queue: { drop_oldest: 4 }        # block (default) | latest | {drop_oldest: N}
//!         capacity: 4                      # queue length for `block`
//!     disabled: false
//! machines:                # optional: the graph spans processes/machines (zenoh)
//!   robot:  { endpoint: "tcp/127.0.0.1:7447" }   # the first one is every node's default
//!   server: { endpoint: "tcp/127.0.0.1:7448" }   # (a node says `machine: server`)
//! variants:                # named patches for ablations
//!   no_blur: { blur: { disabled: true } }
//!   gt_masks: { oracle: true, cull: { in: { mask: camera.gt_mask } } }
//!   faster:  { camera: { params: { frames: 10 } } }
//! ```

mod endpoint;
mod oracle;
mod params;
mod parse;
mod resolved;
pub(crate) mod validate;
mod variant;

pub use parse::{parse_graph, valid_id};
pub use resolved::{ResolvedEdge, ResolvedGraph, ResolvedInput, ResolvedNode, ResolvedOutput};
pub use validate::{ResolveContext, validate};
pub use variant::{Override, OverrideOrigins, apply_overrides, apply_variant, variant_parts};

use crate::yaml::{Key, Span, Yaml};

/// A graph file as written (before validation against the registry).
#[derive(Clone, Debug, PartialEq)]
pub struct GraphSpec {
    /// `name:`.
    pub name: String,
    /// `description:`.
    pub description: Option<String>,
    /// `seed:` (default 0).
    pub seed: u64,
    /// `oracle:` as written: the graph's decisions read ground truth (a variant's own
    /// `oracle:` replaces it when the variant is applied).
    pub oracle: Option<(bool, Span)>,
    /// `nodes:` in file order.
    pub nodes: Vec<NodeSpec>,
    /// `variants:` in file order.
    pub variants: Vec<VariantSpec>,
    /// Span of the `nodes:` key (or the document).
    pub nodes_span: Span,
    /// `machines:` in file order (empty: the graph runs in one process).
    pub machines: Vec<MachineSpec>,
}

/// One entry of `machines:`: a process of a graph that spans several.
#[derive(Clone, Debug, PartialEq)]
pub struct MachineSpec {
    /// Machine name (what a node's `machine:` and `dynaflow run --machine` say).
    pub name: String,
    /// Where the name is written.
    pub span: Span,
    /// The zenoh endpoint this machine listens on (`tcp/HOST:PORT`).
    pub endpoint: String,
    /// Where the endpoint is written.
    pub endpoint_span: Span,
}

/// One node.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeSpec {
    /// Node id.
    pub id: String,
    /// Where the id is written.
    pub id_span: Span,
    /// Operator name.
    pub op: String,
    /// Where the op name is written.
    pub op_span: Span,
    /// `params:` entries as written.
    pub params: Vec<(Key, Yaml)>,
    /// `in:` entries.
    pub inputs: Vec<InputSpec>,
    /// `record:`.
    pub record: RecordSpec,
    /// `disabled:`.
    pub disabled: bool,
    /// `machine:`: the machine of `machines:` that runs it (default: the first).
    pub machine: Option<(String, Span)>,
}

/// Where an input comes from: `node.port`.
#[derive(Clone, Debug, PartialEq)]
pub struct PortRef {
    /// Producer node id.
    pub node: String,
    /// Producer output port.
    pub port: String,
    /// Where the reference is written.
    pub span: Span,
}

/// How an input aligns with the node's frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Join {
    /// The message of exactly this frame (absent if the producer emitted nothing for it).
    Lockstep,
    /// The newest message at or before this frame (held across frames).
    Latest,
}

/// What happens when an input queue is full.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum QueuePolicy {
    /// The producer waits (backpressure). Nothing is lost.
    Block {
        /// Queue length.
        capacity: usize,
    },
    /// The oldest queued message is dropped (and counted) to make room.
    DropOldest {
        /// Queue length.
        capacity: usize,
    },
}

/// Default queue length of a `block` input.
pub const DEFAULT_CAPACITY: usize = 4;

/// One `in:` entry.
#[derive(Clone, Debug, PartialEq)]
pub struct InputSpec {
    /// Input port name.
    pub port: String,
    /// Where the port name is written.
    pub port_span: Span,
    /// The producer, if the reference parsed.
    pub from: Option<PortRef>,
    /// Join mode.
    pub join: Join,
    /// Frames of delay (feedback edges).
    pub delay: u32,
    /// Queue policy.
    pub queue: QueuePolicy,
    /// Whether `queue:` or `capacity:` was written. Without either, offline runs use `block`
    /// and `--realtime` runs `latest`, so a slow node never throttles its sources.
    pub queue_explicit: bool,
    /// False when `delay:` was written but invalid (already reported): the edge is then left
    /// out of the cycle check instead of raising a second, spurious error.
    pub delay_valid: bool,
}

/// Which messages of an output port go to the recorders.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum RecordPolicy {
    /// Every message.
    All,
    /// None.
    None,
    /// Messages whose frame number is a multiple of N.
    Every(u64),
}

/// `record:` of a node: a default for all outputs plus per-port overrides.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct RecordSpec {
    /// Applies to outputs without their own entry (default: all).
    pub default: Option<RecordPolicy>,
    /// `(port, where, policy)`.
    pub ports: Vec<(String, Span, RecordPolicy)>,
}

/// A named set of patches.
#[derive(Clone, Debug, PartialEq)]
pub struct VariantSpec {
    /// Variant name.
    pub name: String,
    /// Where the name is written.
    pub span: Span,
    /// `oracle: true|false` inside the variant: whether its decisions read ground truth.
    pub oracle: Option<(bool, Span)>,
    /// One patch per node.
    pub patches: Vec<NodePatch>,
}

/// Changes a variant makes to one node.
#[derive(Clone, Debug, PartialEq)]
pub struct NodePatch {
    /// Target node id.
    pub node: String,
    /// Where the id is written.
    pub node_span: Span,
    /// Another operator in the node's place, with where it is written: the node's `in` and
    /// `params` are then the patch's alone (the base's belong to the old operator).
    pub op: Option<(String, Span)>,
    /// New `disabled`.
    pub disabled: Option<bool>,
    /// Params to set (merged key by key).
    pub params: Vec<(Key, Yaml)>,
    /// Inputs to rewire (replaced port by port).
    pub inputs: Vec<InputSpec>,
    /// New `record`.
    pub record: Option<RecordSpec>,
    /// New `machine`.
    pub machine: Option<(String, Span)>,
}
