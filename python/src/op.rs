//! The `python` operator's declaration: always registered, so `dynaflow ops` lists it and a
//! graph using it in a build without the `embed` feature gets an error saying how to build it.

use dynaflow_engine::op::{DeclareRequest, Default, Instance, OpError, OpSpec, ParamSpec, ParamType, Params};

const DOC: &str = "A node written in Python: `module` (a `.py` file beside the graph, or an importable module) and `class`, whose `inputs`, `outputs` and `params` tables declare its ports and parameters (read when the graph is validated); the class is constructed as `Class(params, rng)` (a dict of its parameters, a numpy `Generator` seeded from the node's seed) and called as `process(frame)` per frame (`frame.seq`, `.stamp`, `.seed` (a 64-bit draw from the node's generator), `frame[\"port\"]` or `frame.inputs`, absent inputs `None`), returning a dict with every declared output port (`None`: nothing on it this frame), or `None` for nothing at all; optional `start()` and `stop()`. Images and depth arrive as read-only numpy views of the messages; see docs/python.md for every type. Needs the `python` build feature.";

/// `module` and `class`: the parameters every Python node has.
#[cfg(feature = "embed")]
pub(crate) const OWN: [&str; 2] = ["module", "class"];
pub(crate) const OWN_PARAMS: &[ParamSpec] = &[
    ParamSpec {
        name: "module",
        ty: ParamType::Str,
        default: Default::Required,
        doc: "the Python file (`*.py`, relative to the graph file) or an importable module name",
    },
    ParamSpec { name: "class", ty: ParamType::Str, default: Default::Required, doc: "the operator class in `module`" },
];

/// The `python` operator (its doc: `dynaflow ops python`).
pub const PYTHON: OpSpec =
    OpSpec::transform("python", "python", DOC, build).params(OWN_PARAMS).cpu_heavy().declare(declare_node);

#[cfg(feature = "embed")]
fn declare_node(base: &OpSpec, req: &DeclareRequest<'_>) -> Result<OpSpec, String> {
    crate::embedded::declare_node(base, req)
}

#[cfg(feature = "embed")]
fn build(params: &Params) -> Result<Instance, OpError> {
    crate::embedded::build(params)
}

#[cfg(not(feature = "embed"))]
const NOT_BUILT: &str = "this dynaflow was built without Python operators: build it with `cargo build --release --features python` (docs/python.md)";

#[cfg(not(feature = "embed"))]
fn declare_node(_: &OpSpec, _: &DeclareRequest<'_>) -> Result<OpSpec, String> {
    Err(NOT_BUILT.into())
}

#[cfg(not(feature = "embed"))]
fn build(_: &Params) -> Result<Instance, OpError> {
    Err(OpError::Failed(NOT_BUILT.into()))
}
