//! What every dynaflow crate may build on that is not data:
//!
//! - [`rng`]: SplitMix64, the one seeded generator: RANSAC samples with it, the engine derives
//!   each node's seed with it, and named streams (`SplitMix64::named`) give every call site its
//!   own reproducible sequence.
//! - [`wire`]: the protobuf wire format, read: ONNX model files (`dynaflow-infer`) and the
//!   protobuf images of MCAP recordings (`dynaflow-recordings`) share the one reader.
//! - [`yaml`]: a YAML document as a tree that remembers where every node was written: graph
//!   files (`dynaflow-engine`) and sensor descriptions (EuRoC's `sensor.yaml`,
//!   `dynaflow-datasets`) point their errors at `file:line:col` through it.
//!
//! Message types live in `dynaflow-msg`; neither module here is one.
#![warn(missing_docs)]

pub mod rng;
pub mod wire;
pub mod yaml;
