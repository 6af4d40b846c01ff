//! A Python operator class's declaration, read into the engine's port and parameter types.
//!
//! ```python
//! class CullFlow:
//!     """One line for `dynaflow ops`-style listings."""
//!     inputs = {"tracks": "tracks", "model": {"type": "scalars", "required": False, "doc": "..."}}
//!     outputs = {"labels": "point_labels"}
//!     params = {"flow_threshold": {"default": 1.0, "min": 0.0, "doc": "..."}, "verbose": False}
//! ```
//!
//! A port is a type name (the graph's: `image`, `tracks`, ...) or a table with `type`,
//! `required` (inputs; default true) and `doc`. A parameter is its default (its type follows:
//! bool, int, float or str) or a table with `default`, `min`, `max` and `doc`. Names are the
//! graph's (`[a-z][a-z0-9_]*`).

use dynaflow_engine::msg::PortType;
use dynaflow_engine::op::{Default, ParamSpec, ParamType, PortSpec};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyString};

use crate::convert;

/// What a class declares, with the names leaked to `'static` as the engine's declarations
/// are (once per module and class per process).
#[derive(Debug)]
pub(crate) struct Declared {
    /// The class's docstring, first paragraph.
    pub doc: &'static str,
    /// Input ports.
    pub inputs: &'static [PortSpec],
    /// Output ports.
    pub outputs: &'static [PortSpec],
    /// The class's own parameters.
    pub params: &'static [ParamSpec],
}

fn leak(s: String) -> &'static str {
    Box::leak(s.into_boxed_str())
}

fn valid_name(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_ascii_lowercase())
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
}

/// Read the declaration of `class` (an error naming the attribute and the entry).
pub(crate) fn read(class: &Bound<'_, PyAny>, reserved: &[&str]) -> Result<Declared, String> {
    let doc = class
        .getattr("__doc__")
        .ok()
        .and_then(|d| d.extract::<String>().ok())
        .map(|d| d.trim().split("\n\n").next().unwrap_or_default().split_whitespace().collect::<Vec<_>>().join(" "))
        .unwrap_or_default();
    let inputs = ports(class, "inputs", true)?;
    let outputs = ports(class, "outputs", false)?;
    let params = params(class, reserved)?;
    if outputs.is_empty() {
        return Err("`outputs` declares no port: a node must emit something".into());
    }
    if !class.hasattr("process").unwrap_or(false) {
        return Err("the class has no `process(self, frame)` method".into());
    }
    Ok(Declared {
        doc: leak(doc),
        inputs: Box::leak(inputs.into_boxed_slice()),
        outputs: Box::leak(outputs.into_boxed_slice()),
        params: Box::leak(params.into_boxed_slice()),
    })
}

/// The table `attr` of the class (a dict), entries in order.
fn table<'py>(class: &Bound<'py, PyAny>, attr: &str) -> Result<Vec<(String, Bound<'py, PyAny>)>, String> {
    let Ok(value) = class.getattr(attr) else {
        return Ok(Vec::new());
    };
    let dict = value.cast::<PyDict>().map_err(|_| format!("`{attr}` must be a dict of name to declaration"))?;
    dict.iter()
        .map(|(k, v)| {
            let name: String = k.extract().map_err(|_| format!("`{attr}`: the key {k} is not a string"))?;
            if !valid_name(&name) {
                return Err(format!("`{attr}`: `{name}` is not a valid name ([a-z][a-z0-9_]*)"));
            }
            Ok((name, v))
        })
        .collect()
}

