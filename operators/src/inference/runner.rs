//! Which executor runs a model: `cpu` (rten), `reference` (our plain-loop executor, the
//! oracle the others are tested against) or `wgpu` (our planned GPU executor; without an
//! adapter, or for a model it cannot plan, the documented fallback to `cpu` with a warning).

#[cfg(feature = "wgpu")]
use dynaflow_gpu::{Gpu, GpuModel};
use dynaflow_infer::Error;
use dynaflow_infer::Executor;
use dynaflow_infer::onnx::Model;
use dynaflow_infer::reference;
use dynaflow_infer::rten_cpu::RtenModel;
use dynaflow_infer::tensor::Tensor;

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

/// A model ready to run, on whichever executor the backend chose.
pub struct Runner(Box<dyn Executor>);

impl std::fmt::Debug for Runner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Runner")
    }
}

impl Runner {
    /// Load `model` (parsed from `bytes`) on `backend`; the runner and a description for
    /// reports (which backend really runs, and why a fallback happened). A software adapter
    /// (a renderer on the CPU, 40x slower than rten on the same cores) counts as no GPU unless
    /// `allow_software` (the tests' lavapipe runs).
    pub fn new(bytes: &[u8], model: &Model, backend: Backend, allow_software: bool) -> Result<(Self, String), Error> {
        match backend {
            Backend::Reference => {
                reference::check_ops(model)?;
                Ok((Runner(Box::new(model.clone())), "reference".into()))
            }
            Backend::Wgpu => {
                let why = match wgpu_runner(model, allow_software) {
                    Ok(runner) => return Ok(runner),
                    Err(why) => why,
                };
                tracing::warn!("backend `wgpu` unavailable ({why}); running on the CPU");
                let m = RtenModel::load(bytes.to_vec())?;
                Ok((Runner(Box::new(m)), format!("cpu (wgpu fallback: {why})")))
            }
            Backend::Cpu => Ok((Runner(Box::new(RtenModel::load(bytes.to_vec())?)), "cpu".into())),
        }
    }

    /// Run on one named input; the model's outputs.
    pub fn run(&self, name: &str, input: Tensor) -> Result<Vec<Tensor>, Error> {
        self.0.run(&[(name, input)])
    }
}

/// The model planned on a GPU adapter, or why not (no adapter, a software one not allowed, an
/// op or shape the planner cannot take).
#[cfg(feature = "wgpu")]
fn wgpu_runner(model: &Model, allow_software: bool) -> Result<(Runner, String), String> {
    // Planning names an op without a kernel (with its node) and any shape it cannot take;
    // without an adapter there is nothing to plan on.
    match Gpu::new() {
        Ok(gpu) if gpu.software && !allow_software => Err(format!(
            "the only adapter, `{}`, is a software renderer on the CPU (allow it with `allow_software: true` / `--allow-software`)",
            gpu.adapter
        )),
        Ok(gpu) => match GpuModel::new(gpu, model) {
            Ok(m) => {
                let name = format!("wgpu: {}", m.adapter());
                Ok((Runner(Box::new(m)), name))
            }
            Err(e) => Err(e.to_string()),
        },
        Err(e) => Err(e.to_string()),
    }
}

/// Built without the `wgpu` feature: always the CPU, saying why.
#[cfg(not(feature = "wgpu"))]
fn wgpu_runner(_: &Model, _: bool) -> Result<(Runner, String), String> {
    Err("dynaflow was built without its `wgpu` feature".into())
}
