//! YAML tree → [`GraphSpec`]. Checks structure and shapes only; every problem becomes a
//! diagnostic and parsing continues with the rest of the file.

use super::{
    DEFAULT_CAPACITY, GraphSpec, InputSpec, Join, MachineSpec, NodePatch, NodeSpec, PortRef, QueuePolicy, RecordPolicy,
    RecordSpec, VariantSpec,
};
use crate::diag::{Diagnostic, did_you_mean};
use crate::yaml::{Key, Span, Yaml, YamlKind};

const TOP_KEYS: &[&str] = &["name", "description", "seed", "oracle", "nodes", "variants", "machines"];
const NODE_KEYS: &[&str] = &["op", "params", "in", "record", "disabled", "machine"];
const PATCH_KEYS: &[&str] = &["op", "params", "in", "record", "disabled", "machine"];
const MACHINE_KEYS: &[&str] = &["endpoint"];
const INPUT_KEYS: &[&str] = &["from", "join", "delay", "queue", "capacity"];
/// Longest allowed `delay:`; longer feedback needs a state operator, not a queue.
const MAX_DELAY: u32 = 64;
/// Longest allowed queue.
const MAX_CAPACITY: usize = 1 << 20;

/// Longest graph name: it becomes a file name (`<name>-<variant>.summary.json`).
const MAX_NAME_LEN: usize = 100;

/// Whether `name` is a valid graph name: it becomes the stem of the files a run writes in
/// `--out`, so it must stay one plain file name there: ASCII letters, digits, `_`, `-` and
/// `.`, starting with a letter, digit or `_` (no hidden files, no `..`, no path separators).
pub fn valid_graph_name(name: &str) -> bool {
    let mut chars = name.chars();
    name.len() <= MAX_NAME_LEN
        && matches!(chars.next(), Some(c) if c.is_ascii_alphanumeric() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

/// Whether `id` is a valid node or port id.
pub fn valid_id(id: &str) -> bool {
    let mut chars = id.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Whether `id` is a valid variant name: an id, or an ablation row such as `S+G` (`+` allowed
/// after the first character; variant names end up in file names, where `+` is safe).
pub fn valid_variant_id(id: &str) -> bool {
    let mut chars = id.chars();
    id.len() <= MAX_NAME_LEN
        && matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '+'))
}

fn check_id(what: &str, id: &str, span: Span, diags: &mut Vec<Diagnostic>) {
    if !valid_id(id) {
        diags.push(
            Diagnostic::error("bad-id", span, format!("invalid {what} id `{id}`"))
                .with_hint("ids start with a letter or `_` and contain only letters, digits, `_` and `-`"),
        );
    }
}

/// The entries of a mapping, reporting non-mappings, duplicate and unknown keys.
fn entries<'a>(
    node: &'a Yaml,
    what: &str,
    allowed: Option<&[&str]>,
    diags: &mut Vec<Diagnostic>,
) -> Vec<&'a (Key, Yaml)> {
    let YamlKind::Map(list) = &node.kind else {
        if !node.is_null() {
            diags.push(Diagnostic::error(
                "expected-mapping",
                node.span,
                format!("{what} must be a mapping, found {}", node.type_name()),
            ));
        }
        return Vec::new();
    };
    let mut out: Vec<&(Key, Yaml)> = Vec::new();
    let mut seen: std::collections::HashSet<&str> = std::collections::HashSet::new();
    for entry in list {
        let key = &entry.0;
        if !seen.insert(key.text.as_str()) {
            let (code, message) = if what == "`nodes`" {
                ("duplicate-id", format!("duplicate node id `{}`", key.text))
            } else {
                ("duplicate-key", format!("duplicate key `{}` in {what}", key.text))
            };
            diags.push(
                Diagnostic::error(code, key.span, message)
                    .with_hint("each key may appear once; remove or rename one of them"),
            );
            continue;
        }
        if let Some(allowed) = allowed
            && !allowed.contains(&key.text.as_str())
        {
            let hint = did_you_mean(&key.text, allowed.iter().copied())
                .unwrap_or_else(|| format!("allowed keys: {}", allowed.join(", ")));
            diags.push(
                Diagnostic::error("unknown-key", key.span, format!("unknown key `{}` in {what}", key.text))
                    .with_hint(hint),
            );
            continue;
        }
        out.push(entry);
    }
    out
}

