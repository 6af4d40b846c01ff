//! dynaflow's Python operators: a graph node whose ports, parameters and per-frame work a
//! Python class declares, run in CPython embedded through PyO3.
//!
//! - [`PYTHON`]: the `python` operator (`op: python`, `module:`, `class:`); the engine asks it
//!   for the node's declaration while validating the graph (the module is imported then, so an
//!   import, syntax or declaration error is an error at the node, with the Python traceback).
//! - `interp`: the interpreter (started once per process, the user's virtual environment on
//!   its path), module loading, tracebacks.
//! - `declare`: the class's declaration read into the engine's port and parameter types.
//! - `convert`: messages to Python (images and depth as read-only numpy views of the message,
//!   no copy; the rest as numpy arrays and dicts) and back, each returned value checked against
//!   its port's type (dtype, shape, ranges) with an error naming the port and the field.
//!
//! Without the `embed` feature (the root crate's `python`) only the declaration is built: the
//! operator is listed, and a graph that uses it is refused with the feature to build.
//!
//! The operator runs on the runtime's blocking pool (`cpu_heavy`), so Python holding the GIL
//! never stalls the Rust nodes on the async executor.

#[cfg(feature = "embed")]
mod convert;
#[cfg(feature = "embed")]
mod declare;
#[cfg(feature = "embed")]
mod embedded;
#[cfg(feature = "embed")]
mod interp;
mod op;

pub use op::PYTHON;
