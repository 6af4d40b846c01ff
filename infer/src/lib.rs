//! dynaflow's neural-network inference as a plain library, with no engine or async
//! dependency (the `detect` operator is a thin wrapper around it).
//!
//! - `onnx`: a reader for ONNX files (the protobuf wire format decoded by hand for the few
//!   messages a model needs).
//! - `cpu`: the reference executor, one plain loop nest per op: what a model computes here,
//!   checked against onnxruntime, and what GPU kernels are tested against.
//! - `rten_cpu`: the CPU backend, models run by rten (fast, multi-threaded; chosen over tract
//!   by measurement).
//! - `detect`: detector pre- and post-processing: YOLOX letterbox, decoding, class-wise NMS.

pub mod cpu;
pub mod detect;
pub mod onnx;
pub mod rten_cpu;
