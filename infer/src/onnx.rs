//! A reader for ONNX model files: the protobuf wire format decoded by hand for the few
//! messages a model needs (`ModelProto`, `GraphProto`, `NodeProto`, `AttributeProto`,
//! `TensorProto`, `ValueInfoProto`), following `onnx.proto`'s field numbers. No protoc, no
//! generated code; every length and count is checked against the bytes that are there, so a
//! truncated or corrupt file is an error, never a panic or a huge allocation.

use std::collections::BTreeMap;
use std::path::Path;

use crate::Error;

fn bad(msg: impl Into<String>) -> Error {
    Error::Malformed(msg.into())
}

/// Element type of a tensor (ONNX `TensorProto.DataType`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DataType {
    /// 1.
    Float,
    /// 6.
    Int32,
    /// 7.
    Int64,
    /// 11.
    Double,
    /// Anything else (its ONNX code).
    Other(i64),
}

impl DataType {
    fn from_code(c: i64) -> Self {
        match c {
            1 => DataType::Float,
            6 => DataType::Int32,
            7 => DataType::Int64,
            11 => DataType::Double,
            o => DataType::Other(o),
        }
    }
}

/// A constant tensor (initializer, or a `Constant` node's value, or an attribute).
#[derive(Clone, Debug, PartialEq)]
pub struct TensorData {
    /// Name (empty for attributes).
    pub name: String,
    /// Shape.
    pub dims: Vec<i64>,
    /// Element type.
    pub data_type: DataType,
    /// Values as f32 (for float and double tensors).
    pub floats: Vec<f32>,
    /// Values as i64 (for integer tensors).
    pub ints: Vec<i64>,
}

