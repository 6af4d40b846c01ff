//! Helpers of the engine's tests: graphs on the engine's own registry, a seeded generator.
#![allow(clippy::panic, dead_code)]

use dynaflow_engine::spec::ResolvedGraph;
use dynaflow_engine::{LoadRequest, load_str};

pub mod runs;

#[path = "../../../tests/common/rng.rs"]
mod rng;
#[allow(unused_imports)]
pub use rng::Rng;

/// `text` validated against the engine's own registry (flow and `testing.*` operators);
/// panics with the diagnostics if invalid.
pub fn graph(text: &str) -> ResolvedGraph {
    let loaded = load_str("test.yaml", text, None, &dynaflow_engine::testing::registry(), &LoadRequest::default());
    let rendered: Vec<String> = loaded.diagnostics.iter().map(|d| loaded.source.plain(d)).collect();
    loaded.graph.unwrap_or_else(|| panic!("graph invalid:\n{}", rendered.join("\n")))
}
