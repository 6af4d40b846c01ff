//! dynaflow's core: graph files, message types, the operator contract, and the runtime.
//!
//! A graph file is parsed into a spanned YAML tree ([`yaml`]), turned into a
//! [`spec::GraphSpec`], patched by a variant and `--set` overrides, validated against the
//! operator [`op::Registry`] into a [`spec::ResolvedGraph`], and executed by [`runtime::run`],
//! which reports per-node metrics and feeds recorded ports to [`sink::Sink`]s.
//! [`load`] does the file-to-resolved-graph part in one call.

#![warn(missing_docs)]

pub mod diag;
pub mod files;
pub mod flow;
mod load;
pub mod op;
pub mod runtime;
pub mod sink;
pub mod spec;
pub mod testing;
pub use dynaflow_base::yaml;

pub use dynaflow_msg as msg;
pub use load::{LoadRequest, Loaded, MapRequest, SourceOverride, load, load_str};