impl TensorData {
    /// Number of elements the shape says.
    pub fn len(&self) -> usize {
        self.dims.iter().map(|&d| d.max(0) as usize).product()
    }
    /// Whether the tensor has no elements.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// An attribute value.
#[derive(Clone, Debug, PartialEq)]
pub enum Attribute {
    /// `f`.
    Float(f32),
    /// `i`.
    Int(i64),
    /// `s`.
    String(Vec<u8>),
    /// `t`.
    Tensor(TensorData),
    /// `floats`.
    Floats(Vec<f32>),
    /// `ints`.
    Ints(Vec<i64>),
}

/// The ops dynaflow's executors know, each named once: the enum variant is the ONNX
/// `op_type`.
macro_rules! onnx_ops {
    ($($op:ident),* $(,)?) => {
        /// An ONNX operator, parsed once from the node's `op_type`: the ops dynaflow's executors
        /// know, and any other by name (an executor refuses it, naming it).
        #[derive(Clone, Debug, PartialEq, Eq, Hash)]
        pub enum Op {
            $(#[doc = concat!("`", stringify!($op), "`.")] $op,)*
            /// An op no executor here runs.
            Other(String),
        }

        impl Op {
            /// Every op the executors know, by ONNX name.
            pub const NAMES: &'static [&'static str] = &[$(stringify!($op)),*];

            /// The op named `op_type`.
            pub fn parse(op_type: &str) -> Self {
                match op_type {
                    $(stringify!($op) => Op::$op,)*
                    other => Op::Other(other.to_owned()),
                }
            }

            /// The ONNX name.
            pub fn name(&self) -> &str {
                match self {
                    $(Op::$op => stringify!($op),)*
                    Op::Other(name) => name,
                }
            }
        }
    };
}

onnx_ops! {
    Add,
    AveragePool,
    Clip,
    Concat,
    Constant,
    Conv,
    ConvTranspose,
    Div,
    Gather,
    GlobalAveragePool,
    HardSigmoid,
    HardSwish,
    MaxPool,
    Mul,
    Pad,
    Relu,
    Reshape,
    Resize,
    Shape,
    Sigmoid,
    Slice,
    Softmax,
    Sub,
    Transpose,
    Unsqueeze,
}

impl std::fmt::Display for Op {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A graph node.
#[derive(Clone, Debug, PartialEq)]
pub struct Node {
    /// Node name (may be empty).
    pub name: String,
    /// Operator, e.g. `Conv`.
    pub op: Op,
    /// Operator domain (empty: the default ONNX domain).
    pub domain: String,
    /// Input value names (empty string: an omitted optional input).
    pub inputs: Vec<String>,
    /// Output value names.
    pub outputs: Vec<String>,
    /// Attributes by name.
    pub attributes: BTreeMap<String, Attribute>,
}

impl Node {
    /// An integer attribute, or `default`.
    pub fn int(&self, name: &str, default: i64) -> i64 {
        match self.attributes.get(name) {
            Some(Attribute::Int(v)) => *v,
            _ => default,
        }
    }
    /// An integer-list attribute, if present.
    pub fn ints(&self, name: &str) -> Option<&[i64]> {
        match self.attributes.get(name) {
            Some(Attribute::Ints(v)) => Some(v),
            _ => None,
        }
    }
    /// A float attribute, or `default`.
    pub fn float(&self, name: &str, default: f32) -> f32 {
        match self.attributes.get(name) {
            Some(Attribute::Float(v)) => *v,
            _ => default,
        }
    }
    /// A string attribute, or `default`.
    pub fn string(&self, name: &str, default: &str) -> String {
        match self.attributes.get(name) {
            Some(Attribute::String(v)) => String::from_utf8_lossy(v).into_owned(),
            _ => default.to_string(),
        }
    }
    /// How the node is named in messages: its name, or its op type and first output.
    pub fn label(&self) -> String {
        if self.name.is_empty() {
            format!("{} -> {}", self.op, self.outputs.first().map_or("?", String::as_str))
        } else {
            format!("{} ({})", self.name, self.op)
        }
    }
}

/// A graph input or output: name, element type and shape (`None` for a symbolic dimension).
#[derive(Clone, Debug, PartialEq)]
pub struct ValueInfo {
    /// Value name.
    pub name: String,
    /// Element type code.
    pub elem_type: i64,
    /// Dimensions.
    pub shape: Vec<Option<i64>>,
}

/// A model: its main graph, opset and producer.
#[derive(Clone, Debug, PartialEq)]
pub struct Model {
    /// ONNX IR version.
    pub ir_version: i64,
    /// Default-domain opset version.
    pub opset: i64,
    /// `producer_name producer_version`.
    pub producer: String,
    /// Nodes in file order (ONNX requires topological order).
    pub nodes: Vec<Node>,
    /// Initializers by name.
    pub initializers: BTreeMap<String, TensorData>,
    /// Graph inputs that are not initializers.
    pub inputs: Vec<ValueInfo>,
    /// Graph outputs.
    pub outputs: Vec<ValueInfo>,
}

use dynaflow_base::wire::{Reader, Value};

impl From<dynaflow_base::wire::WireError> for Error {
    fn from(e: dynaflow_base::wire::WireError) -> Self {
        bad(e.0)
    }
}

fn string(v: &Value<'_>) -> Result<String, Error> {
    match v {
        Value::Bytes(b) => Ok(String::from_utf8_lossy(b).into_owned()),
        _ => Err(bad("expected a string")),
    }
}

fn int(v: &Value<'_>) -> Result<i64, Error> {
    match v {
        Value::Varint(x) => Ok(*x as i64),
        _ => Err(bad("expected an integer")),
    }
}

/// Repeated int64: packed bytes or one varint.
fn push_ints(v: &Value<'_>, out: &mut Vec<i64>) -> Result<(), Error> {
    match v {
        Value::Varint(x) => out.push(*x as i64),
        Value::Bytes(b) => {
            let mut r = Reader::new(b);
            while !r.done() {
                out.push(r.varint()? as i64);
            }
        }
        _ => return Err(bad("expected integers")),
    }
    Ok(())
}

/// Repeated float: packed bytes or one fixed32.
fn push_floats(v: &Value<'_>, out: &mut Vec<f32>) -> Result<(), Error> {
    match v {
        Value::Fixed32(x) => out.push(f32::from_bits(*x)),
        Value::Bytes(b) => {
            if b.len() % 4 != 0 {
                return Err(bad("packed floats not a multiple of 4 bytes"));
            }
            out.extend(b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])));
        }
        _ => return Err(bad("expected floats")),
    }
    Ok(())
}

