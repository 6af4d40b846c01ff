//! Helpers shared by the integration tests.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use std::path::{Path, PathBuf};

pub mod peers;
mod tempdir;
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

/// A seeded random generator for property tests: reproducible case by case, so a failing
/// case is rerun from its number.
pub struct Rng(rand_chacha::ChaCha8Rng);

impl Rng {
    pub fn new(seed: u64) -> Self {
        use rand_core::SeedableRng;
        Self(rand_chacha::ChaCha8Rng::seed_from_u64(seed))
    }
    /// Uniform in `0..n` (`n > 0`).
    pub fn below(&mut self, n: u64) -> u64 {
        use rand_core::Rng as _;
        // Multiply-shift: unbiased enough for test-case generation.
        ((u128::from(self.0.next_u64()) * u128::from(n)) >> 64) as u64
    }
    /// Uniform in `lo..=hi`.
    pub fn range(&mut self, lo: u64, hi: u64) -> u64 {
        lo + self.below(hi - lo + 1)
    }
    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        (self.below(1 << 20) as f64) < p * f64::from(1u32 << 20)
    }
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len() as u64) as usize]
    }
}

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The `dynaflow` binary built for these tests.
pub fn bin() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_dynaflow"))
}

/// The summary a run wrote (`dynaflow::summary::Summary`, the type `run` writes and `bench`
/// reads); panics naming the file if it is missing or not one.
pub fn summary(path: &Path) -> dynaflow::summary::Summary {
    dynaflow::summary::Summary::read(path).unwrap_or_else(|e| panic!("{e}"))
}
