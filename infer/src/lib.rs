//! dynaflow's neural-network inference as a plain library, with no engine or async
//! dependency (the `detect` operator is a thin wrapper around it).
//!
//! - `onnx`: a reader for ONNX files (the protobuf wire format decoded by hand for the few
//!   messages a model needs).
//! - `tensor`: tensors and the shape arithmetic every executor shares.
//! - `reference`: the reference executor, one plain loop nest per op: what a model computes
//!   here, checked against onnxruntime, and what GPU kernels are tested against.
//! - `rten_cpu`: the CPU backend, models run by rten (fast, multi-threaded; chosen over tract
//!   by measurement).
//! - `Error`: the crate's one error type (reading, checking and running a model).
//! - `detect`: detector pre- and post-processing: YOLOX letterbox, decoding, class-wise NMS.
//! - `segment`: segmenter pre- and post-processing: the input contract, class scores resized to
//!   the frame and decided per pixel, dilation, instances by connected components.

#![warn(missing_docs)]

pub mod detect;
mod error;
pub mod onnx;
pub mod reference;
pub mod rten_cpu;
pub mod segment;
pub mod tensor;

pub use error::Error;

/// What runs a model: the reference executor (an [`onnx::Model`] itself), rten
/// ([`rten_cpu::RtenModel`]) or, in `dynaflow-gpu`, the WGSL executor. The `detect` operator
/// and `dynaflow infer` hold one of them behind this trait.
pub trait Executor: Send + Sync {
    /// Run on the named inputs; every graph output, in the model's order.
    fn run(&self, inputs: &[(&str, tensor::Tensor)]) -> Result<Vec<tensor::Tensor>, crate::Error>;
}

/// The reference executor runs a parsed model as it is.
impl Executor for onnx::Model {
    fn run(&self, inputs: &[(&str, tensor::Tensor)]) -> Result<Vec<tensor::Tensor>, crate::Error> {
        reference::run(self, inputs)
    }
}
