//! Static declarations of operators: ports, parameters, constructor.

use super::{OpError, Operator, Params, Source};
use crate::msg::PortType;

/// Whether a node produces frames or transforms them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OpKind {
    /// No inputs; drives frames.
    Source,
    /// Inputs to outputs.
    Transform,
}

/// What an input's data is used for: validation follows ground truth through the graph by
/// these roles, and a graph whose *decisions* read ground truth must say `oracle: true`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InputRole {
    /// The data shapes the node's outputs (the default).
    Decision,
    /// The node only describes the data (counts, fractions): its outputs carry whatever
    /// ground truth the input carries, but the node itself decides nothing.
    Statistics,
    /// The data only reaches the run's evaluation (the summary's ATE), never an output.
    Evaluation,
}

/// A port declaration.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct PortSpec {
    /// Port name (`[a-z][a-z0-9_]*`).
    pub name: &'static str,
    /// Message type.
    pub ty: PortType,
    /// Inputs only: whether the node fires without it. An absent required input skips the frame.
    pub required: bool,
    /// Inputs only: whether the graph must wire it (required inputs always must; a `wired`
    /// optional input may carry nothing in a frame, but a node without it is a graph error).
    pub wired: bool,
    /// Outputs only: the output has the type of what is wired into this input (`ty` is `Any`).
    pub same_as: Option<&'static str>,
    /// Inputs only: what the data is used for.
    pub role: InputRole,
    /// Outputs only: the port emits ground truth (a generator's exact poses and masks, a
    /// dataset's motion capture), so whatever decides with it is an oracle.
    pub ground_truth: bool,
    /// One line for docs.
    pub doc: &'static str,
}

impl PortSpec {
    const fn new(name: &'static str, ty: PortType, required: bool, doc: &'static str) -> Self {
        Self { name, ty, required, wired: required, same_as: None, role: InputRole::Decision, ground_truth: false, doc }
    }
    /// A required input.
    pub const fn input(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        Self::new(name, ty, true, doc)
    }
    /// An optional input.
    pub const fn optional(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        Self::new(name, ty, false, doc)
    }
    /// An optional input that only reaches the run's evaluation, never an output.
    pub const fn evaluation(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        Self { role: InputRole::Evaluation, ..Self::new(name, ty, false, doc) }
    }
    /// This input with `role` (e.g. a statistics operator's input).
    pub const fn with_role(self, role: InputRole) -> Self {
        Self { role, ..self }
    }
    /// An output.
    pub const fn output(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        Self::new(name, ty, false, doc)
    }
    /// An output that emits ground truth.
    pub const fn ground_truth(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        Self { ground_truth: true, ..Self::new(name, ty, false, doc) }
    }
    /// An output whose type follows the input `input`.
    pub const fn output_like(name: &'static str, input: &'static str, doc: &'static str) -> Self {
        Self { same_as: Some(input), ..Self::new(name, PortType::Any, false, doc) }
    }
}

/// The type and range of a parameter. Ranges are inclusive.
#[derive(Clone, Copy, Debug, serde::Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ParamType {
    /// `true`/`false`.
    Bool,
    /// An integer in `min..=max`.
    Int {
        /// Smallest allowed.
        min: i64,
        /// Largest allowed.
        max: i64,
    },
    /// A finite number in `min..=max`.
    Float {
        /// Smallest allowed.
        min: f64,
        /// Largest allowed.
        max: f64,
    },
    /// Any string.
    Str,
    /// One of a fixed set of strings.
    Enum {
        /// The allowed values.
        values: &'static [&'static str],
    },
    /// A file or folder path (relative paths resolve against the graph file's folder).
    Path,
    /// A string in a format of its own (e.g. camera intrinsics), checked by `check` where
    /// the graph writes it.
    Text {
        /// The format, for docs and errors.
        what: &'static str,
        /// `Err(why)` when the text is not in the format.
        #[serde(skip)]
        check: fn(&str) -> Result<(), String>,
    },
    /// A list: a YAML sequence (or one comma-separated string), each item of type `item`.
    List {
        /// The items' type.
        item: &'static ParamType,
    },
    /// A map: a YAML mapping (or one string of comma-separated `key=value` pairs).
    Map {
        /// The keys' type.
        key: &'static ParamType,
        /// The values' type.
        value: &'static ParamType,
    },
}

