//! The `python` operator with the interpreter: declarations read from the class, the
//! instance constructed at `start` and called per frame.

use std::collections::HashMap;
use std::sync::{Mutex, PoisonError};

use dynaflow_engine::msg::Header;
use dynaflow_engine::op::{
    Context, DeclareRequest, Inputs, Instance, OpError, OpSpec, Operator, Outputs, ParamSpec, Params,
};
use pyo3::exceptions::PyKeyError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyModule};
use rand_core::Rng;

use crate::convert;
use crate::declare::{self, Declared};
use crate::interp::{self, ModuleRef};
use crate::op::{OWN, OWN_PARAMS};

/// Declarations read so far, by module and class (each read once per process).
static DECLARED: Mutex<Option<HashMap<(ModuleRef, String), &'static Declared>>> = Mutex::new(None);

/// The declaration of `class` in `module`, importing it on first use.
fn declared(module: &ModuleRef, class: &str) -> Result<&'static Declared, String> {
    let key = (module.clone(), class.to_owned());
    if let Some(d) = DECLARED.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert_default().get(&key) {
        return Ok(d);
    }
    let d = interp::attach(|py| -> Result<Declared, String> {
        let m = interp::import(py, module)?;
        let cls = m.getattr(class).map_err(|_| {
            let names: Vec<String> = m
                .dict()
                .iter()
                .filter(|(_, v)| v.is_instance_of::<pyo3::types::PyType>())
                .filter_map(|(k, _)| k.extract::<String>().ok())
                .filter(|k| !k.starts_with('_'))
                .collect();
            format!("{module} has no class `{class}` (its classes: {})", names.join(", "))
        })?;
        declare::read(&cls, &OWN).map_err(|e| format!("{module}, class `{class}`: {e}"))
    })?;
    let d: &'static Declared = Box::leak(Box::new(d));
    DECLARED.lock().unwrap_or_else(PoisonError::into_inner).get_or_insert_default().insert(key, d);
    Ok(d)
}

/// The engine's hook: the node's ports and parameters from its class.
pub(crate) fn declare_node(base: &OpSpec, req: &DeclareRequest<'_>) -> Result<OpSpec, String> {
    let text = |k: &str| req.params.get(k).and_then(serde_json::Value::as_str);
    // Without them the parameters' own check says what is missing.
    let (Some(module), Some(class)) = (text("module"), text("class")) else {
        return Ok(*base);
    };
    let d = declared(&ModuleRef::parse(module, req.base_dir), class)?;
    let params: Vec<ParamSpec> = OWN_PARAMS.iter().chain(d.params).copied().collect();
    Ok(OpSpec {
        doc: if d.doc.is_empty() { base.doc } else { d.doc },
        inputs: d.inputs,
        outputs: d.outputs,
        params: Box::leak(params.into_boxed_slice()),
        ..*base
    })
}

/// The node's operator.
pub(crate) fn build(params: &Params) -> Result<Instance, OpError> {
    let text = |k: &str| -> Result<String, OpError> {
        params
            .get(k)
            .and_then(serde_json::Value::as_str)
            .map(str::to_owned)
            .ok_or_else(|| OpError::Config { key: k.to_owned(), message: "a string is required".into() })
    };
    let (module, class) = (text("module")?, text("class")?);
    let module = match ModuleRef::parse(&module, None) {
        ModuleRef::File(_) => ModuleRef::File(params.resolve_path(&module)),
        name => name,
    };
    let declared = declared(&module, &class).map_err(OpError::Failed)?;
    let mut own = params.as_map().clone();
    for k in OWN {
        own.remove(k);
    }
    Ok(Instance::Transform(Box::new(PythonOp { module, class, declared, params: own, state: None })))
}

/// The frame a `process` call gets.
#[pyclass(frozen, name = "Frame")]
struct Frame {
    /// The frame's sequence number.
    #[pyo3(get)]
    seq: u64,
    /// Its sensor time, seconds.
    #[pyo3(get)]
    stamp: f64,
    /// A 64-bit draw from the node's seeded generator for this frame (what dynaflow's own
    /// operators seed their RANSAC with).
    #[pyo3(get)]
    seed: u64,
    /// Port to value (`None` where absent this frame).
    #[pyo3(get)]
    inputs: Py<PyDict>,
}

#[pymethods]
impl Frame {
    fn __getitem__(&self, py: Python<'_>, port: &str) -> PyResult<Py<PyAny>> {
        let inputs = self.inputs.bind(py);
        match inputs.get_item(port)? {
            Some(v) => Ok(v.unbind()),
            None => {
                let names: Vec<String> = inputs.keys().iter().filter_map(|k| k.extract().ok()).collect();
                Err(PyKeyError::new_err(format!("no input `{port}` (the class declares: {})", names.join(", "))))
            }
        }
    }

    fn __repr__(&self) -> String {
        format!("Frame(seq={}, stamp={})", self.seq, self.stamp)
    }
}

/// The constructed instance and numpy.
struct State {
    instance: Py<PyAny>,
    numpy: Py<PyModule>,
}

struct PythonOp {
    module: ModuleRef,
    class: String,
    declared: &'static Declared,
    /// The class's own parameters, validated against its declaration.
    params: serde_json::Map<String, serde_json::Value>,
    state: Option<State>,
}

