//! Semantic checks of a [`GraphSpec`] against the operator registry.
//!
//! Every check runs even when earlier ones failed, so a user sees all problems at once.
//!
//! Why one file of this size: the checks share one index of the graph's nodes, ports and
//! edges built here, and run as one pass over it in the order their diagnostics are printed.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use super::params::check_params;
use super::{
    GraphSpec, Join, NodeSpec, RecordPolicy, ResolvedEdge, ResolvedGraph, ResolvedInput, ResolvedNode, ResolvedOutput,
};
use crate::diag::{Diagnostic, did_you_mean};
use crate::msg::PortType;
use crate::op::{OpKind, OpSpec, Params, Registry};

/// Context that is not part of the graph text.
#[derive(Clone, Debug, Default)]
pub struct ResolveContext {
    /// The graph file's name as given (for provenance).
    pub source_name: String,
    /// The graph file's text.
    pub source_text: Arc<str>,
    /// Folder that relative `path` params resolve against.
    pub base_dir: Option<PathBuf>,
    /// `--seed`.
    pub seed: Option<u64>,
    /// The variant applied to the spec, if any.
    pub variant: Option<String>,
}

/// Validate and resolve. Returns the graph only if there is no error; warnings are returned
/// either way.
pub fn validate(
    spec: &GraphSpec,
    registry: &Registry,
    cx: &ResolveContext,
) -> (Option<ResolvedGraph>, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    let ops: Vec<Option<&OpSpec>> = spec.nodes.iter().map(|n| lookup_op(n, registry, cx, &mut diags)).collect();
    let index: HashMap<&str, usize> = spec.nodes.iter().enumerate().map(|(i, n)| (n.id.as_str(), i)).collect();

    let params: Vec<Params> = spec
        .nodes
        .iter()
        .zip(&ops)
        .map(|(n, op)| match op {
            Some(op) => check_params(n, op, cx, &mut diags),
            None => Params::default(),
        })
        .collect();

    let out_types = resolve_output_types(spec, &ops, &index);
    let edges = check_inputs(spec, &ops, &index, &out_types, &mut diags);
    check_cycles(spec, &edges, &mut diags);
    let dynamic_gt: Vec<Vec<&str>> = ops
        .iter()
        .zip(&params)
        .map(|(op, p)| op.and_then(|op| op.ground_truth_outputs).map_or_else(Vec::new, |f| f(p)))
        .collect();
    let (oracle, carries) = check_oracle(spec, &ops, &dynamic_gt, &edges, cx, &mut diags);

    let all_ops_known = ops.iter().all(Option::is_some);
    if all_ops_known && !ops.iter().flatten().any(|op| op.kind == OpKind::Source) && !spec.nodes.is_empty() {
        diags.push(
            Diagnostic::error(
                "no-source",
                spec.nodes_span,
                "the graph has no source node, so no frame is ever produced",
            )
            .with_hint("add a source such as `synth` or `testing.test_pattern`; `dynaflow ops` marks sources"),
        );
    }
    let sources: Vec<&NodeSpec> = spec
        .nodes
        .iter()
        .zip(&ops)
        .filter(|(_, op)| op.is_some_and(|op| op.kind == OpKind::Source))
        .map(|(n, _)| n)
        .collect();
    if !sources.is_empty() && sources.iter().all(|n| n.disabled) {
        let names: Vec<String> = sources.iter().map(|n| format!("`{}`", n.id)).collect();
        let what = cx.variant.as_ref().map_or_else(String::new, |v| format!(" (with variant `{v}`)"));
        diags.push(
            Diagnostic::error(
                "no-enabled-source",
                sources.first().map(|n| n.id_span),
                format!("every source is disabled{what}: {}; the run would produce no frame", names.join(", ")),
            )
            .with_hint("keep at least one source enabled; disable the nodes that consume it instead"),
        );
    }
    if spec.nodes.is_empty() {
        diags.push(
            Diagnostic::error("no-nodes", spec.nodes_span, "the graph has no nodes")
                .with_hint("add nodes under `nodes:`"),
        );
    }

    let edge_of: HashMap<(usize, usize), usize> =
        edges.iter().enumerate().map(|(e, se)| ((se.edge.to_node, se.edge.to_port), e)).collect();
    let mut nodes = Vec::new();
    for (i, (n, op)) in spec.nodes.iter().zip(&ops).enumerate() {
        let Some(op) = op else { continue };
        let outputs = op
            .outputs
            .iter()
            .enumerate()
            .map(|(j, p)| ResolvedOutput {
                name: p.name,
                ty: out_types.get(i).and_then(|t| t.get(j)).copied().unwrap_or(p.ty),
                record: record_policy(n, p.name),
                ground_truth: carries.get(i).and_then(|c| c.get(j)).copied().unwrap_or(false),
            })
            .collect::<Vec<_>>();
        for (port, span, _) in &n.record.ports {
            if op.output(port).is_none() {
                diags.push(
                    Diagnostic::error(
                        "unknown-port",
                        *span,
                        format!("`{}/record` names unknown output `{port}`", n.id),
                    )
                    .with_hint(port_hint(port, op.outputs.iter().map(|p| p.name))),
                );
            }
        }
        let inputs = op
            .inputs
            .iter()
            .enumerate()
            .map(|(j, p)| ResolvedInput {
                name: p.name,
                ty: p.ty,
                required: p.required,
                edge: edge_of.get(&(i, j)).copied(),
            })
            .collect();
        nodes.push(ResolvedNode {
            id: n.id.as_str().into(),
            op: **op,
            params: params.get(i).cloned().unwrap_or_default(),
            inputs,
            outputs,
            disabled: n.disabled,
            machine: machine_of(spec, n),
        });
    }
    check_unused_outputs(spec, &nodes, &edges, &mut diags);
    check_machines(spec, &nodes, &edges, &mut diags);

    let errors = diags.iter().any(Diagnostic::is_error);
    diags.sort_by_key(|d| (d.span.map_or(usize::MAX, |s| s.offset), d.severity));
    if errors || nodes.len() != spec.nodes.len() {
        return (None, diags);
    }
    let graph = ResolvedGraph {
        name: spec.name.clone(),
        seed: cx.seed.unwrap_or(spec.seed),
        variant: cx.variant.clone(),
        source_text: cx.source_text.clone(),
        source_name: cx.source_name.clone(),
        oracle,
        nodes,
        edges: edges.into_iter().map(|e| e.edge).collect(),
        machines: spec.machines.iter().map(|m| (Arc::from(m.name.as_str()), m.endpoint.clone())).collect(),
    };
    (Some(graph), diags)
}