fn ports(class: &Bound<'_, PyAny>, attr: &str, input: bool) -> Result<Vec<PortSpec>, String> {
    table(class, attr)?
        .into_iter()
        .map(|(name, decl)| {
            let where_ = format!("`{attr}`: port `{name}`");
            let (ty, required, doc) = if let Ok(ty) = decl.extract::<String>() {
                (ty, true, String::new())
            } else if let Ok(d) = decl.cast::<PyDict>() {
                let get = |k: &str| d.get_item(k).ok().flatten();
                let ty = get("type")
                    .and_then(|t| t.extract::<String>().ok())
                    .ok_or_else(|| format!("{where_}: the table has no `type` string"))?;
                let required = match get("required") {
                    None => true,
                    Some(r) => {
                        r.extract::<bool>().map_err(|_| format!("{where_}: `required` must be true or false"))?
                    }
                };
                let doc = get("doc").and_then(|t| t.extract::<String>().ok()).unwrap_or_default();
                (ty, required, doc)
            } else {
                return Err(format!("{where_}: expected a type name or a table with `type`"));
            };
            let port = PortType::ALL.iter().copied().find(|p| p.name() == ty).ok_or_else(|| {
                let all: Vec<&str> = convert::SUPPORTED.iter().map(|p| p.name()).collect();
                format!("{where_}: unknown type `{ty}` (types: {})", all.join(", "))
            })?;
            if !convert::SUPPORTED.contains(&port) {
                let all: Vec<&str> = convert::SUPPORTED.iter().map(|p| p.name()).collect();
                return Err(format!(
                    "{where_}: type `{ty}` does not reach Python operators yet (they take: {})",
                    all.join(", ")
                ));
            }
            let (name, doc) = (leak(name), leak(doc));
            Ok(match (input, required) {
                (true, true) => PortSpec::input(name, port, doc),
                (true, false) => PortSpec::optional(name, port, doc),
                (false, _) => PortSpec::output(name, port, doc),
            })
        })
        .collect()
}

fn params(class: &Bound<'_, PyAny>, reserved: &[&str]) -> Result<Vec<ParamSpec>, String> {
    table(class, "params")?
        .into_iter()
        .map(|(name, decl)| {
            let where_ = format!("`params`: `{name}`");
            if reserved.contains(&name.as_str()) {
                return Err(format!("{where_}: the name is the operator's own (`{}`)", reserved.join("`, `")));
            }
            let (default, min, max, doc) = match decl.cast::<PyDict>() {
                Ok(d) => {
                    let get = |k: &str| d.get_item(k).ok().flatten();
                    let default = get("default").ok_or_else(|| format!("{where_}: the table has no `default`"))?;
                    let num = |k: &str| -> Result<Option<f64>, String> {
                        get(k)
                            .map(|v| v.extract::<f64>().map_err(|_| format!("{where_}: `{k}` must be a number")))
                            .transpose()
                    };
                    let doc = get("doc").and_then(|t| t.extract::<String>().ok()).unwrap_or_default();
                    (default, num("min")?, num("max")?, doc)
                }
                Err(_) => (decl, None, None, String::new()),
            };
            let (ty, json) = if default.is_instance_of::<PyBool>() {
                (ParamType::Bool, serde_json::Value::Bool(default.extract().unwrap_or(false)))
            } else if default.is_instance_of::<PyInt>() {
                let v: i64 = default.extract().map_err(|_| format!("{where_}: the default does not fit 64 bits"))?;
                let (lo, hi) = (min.map_or(i64::MIN, |m| m.ceil() as i64), max.map_or(i64::MAX, |m| m.floor() as i64));
                (ParamType::Int { min: lo, max: hi }, serde_json::Value::from(v))
            } else if default.is_instance_of::<PyFloat>() {
                let v: f64 = default.extract().unwrap_or(f64::NAN);
                let (lo, hi) = (min.unwrap_or(f64::MIN), max.unwrap_or(f64::MAX));
                let json = serde_json::Number::from_f64(v)
                    .map(serde_json::Value::Number)
                    .ok_or_else(|| format!("{where_}: the default {v} is not finite"))?;
                (ParamType::Float { min: lo, max: hi }, json)
            } else if default.is_instance_of::<PyString>() {
                (ParamType::Str, serde_json::Value::String(default.extract().unwrap_or_default()))
            } else {
                return Err(format!("{where_}: the default must be a bool, int, float or str"));
            };
            let in_range = match (&ty, &json) {
                (ParamType::Int { min, max }, v) => v.as_i64().is_some_and(|v| (*min..=*max).contains(&v)),
                (ParamType::Float { min, max }, v) => v.as_f64().is_some_and(|v| (*min..=*max).contains(&v)),
                _ => true,
            };
            if !in_range {
                return Err(format!("{where_}: the default {json} is outside its own range"));
            }
            Ok(ParamSpec { name: leak(name), ty, default: Default::Json(leak(json.to_string())), doc: leak(doc) })
        })
        .collect()
}