impl PythonOp {
    /// A Python error as the operator's: where (`Class.method`, the frame) and the traceback.
    fn failed(&self, py: Python<'_>, what: &str, e: &PyErr) -> OpError {
        OpError::Failed(format!("{}.{what} raised:\n{}", self.class, interp::describe(py, e)))
    }

    /// Calls `method` if the class defines it.
    fn call_optional(&self, method: &str) -> Result<(), OpError> {
        let Some(state) = &self.state else { return Ok(()) };
        interp::attach(|py| {
            let inst = state.instance.bind(py);
            if inst.hasattr(method).unwrap_or(false) {
                inst.call_method0(method).map_err(|e| self.failed(py, &format!("{method}()"), &e))?;
            }
            Ok(())
        })
    }
}

impl Operator for PythonOp {
    fn start(&mut self, ctx: &mut Context) -> Result<(), OpError> {
        let state = interp::attach(|py| -> Result<State, OpError> {
            let numpy = py.import("numpy").map_err(|e| {
                OpError::Failed(format!(
                    "Python operators need numpy, which does not import:\n{}{}",
                    interp::describe(py, &e),
                    interp::venv_note().map(|n| format!("\n(note: {n})")).unwrap_or_default()
                ))
            })?;
            let m = interp::import(py, &self.module).map_err(OpError::Failed)?;
            let cls = m.getattr(self.class.as_str()).map_err(|e| self.failed(py, "<class lookup>", &e))?;
            let params = py
                .import("json")
                .and_then(|j| j.call_method1("loads", (serde_json::Value::Object(self.params.clone()).to_string(),)))
                .map_err(|e| self.failed(py, "<parameters>", &e))?;
            let rng = numpy
                .getattr("random")
                .and_then(|r| r.call_method1("default_rng", (ctx.seed,)))
                .map_err(|e| self.failed(py, "<rng>", &e))?;
            let instance = cls.call1((params, rng)).map_err(|e| self.failed(py, "__init__", &e))?;
            Ok(State { instance: instance.unbind(), numpy: numpy.unbind() })
        })?;
        self.state = Some(state);
        self.call_optional("start")
    }

    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let Some(state) = &self.state else {
            return Err(OpError::Failed("process before start".into()));
        };
        let header = inputs.header().cloned().unwrap_or_else(|| Header {
            seq: inputs.seq,
            stamp: 0.0,
            frame_id: "python".into(),
        });
        let seed = ctx.rng.next_u64();
        let seq = inputs.seq;
        interp::attach(|py| {
            let np = state.numpy.bind(py);
            let dict = PyDict::new(py);
            for port in self.declared.inputs {
                let value = match inputs.declared(port.name)? {
                    Some(m) => convert::to_py(np, m).map_err(|e| self.failed(py, "<input conversion>", &e))?,
                    None => py.None().into_bound(py),
                };
                dict.set_item(port.name, value).map_err(|e| self.failed(py, "<inputs>", &e))?;
            }
            let frame = Frame { seq, stamp: header.stamp, seed, inputs: dict.unbind() };
            let frame = Bound::new(py, frame).map_err(|e| self.failed(py, "<frame>", &e))?;
            let ret = state.instance.bind(py).call_method1("process", (frame,)).map_err(|e| {
                OpError::Failed(format!("{}.process raised at frame {seq}:\n{}", self.class, interp::describe(py, &e)))
            })?;
            let mut out = Outputs::new();
            if ret.is_none() {
                return Ok(out);
            }
            let declared: Vec<&str> = self.declared.outputs.iter().map(|p| p.name).collect();
            let ret = ret.cast::<PyDict>().map_err(|_| {
                OpError::Failed(format!(
                    "{}.process returned {} at frame {seq}; it returns a dict of output port to value ({})",
                    self.class,
                    ret.get_type().name().map_or_else(|_| "a value".into(), |n| n.to_string()),
                    declared.join(", ")
                ))
            })?;
            // Every declared port is answered (`None`: nothing this frame), so a misspelt or
            // forgotten key is an error, not a silently empty port.
            if let Some(missing) = self.declared.outputs.iter().find(|p| !ret.contains(p.name).unwrap_or(false)) {
                return Err(OpError::Failed(format!(
                    "{}.process returned no `{}` at frame {seq}: return every declared output ({}), `None` for nothing this frame, or `None` for the whole frame",
                    self.class,
                    missing.name,
                    declared.join(", ")
                )));
            }
            for (k, v) in ret.iter() {
                let name: String = k.extract().unwrap_or_default();
                let Some(port) = self.declared.outputs.iter().find(|p| p.name == name) else {
                    return Err(OpError::Failed(format!(
                        "{}.process returned port `{name}` at frame {seq}, which the class does not declare (outputs: {})",
                        self.class,
                        declared.join(", ")
                    )));
                };
                if v.is_none() {
                    continue;
                }
                let body = convert::from_py(port.ty, port.name, &v)
                    .map_err(|e| OpError::Failed(format!("{}.process at frame {seq}: {e}", self.class)))?;
                out.push(port.name, header.clone(), body);
            }
            Ok(out)
        })
    }

    fn stop(&mut self, _ctx: &mut Context) -> Result<(), OpError> {
        let r = self.call_optional("stop");
        if let Some(state) = self.state.take() {
            interp::attach(|_| drop(state));
        }
        r
    }
}