fn string(node: &Yaml, what: &str, diags: &mut Vec<Diagnostic>) -> Option<String> {
    match &node.kind {
        YamlKind::Scalar { text, .. } if !node.is_null() => Some(text.clone()),
        _ => {
            diags.push(Diagnostic::error(
                "expected-string",
                node.span,
                format!("{what} must be a string, found {}", node.type_name()),
            ));
            None
        }
    }
}

fn unsigned(node: &Yaml, what: &str, max: u64, diags: &mut Vec<Diagnostic>) -> Option<u64> {
    match node.to_json().as_u64() {
        Some(v) if v <= max => Some(v),
        _ => {
            diags.push(
                Diagnostic::error("bad-value", node.span, format!("{what} must be an integer in 0..={max}"))
                    .with_hint(format!("found {}", node.type_name())),
            );
            None
        }
    }
}

fn boolean(node: &Yaml, what: &str, diags: &mut Vec<Diagnostic>) -> Option<bool> {
    match node.to_json() {
        serde_json::Value::Bool(b) => Some(b),
        _ => {
            diags.push(Diagnostic::error(
                "bad-value",
                node.span,
                format!("{what} must be `true` or `false`, found {}", node.type_name()),
            ));
            None
        }
    }
}

/// Parse a whole graph document. Returns the spec (possibly partial) and every problem found.
pub fn parse_graph(doc: &Yaml) -> (GraphSpec, Vec<Diagnostic>) {
    let mut diags = Vec::new();
    let mut spec = GraphSpec {
        name: String::new(),
        description: None,
        seed: 0,
        oracle: None,
        nodes: Vec::new(),
        variants: Vec::new(),
        nodes_span: doc.span,
        machines: Vec::new(),
    };
    if !matches!(doc.kind, YamlKind::Map(_)) {
        diags.push(
            Diagnostic::error(
                "expected-mapping",
                doc.span,
                format!("a graph file must be a mapping, found {}", doc.type_name()),
            )
            .with_hint("start with `name: my_graph` and a `nodes:` mapping"),
        );
        return (spec, diags);
    }
    let top = entries(doc, "the graph", Some(TOP_KEYS), &mut diags);
    let mut seen_name = false;
    let mut seen_nodes = false;
    for (key, value) in top {
        match key.text.as_str() {
            "name" => {
                seen_name = true;
                if let Some(name) = string(value, "`name`", &mut diags) {
                    if !valid_graph_name(&name) {
                        diags.push(
                            Diagnostic::error("bad-name", value.span, format!("invalid graph name `{name}`"))
                                .with_hint(format!(
                                    "the name becomes the file names of the run's outputs: use letters, digits, `_`, `-` and `.` (at most {MAX_NAME_LEN}), starting with a letter, digit or `_`"
                                )),
                        );
                    }
                    spec.name = name;
                }
            }
            "description" => spec.description = string(value, "`description`", &mut diags),
            "seed" => spec.seed = unsigned(value, "`seed`", u64::MAX, &mut diags).unwrap_or(0),
            "oracle" => spec.oracle = boolean(value, "`oracle`", &mut diags).map(|b| (b, key.span)),
            "nodes" => {
                seen_nodes = true;
                spec.nodes_span = key.span;
                for (id, body) in entries(value, "`nodes`", None, &mut diags) {
                    check_id("node", &id.text, id.span, &mut diags);
                    if let Some(node) = parse_node(id, body, &mut diags) {
                        spec.nodes.push(node);
                    }
                }
            }
            "machines" => {
                for (name, body) in entries(value, "`machines`", None, &mut diags) {
                    check_id("machine", &name.text, name.span, &mut diags);
                    if let Some(m) = parse_machine(name, body, &mut diags) {
                        spec.machines.push(m);
                    }
                }
                if spec.machines.is_empty() {
                    diags.push(
                        Diagnostic::error("bad-value", value.span, "`machines` names no machine")
                            .with_hint("write `machines: { robot: { endpoint: \"tcp/127.0.0.1:7447\" } }`, or leave `machines` out to run in one process"),
                    );
                }
            }
            "variants" => {
                for (name, body) in entries(value, "`variants`", None, &mut diags) {
                    if !valid_variant_id(&name.text) {
                        diags.push(
                            Diagnostic::error("bad-id", name.span, format!("invalid variant id `{}`", name.text))
                                .with_hint("variant ids start with a letter or `_` and contain only letters, digits, `_`, `-` and `+`"),
                        );
                    }
                    let mut oracle = None;
                    let mut patches = Vec::new();
                    for (node, patch) in entries(body, &format!("variant `{}`", name.text), None, &mut diags) {
                        // `oracle: true|false` declares the variant's use of ground truth; a
                        // mapping under the same key would patch a node named `oracle`.
                        if node.text == "oracle" && !matches!(patch.kind, YamlKind::Map(_)) {
                            let what = format!("`oracle` of variant `{}`", name.text);
                            oracle = boolean(patch, &what, &mut diags).map(|b| (b, node.span));
                        } else {
                            patches.push(parse_patch(&name.text, node, patch, &mut diags));
                        }
                    }
                    spec.variants.push(VariantSpec { name: name.text.clone(), span: name.span, oracle, patches });
                }
            }
            _ => {}
        }
    }
    if !seen_name {
        diags.push(
            Diagnostic::error("missing-key", Span::new(doc.span.offset, 0), "the graph has no `name`")
                .with_hint("add `name: my_graph` at the top"),
        );
    }
    if !seen_nodes {
        diags.push(
            Diagnostic::error("missing-key", Span::new(doc.span.offset, 0), "the graph has no `nodes`")
                .with_hint("add a `nodes:` mapping of node id to `{ op: ..., params: ..., in: ... }`"),
        );
    }
    (spec, diags)
}