fn tensor(buf: &[u8]) -> Result<TensorData, Error> {
    let mut r = Reader::new(buf);
    let mut t = TensorData {
        name: String::new(),
        dims: Vec::new(),
        data_type: DataType::Other(0),
        floats: Vec::new(),
        ints: Vec::new(),
    };
    let mut raw: Option<&[u8]> = None;
    let (mut doubles, mut external) = (Vec::new(), false);
    while !r.done() {
        let (num, v) = r.field()?;
        match num {
            1 => push_ints(&v, &mut t.dims)?,
            2 => t.data_type = DataType::from_code(int(&v)?),
            4 => push_floats(&v, &mut t.floats)?,
            5 | 7 => push_ints(&v, &mut t.ints)?,
            8 => t.name = string(&v)?,
            9 => {
                if let Value::Bytes(b) = v {
                    raw = Some(b);
                }
            }
            10 => match v {
                Value::Fixed64(x) => doubles.push(f64::from_bits(x)),
                Value::Bytes(b) => {
                    doubles.extend(b.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8]))))
                }
                _ => return Err(bad("double_data")),
            },
            14 => external = int(&v)? == 1,
            _ => {}
        }
    }
    if external {
        return Err(Error::Unsupported(format!("tensor `{}` keeps its data in an external file", t.name)));
    }
    if t.dims.iter().any(|&d| d < 0) {
        return Err(bad(format!("tensor `{}` has a negative dimension", t.name)));
    }
    let n = t.dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d as usize)).ok_or_else(|| bad("tensor too large"))?;
    if let Some(raw) = raw {
        let width = match t.data_type {
            DataType::Float | DataType::Int32 => 4,
            DataType::Int64 | DataType::Double => 8,
            DataType::Other(c) => {
                return Err(Error::Unsupported(format!("tensor `{}` has element type {c}", t.name)));
            }
        };
        if raw.len() != n.checked_mul(width).ok_or_else(|| bad("tensor too large"))? {
            return Err(bad(format!("tensor `{}`: {} bytes for {n} elements", t.name, raw.len())));
        }
        match t.data_type {
            DataType::Float => {
                t.floats = raw.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
            }
            DataType::Double => {
                t.floats =
                    raw.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])) as f32).collect();
            }
            DataType::Int32 => {
                t.ints = raw.chunks_exact(4).map(|c| i64::from(i32::from_le_bytes([c[0], c[1], c[2], c[3]]))).collect()
            }
            DataType::Int64 => {
                t.ints = raw.chunks_exact(8).map(|c| i64::from_le_bytes(c.try_into().unwrap_or([0; 8]))).collect()
            }
            DataType::Other(_) => {}
        }
    } else if !doubles.is_empty() {
        t.floats = doubles.iter().map(|&d| d as f32).collect();
    }
    let have = t.floats.len().max(t.ints.len());
    if have != n {
        return Err(bad(format!("tensor `{}`: {have} values for shape {:?}", t.name, t.dims)));
    }
    Ok(t)
}

fn attribute(buf: &[u8]) -> Result<(String, Attribute), Error> {
    let mut r = Reader::new(buf);
    let (mut name, mut ty) = (String::new(), 0i64);
    let (mut f, mut i, mut s, mut t) = (None, None, None, None);
    let (mut floats, mut ints) = (Vec::new(), Vec::new());
    while !r.done() {
        let (num, v) = r.field()?;
        match num {
            1 => name = string(&v)?,
            2 => {
                if let Value::Fixed32(x) = v {
                    f = Some(f32::from_bits(x));
                }
            }
            3 => i = Some(int(&v)?),
            4 => {
                if let Value::Bytes(b) = v {
                    s = Some(b.to_vec());
                }
            }
            5 => {
                if let Value::Bytes(b) = v {
                    t = Some(tensor(b)?);
                }
            }
            7 => push_floats(&v, &mut floats)?,
            8 => push_ints(&v, &mut ints)?,
            20 => ty = int(&v)?,
            _ => {}
        }
    }
    // AttributeType: 1 FLOAT, 2 INT, 3 STRING, 4 TENSOR, 6 FLOATS, 7 INTS.
    let a = match (ty, f, i, s, t) {
        (1, Some(f), ..) => Attribute::Float(f),
        (2, _, Some(i), ..) => Attribute::Int(i),
        (3, _, _, Some(s), _) => Attribute::String(s),
        (4, _, _, _, Some(t)) => Attribute::Tensor(t),
        (6, ..) => Attribute::Floats(floats),
        (7, ..) => Attribute::Ints(ints),
        (0, Some(f), ..) => Attribute::Float(f),
        (0, _, Some(i), ..) => Attribute::Int(i),
        _ => Attribute::Ints(ints),
    };
    Ok((name, a))
}

fn node(buf: &[u8]) -> Result<Node, Error> {
    let mut r = Reader::new(buf);
    let mut op_type = String::new();
    let mut n = Node {
        name: String::new(),
        op: Op::Other(String::new()),
        domain: String::new(),
        inputs: Vec::new(),
        outputs: Vec::new(),
        attributes: BTreeMap::new(),
    };
    while !r.done() {
        let (num, v) = r.field()?;
        match num {
            1 => n.inputs.push(string(&v)?),
            2 => n.outputs.push(string(&v)?),
            3 => n.name = string(&v)?,
            4 => op_type = string(&v)?,
            5 => {
                if let Value::Bytes(b) = v {
                    let (k, a) = attribute(b)?;
                    n.attributes.insert(k, a);
                }
            }
            7 => n.domain = string(&v)?,
            _ => {}
        }
    }
    n.op = Op::parse(&op_type);
    if op_type.is_empty() {
        return Err(bad(format!("node `{}` has no op_type", n.name)));
    }
    Ok(n)
}