/// The machine a node runs on: its `machine:`, else the first of `machines:`, else none.
fn machine_of(spec: &GraphSpec, n: &NodeSpec) -> Option<Arc<str>> {
    let first = spec.machines.first()?;
    Some(Arc::from(n.machine.as_ref().map_or(first.name.as_str(), |(m, _)| m.as_str())))
}

/// `machines:` and `machine:`: every machine named is defined, endpoints differ, and every
/// edge between two machines carries a payload the wire encoding can carry.
fn check_machines(spec: &GraphSpec, nodes: &[ResolvedNode], edges: &[SpannedEdge], diags: &mut Vec<Diagnostic>) {
    // (A machine named twice is a duplicate key, reported by the parser.)
    // Each endpoint's socket in one spelling (`None` for a malformed one, reported by the parser).
    let sockets: Vec<Option<(String, u16)>> =
        spec.machines.iter().map(|m| super::endpoint::canonical_endpoint(&m.endpoint).ok()).collect();
    for (i, m) in spec.machines.iter().enumerate() {
        if let Some((other, _)) = spec.machines[..i]
            .iter()
            .zip(&sockets)
            .find(|(o, s)| o.endpoint == m.endpoint || (s.is_some() && **s == sockets[i]))
        {
            diags.push(
                Diagnostic::error(
                    "bad-value",
                    m.endpoint_span,
                    format!(
                        "machines `{}` and `{}` both listen on `{}` (`{}` and `{}`)",
                        other.name,
                        m.name,
                        sockets[i].as_ref().map_or_else(|| m.endpoint.clone(), |(h, p)| format!("{h}:{p}")),
                        other.endpoint,
                        m.endpoint
                    ),
                )
                .with_hint("give each machine its own endpoint (another port on the same host)"),
            );
        }
    }
    let names: Vec<&str> = spec.machines.iter().map(|m| m.name.as_str()).collect();
    for n in &spec.nodes {
        let Some((m, span)) = &n.machine else { continue };
        if names.is_empty() {
            diags.push(
                Diagnostic::error(
                    "unknown-machine",
                    *span,
                    format!("node `{}` names machine `{m}`, but the graph has no `machines:`", n.id),
                )
                .with_hint(
                    "add `machines: { NAME: { endpoint: \"tcp/HOST:PORT\" } }` at the top level, or remove `machine:`",
                ),
            );
        } else if !names.contains(&m.as_str()) {
            let hint = did_you_mean(m, names.iter().copied())
                .unwrap_or_else(|| format!("the graph's machines: {}", names.join(", ")));
            diags.push(
                Diagnostic::error("unknown-machine", *span, format!("node `{}` names undefined machine `{m}`", n.id))
                    .with_hint(hint),
            );
        }
    }
    // One transport for the whole graph: a TLS machine would refuse a plain-TCP peer.
    if let Some(first) = spec.machines.first() {
        let scheme = |e: &str| e.split_once('/').map(|(s, _)| s.to_owned());
        for m in &spec.machines[1..] {
            if scheme(&m.endpoint) != scheme(&first.endpoint) {
                diags.push(
                    Diagnostic::error(
                        "bad-value",
                        m.endpoint_span,
                        format!(
                            "machine `{}` uses `{}` but `{}` uses `{}`",
                            m.name, m.endpoint, first.name, first.endpoint
                        ),
                    )
                    .with_hint("every machine of a graph uses one transport: all `tls/` (authenticated) or all `tcp/`"),
                );
            }
        }
    }
    // Every machine runs a node: one with none would join the start-up barrier and do
    // nothing, and its process is easily forgotten.
    for m in &spec.machines {
        if !nodes.iter().any(|n| !n.disabled && n.machine.as_deref() == Some(m.name.as_str())) {
            diags.push(
                Diagnostic::error("unused-machine", m.span, format!("machine `{}` runs no node", m.name))
                    .with_hint(format!("place a node on it with `machine: {}`, or remove it from `machines:`", m.name)),
            );
        }
    }
    if names.len() < 2 {
        return;
    }
    let node_at = |i: usize| spec.nodes.get(i).and_then(|n| nodes.iter().find(|r| *r.id == *n.id));
    for se in edges {
        let (Some(from), Some(to)) = (node_at(se.edge.from_node), node_at(se.edge.to_node)) else { continue };
        if from.machine == to.machine {
            continue;
        }
        let ty = from.outputs.get(se.edge.from_port).map_or(PortType::Any, |o| o.ty);
        if !crate::msg::codec::encodable(ty) {
            diags.push(
                Diagnostic::error(
                    "not-serialisable",
                    se.span,
                    format!(
                        "the edge from `{}` (machine `{}`) to `{}` (machine `{}`) carries `{ty}`, which cannot cross machines",
                        from.id,
                        from.machine.as_deref().unwrap_or("?"),
                        to.id,
                        to.machine.as_deref().unwrap_or("?"),
                    ),
                )
                .with_hint("place both nodes on one machine, or feed the edge from a typed output"),
            );
        }
    }
}

