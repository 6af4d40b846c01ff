//! Which executor runs a model: `cpu` (rten), `reference` (our plain-loop executor, the
//! oracle the others are tested against) or `wgpu` (our planned GPU executor; without an
//! adapter, or for a model it cannot plan, the documented fallback to `cpu` with a warning).

use dynaflow_gpu::{Gpu, GpuModel};
use dynaflow_infer::cpu::{self, Tensor};
use dynaflow_infer::onnx::Model;
use dynaflow_infer::rten_cpu::RtenModel;

dynaflow_engine::param_enum! {
    /// Where a model runs: the graph parameter and `dynaflow infer --backend` alike.
    pub enum Backend {
        /// rten on the CPU (SIMD, multi-threaded).
        Cpu = "cpu",
        /// Our planned WGSL executor on a GPU adapter (falls back to `cpu`, saying so).
        Wgpu = "wgpu",
        /// The reference executor: plain loops, the oracle the others are tested against.
        Reference = "reference",
    }
}

/// A model ready to run.
pub enum Runner {
    /// rten on the CPU.
    Cpu(Box<RtenModel>),
    /// The reference executor.
    Reference(Model),
    /// The wgpu executor.
    Gpu(Box<GpuModel>),
}

impl std::fmt::Debug for Runner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Runner::Cpu(_) => f.write_str("Runner::Cpu"),
            Runner::Reference(_) => f.write_str("Runner::Reference"),
            Runner::Gpu(g) => write!(f, "Runner::Gpu({})", g.adapter()),
        }
    }
}

impl Runner {
    /// Load `model` (parsed from `bytes`) on `backend`; the runner and a description for
    /// reports (which backend really runs, and why a fallback happened). A software adapter
    /// (a renderer on the CPU, 40x slower than rten on the same cores) counts as no GPU unless
    /// `allow_software` (the tests' lavapipe runs).
    pub fn new(bytes: &[u8], model: &Model, backend: Backend, allow_software: bool) -> Result<(Self, String), String> {
        match backend {
            Backend::Reference => {
                cpu::check_ops(model).map_err(|e| e.to_string())?;
                Ok((Runner::Reference(model.clone()), "reference".into()))
            }
            Backend::Wgpu => {
                // Planning names an op without a kernel (with its node) and any shape it
                // cannot take; without an adapter there is nothing to plan on.
                let why = match Gpu::new() {
                    Ok(gpu) if gpu.software && !allow_software => format!(
                        "the only adapter, `{}`, is a software renderer on the CPU (allow it with `allow_software: true` / `--allow-software`)",
                        gpu.adapter
                    ),
                    Ok(gpu) => match GpuModel::new(gpu, model) {
                        Ok(m) => {
                            let name = format!("wgpu: {}", m.adapter());
                            return Ok((Runner::Gpu(Box::new(m)), name));
                        }
                        Err(e) => e.to_string(),
                    },
                    Err(e) => e.to_string(),
                };
                tracing::warn!("backend `wgpu` unavailable ({why}); running on the CPU");
                let m = RtenModel::load(bytes.to_vec())?;
                Ok((Runner::Cpu(Box::new(m)), format!("cpu (wgpu fallback: {why})")))
            }
            Backend::Cpu => Ok((Runner::Cpu(Box::new(RtenModel::load(bytes.to_vec())?)), "cpu".into())),
        }
    }

    /// Run on one named input; the model's outputs.
    pub fn run(&self, name: &str, input: Tensor) -> Result<Vec<Tensor>, String> {
        match self {
            Runner::Cpu(m) => m.run(&[(name, input)]),
            Runner::Reference(m) => cpu::run(m, &[(name, input)]).map_err(|e| e.to_string()),
            Runner::Gpu(m) => m.run(&[(name, input)]).map_err(|e| e.to_string()),
        }
    }
}
