//! Declaring an operator once: typed parameters ([`params!`](crate::params),
//! [`param_enum!`](crate::param_enum)) and typed port handles ([`In`], [`Out`]).
//!
//! A parameter struct written with `params!` is the operator's only statement of its
//! parameters: the macro derives the [`ParamSpec`] table that validation, `dynaflow ops` and
//! the docs read (names, types, ranges, defaults, docs) and the constructor that turns
//! validated [`Params`] into the struct. The Rust type of each field decides the declared
//! type through [`Param`]: integers and numbers take an inclusive range written after the
//! type, enums come from `param_enum!`, lists are `Vec<T>` and maps [`ParamMap`], each
//! element checked at its own YAML position.
//!
//! A port handle is declared once as a `const` and used both in the [`OpSpec`](super::OpSpec)
//! (`inputs: &[IMAGE.spec, MASK.spec]`) and in the operator's code (`MASK.get(inputs)?`), so a
//! misspelt port is a compile error, and reading a port the operator did not declare is an
//! operator-bug error, never a silent "absent".

use std::marker::PhantomData;
use std::path::PathBuf;
use std::sync::Arc;

use super::spec::{InputRole, ParamType, PortSpec};
use super::{Inputs, OpError, Outputs, Params};
use crate::msg::{Header, Message, Payload};

/// A Rust type a parameter can have.
pub trait Param: Sized {
    /// The declared type (a range written in `params!` narrows `Int` and `Float`).
    const TYPE: ParamType;
    /// The default when `params!` gives none: the parameter is required unless the type
    /// says otherwise ([`Seeded`]).
    const ABSENT: super::Default = super::Default::Required;
    /// From a validated value (relative paths resolve against `params`' graph folder).
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String>;
    /// As JSON (for defaults in docs and validation).
    fn to_json(&self) -> serde_json::Value;
}

/// `ty` narrowed to `lo..=hi`; a range on anything but a number does not compile.
pub const fn ranged(ty: ParamType, lo: f64, hi: f64) -> ParamType {
    match ty {
        ParamType::Int { .. } => ParamType::Int { min: lo as i64, max: hi as i64 },
        ParamType::Float { .. } => ParamType::Float { min: lo, max: hi },
        _ => panic!("a range applies to integer and number parameters only"),
    }
}

/// A `///` doc comment as one line (the leading space of each line dropped).
pub const fn doc_line(s: &'static str) -> &'static str {
    s.trim_ascii()
}

macro_rules! int_param {
    ($($t:ty),*) => {$(
        impl Param for $t {
            const TYPE: ParamType = ParamType::Int {
                min: <$t>::MIN as i64,
                max: if <$t>::MAX as u128 > i64::MAX as u128 { i64::MAX } else { <$t>::MAX as i64 },
            };
            fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
                value
                    .as_i64()
                    .and_then(|v| <$t>::try_from(v).ok())
                    .or_else(|| value.as_u64().and_then(|v| <$t>::try_from(v).ok()))
                    .ok_or_else(|| format!("expected an integer that fits {}, found {value}", stringify!($t)))
            }
            fn to_json(&self) -> serde_json::Value {
                serde_json::json!(*self)
            }
        }
    )*};
}
int_param!(u8, u16, u32, u64, usize, i32, i64);

impl Param for f64 {
    const TYPE: ParamType = ParamType::Float { min: f64::MIN, max: f64::MAX };
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        value.as_f64().filter(|v| v.is_finite()).ok_or_else(|| format!("expected a finite number, found {value}"))
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!(*self)
    }
}

impl Param for f32 {
    const TYPE: ParamType = ParamType::Float { min: f32::MIN as f64, max: f32::MAX as f64 };
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        f64::from_json(value, params).map(|v| v as f32)
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!(f64::from(*self))
    }
}

impl Param for bool {
    const TYPE: ParamType = ParamType::Bool;
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        value.as_bool().ok_or_else(|| format!("expected true or false, found {value}"))
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!(*self)
    }
}

impl Param for String {
    const TYPE: ParamType = ParamType::Str;
    fn from_json(value: &serde_json::Value, _: &Params) -> Result<Self, String> {
        value.as_str().map(str::to_owned).ok_or_else(|| format!("expected a string, found {value}"))
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!(self)
    }
}

