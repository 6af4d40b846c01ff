//! Parameter validation: every value of a node's `params` against its operator's declared
//! type, each list item and map entry at its own place in the file, defaults filled in.

use super::NodeSpec;
use super::validate::ResolveContext;
use crate::diag::{Diagnostic, did_you_mean};
use crate::op::{OpSpec, ParamSpec, ParamType, Params};
use crate::yaml::{Span, Yaml, YamlKind};

pub(super) fn check_params(n: &NodeSpec, op: &OpSpec, cx: &ResolveContext, diags: &mut Vec<Diagnostic>) -> Params {
    let mut values = serde_json::Map::new();
    for (key, value) in &n.params {
        let Some(p) = op.param(&key.text) else {
            let hint = did_you_mean(&key.text, op.params.iter().map(|p| p.name)).unwrap_or_else(|| {
                if op.params.is_empty() {
                    format!("`{}` takes no parameters", op.name)
                } else {
                    format!("`{}` takes: {}", op.name, op.params.iter().map(|p| p.name).collect::<Vec<_>>().join(", "))
                }
            });
            diags.push(
                Diagnostic::error(
                    "unknown-param",
                    key.span,
                    format!("node `{}`: unknown param `{}` for op `{}`", n.id, key.text, op.name),
                )
                .with_hint(hint),
            );
            continue;
        };
        if let Some(v) = check_value(n, p, value, diags) {
            values.insert(p.name.to_owned(), v);
        }
    }
    for p in op.params {
        if values.contains_key(p.name)
            || n.params.iter().any(|(k, _)| k.text == p.name)
            || matches!(p.default, crate::op::Default::FromGraphSeed)
        {
            continue;
        }
        match p.default.to_json() {
            Some(v) => {
                values.insert(p.name.to_owned(), v);
            }
            None => diags.push(
                Diagnostic::error(
                    "missing-param",
                    n.id_span,
                    format!("node `{}`: required param `{}` is missing", n.id, p.name),
                )
                .with_hint(format!(
                    "add `params: {{ {}: <{}> }}` ({})",
                    p.name,
                    p.ty.describe(),
                    p.doc
                )),
            ),
        }
    }
    Params::new(values, cx.base_dir.clone())
}

/// Check one value against its declaration.
fn check_value(n: &NodeSpec, p: &ParamSpec, value: &Yaml, diags: &mut Vec<Diagnostic>) -> Option<serde_json::Value> {
    check_typed(&format!("node `{}`", n.id), p.name, &p.ty, p.doc, value, diags)
}