/// Follows ground truth through the graph and checks the graph's `oracle:` declaration
/// against what its decisions read. Returns what the resolved graph records: `None` for a
/// graph that decides without ground truth, else the decisions that read it; and per node
/// and output whether it carries ground truth.
fn check_oracle(
    spec: &GraphSpec,
    ops: &[Option<&OpSpec>],
    dynamic_gt: &[Vec<&str>],
    edges: &[SpannedEdge],
    cx: &ResolveContext,
    diags: &mut Vec<Diagnostic>,
) -> (Option<Vec<String>>, Vec<Vec<bool>>) {
    let wires: Vec<super::oracle::Wire> = edges
        .iter()
        .map(|e| ((e.edge.from_node, e.edge.from_port), (e.edge.to_node, e.edge.to_port), e.span))
        .collect();
    let super::oracle::Analysis { uses, carries } = super::oracle::analyse(spec, ops, dynamic_gt, &wires);
    let declared = spec.oracle.is_some_and(|(b, _)| b);
    let what = cx.variant.as_ref().map_or_else(|| "the graph".to_owned(), |v| format!("variant `{v}`"));
    if !declared {
        let hint = match &cx.variant {
            Some(v) => format!(
                "if {what} is meant to decide with ground truth (a bound, not a result), add `oracle: true` to the variant (`{v}: {{ oracle: true, ... }}`); otherwise wire an estimate (a detector's mask, the tracker's pose)"
            ),
            None => "if the graph is meant to decide with ground truth (a bound, not a result), add `oracle: true` at its top; otherwise wire an estimate (a detector's mask, the tracker's pose)".to_owned(),
        };
        for u in &uses {
            diags.push(
                Diagnostic::error(
                    "undeclared-oracle",
                    u.span,
                    format!("{what} decides with ground truth but does not declare `oracle: true`: {}", u.describe()),
                )
                .with_hint(hint.clone()),
            );
        }
    } else if uses.is_empty() {
        diags.push(
            Diagnostic::warning(
                "unused-oracle",
                spec.oracle.map(|(_, s)| s),
                format!("{what} declares `oracle: true`, but none of its decisions reads ground truth"),
            )
            .with_hint("remove `oracle: true` (or set it to `false` in this variant), so its results are not marked as an oracle's"),
        );
    }
    let oracle =
        (declared || !uses.is_empty()).then(|| uses.iter().map(super::oracle::GroundTruthUse::describe).collect());
    (oracle, carries)
}

