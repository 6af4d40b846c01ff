//! From a graph file on disk to a validated graph, with every diagnostic.

use std::path::{Path, PathBuf};

use crate::diag::{Diagnostic, Source};
use crate::op::Registry;
use crate::spec::{self, GraphSpec, Override, ResolvedGraph};
use crate::yaml;

/// What to apply on top of the file.
#[derive(Clone, Debug, Default)]
pub struct LoadRequest {
    /// `--variant`.
    pub variant: Option<String>,
    /// `--set node.param=value`.
    pub overrides: Vec<Override>,
    /// `--seed`.
    pub seed: Option<u64>,
    /// Also validate every variant (what `dynaflow validate` does).
    pub all_variants: bool,
    /// `--input DIR`: replace the graph's single source with this reader.
    pub source: Option<SourceOverride>,
    /// `--save-map`, `--load-map`, `--localise`: set on the graph's map-keeping node.
    pub map: MapRequest,
}

/// `dynaflow run --save-map FILE --load-map FILE --localise`: what the graph's one enabled
/// node with a map ([`crate::op::OpSpec::map_store`], the tracker) gets, through the
/// parameters its operator names (typed: no parameter name or node id is spelled here).
#[derive(Clone, Debug, Default)]
pub struct MapRequest {
    /// Write the map here at the end.
    pub save: Option<PathBuf>,
    /// Start in this map.
    pub load: Option<PathBuf>,
    /// Localisation mode: no new key frames.
    pub localise: bool,
}

impl MapRequest {
    /// Whether it asks for nothing.
    pub fn is_empty(&self) -> bool {
        self.save.is_none() && self.load.is_none() && !self.localise
    }

    /// The overrides it makes of `spec` (after its variant): one per flag, on the one enabled
    /// node whose operator keeps a map; an error when there is no such node, or several.
    pub fn overrides(&self, spec: &GraphSpec, registry: &Registry) -> Result<Vec<Override>, Diagnostic> {
        if self.is_empty() {
            return Ok(Vec::new());
        }
        let keepers: Vec<(&str, crate::op::MapStore)> = spec
            .nodes
            .iter()
            .filter(|n| !n.disabled)
            .filter_map(|n| Some((n.id.as_str(), registry.get(&n.op)?.map_store?)))
            .collect();
        let [(node, store)] = keepers.as_slice() else {
            let names: Vec<&str> = keepers.iter().map(|(n, _)| *n).collect();
            return Err(Diagnostic::error(
                "map-store",
                None,
                format!(
                    "--save-map, --load-map and --localise need one enabled tracker in the graph, it has {}{}",
                    keepers.len(),
                    if names.is_empty() { String::new() } else { format!(" ({})", names.join(", ")) }
                ),
            )
            .with_hint("set the `save_map`, `load_map` and `mapping` params of the tracker you mean with --set"));
        };
        let scalar = |text: String, quoted: bool| yaml::Yaml {
            kind: yaml::YamlKind::Scalar { text, quoted },
            span: yaml::Span::new(0, 0),
        };
        // Relative to the working directory, as typed (graph params resolve against the graph
        // file's folder).
        let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        let mut out = Vec::new();
        let mut set = |param: &str, value: yaml::Yaml, text: String| {
            out.push(Override { node: (*node).to_owned(), param: param.to_owned(), value, text });
        };
        if let Some(p) = &self.save {
            set(store.save, scalar(abs(p).display().to_string(), true), format!("--save-map {}", p.display()));
        }
        if let Some(p) = &self.load {
            set(store.load, scalar(abs(p).display().to_string(), true), format!("--load-map {}", p.display()));
        }
        if self.localise {
            set(store.mapping, scalar("false".into(), false), "--localise".into());
        }
        Ok(out)
    }
}

/// A replacement for the graph's source node (`dynaflow run --input DIR`).
#[derive(Clone, Debug, Default)]
pub struct SourceOverride {
    /// Reader operator, e.g. `tum_rgbd`.
    pub op: String,
    /// Its parameters (values are YAML, like `--set`).
    pub params: Vec<(String, String)>,
    /// What the user gave, for messages (`--input DIR`).
    pub origin: String,
}