fn value_info(buf: &[u8]) -> Result<ValueInfo, Error> {
    let mut r = Reader::new(buf);
    let mut vi = ValueInfo { name: String::new(), elem_type: 0, shape: Vec::new() };
    while !r.done() {
        let (num, v) = r.field()?;
        match (num, v) {
            (1, v) => vi.name = string(&v)?,
            (2, Value::Bytes(tp)) => {
                // TypeProto.tensor_type = 1 -> elem_type = 1, shape = 2 -> dim = 1.
                let mut t = Reader::new(tp);
                while !t.done() {
                    if let (1, Value::Bytes(tt)) = t.field()? {
                        let mut tr = Reader::new(tt);
                        while !tr.done() {
                            match tr.field()? {
                                (1, v) => vi.elem_type = int(&v)?,
                                (2, Value::Bytes(sh)) => {
                                    let mut sr = Reader::new(sh);
                                    while !sr.done() {
                                        if let (1, Value::Bytes(dim)) = sr.field()? {
                                            let mut dr = Reader::new(dim);
                                            let mut d = None;
                                            while !dr.done() {
                                                if let (1, v) = dr.field()? {
                                                    d = Some(int(&v)?);
                                                }
                                            }
                                            vi.shape.push(d);
                                        }
                                    }
                                }
                                _ => {}
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(vi)
}

/// Decode a model from its bytes.
pub fn parse(bytes: &[u8]) -> Result<Model, Error> {
    let mut r = Reader::new(bytes);
    let mut m = Model {
        ir_version: 0,
        opset: 0,
        producer: String::new(),
        nodes: Vec::new(),
        initializers: BTreeMap::new(),
        inputs: Vec::new(),
        outputs: Vec::new(),
    };
    let mut graph = None;
    let mut producer = (String::new(), String::new());
    while !r.done() {
        let (num, v) = r.field()?;
        match num {
            1 => m.ir_version = int(&v)?,
            2 => producer.0 = string(&v)?,
            3 => producer.1 = string(&v)?,
            7 => {
                if let Value::Bytes(b) = v {
                    graph = Some(b);
                }
            }
            8 => {
                if let Value::Bytes(b) = v {
                    let mut o = Reader::new(b);
                    let (mut domain, mut version) = (String::new(), 0);
                    while !o.done() {
                        match o.field()? {
                            (1, v) => domain = string(&v)?,
                            (2, v) => version = int(&v)?,
                            _ => {}
                        }
                    }
                    if domain.is_empty() || domain == "ai.onnx" {
                        m.opset = version;
                    }
                }
            }
            _ => {}
        }
    }
    m.producer = format!("{} {}", producer.0, producer.1).trim().to_string();
    let graph = graph.ok_or_else(|| bad("no graph (is this an ONNX file?)"))?;
    let mut g = Reader::new(graph);
    let mut inputs = Vec::new();
    while !g.done() {
        let (num, v) = g.field()?;
        let Value::Bytes(b) = v else { continue };
        match num {
            1 => m.nodes.push(node(b)?),
            5 => {
                let t = tensor(b)?;
                m.initializers.insert(t.name.clone(), t);
            }
            11 => inputs.push(value_info(b)?),
            12 => m.outputs.push(value_info(b)?),
            _ => {}
        }
    }
    m.inputs = inputs.into_iter().filter(|i| !m.initializers.contains_key(&i.name)).collect();
    if m.nodes.is_empty() || m.outputs.is_empty() {
        return Err(bad("the graph has no nodes or no outputs"));
    }
    Ok(m)
}

/// Read and decode a model file.
pub fn load(path: &Path) -> Result<Model, Error> {
    load_with_bytes(path).map(|(m, _)| m)
}

/// Read and decode a model file; the model and the file's bytes (for another runtime).
pub fn load_with_bytes(path: &Path) -> Result<(Model, Vec<u8>), Error> {
    let bytes =
        std::fs::read(path).map_err(|e| Error::Io { path: path.display().to_string(), message: e.to_string() })?;
    let model = parse(&bytes).map_err(|e| match e {
        Error::Malformed(m) => Error::Malformed(format!("{}: {m}", path.display())),
        Error::Unsupported(m) => Error::Unsupported(format!("{}: {m}", path.display())),
        io => io,
    })?;
    Ok((model, bytes))
}