/// Per-node declarations made so far, by operator, `params` and folder: each is made (a
/// Python module imported) and leaked once per process.
type Declared = std::collections::HashMap<(String, String, Option<PathBuf>), &'static OpSpec>;
static DECLARED: std::sync::Mutex<Option<Declared>> = std::sync::Mutex::new(None);

/// The node's declaration from an operator that declares per node (`OpSpec::declare`).
fn declare_node(
    n: &NodeSpec,
    op: &OpSpec,
    declare: crate::op::DeclareFn,
    cx: &ResolveContext,
) -> Result<&'static OpSpec, String> {
    let params: serde_json::Map<String, serde_json::Value> =
        n.params.iter().map(|(k, v)| (k.text.clone(), v.to_json())).collect();
    let key = (op.name.to_owned(), serde_json::Value::Object(params.clone()).to_string(), cx.base_dir.clone());
    let lock = || DECLARED.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(d) = lock().get_or_insert_default().get(&key) {
        return Ok(d);
    }
    let req = crate::op::DeclareRequest { node: &n.id, params: &params, base_dir: cx.base_dir.as_deref() };
    let spec: &'static OpSpec = Box::leak(Box::new(declare(op, &req)?));
    lock().get_or_insert_default().insert(key, spec);
    Ok(spec)
}

fn lookup_op<'r>(
    n: &NodeSpec,
    registry: &'r Registry,
    cx: &ResolveContext,
    diags: &mut Vec<Diagnostic>,
) -> Option<&'r OpSpec> {
    if n.op.is_empty() {
        return None; // already reported by the parser
    }
    let op = registry.get(&n.op);
    if let Some(declare) = op.and_then(|o| o.declare) {
        let op = op?;
        return match declare_node(n, op, declare, cx) {
            Ok(spec) => Some(spec),
            Err(message) => {
                diags.push(
                    Diagnostic::error("op-declaration", n.op_span, format!("node `{}`: {message}", n.id)).with_hint(
                        format!(
                            "`{}` reads this node's ports and parameters from its `params` when the graph is validated",
                            op.name
                        ),
                    ),
                );
                None
            }
        };
    }
    if op.is_none() {
        // A namespaced operator (`testing.fault`) is also found by its name alone.
        let hint = registry
            .migration(&n.op)
            .map(str::to_owned)
            .or_else(|| did_you_mean(&n.op, registry.names()))
            .or_else(|| {
                let guess = did_you_mean(bare_of(&n.op), registry.names().map(bare_of))?;
                let full = registry.names().find(|name| guess.contains(&format!("`{}`", bare_of(name))))?;
                Some(format!("did you mean `{full}`?"))
            })
            .unwrap_or_else(|| "run `dynaflow ops` to list operators".to_owned());
        diags.push(
            Diagnostic::error("unknown-op", n.op_span, format!("node `{}`: unknown op `{}`", n.id, n.op))
                .with_hint(hint),
        );
    }
    op
}