fn parse_node(id: &Key, body: &Yaml, diags: &mut Vec<Diagnostic>) -> Option<NodeSpec> {
    let what = format!("node `{}`", id.text);
    if !matches!(body.kind, YamlKind::Map(_)) {
        diags.push(
            Diagnostic::error(
                "expected-mapping",
                body.span,
                format!("{what} must be a mapping, found {}", body.type_name()),
            )
            .with_hint("write `{ op: name, params: {...}, in: {...} }`"),
        );
        return None;
    }
    let mut node = NodeSpec {
        id: id.text.clone(),
        id_span: id.span,
        op: String::new(),
        op_span: id.span,
        params: Vec::new(),
        inputs: Vec::new(),
        record: RecordSpec::default(),
        disabled: false,
        machine: None,
    };
    let mut has_op = false;
    for (key, value) in entries(body, &what, Some(NODE_KEYS), diags) {
        match key.text.as_str() {
            "op" => {
                has_op = true;
                node.op_span = value.span;
                node.op = string(value, &format!("`{}/op`", id.text), diags).unwrap_or_default();
            }
            "params" => node.params = param_entries(&id.text, value, diags),
            "in" => node.inputs = parse_inputs(&id.text, value, diags),
            "record" => node.record = parse_record(&id.text, value, diags),
            "disabled" => node.disabled = boolean(value, &format!("`{}/disabled`", id.text), diags).unwrap_or(false),
            "machine" => {
                node.machine = string(value, &format!("`{}/machine`", id.text), diags).map(|m| (m, value.span));
            }
            _ => {}
        }
    }
    if !has_op {
        diags.push(
            Diagnostic::error("missing-key", id.span, format!("{what} has no `op`"))
                .with_hint("add `op: <operator>`; `dynaflow ops` lists them"),
        );
    }
    Some(node)
}

fn param_entries(node: &str, value: &Yaml, diags: &mut Vec<Diagnostic>) -> Vec<(Key, Yaml)> {
    entries(value, &format!("`{node}/params`"), None, diags).into_iter().cloned().collect()
}

fn parse_machine(name: &Key, body: &Yaml, diags: &mut Vec<Diagnostic>) -> Option<MachineSpec> {
    let what = format!("machine `{}`", name.text);
    let hint = "write `{ endpoint: \"tcp/HOST:PORT\" }`: where this machine's process listens";
    if !matches!(body.kind, YamlKind::Map(_)) {
        diags.push(
            Diagnostic::error(
                "expected-mapping",
                body.span,
                format!("{what} must be a mapping, found {}", body.type_name()),
            )
            .with_hint(hint),
        );
        return None;
    }
    let mut endpoint = None;
    for (key, value) in entries(body, &what, Some(MACHINE_KEYS), diags) {
        if key.text == "endpoint" {
            endpoint = string(value, &format!("`{}/endpoint`", name.text), diags).map(|e| (e, value.span));
        }
    }
    let Some((endpoint, endpoint_span)) = endpoint else {
        diags.push(Diagnostic::error("missing-key", name.span, format!("{what} has no `endpoint`")).with_hint(hint));
        return None;
    };
    if let Err(why) = super::endpoint::check_endpoint(&endpoint) {
        diags.push(
            Diagnostic::error("bad-value", endpoint_span, format!("endpoint `{endpoint}` of {what}: {why}"))
                .with_hint("an endpoint such as `tcp/127.0.0.1:7447` (loopback) or `tls/robot.local:7447` (across a network, with `run --tls`)"),
        );
    }
    Some(MachineSpec { name: name.text.clone(), span: name.span, endpoint, endpoint_span })
}