/// Point the graph's only source node at another reader.
fn apply_source(spec: &mut GraphSpec, registry: &Registry, over: &SourceOverride) -> Vec<Diagnostic> {
    let sources: Vec<usize> = spec
        .nodes
        .iter()
        .enumerate()
        .filter(|(_, n)| registry.get(&n.op).is_some_and(|op| op.kind == crate::op::OpKind::Source))
        .map(|(i, _)| i)
        .collect();
    let [i] = sources.as_slice() else {
        let names: Vec<String> =
            sources.iter().filter_map(|i| spec.nodes.get(*i)).map(|n| format!("`{}`", n.id)).collect();
        return vec![
            Diagnostic::error(
                "input-ambiguous",
                None,
                format!(
                    "`{}` replaces the graph's source, but the graph has {} source nodes ({})",
                    over.origin,
                    sources.len(),
                    names.join(", ")
                ),
            )
            .with_hint("use a graph with exactly one source, or set the reader's `path` with --set"),
        ];
    };
    let Some(node) = spec.nodes.get_mut(*i) else { return Vec::new() };
    let span = node.id_span;
    let old_op = registry.get(&node.op);
    node.op = over.op.clone();
    node.op_span = span;
    node.params = over
        .params
        .iter()
        .map(|(k, v)| {
            (
                crate::yaml::Key { text: k.clone(), span },
                crate::yaml::Yaml { kind: crate::yaml::YamlKind::Scalar { text: v.clone(), quoted: true }, span },
            )
        })
        .collect();
    tracing::info!("`{}`: node `{}` now reads with `{}`", over.origin, node.id, over.op);
    let source_id = node.id.clone();
    // Ground truth the old source had and the new reader lacks (KITTI has no masks, an image
    // folder no poses): optional inputs fed by it are unwired, and nodes that need it (and
    // nodes that need those) are left out of the run, each said in a warning. Other ports the
    // reader lacks (an image folder has no depth) unwire the optional inputs they fed.
    let new_op = registry.get(&over.op);
    let missing = |port: &str| new_op.is_some_and(|n| !n.outputs.iter().any(|p| p.name == port));
    let ground_truth = |port: &str| old_op.is_some_and(|o| o.outputs.iter().any(|p| p.name == port && p.ground_truth));
    let reads_missing = |f: &crate::spec::PortRef| f.node == source_id && missing(&f.port);
    if !spec.nodes.iter().any(|n| n.inputs.iter().any(|i| i.from.as_ref().is_some_and(reads_missing))) {
        return Vec::new();
    }
    let mut diags = Vec::new();
    let mut removed: Vec<String> = Vec::new();
    loop {
        let mut changed = false;
        let mut keep = Vec::with_capacity(spec.nodes.len());
        for mut n in std::mem::take(&mut spec.nodes) {
            // A disabled node (it runs in no frame) that reads a port the reader lacks is left
            // out quietly: variants were applied before this, so none can enable it.
            if n.disabled && n.inputs.iter().any(|i| i.from.as_ref().is_some_and(reads_missing)) {
                tracing::info!(
                    "`{}`: disabled node `{}` reads a port `{}` lacks; left out",
                    over.origin,
                    n.id,
                    over.op
                );
                removed.push(n.id.clone());
                changed = true;
                continue;
            }
            let op = registry.get(&n.op);
            let needed =
                |port: &str| op.is_some_and(|o| o.inputs.iter().any(|p| p.name == port && (p.required || p.wired)));
            // Lost ground truth, or the output of a node left out.
            let gone =
                |f: &crate::spec::PortRef| (reads_missing(f) && ground_truth(&f.port)) || removed.contains(&f.node);
            if n.inputs.iter().any(|inp| inp.from.as_ref().is_some_and(gone) && needed(&inp.port)) {
                let what: Vec<String> = n
                    .inputs
                    .iter()
                    .filter_map(|inp| inp.from.as_ref().filter(|f| gone(f)).map(|f| format!("`{}.{}`", f.node, f.port)))
                    .collect();
                diags.push(Diagnostic::warning(
                    "input-lacks-ground-truth",
                    Some(n.id_span),
                    format!(
                        "`{}`: node `{}` is left out of the run: it needs {}, which `{}` does not have",
                        over.origin,
                        n.id,
                        what.join(", "),
                        over.op
                    ),
                ));
                removed.push(n.id.clone());
                changed = true;
                continue;
            }
            // An optional input (one the node runs without: a monocular tracker's `depth`, a
            // tracker's `gt_pose`) fed by what the reader lacks is unwired; a needed one that is
            // not ground truth stays, and validation names the missing port at its place in
            // the file (a culling rule that judges with depth, on a reader without depth).
            let before = n.inputs.len();
            let optional =
                |port: &str| op.is_some_and(|o| o.inputs.iter().any(|p| p.name == port && !p.required && !p.wired));
            n.inputs
                .retain(|inp| !inp.from.as_ref().is_some_and(|f| gone(f) || (reads_missing(f) && optional(&inp.port))));
            if n.inputs.len() < before {
                changed = true;
                tracing::info!("`{}`: node `{}` runs without what `{}` does not give", over.origin, n.id, over.op);
            }
            keep.push(n);
        }
        spec.nodes = keep;
        if !changed {
            break;
        }
    }
    diags
}