/// `op` without a namespace.
fn bare_of(op: &str) -> &str {
    op.rsplit_once('.').map_or(op, |(_, b)| b)
}

fn port_hint<'a>(given: &str, names: impl Iterator<Item = &'a str> + Clone) -> String {
    did_you_mean(given, names.clone()).unwrap_or_else(|| {
        let all: Vec<_> = names.map(|n| format!("`{n}`")).collect();
        if all.is_empty() { "this operator has no such ports".to_owned() } else { format!("ports: {}", all.join(", ")) }
    })
}

fn record_policy(n: &NodeSpec, port: &str) -> RecordPolicy {
    n.record
        .ports
        .iter()
        .find(|(p, _, _)| p == port)
        .map(|(_, _, r)| *r)
        .or(n.record.default)
        .unwrap_or(RecordPolicy::All)
}

/// Output types, with `same_as` outputs following what is wired into their input (through
/// chains of pass-through nodes, in any file order: linear time, iterative).
fn resolve_output_types(spec: &GraphSpec, ops: &[Option<&OpSpec>], index: &HashMap<&str, usize>) -> Vec<Vec<PortType>> {
    #[derive(Clone, Copy, PartialEq)]
    enum State {
        Todo,
        Busy,
        Done,
    }
    let mut types: Vec<Vec<PortType>> =
        ops.iter().map(|op| op.map_or_else(Vec::new, |op| op.outputs.iter().map(|p| p.ty).collect())).collect();
    let mut state: Vec<Vec<State>> = ops
        .iter()
        .map(|op| {
            op.map_or_else(Vec::new, |op| {
                op.outputs.iter().map(|p| if p.same_as.is_some() { State::Todo } else { State::Done }).collect()
            })
        })
        .collect();
    // The output that `same_as` output (i, j) copies its type from.
    let upstream = |i: usize, j: usize| -> Option<(usize, usize)> {
        let op = ops.get(i).copied().flatten()?;
        let input = op.outputs.get(j)?.same_as?;
        let r = spec.nodes.get(i)?.inputs.iter().find(|inp| inp.port == input)?.from.as_ref()?;
        let k = *index.get(r.node.as_str())?;
        let port = ops.get(k).copied().flatten()?.outputs.iter().position(|p| p.name == r.port)?;
        Some((k, port))
    };
    let get = |st: &Vec<Vec<State>>, (i, j): (usize, usize)| st.get(i).and_then(|s| s.get(j)).copied();
    for i in 0..state.len() {
        for j in 0..state.get(i).map_or(0, Vec::len) {
            if get(&state, (i, j)) != Some(State::Todo) {
                continue;
            }
            let mut stack = vec![(i, j)];
            while let Some(&at) = stack.last() {
                if let Some(s) = state.get_mut(at.0).and_then(|s| s.get_mut(at.1)) {
                    *s = State::Busy;
                }
                let resolved = match upstream(at.0, at.1) {
                    // Unwired, or a pass-through loop (closed by a delay): nothing to copy.
                    None => Some(PortType::Any),
                    Some(up) => match get(&state, up) {
                        Some(State::Done) => types.get(up.0).and_then(|t| t.get(up.1)).copied(),
                        Some(State::Todo) => {
                            stack.push(up);
                            None
                        }
                        Some(State::Busy) | None => Some(PortType::Any),
                    },
                };
                if let Some(ty) = resolved {
                    if let Some(t) = types.get_mut(at.0).and_then(|t| t.get_mut(at.1)) {
                        *t = ty;
                    }
                    if let Some(s) = state.get_mut(at.0).and_then(|s| s.get_mut(at.1)) {
                        *s = State::Done;
                    }
                    stack.pop();
                }
            }
        }
    }
    types
}

