//! The CPU backend: models run by [rten](https://crates.io/crates/rten) (pure Rust, maintained,
//! SIMD GEMM and multi-threaded), chosen over tract by measurement (docs/benchmarks.md: on
//! YOLOX-nano 416x416, 21 ms against tract-onnx's 38 ms and our reference executor's 237 ms;
//! 32 crates and 43 s cold build against tract's 122 crates and 4 minutes). Our reference
//! executor stays the plain-loop oracle the GPU kernels are tested against.

use rten::{Model, NodeId};
use rten_tensor::prelude::*;

use crate::Error;
use crate::tensor::Tensor;

/// A model loaded into rten.
pub struct RtenModel {
    model: Model,
    inputs: Vec<(String, NodeId)>,
    outputs: Vec<NodeId>,
}

impl std::fmt::Debug for RtenModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RtenModel").field("inputs", &self.inputs).field("outputs", &self.outputs.len()).finish()
    }
}

impl RtenModel {
    /// Load an ONNX model from its bytes (rten's own checks: unsupported ops and malformed
    /// files are errors, with rten's message).
    pub fn load(bytes: Vec<u8>) -> Result<Self, Error> {
        let model = Model::load(bytes).map_err(|e| Error::Backend(format!("rten: {e}")))?;
        let inputs = model
            .input_ids()
            .iter()
            .map(|&id| {
                let name = model.node_info(id).and_then(|i| i.name().map(str::to_string)).unwrap_or_default();
                (name, id)
            })
            .collect();
        let outputs = model.output_ids().to_vec();
        Ok(Self { model, inputs, outputs })
    }

    /// Run on the named float inputs; every graph output, in the model's order.
    pub fn run(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, Error> {
        let tensors: Vec<(NodeId, rten_tensor::Tensor<f32>)> = self
            .inputs
            .iter()
            .map(|(name, id)| {
                let t = inputs
                    .iter()
                    .find(|(n, _)| n == name)
                    .map(|(_, t)| t)
                    .ok_or_else(|| Error::MissingInput(name.clone()))?;
                Ok((*id, rten_tensor::Tensor::from_data(t.shape(), t.floats())))
            })
            .collect::<Result<_, Error>>()?;
        let views = tensors.iter().map(|(id, t)| (*id, t.view().into())).collect();
        let outs = self.model.run(views, &self.outputs, None).map_err(|e| Error::Backend(format!("rten: {e}")))?;
        outs.into_iter()
            .map(|v| {
                let t: rten_tensor::Tensor<f32> =
                    v.try_into().map_err(|_| Error::Backend("rten: a model output is not a float tensor".into()))?;
                Ok(Tensor::F32 { shape: t.shape().to_vec(), data: t.to_vec() })
            })
            .collect()
    }
}

impl crate::Executor for RtenModel {
    fn run(&self, inputs: &[(&str, Tensor)]) -> Result<Vec<Tensor>, Error> {
        RtenModel::run(self, inputs)
    }
}