/// A file or folder: relative paths resolve against the graph file's folder; an empty path
/// stays empty (operators that take an optional path read it as "none").
impl Param for PathBuf {
    const TYPE: ParamType = ParamType::Path;
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        let s = value.as_str().ok_or_else(|| format!("expected a path, found {value}"))?;
        Ok(if s.is_empty() { PathBuf::new() } else { params.resolve_path(s) })
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::json!(self.display().to_string())
    }
}

/// A seed: unset unless given, then the operator derives it from its node's seed (the graph
/// seed mixed with the node id), so `--seed` changes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Seeded(pub Option<u64>);

impl Seeded {
    /// The given seed, or `node_seed`.
    pub fn or(self, node_seed: u64) -> u64 {
        self.0.unwrap_or(node_seed)
    }
}

impl Param for Seeded {
    const TYPE: ParamType = <u64 as Param>::TYPE;
    const ABSENT: super::Default = super::Default::FromGraphSeed;
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        if value.is_null() {
            return Ok(Seeded(None));
        }
        u64::from_json(value, params).map(|v| Seeded(Some(v)))
    }
    fn to_json(&self) -> serde_json::Value {
        self.0.map_or(serde_json::Value::Null, |v| serde_json::json!(v))
    }
}

/// A list: a YAML sequence, or (the older form) one string of comma-separated items.
impl<T: Param> Param for Vec<T> {
    const TYPE: ParamType = ParamType::List { item: &T::TYPE };
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        match value {
            serde_json::Value::Array(items) => items.iter().map(|v| T::from_json(v, params)).collect(),
            serde_json::Value::String(s) => split_list(s).map(|v| T::from_json(&item_value(v), params)).collect(),
            other => Err(format!("expected a list, found {other}")),
        }
    }
    fn to_json(&self) -> serde_json::Value {
        serde_json::Value::Array(self.iter().map(Param::to_json).collect())
    }
}

/// A map: a YAML mapping, or (the older form) one string of comma-separated `key=value`
/// pairs. Validated values reach the operator with their keys in name order (no operator may
/// depend on the order written); a key given twice keeps its last value.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamMap<K, V>(pub Vec<(K, V)>);

impl<K: Param + PartialEq, V: Param> Param for ParamMap<K, V> {
    const TYPE: ParamType = ParamType::Map { key: &K::TYPE, value: &V::TYPE };
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        let pairs: Vec<(serde_json::Value, serde_json::Value)> = match value {
            serde_json::Value::Object(m) => m.iter().map(|(k, v)| (k.as_str().into(), v.clone())).collect(),
            serde_json::Value::String(s) => split_pairs(s)?,
            other => return Err(format!("expected a map, found {other}")),
        };
        let mut out: Vec<(K, V)> = Vec::new();
        for (k, v) in pairs {
            let (k, v) = (K::from_json(&k, params)?, V::from_json(&v, params)?);
            out.retain(|(e, _)| *e != k);
            out.push((k, v));
        }
        Ok(ParamMap(out))
    }
    fn to_json(&self) -> serde_json::Value {
        let key = |k: &K| match k.to_json() {
            serde_json::Value::String(s) => s,
            other => other.to_string(),
        };
        serde_json::Value::Object(self.0.iter().map(|(k, v)| (key(k), v.to_json())).collect())
    }
}

/// The items of a comma-separated list (trimmed, empty items dropped: an empty string is an
/// empty list).
pub(crate) fn split_list(s: &str) -> impl Iterator<Item = &str> {
    comma_items(s).map(|(_, item)| item)
}

/// The trimmed, non-empty items of a comma-separated string, each with its byte offset in
/// `s` (validation turns the offsets into file positions).
pub(crate) fn comma_items(s: &str) -> impl Iterator<Item = (usize, &str)> {
    s.split(',')
        .scan(0, |pos, part| {
            let at = *pos + part.len() - part.trim_start().len();
            *pos += part.len() + 1;
            Some((at, part.trim()))
        })
        .filter(|(_, item)| !item.is_empty())
}

/// `key=value` pairs of a comma-separated string.
pub(crate) fn split_pairs(s: &str) -> Result<Vec<(serde_json::Value, serde_json::Value)>, String> {
    split_list(s)
        .map(|pair| {
            let (k, v) = pair.split_once('=').ok_or_else(|| format!("`{pair}` is not `key=value`"))?;
            Ok((k.trim().into(), item_value(v.trim())))
        })
        .collect()
}