/// The producer node and output index of `from`, reporting an unknown node or port. `None`
/// without a diagnostic when the producer's op is unknown (reported at the producer).
fn resolve_ref(
    spec: &GraphSpec,
    ops: &[Option<&OpSpec>],
    index: &HashMap<&str, usize>,
    n: &NodeSpec,
    port: &str,
    from: &super::PortRef,
    diags: &mut Vec<Diagnostic>,
) -> Option<(usize, usize)> {
    let Some(&k) = index.get(from.node.as_str()) else {
        let hint = did_you_mean(&from.node, spec.nodes.iter().map(|n| n.id.as_str())).unwrap_or_else(|| {
            let ids: Vec<&str> = spec.nodes.iter().map(|n| n.id.as_str()).take(20).collect();
            format!("nodes: {}", ids.join(", "))
        });
        diags.push(
            Diagnostic::error(
                "unknown-node",
                from.span,
                format!("input `{}/{port}` refers to unknown node `{}`", n.id, from.node),
            )
            .with_hint(hint),
        );
        return None;
    };
    let producer = ops.get(k).copied().flatten()?;
    let Some(p) = producer.outputs.iter().position(|o| o.name == from.port) else {
        diags.push(
            Diagnostic::error(
                "unknown-port",
                from.span,
                format!(
                    "input `{}/{port}`: node `{}` (op `{}`) has no output `{}`",
                    n.id, from.node, producer.name, from.port
                ),
            )
            .with_hint(port_hint(&from.port, producer.outputs.iter().map(|o| o.name))),
        );
        return None;
    };
    Some((k, p))
}

struct SpannedEdge {
    edge: ResolvedEdge,
    span: crate::yaml::Span,
    delay_valid: bool,
}

