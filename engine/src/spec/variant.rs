//! Variants and command-line overrides: both patch a [`GraphSpec`] before validation, so a
//! variant is checked exactly like the base graph.

use super::{GraphSpec, NodePatch, VariantSpec};
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

/// The variants `name` stands for, in order: the variant of that name, or variants joined
/// by `+` (`mono+no_loop`). A variant's own name may contain `+` (an ablation row such as
/// `S+G`): the longest name that is a variant is taken first at each step, so `S+G+no_loop` is
/// `S+G` then `no_loop`. `None` when no split names only variants.
pub fn variant_parts<'a>(spec: &'a GraphSpec, name: &str) -> Option<Vec<&'a VariantSpec>> {
    fn split<'a>(spec: &'a GraphSpec, tokens: &[&str], out: &mut Vec<&'a VariantSpec>) -> bool {
        if tokens.is_empty() {
            return !out.is_empty();
        }
        for end in (1..=tokens.len()).rev() {
            let candidate = tokens[..end].join("+");
            if let Some(v) = spec.variants.iter().find(|v| v.name == candidate) {
                out.push(v);
                if split(spec, &tokens[end..], out) {
                    return true;
                }
                out.pop();
            }
        }
        false
    }
    let tokens: Vec<&str> = name.split('+').collect();
    let mut out = Vec::new();
    split(spec, &tokens, &mut out).then_some(out)
}

/// What a patch sets, for telling whether two composed variants set the same thing.
#[derive(Clone, Debug, PartialEq)]
enum Setting {
    Disabled(bool),
    Machine(String),
    Op(String),
    Param(String, Yaml),
    Input(String),
    Record,
}

impl Setting {
    fn of(patch: &NodePatch) -> Vec<Self> {
        let mut out = Vec::new();
        if let Some(d) = patch.disabled {
            out.push(Self::Disabled(d));
        }
        if let Some((m, _)) = &patch.machine {
            out.push(Self::Machine(m.clone()));
        }
        if let Some((op, _)) = &patch.op {
            out.push(Self::Op(op.clone()));
        }
        out.extend(patch.params.iter().map(|(k, v)| Self::Param(k.text.clone(), v.clone())));
        out.extend(patch.inputs.iter().map(|i| Self::Input(i.port.clone())));
        if patch.record.is_some() {
            out.push(Self::Record);
        }
        out
    }

    /// Whether `self` and a later `other` on the same node collide: both set one thing (a
    /// flag or a parameter set to the same value is no collision: the order cannot matter),
    /// or `other` puts an operator in the node (even the same one), which drops what `self`
    /// set on it.
    fn collides(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::Disabled(a), Self::Disabled(b)) => a != b,
            (Self::Machine(a), Self::Machine(b)) => a != b,
            (Self::Param(a, va), Self::Param(b, vb)) => a == b && !same_value(va, vb),
            (Self::Input(a), Self::Input(b)) => a == b,
            (Self::Record, Self::Record) => true,
            (Self::Param(..) | Self::Input(_) | Self::Op(_), Self::Op(_)) => true,
            _ => false,
        }
    }

    fn describe(&self) -> String {
        match self {
            Self::Disabled(_) => "`disabled`".into(),
            Self::Machine(_) => "`machine`".into(),
            Self::Op(_) => "`op`".into(),
            Self::Param(k, _) => format!("param `{k}`"),
            Self::Input(p) => format!("input `{p}`"),
            Self::Record => "`record`".into(),
        }
    }
}

/// Two YAML values equal as values (their places in the file aside).
fn same_value(a: &Yaml, b: &Yaml) -> bool {
    match (&a.kind, &b.kind) {
        (YamlKind::Scalar { text: x, .. }, YamlKind::Scalar { text: y, .. }) => x == y,
        (YamlKind::Seq(x), YamlKind::Seq(y)) => x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same_value(p, q)),
        (YamlKind::Map(x), YamlKind::Map(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|((kp, p), (kq, q))| kp.text == kq.text && same_value(p, q))
        }
        _ => false,
    }
}

/// Apply the variant `name`: one variant, or several joined by `+`, applied in order
/// ([`variant_parts`]). An unknown variant is an `Err`. Patches of unknown nodes are errors
/// too, returned beside the spec with the other patches applied, so validation of the rest
/// still runs and reports everything else at once; so is a composed variant setting what an
/// earlier one in the list set (to another value), located at the later one's patch.
pub fn apply_variant(spec: &GraphSpec, name: &str) -> Result<(GraphSpec, Vec<Diagnostic>), Vec<Diagnostic>> {
    let Some(parts) = variant_parts(spec, name) else {
        let unknown = name.split('+').find(|p| !spec.variants.iter().any(|v| v.name == *p)).unwrap_or(name);
        let hint = did_you_mean(unknown, spec.variants.iter().map(|v| v.name.as_str())).unwrap_or_else(|| {
            if spec.variants.is_empty() {
                "this graph defines no variants".to_owned()
            } else {
                format!(
                    "variants: {} (join several with `+`, or repeat `--variant`)",
                    spec.variants.iter().map(|v| v.name.as_str()).collect::<Vec<_>>().join(", ")
                )
            }
        });
        return Err(vec![
            Diagnostic::error("unknown-variant", None, format!("unknown variant `{name}`")).with_hint(hint),
        ]);
    };
    let mut out = spec.clone();
    let mut diags = Vec::new();
    // What each earlier variant of the list set: (variant, node, setting).
    let mut set: Vec<(&str, &str, Setting)> = Vec::new();
    let mut oracle_by: Option<(&str, bool)> = None;
    for variant in &parts {
        if let Some((o, span)) = variant.oracle {
            if let Some((by, earlier)) = oracle_by.filter(|&(_, e)| e != o) {
                diags.push(
                    Diagnostic::error(
                        "variant-conflict",
                        Some(span),
                        format!(
                            "variant `{}` sets `oracle: {o}`, variant `{by}` before it `oracle: {earlier}`",
                            variant.name
                        ),
                    )
                    .with_hint("leave one of the two out, or write a variant that combines them"),
                );
            }
            oracle_by = Some((&variant.name, o));
            out.oracle = variant.oracle;
        }
        let mut mine = Vec::new();
        for patch in &variant.patches {
            for s in Setting::of(patch) {
                if let Some((by, _, first)) = set.iter().find(|(_, n, e)| *n == patch.node && e.collides(&s)) {
                    diags.push(
                        Diagnostic::error(
                            "variant-conflict",
                            Some(patch.node_span),
                            format!(
                                "variant `{}` sets {} of node `{}`, which variant `{by}` before it sets ({})",
                                variant.name,
                                s.describe(),
                                patch.node,
                                first.describe()
                            ),
                        )
                        .with_hint("leave one of the two out, or write a variant that combines them"),
                    );
                }
                mine.push((variant.name.as_str(), patch.node.as_str(), s));
            }
            if !apply_patch(&mut out, patch) {
                diags.push(
                    Diagnostic::error(
                        "unknown-node",
                        patch.node_span,
                        format!("variant `{}` patches unknown node `{}`", variant.name, patch.node),
                    )
                    .with_opt_hint(did_you_mean(&patch.node, spec.nodes.iter().map(|n| n.id.as_str()))),
                );
            }
        }
        set.extend(mine);
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
