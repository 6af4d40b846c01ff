//! Helpers shared by the integration tests.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

use dynaflow_engine::spec::ResolvedGraph;
use dynaflow_engine::{LoadRequest, load_str};

/// A fresh, empty folder under the system temp dir (removed on drop).
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "dynaflow-test-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

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
