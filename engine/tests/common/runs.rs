//! Running a graph to memory and reading its scalars: the runtime tests of the engine crate
//! and of the workspace share these.
#![allow(clippy::unwrap_used, clippy::panic, dead_code)]

use dynaflow_engine::msg::{Body, Message};
use dynaflow_engine::runtime::{RunOptions, RunReport};
use dynaflow_engine::sink::MemorySink;
use dynaflow_engine::spec::ResolvedGraph;

/// Run `graph` with `options`, every message kept in memory.
pub fn run_with(graph: &ResolvedGraph, options: RunOptions) -> (RunReport, MemorySink) {
    dynaflow_engine::testing::run_to_memory(graph, options).unwrap()
}

/// Run `graph` with the default options.
pub fn run(graph: &ResolvedGraph) -> (RunReport, MemorySink) {
    run_with(graph, RunOptions::default())
}

/// The scalar `key` of a `Scalars` message.
pub fn scalar(m: &Message, key: &str) -> f64 {
    match &m.body {
        Body::Scalars(s) => s.get(key).unwrap(),
        other => panic!("not scalars: {other:?}"),
    }
}
