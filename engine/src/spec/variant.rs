//! Variants and command-line overrides: both patch a [`GraphSpec`] before validation, so a
//! variant is checked exactly like the base graph.

use super::{GraphSpec, NodePatch};
use crate::diag::{Diagnostic, did_you_mean};
use crate::yaml::{self, Key, Yaml, YamlKind};

/// A `--set node.param=value` override.
#[derive(Clone, Debug, PartialEq)]
pub struct Override {
    /// Target node id.
    pub node: String,
    /// Parameter key.
    pub param: String,
    /// The value, parsed as YAML (so `3`, `true`, `[1, 2]` and `abc` all work).
    pub value: Yaml,
    /// The flag as given, for messages (`--set node.param=value`, `--save-map FILE`).
    pub text: String,
}

impl Override {
    /// Parse `node.param=value`.
    pub fn parse(text: &str) -> Result<Self, String> {
        let (path, value) =
            text.split_once('=').ok_or_else(|| format!("`--set {text}`: expected `node.param=value`"))?;
        let (node, param) = path
            .split_once('.')
            .ok_or_else(|| format!("`--set {text}`: expected `node.param=value` (no `.` in `{path}`)"))?;
        let value =
            yaml::parse(value).map_err(|e| format!("`--set {text}`: value is not valid YAML: {}", e.message))?;
        Ok(Self { node: node.trim().to_owned(), param: param.trim().to_owned(), value, text: format!("--set {text}") })
    }
}

fn merge_params(into: &mut Vec<(Key, Yaml)>, patch: &[(Key, Yaml)]) {
    for (k, v) in patch {
        match into.iter_mut().find(|(ek, _)| ek.text == k.text) {
            Some(slot) => *slot = (k.clone(), v.clone()),
            None => into.push((k.clone(), v.clone())),
        }
    }
}

fn apply_patch(spec: &mut GraphSpec, patch: &NodePatch) -> bool {
    let Some(node) = spec.nodes.iter_mut().find(|n| n.id == patch.node) else {
        return false;
    };
    if let Some(d) = patch.disabled {
        node.disabled = d;
    }
    if let Some(m) = &patch.machine {
        node.machine = Some(m.clone());
    }
    if let Some((op, span)) = &patch.op {
        node.op.clone_from(op);
        node.op_span = *span;
        node.params.clear();
        node.inputs.clear();
    }
    merge_params(&mut node.params, &patch.params);
    for input in &patch.inputs {
        match node.inputs.iter_mut().find(|i| i.port == input.port) {
            Some(slot) => *slot = input.clone(),
            None => node.inputs.push(input.clone()),
        }
    }
    if let Some(r) = &patch.record {
        node.record = r.clone();
    }
    true
}

/// Apply the variant `name`. An unknown variant is an `Err`. Patches of unknown nodes are
/// errors too, returned beside the spec with the other patches applied, so validation of the
/// rest still runs and reports everything else at once.
pub fn apply_variant(spec: &GraphSpec, name: &str) -> Result<(GraphSpec, Vec<Diagnostic>), Vec<Diagnostic>> {
    let Some(variant) = spec.variants.iter().find(|v| v.name == name) else {
        let hint = did_you_mean(name, spec.variants.iter().map(|v| v.name.as_str())).unwrap_or_else(|| {
            if spec.variants.is_empty() {
                "this graph defines no variants".to_owned()
            } else {
                format!("variants: {}", spec.variants.iter().map(|v| v.name.as_str()).collect::<Vec<_>>().join(", "))
            }
        });
        return Err(vec![
            Diagnostic::error("unknown-variant", None, format!("unknown variant `{name}`")).with_hint(hint),
        ]);
    };
    let mut out = spec.clone();
    if variant.oracle.is_some() {
        out.oracle = variant.oracle;
    }
    let mut diags = Vec::new();
    for patch in &variant.patches {
        if !apply_patch(&mut out, patch) {
            diags.push(
                Diagnostic::error(
                    "unknown-node",
                    patch.node_span,
                    format!("variant `{name}` patches unknown node `{}`", patch.node),
                )
                .with_opt_hint(did_you_mean(&patch.node, spec.nodes.iter().map(|n| n.id.as_str()))),
            );
        }
    }
    Ok((out, diags))
}

/// Where each `--set` value stands in for the file: diagnostics at its `marker` span belong
/// at `at` (the overridden node's id) and say which flag they came from.
#[derive(Clone, Debug, Default)]
pub struct OverrideOrigins(Vec<(yaml::Span, yaml::Span, String)>);

impl OverrideOrigins {
    /// Move diagnostics on an override's value onto its node, naming the flag.
    pub fn attribute(&self, diags: &mut [Diagnostic]) {
        for d in diags {
            if let Some((_, at, text)) = self.0.iter().find(|(m, _, _)| Some(*m) == d.span) {
                d.span = Some(*at);
                d.message = format!("`{text}`: {}", d.message);
            }
        }
    }
}

/// Apply `--set` overrides. Each value (and its key) gets a span of its own past the end of
/// the file, so the diagnostics validation gives on it can be told apart and moved onto the
/// overridden node with the flag named ([`OverrideOrigins::attribute`]).
pub fn apply_overrides(spec: &mut GraphSpec, overrides: &[Override]) -> (Vec<Diagnostic>, OverrideOrigins) {
    let mut diags = Vec::new();
    let mut origins = OverrideOrigins::default();
    for (i, o) in overrides.iter().enumerate() {
        let known: Vec<String> = spec.nodes.iter().map(|n| n.id.clone()).collect();
        let Some(node) = spec.nodes.iter_mut().find(|n| n.id == o.node) else {
            diags.push(
                Diagnostic::error("unknown-node", None, format!("`{}`: no node `{}`", o.text, o.node))
                    .with_opt_hint(did_you_mean(&o.node, known.iter().map(String::as_str))),
            );
            continue;
        };
        let marker = yaml::Span::new(usize::MAX - i, 0);
        origins.0.push((marker, node.id_span, o.text.clone()));
        let value = respan(&o.value, marker);
        merge_params(&mut node.params, &[(Key { text: o.param.clone(), span: marker }, value)]);
    }
    (diags, origins)
}

fn respan(v: &Yaml, span: yaml::Span) -> Yaml {
    let kind = match &v.kind {
        YamlKind::Scalar { .. } => v.kind.clone(),
        YamlKind::Seq(items) => YamlKind::Seq(items.iter().map(|i| respan(i, span)).collect()),
        YamlKind::Map(entries) => {
            YamlKind::Map(entries.iter().map(|(k, v)| (Key { text: k.text.clone(), span }, respan(v, span))).collect())
        }
    };
    Yaml { kind, span }
}