fn parse_patch(variant: &str, node: &Key, body: &Yaml, diags: &mut Vec<Diagnostic>) -> NodePatch {
    let mut patch = NodePatch {
        node: node.text.clone(),
        node_span: node.span,
        op: None,
        disabled: None,
        params: Vec::new(),
        inputs: Vec::new(),
        record: None,
        machine: None,
    };
    let what = format!("variant `{variant}` patch of `{}`", node.text);
    for (key, value) in entries(body, &what, Some(PATCH_KEYS), diags) {
        match key.text.as_str() {
            "op" => {
                patch.op = string(value, &format!("`{}/op`", node.text), diags).map(|op| (op, value.span));
            }
            "params" => patch.params = param_entries(&node.text, value, diags),
            "in" => patch.inputs = parse_inputs(&node.text, value, diags),
            "record" => patch.record = Some(parse_record(&node.text, value, diags)),
            "disabled" => patch.disabled = boolean(value, &format!("`{}/disabled`", node.text), diags),
            "machine" => {
                patch.machine = string(value, &format!("`{}/machine`", node.text), diags).map(|m| (m, value.span));
            }
            _ => {}
        }
    }
    patch
}

/// Parse `node.port`.
pub(crate) fn parse_port_ref(value: &Yaml, node: &str, port: &str, diags: &mut Vec<Diagnostic>) -> Option<PortRef> {
    let text = string(value, &format!("input `{node}/{port}`"), diags)?;
    match text.split_once('.') {
        Some((n, p)) if valid_id(n) && valid_id(p) => {
            Some(PortRef { node: n.to_owned(), port: p.to_owned(), span: value.span })
        }
        _ => {
            let hint = match text.split_once('/') {
                Some((n, p)) => format!("write `{n}.{p}` (node and port are joined with a dot)"),
                None => "write `<node>.<output port>`, e.g. `camera.rgb`".to_owned(),
            };
            diags.push(
                Diagnostic::error(
                    "bad-port-ref",
                    value.span,
                    format!("input `{node}/{port}`: `{text}` is not a `node.port` reference"),
                )
                .with_hint(hint),
            );
            None
        }
    }
}

fn parse_inputs(node: &str, value: &Yaml, diags: &mut Vec<Diagnostic>) -> Vec<InputSpec> {
    let mut out = Vec::new();
    for (port, body) in entries(value, &format!("`{node}/in`"), None, diags) {
        check_id("port", &port.text, port.span, diags);
        let mut input = InputSpec {
            port: port.text.clone(),
            port_span: port.span,
            from: None,
            join: Join::Lockstep,
            delay: 0,
            queue: QueuePolicy::Block { capacity: DEFAULT_CAPACITY },
            queue_explicit: false,
            delay_valid: true,
        };
        if matches!(body.kind, YamlKind::Scalar { .. }) {
            input.from = parse_port_ref(body, node, &port.text, diags);
            out.push(input);
            continue;
        }
        let what = format!("input `{node}/{}`", port.text);
        let mut capacity: Option<(usize, Span)> = None;
        let mut has_from = false;
        for (key, v) in entries(body, &what, Some(INPUT_KEYS), diags) {
            match key.text.as_str() {
                "from" => {
                    has_from = true;
                    input.from = parse_port_ref(v, node, &port.text, diags);
                }
                "join" => match v.as_str() {
                    Some("lockstep") => input.join = Join::Lockstep,
                    Some("latest") => input.join = Join::Latest,
                    _ => diags.push(
                        Diagnostic::error(
                            "bad-value",
                            v.span,
                            format!("{what}: `join` must be `lockstep` or `latest`"),
                        )
                        .with_opt_hint(v.as_str().and_then(|s| did_you_mean(s, ["lockstep", "latest"]))),
                    ),
                },
                "delay" => match unsigned(v, &format!("{what}: `delay`"), u64::from(MAX_DELAY), diags) {
                    Some(d) => input.delay = u32::try_from(d).unwrap_or(MAX_DELAY),
                    None => input.delay_valid = false,
                },
                "queue" => {
                    input.queue_explicit = true;
                    if let Some(q) = parse_queue(v, &what, diags) {
                        input.queue = q;
                    }
                }
                "capacity" => {
                    input.queue_explicit = true;
                    if let Some(c) = unsigned(v, &format!("{what}: `capacity`"), MAX_CAPACITY as u64, diags) {
                        if c == 0 {
                            diags.push(Diagnostic::error(
                                "bad-value",
                                v.span,
                                format!("{what}: `capacity` must be at least 1"),
                            ));
                        } else {
                            capacity = Some((c as usize, v.span));
                        }
                    }
                }
                _ => {}
            }
        }
        if !has_from && matches!(body.kind, YamlKind::Map(_)) {
            diags.push(
                Diagnostic::error("missing-key", port.span, format!("{what} has no `from`"))
                    .with_hint("add `from: <node>.<port>`"),
            );
        }
        if let Some((c, span)) = capacity {
            match &mut input.queue {
                QueuePolicy::Block { capacity } => *capacity = c,
                QueuePolicy::DropOldest { .. } => diags.push(
                    Diagnostic::error("bad-value", span, format!("{what}: `capacity` applies to `block` queues"))
                        .with_hint("a dropping queue's length is its `drop_oldest: N`"),
                ),
            }
        }
        out.push(input);
    }
    out
}