impl ParamType {
    /// A human description ("integer in 1..=10000").
    pub fn describe(&self) -> String {
        match self {
            ParamType::Bool => "boolean".into(),
            ParamType::Int { min: i64::MIN, max: i64::MAX } => "integer".into(),
            ParamType::Int { min, max } => format!("integer in {min}..={max}"),
            ParamType::Float { min, max } if *min == f64::MIN && *max == f64::MAX => "finite number".into(),
            ParamType::Float { min, max } => format!("number in {min}..={max}"),
            ParamType::Str => "string".into(),
            ParamType::Enum { values } if values.len() > 12 => {
                format!("one of {} names (`{}`, `{}`, ...)", values.len(), values[0], values[1])
            }
            ParamType::Enum { values } => {
                format!("one of {}", values.iter().map(|v| format!("`{v}`")).collect::<Vec<_>>().join(", "))
            }
            ParamType::Path => "path".into(),
            ParamType::Text { what, .. } => (*what).to_owned(),
            ParamType::List { item } => format!("list of ({})", item.describe()),
            ParamType::Map { key, value } => format!("map of ({}) to ({})", key.describe(), value.describe()),
        }
    }
}

/// A parameter's default.
#[derive(Clone, Copy, Debug)]
pub enum Default {
    /// The parameter must be given.
    Required,
    /// Unset unless given: the operator derives the value from its node's seed (the graph
    /// seed mixed with the node id), so `--seed` changes it.
    FromGraphSeed,
    /// The default value, as JSON (written by `params!` from the typed default).
    Value(fn() -> serde_json::Value),
    /// The default value as JSON text: a parameter declared at run time (a Python operator's).
    Json(&'static str),
}

impl Default {
    /// As JSON, `None` when required or seeded.
    pub fn to_json(self) -> Option<serde_json::Value> {
        match self {
            Default::Required | Default::FromGraphSeed => None,
            Default::Value(f) => Some(f()),
            Default::Json(text) => serde_json::from_str(text).ok(),
        }
    }
}

impl serde::Serialize for Default {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.to_json().serialize(s)
    }
}

/// An operator's map parameters, named: what `--save-map FILE`, `--load-map FILE` and
/// `--localise` set (a path, a path, `false`). The registry's test checks each names a
/// parameter of the right type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MapStore {
    /// The path the map is written to at the end.
    pub save: &'static str,
    /// The path of a map to start in.
    pub load: &'static str,
    /// The boolean that is `false` in localisation mode.
    pub mapping: &'static str,
}

/// A parameter declaration.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct ParamSpec {
    /// Key in the node's `params`.
    pub name: &'static str,
    /// Type and range.
    #[serde(flatten)]
    pub ty: ParamType,
    /// Default value.
    pub default: Default,
    /// One line for docs.
    pub doc: &'static str,
}

/// The parameter tables `a` then `b` as one (`N` = both lengths): for operators that share a
/// common table and add their own (`const P: [ParamSpec; A.len() + B.len()] = concat_params(A, B)`).
pub const fn concat_params<const N: usize>(a: &[ParamSpec], b: &[ParamSpec]) -> [ParamSpec; N] {
    assert!(a.len() + b.len() == N && !a.is_empty(), "N must be the sum of the lengths, `a` not empty");
    let mut out = [a[0]; N];
    let mut i = 0;
    while i < N {
        out[i] = if i < a.len() { a[i] } else { b[i - a.len()] };
        i += 1;
    }
    out
}

/// A constructed operator.
pub enum Instance {
    /// A frame producer.
    Source(Box<dyn Source>),
    /// A frame transformer.
    Transform(Box<dyn Operator>),
}

impl std::fmt::Debug for Instance {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Instance::Source(_) => "Instance::Source",
            Instance::Transform(_) => "Instance::Transform",
        })
    }
}

/// What an operator that declares its ports per node (a Python operator, whose class declares
/// them) is asked while its node is validated.
#[derive(Clone, Copy, Debug)]
pub struct DeclareRequest<'a> {
    /// The node id.
    pub node: &'a str,
    /// The node's `params` as written (before validation).
    pub params: &'a serde_json::Map<String, serde_json::Value>,
    /// The graph file's folder (relative paths resolve against it).
    pub base_dir: Option<&'a std::path::Path>,
}