/// A list item written inside a string: a number where it reads as one, else a string.
pub(crate) fn item_value(s: &str) -> serde_json::Value {
    s.parse::<i64>()
        .map(serde_json::Value::from)
        .or_else(|_| s.parse::<f64>().map(serde_json::Value::from))
        .unwrap_or_else(|_| s.into())
}

/// Declares an operator's parameters once, as a typed struct.
///
/// ```ignore
/// dynaflow_engine::params! {
///     /// `orb_extract`'s parameters.
///     pub struct Config {
///         /// keypoints wanted over all levels
///         features: usize [1, 100_000] = 1000,
///         /// the `.onnx` file
///         model: PathBuf,
///         seed: Seeded,
///     }
/// }
/// ```
///
/// Each field's doc comment is its documentation, `[lo, hi]` after a numeric type its
/// inclusive range, `= expr` its default (checked against the type by the compiler; without
/// one the parameter is required, or seeded for [`Seeded`]). The macro emits the struct with
/// public fields, `Config::PARAMS` (the table for [`OpSpec::params`](super::OpSpec)) and
/// `Config::from_params`.
#[macro_export]
macro_rules! params {
    (
        $(#[doc = $sdoc:literal])*
        $vis:vis struct $name:ident {
            $(
                $(#[doc = $doc:literal])*
                $field:ident : $ty:ty $([$lo:expr, $hi:expr])? $(= $default:expr)?
            ),* $(,)?
        }
    ) => {
        $(#[doc = $sdoc])*
        #[derive(Clone, Debug)]
        $vis struct $name {
            $(
                $(#[doc = $doc])*
                pub $field: $ty,
            )*
        }

        impl $name {
            /// The parameter table (for `OpSpec::params`).
            pub const PARAMS: &'static [$crate::op::ParamSpec] = &[$(
                $crate::op::ParamSpec {
                    name: stringify!($field),
                    ty: $crate::params!(@ty $ty $(, $lo, $hi)?),
                    default: $crate::params!(@default $ty $(, $default)?),
                    doc: $crate::op::doc_line(concat!($($doc),*)),
                }
            ),*];

            /// The struct from validated parameters; an error names the key.
            pub fn from_params(params: &$crate::op::Params) -> ::std::result::Result<Self, $crate::op::OpError> {
                Ok(Self { $($field: params.value::<$ty>(stringify!($field))?,)* })
            }
        }
    };
    (@ty $ty:ty) => { <$ty as $crate::op::Param>::TYPE };
    (@ty $ty:ty, $lo:expr, $hi:expr) => {
        $crate::op::ranged(<$ty as $crate::op::Param>::TYPE, $lo as f64, $hi as f64)
    };
    (@default $ty:ty) => { <$ty as $crate::op::Param>::ABSENT };
    (@default $ty:ty, $default:expr) => {
        $crate::op::Default::Value(|| {
            let v: $ty = $default;
            <$ty as $crate::op::Param>::to_json(&v)
        })
    };
}

/// Declares an enum parameter type: its variants and the names graphs write.
///
/// ```ignore
/// dynaflow_engine::param_enum! {
///     /// How keypoints are spread.
///     pub enum Distribution { Quadtree = "quadtree", Harris = "harris" }
/// }
/// ```
#[macro_export]
macro_rules! param_enum {
    (
        $(#[doc = $edoc:literal])*
        $vis:vis enum $name:ident {
            $( $(#[doc = $doc:literal])* $variant:ident = $text:literal ),+ $(,)?
        }
    ) => {
        $(#[doc = $edoc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        $vis enum $name {
            $( $(#[doc = $doc])* $variant, )+
        }

        impl $name {
            /// The names graphs write, in declaration order.
            pub const NAMES: &'static [&'static str] = &[$($text),+];
            /// The name graphs write.
            pub fn as_str(self) -> &'static str {
                match self { $( Self::$variant => $text, )+ }
            }
            /// The variant graphs name `name`.
            pub fn from_name(name: &str) -> Option<Self> {
                match name { $( $text => Some(Self::$variant), )+ _ => None }
            }
        }

        impl $crate::op::Param for $name {
            const TYPE: $crate::op::ParamType = $crate::op::ParamType::Enum { values: Self::NAMES };
            fn from_json(
                value: &::serde_json::Value,
                _: &$crate::op::Params,
            ) -> ::std::result::Result<Self, ::std::string::String> {
                value
                    .as_str()
                    .and_then(Self::from_name)
                    .ok_or_else(|| format!("expected one of {:?}, found {value}", Self::NAMES))
            }
            fn to_json(&self) -> ::serde_json::Value {
                ::serde_json::Value::String(self.as_str().to_owned())
            }
        }
    };
}

/// A typed input port, declared once as a `const`.
#[derive(Clone, Copy, Debug)]
pub struct In<T> {
    /// The declaration (for `OpSpec::inputs`).
    pub spec: PortSpec,
    ty: PhantomData<fn() -> T>,
}

impl<T: Payload> In<T> {
    const fn make(name: &'static str, required: bool, wired: bool, doc: &'static str) -> Self {
        let mut spec = PortSpec::output(name, T::PORT, doc);
        spec.required = required;
        spec.wired = wired;
        Self { spec, ty: PhantomData }
    }
    /// An input the node needs every frame (a frame without it is skipped).
    pub const fn required(name: &'static str, doc: &'static str) -> Self {
        Self::make(name, true, true, doc)
    }
    /// An input that must be wired, but may carry nothing in a frame (the node runs and
    /// treats the frame as its doc says).
    pub const fn wired(name: &'static str, doc: &'static str) -> Self {
        Self::make(name, false, true, doc)
    }
    /// An input the node can do without.
    pub const fn optional(name: &'static str, doc: &'static str) -> Self {
        Self::make(name, false, false, doc)
    }
    /// This input with `role` (statistics or evaluation only).
    pub const fn with_role(mut self, role: InputRole) -> Self {
        self.spec.role = role;
        self
    }

    /// The message on this port this frame, if any.
    pub fn message<'a>(&self, inputs: &'a Inputs) -> Result<Option<&'a Arc<Message>>, OpError> {
        inputs.declared(self.spec.name)
    }
    /// The message and its payload on this port this frame, if any; a message of another
    /// type is an error.
    pub fn find<'a>(&self, inputs: &'a Inputs) -> Result<Option<(&'a Arc<Message>, &'a T)>, OpError> {
        self.message(inputs)?.map(|m| Ok((m, self.payload(m)?))).transpose()
    }
    /// The payload on this port this frame, if any; a message of another type is an error.
    pub fn get<'a>(&self, inputs: &'a Inputs) -> Result<Option<&'a T>, OpError> {
        Ok(self.find(inputs)?.map(|(_, t)| t))
    }
    /// The message and payload on this port; absent is an error naming the port.
    pub fn require<'a>(&self, inputs: &'a Inputs) -> Result<(&'a Message, &'a T), OpError> {
        let (msg, t) = self
            .find(inputs)?
            .ok_or_else(|| OpError::Input(format!("input `{}` is absent at frame {}", self.spec.name, inputs.seq)))?;
        Ok((msg, t))
    }
    fn payload<'a>(&self, msg: &'a Message) -> Result<&'a T, OpError> {
        T::of(&msg.body).ok_or_else(|| {
            OpError::Input(format!(
                "`{}` expects {}, got {}",
                self.spec.name,
                T::PORT.name(),
                msg.body.port_type().name()
            ))
        })
    }
}

