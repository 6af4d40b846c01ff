//! Helpers shared by the integration tests.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};

pub mod peers;
pub mod process;
mod rng;
mod tempdir;
#[allow(unused_imports)]
pub use rng::Rng;
#[allow(unused_imports)]
pub use tempdir::TempDir;

use dynaflow_engine::spec::ResolvedGraph;
use dynaflow_engine::{LoadRequest, load_str};

/// Validate graph text with the shipped operators; panics with the diagnostics if invalid.
pub fn graph(text: &str) -> ResolvedGraph {
    graph_with(text, &LoadRequest::default())
}

pub fn graph_with(text: &str, req: &LoadRequest) -> ResolvedGraph {
    let loaded = load_str("test.yaml", text, None, &dynaflow::registry(), req);
    let rendered: Vec<String> = loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect();
    loaded.graph.unwrap_or_else(|| panic!("graph invalid:\n{}", rendered.join("\n")))
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `dynaflow` binary built for these tests.
pub fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_dynaflow"))
}

/// Write `yaml` (a graph named `name`) to `dir/<name>.yaml`, run it with `--record mcap` into
/// `dir` (it must exit 0), and return the recording, `dir/<name>.mcap`.
pub fn record_mcap(dir: &Path, name: &str, yaml: &str) -> PathBuf {
    let graph = dir.join(format!("{name}.yaml"));
    std::fs::write(&graph, yaml).unwrap();
    let out = bin().args(["run", "--no-progress", "--record", "mcap", "--out"]).arg(dir).arg(&graph).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    dir.join(format!("{name}.mcap"))
}

/// The summary a run wrote (`dynaflow::summary::Summary`, the type `run` writes and `bench`
/// reads); panics naming the file if it is missing or not one.
pub fn summary(path: &Path) -> dynaflow::summary::Summary {
    dynaflow::summary::Summary::read(path).unwrap_or_else(|e| panic!("{e}"))
}