fn check_inputs(
    spec: &GraphSpec,
    ops: &[Option<&OpSpec>],
    index: &HashMap<&str, usize>,
    out_types: &[Vec<PortType>],
    diags: &mut Vec<Diagnostic>,
) -> Vec<SpannedEdge> {
    let mut edges = Vec::new();
    for (i, (n, op)) in spec.nodes.iter().zip(ops).enumerate() {
        let Some(op) = op else {
            // The op is unknown (reported), but where its inputs come from is independent of
            // it: report references to unknown nodes and ports too.
            for input in &n.inputs {
                if let Some(from) = &input.from {
                    resolve_ref(spec, ops, index, n, &input.port, from, diags);
                }
            }
            continue;
        };
        if op.kind == OpKind::Source && !n.inputs.is_empty() {
            let span = n.inputs.first().map_or(n.id_span, |i| i.port_span);
            diags.push(
                Diagnostic::error(
                    "source-has-inputs",
                    span,
                    format!("node `{}`: `{}` is a source and takes no inputs", n.id, op.name),
                )
                .with_hint("remove the `in:` block"),
            );
            continue;
        }
        let mut seen_ports: Vec<&str> = Vec::new();
        for input in &n.inputs {
            let Some(j) = op.inputs.iter().position(|p| p.name == input.port) else {
                diags.push(
                    Diagnostic::error(
                        "unknown-port",
                        input.port_span,
                        format!("node `{}`: op `{}` has no input `{}`", n.id, op.name, input.port),
                    )
                    .with_hint(port_hint(&input.port, op.inputs.iter().map(|p| p.name))),
                );
                continue;
            };
            seen_ports.push(op.inputs.get(j).map_or("", |p| p.name));
            let Some(from) = &input.from else { continue };
            let Some((k, p)) = resolve_ref(spec, ops, index, n, &input.port, from, diags) else { continue };
            let produced = out_types.get(k).and_then(|t| t.get(p)).copied().unwrap_or(PortType::Any);
            let wanted = op.inputs.get(j).map_or(PortType::Any, |p| p.ty);
            if produced != PortType::Any && !produced.feeds(wanted) {
                let candidates: Vec<String> = spec
                    .nodes
                    .iter()
                    .enumerate()
                    .flat_map(|(m, node)| {
                        let types = out_types.get(m).cloned().unwrap_or_default();
                        let outs = ops.get(m).copied().flatten().map(|o| o.outputs).unwrap_or_default();
                        outs.iter()
                            .zip(types)
                            .filter(|(_, t)| t.feeds(wanted))
                            .map(move |(o, _)| format!("`{}.{}`", node.id, o.name))
                            .collect::<Vec<_>>()
                    })
                    .take(4)
                    .collect();
                let hint = if candidates.is_empty() {
                    format!("`{}/{}` needs a {wanted} output; no node in this graph produces one", n.id, input.port)
                } else {
                    format!("`{}/{}` needs {wanted}; outputs of that type: {}", n.id, input.port, candidates.join(", "))
                };
                diags.push(
                    Diagnostic::error(
                        "port-type-mismatch",
                        from.span,
                        format!(
                            "input `{}/{}` expects {wanted} but `{}.{}` produces {produced}",
                            n.id, input.port, from.node, from.port
                        ),
                    )
                    .with_hint(hint),
                );
                continue;
            }
            if let Some(prod_node) = spec.nodes.get(k)
                && prod_node.disabled
                && !n.disabled
                && let Some(decl) = op.inputs.get(j).filter(|p| p.wired)
            {
                let effect = if decl.required {
                    format!("`{}` will skip every frame", n.id)
                } else {
                    format!("`{}` will see nothing on it", n.id)
                };
                diags.push(
                    Diagnostic::warning(
                        "disabled-input",
                        from.span,
                        format!("input `{}/{}` is fed by disabled node `{}`: {effect}", n.id, input.port, from.node),
                    )
                    .with_hint("disable this node too, or rewire the input in the variant"),
                );
            }
            edges.push(SpannedEdge {
                edge: ResolvedEdge {
                    from_node: k,
                    from_port: p,
                    to_node: i,
                    to_port: j,
                    join: input.join,
                    delay: input.delay,
                    queue: input.queue,
                    queue_explicit: input.queue_explicit,
                },
                delay_valid: input.delay_valid,
                span: from.span,
            });
        }
        // A disabled node does not run: what it must have wired is checked when a variant
        // enables it (as graphs keep a stereo matcher wired only in their stereo variant).
        if op.kind == OpKind::Transform && !n.disabled {
            for p in op.inputs.iter().filter(|p| p.wired && !seen_ports.contains(&p.name)) {
                let producers: Vec<String> = spec
                    .nodes
                    .iter()
                    .enumerate()
                    .flat_map(|(m, node)| {
                        let types = out_types.get(m).cloned().unwrap_or_default();
                        ops.get(m)
                            .copied()
                            .flatten()
                            .map(|o| o.outputs)
                            .unwrap_or_default()
                            .iter()
                            .zip(types)
                            .filter(|(_, t)| *t != PortType::Any && t.feeds(p.ty))
                            .map(move |(o, _)| format!("{}.{}", node.id, o.name))
                            .collect::<Vec<_>>()
                    })
                    .collect();
                // An output of the input's own name first (`right: camera.right`).
                let mut producers = producers;
                producers.sort_by_key(|r| !r.ends_with(&format!(".{}", p.name)));
                producers.truncate(3);
                let hint = match producers.first() {
                    Some(first) => format!("wire it, e.g. `in: {{ {}: {first} }}`", p.name),
                    None => format!("wire it to an output of type {}", p.ty),
                };
                diags.push(
                    Diagnostic::error(
                        "missing-input",
                        n.id_span,
                        format!("node `{}`: required input `{}` ({}) is not connected", n.id, p.name, p.ty),
                    )
                    .with_hint(hint),
                );
            }
            let drives = n.inputs.iter().any(|inp| inp.join == Join::Lockstep && inp.delay == 0);
            if !drives && !n.inputs.is_empty() {
                diags.push(
                    Diagnostic::error("no-driving-input", n.id_span, format!("node `{}` has no undelayed `join: lockstep` input, so nothing decides which frames it runs", n.id))
                        .with_hint("wire at least one input with the default `join: lockstep` and no `delay`"),
                );
            }
        }
    }
    edges
}