/// A typed output port, declared once as a `const`.
#[derive(Clone, Copy, Debug)]
pub struct Out<T> {
    /// The declaration (for `OpSpec::outputs`).
    pub spec: PortSpec,
    ty: PhantomData<fn() -> T>,
}

impl<T: Payload> Out<T> {
    /// An output.
    pub const fn new(name: &'static str, doc: &'static str) -> Self {
        Self { spec: PortSpec::output(name, T::PORT, doc), ty: PhantomData }
    }
    /// An output that emits ground truth.
    pub const fn ground_truth(name: &'static str, doc: &'static str) -> Self {
        Self { spec: PortSpec::ground_truth(name, T::PORT, doc), ty: PhantomData }
    }
    /// Emit `value` on this port.
    pub fn push(&self, out: &mut Outputs, header: Header, value: T) {
        out.push(self.spec.name, header, value.into_body());
    }
}

impl Out<crate::msg::Body> {
    /// An output whose type follows the input `input` (any message).
    pub const fn like(name: &'static str, input: &'static str, doc: &'static str) -> Self {
        Self { spec: PortSpec::output_like(name, input, doc), ty: PhantomData }
    }
}

impl Outputs {
    /// Builder form of [`Out::push`].
    #[must_use]
    pub fn send<T: Payload>(mut self, port: &Out<T>, header: Header, value: T) -> Self {
        port.push(&mut self, header, value);
        self
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::msg::{Body, Scalars};
    use crate::op::{Default, Inputs, OpError, ParamType, Params};

    crate::param_enum! {
        enum Colour { Red = "red", Blue = "blue" }
    }

    crate::params! {
        /// A test operator's parameters.
        struct Config {
            /// a count
            count: u32 [1, 10] = 3,
            /// a colour
            colour: Colour = Colour::Blue,
            /// names
            names: Vec<String> = vec!["a".into()],
            /// weights
            weights: ParamMap<String, f64> = ParamMap(Vec::new()),
            /// required
            path: std::path::PathBuf,
            seed: Seeded,
        }
    }

    fn params(v: serde_json::Value) -> Params {
        let serde_json::Value::Object(map) = v else { unreachable!("an object") };
        Params::new(map, Some("/graphs".into()))
    }

    #[test]
    fn the_table_is_derived_from_the_struct() {
        let t = Config::PARAMS;
        assert_eq!(
            t.iter().map(|p| p.name).collect::<Vec<_>>(),
            ["count", "colour", "names", "weights", "path", "seed"]
        );
        assert!(matches!(t[0].ty, ParamType::Int { min: 1, max: 10 }));
        assert_eq!(t[0].doc, "a count");
        assert_eq!(t[0].default.to_json(), Some(serde_json::json!(3)));
        assert!(matches!(t[1].ty, ParamType::Enum { values: ["red", "blue"] }));
        assert_eq!(t[1].default.to_json(), Some(serde_json::json!("blue")));
        assert!(matches!(t[2].ty, ParamType::List { item: ParamType::Str }));
        assert_eq!(t[2].default.to_json(), Some(serde_json::json!(["a"])));
        assert!(matches!(t[3].ty, ParamType::Map { key: ParamType::Str, value: ParamType::Float { .. } }));
        assert!(matches!(t[4].default, Default::Required));
        assert!(matches!(t[5].default, Default::FromGraphSeed));
        // u64's declared maximum is i64's, never a wrapped -1.
        assert!(matches!(<u64 as Param>::TYPE, ParamType::Int { min: 0, max: i64::MAX }));
    }

    #[test]
    fn values_parse_into_their_types_and_errors_name_the_key() {
        let c = Config::from_params(&params(serde_json::json!({
            "count": 4, "colour": "red", "names": "x, y,,z", "weights": "a=1,b=2.5,a=3", "path": "data/seq"
        })))
        .unwrap();
        assert_eq!((c.count, c.colour, c.names), (4, Colour::Red, vec!["x".into(), "y".into(), "z".into()]));
        assert_eq!(c.weights, ParamMap(vec![("b".into(), 2.5), ("a".into(), 3.0)]));
        assert_eq!(c.path, std::path::Path::new("/graphs/data/seq"));
        assert_eq!(c.seed, Seeded(None));
        let e = Config::from_params(&params(serde_json::json!({
            "count": 4, "colour": "green", "names": [], "weights": {}, "path": ""
        })))
        .unwrap_err();
        assert!(matches!(&e, OpError::Config { key, .. } if key == "colour"), "{e}");
    }

    #[test]
    fn reading_an_undeclared_input_is_an_operator_bug_not_absent() {
        const DECLARED: In<Scalars> = In::optional("declared", "a port");
        const OTHER: In<Scalars> = In::optional("undeclared", "a port the operator does not list");
        let inputs = Inputs::new(0, vec![("declared", None)]);
        assert!(DECLARED.get(&inputs).unwrap().is_none());
        let e = OTHER.get(&inputs).unwrap_err();
        assert!(matches!(&e, OpError::Contract(m) if m.contains("`undeclared`") && m.contains("`declared`")), "{e}");
        // A message of another type than the handle's is an error naming the port.
        let msg = std::sync::Arc::new(crate::msg::Message::new(
            crate::msg::Header { seq: 0, stamp: 0.0, frame_id: "c".into() },
            Body::Scalars(Scalars::one("v", 1.0)),
        ));
        const AS_IMAGE: In<crate::msg::Image> = In::required("declared", "a port");
        let inputs = Inputs::new(0, vec![("declared", Some(msg))]);
        assert_eq!(DECLARED.require(&inputs).unwrap().1.get("v"), Some(1.0));
        assert!(AS_IMAGE.require(&inputs).is_err());
    }
}
