//! `dynaflow graph`: Mermaid or dot.

use std::path::Path;

use dynaflow_engine::LoadRequest;
use dynaflow_engine::spec::{Join, QueuePolicy, ResolvedGraph};

use crate::cli::{EXIT_BAD_INPUT, EXIT_OK};

pub fn graph(path: &Path, dot: bool, variant: Option<String>) -> u8 {
    let req = LoadRequest { variant, ..LoadRequest::default() };
    let Some(graph) = super::load_and_report(path, &req).and_then(|l| l.graph) else {
        return EXIT_BAD_INPUT;
    };
    say!("{}", if dot { to_dot(&graph) } else { to_mermaid(&graph) });
    EXIT_OK
}

fn edge_note(g: &ResolvedGraph, i: usize) -> String {
    let Some(e) = g.edges.get(i) else { return String::new() };
    let mut parts = Vec::new();
    let from = g.nodes.get(e.from_node).and_then(|n| n.outputs.get(e.from_port)).map_or("?", |p| p.name);
    let to = g.nodes.get(e.to_node).and_then(|n| n.inputs.get(e.to_port)).map_or("?", |p| p.name);
    parts.push(if from == to { from.to_owned() } else { format!("{from}→{to}") });
    if e.join == Join::Latest {
        parts.push("latest".into());
    }
    if e.delay > 0 {
        parts.push(format!("delay {}", e.delay));
    }
    if let QueuePolicy::DropOldest { capacity } = e.queue {
        parts.push(format!("drop_oldest {capacity}"));
    }
    parts.join(", ")
}

/// Mermaid flowchart.
pub fn to_mermaid(g: &ResolvedGraph) -> String {
    let mut out = String::from("flowchart LR\n");
    for n in &g.nodes {
        let style = if n.disabled { ":::disabled" } else { "" };
        out.push_str(&format!("  {}[\"{}<br/><small>{}</small>\"]{style}\n", n.id, n.id, n.op.name));
    }
    for (i, e) in g.edges.iter().enumerate() {
        let (Some(a), Some(b)) = (g.nodes.get(e.from_node), g.nodes.get(e.to_node)) else { continue };
        let arrow = if e.delay > 0 || e.join == Join::Latest { "-.->" } else { "-->" };
        out.push_str(&format!("  {} {arrow}|\"{}\"| {}\n", a.id, edge_note(g, i), b.id));
    }
    out.push_str("  classDef disabled stroke-dasharray: 5 5,opacity:0.5\n");
    out
}

/// Graphviz dot.
pub fn to_dot(g: &ResolvedGraph) -> String {
    let mut out = format!("digraph \"{}\" {{\n  rankdir=LR;\n  node [shape=box, fontname=\"Helvetica\"];\n", g.name);
    for n in &g.nodes {
        let style = if n.disabled { ", style=dashed" } else { "" };
        out.push_str(&format!("  \"{}\" [label=\"{}\\n({})\"{style}];\n", n.id, n.id, n.op.name));
    }
    for (i, e) in g.edges.iter().enumerate() {
        let (Some(a), Some(b)) = (g.nodes.get(e.from_node), g.nodes.get(e.to_node)) else { continue };
        let style = if e.delay > 0 || e.join == Join::Latest { ", style=dashed" } else { "" };
        out.push_str(&format!("  \"{}\" -> \"{}\" [label=\"{}\"{style}];\n", a.id, b.id, edge_note(g, i)));
    }
    out.push_str("}\n");
    out
}