/// Cycles must contain at least one delayed edge; find strongly connected components of the
/// undelayed edges (Tarjan) and report each non-trivial one.
fn check_cycles(spec: &GraphSpec, edges: &[SpannedEdge], diags: &mut Vec<Diagnostic>) {
    let n = spec.nodes.len();
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
    // An edge whose `delay:` did not parse was reported already; leaving it out avoids a
    // second, spurious "cycle without a delay" error.
    for e in edges.iter().filter(|e| e.edge.delay == 0 && e.delay_valid) {
        if let Some(list) = adj.get_mut(e.edge.from_node) {
            list.push(e.edge.to_node);
        }
    }
    for comp in tarjan(&adj) {
        let cyclic = comp.len() > 1 || comp.first().is_some_and(|&v| adj.get(v).is_some_and(|a| a.contains(&v)));
        if !cyclic {
            continue;
        }
        let mut ids: Vec<usize> = comp.clone();
        ids.sort_unstable();
        let names: Vec<&str> = ids.iter().filter_map(|&i| spec.nodes.get(i).map(|n| n.id.as_str())).collect();
        let edge = edges
            .iter()
            .filter(|e| e.edge.delay == 0 && comp.contains(&e.edge.from_node) && comp.contains(&e.edge.to_node))
            .max_by_key(|e| e.span.offset);
        let (span, hint) = match edge {
            Some(e) => {
                let to = spec.nodes.get(e.edge.to_node);
                let port = to
                    .and_then(|t| t.inputs.iter().find(|i| i.from.as_ref().is_some_and(|f| f.span == e.span)))
                    .map_or("?", |i| i.port.as_str());
                (
                    Some(e.span),
                    format!(
                        "add `delay: 1` to one edge of the cycle, e.g. `{}/{port}`: `{{ from: ..., delay: 1 }}`",
                        to.map_or("?", |t| t.id.as_str())
                    ),
                )
            }
            None => (None, "add `delay: 1` to one edge of the cycle".to_owned()),
        };
        diags.push(
            Diagnostic::error(
                "cycle",
                span,
                format!(
                    "cycle without a delay through nodes {}",
                    names.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(" -> ")
                ),
            )
            .with_hint(hint),
        );
    }
}

fn tarjan(adj: &[Vec<usize>]) -> Vec<Vec<usize>> {
    struct St<'a> {
        adj: &'a [Vec<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    // Iterative to survive very large generated graphs without stack overflow.
    fn visit(st: &mut St<'_>, root: usize) {
        let mut work: Vec<(usize, usize)> = vec![(root, 0)];
        while let Some(&mut (v, ref mut child)) = work.last_mut() {
            if *child == 0 && st.index[v].is_none() {
                st.index[v] = Some(st.next);
                st.low[v] = st.next;
                st.next += 1;
                st.stack.push(v);
                st.on[v] = true;
            }
            if let Some(&w) = st.adj[v].get(*child) {
                *child += 1;
                match st.index[w] {
                    None => work.push((w, 0)),
                    Some(iw) if st.on[w] => st.low[v] = st.low[v].min(iw),
                    Some(_) => {}
                }
                continue;
            }
            work.pop();
            if let Some(&(parent, _)) = work.last() {
                st.low[parent] = st.low[parent].min(st.low[v]);
            }
            if Some(st.low[v]) == st.index[v] {
                let mut comp = Vec::new();
                while let Some(w) = st.stack.pop() {
                    st.on[w] = false;
                    comp.push(w);
                    if w == v {
                        break;
                    }
                }
                st.out.push(comp);
            }
        }
    }
    let n = adj.len();
    let mut st = St {
        adj,
        index: vec![None; n],
        low: vec![0; n],
        on: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if st.index[v].is_none() {
            visit(&mut st, v);
        }
    }
    st.out
}

fn check_unused_outputs(spec: &GraphSpec, nodes: &[ResolvedNode], edges: &[SpannedEdge], diags: &mut Vec<Diagnostic>) {
    let consumed: std::collections::HashSet<(usize, usize)> =
        edges.iter().map(|e| (e.edge.from_node, e.edge.from_port)).collect();
    for (i, node) in nodes.iter().enumerate() {
        if node.disabled {
            continue;
        }
        for (j, out) in node.outputs.iter().enumerate() {
            let consumed = consumed.contains(&(i, j));
            if !consumed && out.record == RecordPolicy::None {
                let span = spec.nodes.get(i).map(|n| n.id_span);
                diags.push(
                    Diagnostic::warning(
                        "unused-output",
                        span,
                        format!("output `{}.{}` is neither consumed nor recorded", node.id, out.name),
                    )
                    .with_hint("wire it to a node, or record it (`record: all`)"),
                );
            }
        }
    }
}