fn parse_queue(v: &Yaml, what: &str, diags: &mut Vec<Diagnostic>) -> Option<QueuePolicy> {
    let hint = "use `block`, `latest` or `{ drop_oldest: N }`";
    match (&v.kind, v.as_str()) {
        (_, Some("block")) => Some(QueuePolicy::Block { capacity: DEFAULT_CAPACITY }),
        (_, Some("latest")) => Some(QueuePolicy::DropOldest { capacity: 1 }),
        (YamlKind::Map(list), _) if list.len() == 1 && list.first().is_some_and(|(k, _)| k.text == "drop_oldest") => {
            let n = list.first().map(|(_, n)| n)?;
            match unsigned(n, &format!("{what}: `drop_oldest`"), MAX_CAPACITY as u64, diags) {
                Some(0) => {
                    diags.push(Diagnostic::error(
                        "bad-value",
                        n.span,
                        format!("{what}: `drop_oldest` must be at least 1"),
                    ));
                    None
                }
                Some(c) => Some(QueuePolicy::DropOldest { capacity: c as usize }),
                None => None,
            }
        }
        _ => {
            let suggestion = v.as_str().and_then(|s| did_you_mean(s, ["block", "latest", "drop_oldest"]));
            diags.push(
                Diagnostic::error("bad-value", v.span, format!("{what}: unknown queue policy"))
                    .with_hint(suggestion.map_or_else(|| hint.to_owned(), |s| format!("{s} ({hint})"))),
            );
            None
        }
    }
}

fn parse_record_policy(v: &Yaml, what: &str, diags: &mut Vec<Diagnostic>) -> Option<RecordPolicy> {
    let bad = |diags: &mut Vec<Diagnostic>| {
        diags.push(
            Diagnostic::error("bad-value", v.span, format!("{what}: unknown record policy"))
                .with_hint("use `all`, `none`, `every N` or `{ every: N }`"),
        );
        None
    };
    match &v.kind {
        YamlKind::Scalar { text, .. } => match text.as_str() {
            "all" => Some(RecordPolicy::All),
            "none" => Some(RecordPolicy::None),
            other => match other.strip_prefix("every").map(str::trim).map(str::parse::<u64>) {
                Some(Ok(n)) if n >= 1 => Some(RecordPolicy::Every(n)),
                _ => bad(diags),
            },
        },
        YamlKind::Map(list) if list.len() == 1 => match list.first() {
            Some((k, n)) if k.text == "every" => match n.to_json().as_u64() {
                Some(n) if n >= 1 => Some(RecordPolicy::Every(n)),
                _ => bad(diags),
            },
            _ => bad(diags),
        },
        _ => bad(diags),
    }
}

fn parse_record(node: &str, value: &Yaml, diags: &mut Vec<Diagnostic>) -> RecordSpec {
    let what = format!("`{node}/record`");
    let is_port_map = matches!(&value.kind, YamlKind::Map(list) if !(list.len() == 1 && list.first().is_some_and(|(k, _)| k.text == "every")));
    if !is_port_map {
        return RecordSpec { default: parse_record_policy(value, &what, diags), ports: Vec::new() };
    }
    let mut spec = RecordSpec::default();
    for (port, v) in entries(value, &what, None, diags) {
        if let Some(p) = parse_record_policy(v, &format!("`{node}/record/{}`", port.text), diags) {
            spec.ports.push((port.text.clone(), port.span, p));
        }
    }
    spec
}