/// The outcome of loading a graph.
#[derive(Debug)]
pub struct Loaded {
    /// The text, for rendering diagnostics.
    pub source: Source,
    /// The parsed spec, if the YAML parsed.
    pub spec: Option<GraphSpec>,
    /// The resolved graph, if there was no error.
    pub graph: Option<ResolvedGraph>,
    /// Errors and warnings, in file order.
    pub diagnostics: Vec<Diagnostic>,
}

impl Loaded {
    /// Whether any diagnostic is an error.
    pub fn has_errors(&self) -> bool {
        self.diagnostics.iter().any(Diagnostic::is_error)
    }
}

/// Read and validate a graph file. Only an unreadable file is an `Err`; everything wrong with
/// its content is a diagnostic.
pub fn load(path: &Path, registry: &Registry, req: &LoadRequest) -> Result<Loaded, std::io::Error> {
    let bytes = std::fs::read(path)?;
    let text = String::from_utf8(bytes).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
        )
    })?;
    let base = path.parent().map(Path::to_path_buf);
    Ok(load_str(&path.display().to_string(), &text, base, registry, req))
}

/// Validate graph text.
pub fn load_str(
    name: &str,
    text: &str,
    base_dir: Option<std::path::PathBuf>,
    registry: &Registry,
    req: &LoadRequest,
) -> Loaded {
    let source = Source::new(name, text);
    let doc = match yaml::parse(text) {
        Ok(doc) => doc,
        Err(e) => {
            let d = Diagnostic::error("yaml-syntax", e.span, format!("YAML syntax error: {}", e.message))
                .with_hint("check indentation, `:` after keys, and matching brackets/quotes");
            return Loaded { source, spec: None, graph: None, diagnostics: vec![d] };
        }
    };
    let (base_spec, mut diags) = spec::parse_graph(&doc);
    let cx = spec::ResolveContext {
        source_name: name.to_owned(),
        source_text: text.into(),
        base_dir,
        seed: req.seed,
        variant: req.variant.clone(),
    };
    let mut graph;
    // Validation runs even after parse errors (on what did parse), so every problem shows
    // at once; the parser leaves out what it could not understand.
    {
        let mut spec = base_spec.clone();
        if let Some(v) = &req.variant {
            match spec::apply_variant(&base_spec, v) {
                Ok((s, d)) => {
                    spec = s;
                    diags.extend(d);
                }
                Err(d) => diags.extend(d),
            }
        }
        if let Some(over) = &req.source {
            diags.extend(apply_source(&mut spec, registry, over));
        }
        let mut overrides = req.overrides.clone();
        match req.map.overrides(&spec, registry) {
            Ok(o) => overrides.extend(o),
            Err(d) => diags.push(d),
        }
        let (d, origins) = spec::apply_overrides(&mut spec, &overrides);
        diags.extend(d);
        let (g, mut d) = spec::validate(&spec, registry, &cx);
        origins.attribute(&mut d);
        diags.extend(d);
        graph = g;
        if req.all_variants {
            for variant in &base_spec.variants {
                if req.variant.as_deref() == Some(variant.name.as_str()) {
                    continue;
                }
                let extra = match spec::apply_variant(&base_spec, &variant.name) {
                    Ok((s, mut d)) => {
                        let vcx = spec::ResolveContext { variant: Some(variant.name.clone()), ..cx.clone() };
                        d.extend(spec::validate(&s, registry, &vcx).1);
                        d
                    }
                    Err(d) => d,
                };
                for mut d in extra {
                    if diags.iter().any(|e| e.code == d.code && e.span == d.span && e.message == d.message) {
                        continue;
                    }
                    let tag = format!("variant `{}`", variant.name);
                    if !d.message.contains(&tag) {
                        d.message = format!("{tag}: {}", d.message);
                    }
                    diags.push(d);
                }
            }
        }
    }
    if diags.iter().any(Diagnostic::is_error) {
        graph = None;
    }
    diags.sort_by_key(|d| (d.span.map_or(0, |s| s.offset), d.severity));
    Loaded { source, spec: Some(base_spec), graph, diagnostics: diags }
}