/// Check `value` against `ty`, each list item and map entry at its own span. Range checks are
/// written as containment so NaN and infinities fail.
fn check_typed(
    node: &str,
    path: &str,
    ty: &ParamType,
    doc: &str,
    value: &Yaml,
    diags: &mut Vec<Diagnostic>,
) -> Option<serde_json::Value> {
    let what = format!("{node}: param `{path}`");
    let json = value.to_json();
    let bad_type = |diags: &mut Vec<Diagnostic>| {
        diags.push(
            Diagnostic::error(
                "param-type",
                value.span,
                format!("{what} expects {}, found {}", ty.describe(), value.type_name()),
            )
            .with_hint(doc.to_owned()),
        );
        None
    };
    let out_of_range = |diags: &mut Vec<Diagnostic>,
                        v: &dyn std::fmt::Display,
                        min: &dyn std::fmt::Display,
                        max: &dyn std::fmt::Display| {
        diags.push(
            Diagnostic::error("param-range", value.span, format!("{what} = {v} is out of range {min}..={max}"))
                .with_hint(doc.to_owned()),
        );
        None
    };
    match *ty {
        ParamType::Bool => json.is_boolean().then_some(json).or_else(|| bad_type(diags)),
        ParamType::Int { min, max } => match json.as_i64() {
            Some(v) if (min..=max).contains(&v) => Some(json),
            Some(v) => out_of_range(diags, &v, &min, &max),
            None => bad_type(diags),
        },
        ParamType::Float { min, max } => match json.as_f64() {
            Some(v) if (min..=max).contains(&v) => Some(json),
            Some(v) => out_of_range(diags, &v, &min, &max),
            None => match value.as_str() {
                // `.nan`/`.inf` and friends: numbers, but never in range.
                Some(s)
                    if matches!(
                        s.to_ascii_lowercase().as_str(),
                        ".nan" | ".inf" | "-.inf" | "+.inf" | "nan" | "inf"
                    ) =>
                {
                    diags.push(
                        Diagnostic::error(
                            "param-range",
                            value.span,
                            format!("{what} = {s} is out of range {min}..={max}"),
                        )
                        .with_hint("the value must be a finite number"),
                    );
                    None
                }
                _ => bad_type(diags),
            },
        },
        ParamType::Str | ParamType::Path => match &value.kind {
            YamlKind::Scalar { text, .. } if !value.is_null() => Some(serde_json::Value::String(text.clone())),
            _ => bad_type(diags),
        },
        ParamType::Text { check, .. } => match &value.kind {
            YamlKind::Scalar { text, .. } if !value.is_null() => match check(text) {
                Ok(()) => Some(serde_json::Value::String(text.clone())),
                Err(why) => {
                    diags.push(
                        Diagnostic::error("param-value", value.span, format!("{what}: {why}"))
                            .with_hint(format!("write {}", ty.describe())),
                    );
                    None
                }
            },
            _ => bad_type(diags),
        },
        ParamType::Enum { values } => match value.as_str() {
            Some(s) if values.contains(&s) => Some(serde_json::Value::String(s.to_owned())),
            Some(s) => {
                let hint = did_you_mean(s, values.iter().copied()).unwrap_or_else(|| ty.describe());
                diags.push(
                    Diagnostic::error("param-value", value.span, format!("{what}: `{s}` is not {}", ty.describe()))
                        .with_hint(hint),
                );
                None
            }
            None => bad_type(diags),
        },
        ParamType::List { item } => {
            let items: Vec<Yaml> = match &value.kind {
                YamlKind::Seq(items) => items.clone(),
                YamlKind::Scalar { text, quoted } if !value.is_null() => {
                    comma_items(text, *quoted, value.span).into_iter().map(|(t, span)| Yaml::scalar(t, span)).collect()
                }
                _ => return bad_type(diags),
            };
            let mut ok = true;
            let mut out = Vec::new();
            for (i, v) in items.iter().enumerate() {
                match check_typed(node, &format!("{path}[{i}]"), item, doc, v, diags) {
                    Some(j) => out.push(j),
                    None => ok = false,
                }
            }
            ok.then_some(serde_json::Value::Array(out))
        }
        ParamType::Map { key, value: vty } => {
            let entries: Vec<(Yaml, Yaml)> = match &value.kind {
                YamlKind::Map(entries) => {
                    entries.iter().map(|(k, v)| (Yaml::quoted(k.text.clone(), k.span), v.clone())).collect()
                }
                YamlKind::Scalar { text, quoted } if !value.is_null() => {
                    let mut entries = Vec::new();
                    for (pair, span) in comma_items(text, *quoted, value.span) {
                        let Some((k, v)) = pair.split_once('=') else {
                            diags.push(
                                Diagnostic::error("param-value", span, format!("{what}: `{pair}` is not `key=value`"))
                                    .with_hint(format!("write a mapping, e.g. `{{ {pair}: <value> }}`")),
                            );
                            return None;
                        };
                        let vspan = Span::new(span.offset + k.len() + 1, v.len());
                        entries.push((
                            Yaml::quoted(k.trim(), Span::new(span.offset, k.len())),
                            Yaml::scalar(v.trim(), vspan),
                        ));
                    }
                    entries
                }
                _ => return bad_type(diags),
            };
            let mut ok = true;
            let mut out = serde_json::Map::new();
            for (k, v) in &entries {
                let kj = check_typed(node, &format!("{path}` key `{}", k.as_str().unwrap_or("?")), key, doc, k, diags);
                let vj = check_typed(node, &format!("{path}.{}", k.as_str().unwrap_or("?")), vty, doc, v, diags);
                match (kj, vj) {
                    (Some(serde_json::Value::String(k)), Some(v)) => {
                        out.insert(k, v);
                    }
                    _ => ok = false,
                }
            }
            ok.then_some(serde_json::Value::Object(out))
        }
    }
}

/// The items of a comma-separated scalar with their spans.
fn comma_items(text: &str, quoted: bool, span: Span) -> Vec<(String, Span)> {
    // A plain scalar's text starts where it is written, a quoted one's after its quote (the
    // span may run on over trailing blanks; escapes inside quotes would shift the items, so a
    // quoted text shorter than written, less its quotes, keeps the whole span).
    let start = match span.len.checked_sub(text.len()) {
        Some(_) if !quoted => Some(span.offset),
        Some(d) if d >= 2 && !text.contains(['\\', '\'']) => Some(span.offset + 1),
        _ => None,
    };
    crate::op::comma_items(text)
        .map(|(at, item)| (item.to_owned(), start.map_or(span, |o| Span::new(o + at, item.len()))))
        .collect()
}