/// An operator's per-node declaration: its ports and parameters for the node's `params`
/// (`Err`: why the node cannot be declared, reported at the node).
pub type DeclareFn = fn(&OpSpec, &DeclareRequest<'_>) -> Result<OpSpec, String>;

/// Everything the engine knows about an operator before running it.
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct OpSpec {
    /// Name used as `op:` in graphs.
    pub name: &'static str,
    /// Family (module) it belongs to, for docs.
    pub family: &'static str,
    /// One paragraph for docs.
    pub doc: &'static str,
    /// Source or transform.
    pub kind: OpKind,
    /// Input ports.
    pub inputs: &'static [PortSpec],
    /// Output ports.
    pub outputs: &'static [PortSpec],
    /// Parameters.
    pub params: &'static [ParamSpec],
    /// Run `process` on the blocking pool (CPU-heavy work).
    pub cpu_heavy: bool,
    /// Outputs that emit ground truth depending on the parameters (a replayed recording's
    /// ground-truth topics), beside the ports declared [`PortSpec::ground_truth`]; called at
    /// validation.
    #[serde(skip)]
    pub ground_truth_outputs: Option<fn(&Params) -> Vec<&'static str>>,
    /// The parameters through which `dynaflow run --save-map/--load-map/--localise` reach
    /// this operator (a tracker that keeps a map), if it has them.
    #[serde(skip)]
    pub map_store: Option<MapStore>,
    /// Ports and parameters declared per node (from the node's `params`) instead of the
    /// static tables above, which then describe what every node has (`dynaflow ops`).
    #[serde(skip)]
    pub declare: Option<DeclareFn>,
    /// Parameters that may change while the graph runs (thresholds and gates, never model
    /// files or sizes): `run --set-at FRAME:node.param=value` changes them from a frame on,
    /// through [`super::Operator::set_params`].
    pub tunable: &'static [&'static str],
    /// Constructor from validated parameters.
    #[serde(skip)]
    pub build: fn(&Params) -> Result<Instance, OpError>,
}

impl OpSpec {
    /// A source (no inputs) named `name` in `family`, documented by `doc`, made by `build`;
    /// ports and parameters follow: `OpSpec::source(..).outputs(&[..]).params(..)`.
    pub const fn source(
        name: &'static str,
        family: &'static str,
        doc: &'static str,
        build: fn(&Params) -> Result<Instance, OpError>,
    ) -> Self {
        Self::new(name, family, doc, OpKind::Source, build)
    }

    /// A transform named `name` in `family`, documented by `doc`, made by `build`.
    pub const fn transform(
        name: &'static str,
        family: &'static str,
        doc: &'static str,
        build: fn(&Params) -> Result<Instance, OpError>,
    ) -> Self {
        Self::new(name, family, doc, OpKind::Transform, build)
    }

    const fn new(
        name: &'static str,
        family: &'static str,
        doc: &'static str,
        kind: OpKind,
        build: fn(&Params) -> Result<Instance, OpError>,
    ) -> Self {
        Self {
            name,
            family,
            doc,
            kind,
            inputs: &[],
            outputs: &[],
            params: &[],
            cpu_heavy: false,
            ground_truth_outputs: None,
            map_store: None,
            declare: None,
            tunable: &[],
            build,
        }
    }

    /// With these input ports.
    pub const fn inputs(mut self, inputs: &'static [PortSpec]) -> Self {
        self.inputs = inputs;
        self
    }

    /// With these output ports.
    pub const fn outputs(mut self, outputs: &'static [PortSpec]) -> Self {
        self.outputs = outputs;
        self
    }

    /// With these parameters.
    pub const fn params(mut self, params: &'static [ParamSpec]) -> Self {
        self.params = params;
        self
    }

    /// Runs `process` on the blocking pool (CPU-heavy work).
    pub const fn cpu_heavy(mut self) -> Self {
        self.cpu_heavy = true;
        self
    }

    /// With outputs that carry ground truth depending on the parameters.
    pub const fn ground_truth_outputs(mut self, outputs: fn(&Params) -> Vec<&'static str>) -> Self {
        self.ground_truth_outputs = Some(outputs);
        self
    }

    /// With the parameters `dynaflow run --save-map/--load-map/--localise` set.
    pub const fn map_store(mut self, store: MapStore) -> Self {
        self.map_store = Some(store);
        self
    }

    /// With these parameters changeable while the graph runs (each one of [`OpSpec::params`];
    /// the operator takes them in [`super::Operator::set_params`]).
    pub const fn tunable(mut self, tunable: &'static [&'static str]) -> Self {
        self.tunable = tunable;
        self
    }

    /// With ports and parameters declared per node by `declare`.
    pub const fn declare(mut self, declare: DeclareFn) -> Self {
        self.declare = Some(declare);
        self
    }

    /// The input port named `name`.
    pub fn input(&self, name: &str) -> Option<&'static PortSpec> {
        self.inputs.iter().find(|p| p.name == name)
    }
    /// The output port named `name`.
    pub fn output(&self, name: &str) -> Option<&'static PortSpec> {
        self.outputs.iter().find(|p| p.name == name)
    }
    /// The parameter named `name`.
    pub fn param(&self, name: &str) -> Option<&'static ParamSpec> {
        self.params.iter().find(|p| p.name == name)
    }
}
