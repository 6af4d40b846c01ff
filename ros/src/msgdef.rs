//! ROS message definitions as a bag stores them: the `.msg` text of the top-level type followed by
//! each type it uses, separated by a line of `=` and a `MSG: pkg/Type` line (a ROS 1 connection
//! header's `message_definition`, a ROS 2 MCAP `ros2msg` schema). Parsed into a [`Registry`] the
//! decoders walk, so a message's layout comes from the bag, never from a guess.
//!
//! Names are kept as `pkg/Type` (ROS 2's `pkg/msg/Type` loses its `msg/`). Constants are read
//! and dropped (they are not on the wire); ROS 2 default values are ignored likewise.

use std::collections::BTreeMap;
use std::sync::Arc;

/// Which ROS wrote the definition: it decides what `Header`, `time`, `duration`, `char` and
/// `byte` mean.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// ROS 1: `Header` is `std_msgs/Header`; `time` and `duration` are primitives.
    Ros1,
    /// ROS 2: time is `builtin_interfaces/Time` (`sec: int32`, `nanosec: uint32`).
    Ros2,
}

/// A primitive type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Primitive {
    /// `bool`: one byte.
    Bool,
    /// `int8` (ROS 1's `byte`).
    I8,
    /// `uint8`, `char` (ROS 2's `byte`).
    U8,
    /// `int16`.
    I16,
    /// `uint16`.
    U16,
    /// `int32`.
    I32,
    /// `uint32`.
    U32,
    /// `int64`.
    I64,
    /// `uint64`.
    U64,
    /// `float32`.
    F32,
    /// `float64`.
    F64,
    /// `string` (ROS 2 `string<=N` too).
    String,
    /// ROS 1 `time`: `uint32` seconds, `uint32` nanoseconds.
    Time,
    /// ROS 1 `duration`: `int32` seconds, `int32` nanoseconds.
    Duration,
}

impl Primitive {
    fn parse(token: &str, dialect: Dialect) -> Option<Self> {
        Some(match token {
            "bool" => Primitive::Bool,
            "int8" => Primitive::I8,
            "byte" if dialect == Dialect::Ros1 => Primitive::I8,
            "uint8" | "char" | "byte" => Primitive::U8,
            "int16" => Primitive::I16,
            "uint16" => Primitive::U16,
            "int32" => Primitive::I32,
            "uint32" => Primitive::U32,
            "int64" => Primitive::I64,
            "uint64" => Primitive::U64,
            "float32" => Primitive::F32,
            "float64" => Primitive::F64,
            "string" => Primitive::String,
            "time" if dialect == Dialect::Ros1 => Primitive::Time,
            "duration" if dialect == Dialect::Ros1 => Primitive::Duration,
            t if t.starts_with("string<=") => Primitive::String,
            _ => return None,
        })
    }

    /// Bytes on the wire (strings: their length prefix), and the CDR alignment.
    pub(crate) fn size(self) -> usize {
        match self {
            Primitive::Bool | Primitive::I8 | Primitive::U8 => 1,
            Primitive::I16 | Primitive::U16 => 2,
            Primitive::I32 | Primitive::U32 | Primitive::F32 | Primitive::String => 4,
            Primitive::I64 | Primitive::U64 | Primitive::F64 | Primitive::Time | Primitive::Duration => 8,
        }
    }
}

/// A field's element type.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// A primitive.
    Primitive(Primitive),
    /// A message, `pkg/Type`.
    Message(Arc<str>),
}

/// Whether a field is an array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Array {
    /// One value.
    Scalar,
    /// `T[N]`: N values, no length on the wire.
    Fixed(usize),
    /// `T[]` or ROS 2's `T[<=N]`: a length, then the values.
    Sequence,
}

/// One field of a message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Field {
    /// Its name.
    pub name: Arc<str>,
    /// Element type.
    pub ty: FieldType,
    /// Array kind.
    pub array: Array,
}

/// A message type's fields, in wire order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MessageDef {
    /// `pkg/Type`.
    pub name: Arc<str>,
    /// Fields in order.
    pub fields: Vec<Field>,
}

/// What a definition can be wrong with: the type and 1-based line within its section.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("message definition of `{ty}`, line {line}: {message}")]
pub struct DefError {
    /// The type whose section is wrong.
    pub ty: String,
    /// Line within that section (0: the section as a whole).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

/// A top-level type and every type it uses, resolved.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Registry {
    /// The top-level type, `pkg/Type`.
    pub root: Arc<str>,
    /// Which ROS wrote it.
    pub dialect: Dialect,
    defs: BTreeMap<Arc<str>, MessageDef>,
}

/// `pkg/msg/Type` -> `pkg/Type` (ROS 2 interface names; `srv`/`action` kept as they are).
pub fn normalize_type(name: &str) -> String {
    let name = name.trim();
    match name.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, "msg", ty] => format!("{pkg}/{ty}"),
        _ => name.to_string(),
    }
}

fn is_separator(line: &str) -> bool {
    let t = line.trim();
    t.len() >= 3 && t.chars().all(|c| c == '=')
}

impl Registry {
    /// Parses the concatenated definition of `root` (its own section first, then
    /// `MSG: pkg/Type` sections). ROS 2's `builtin_interfaces/Time` and `Duration` are known
    /// without a section (rosbag2 writers leave them out now and then).
    pub fn parse(root: &str, text: &str, dialect: Dialect) -> Result<Self, DefError> {
        let root: Arc<str> = normalize_type(root).into();
        let mut sections: Vec<(Arc<str>, Vec<&str>)> = vec![(root.clone(), Vec::new())];
        let mut lines = text.lines().peekable();
        while let Some(line) = lines.next() {
            if is_separator(line) {
                // The next non-empty line names the section.
                let name = loop {
                    match lines.next() {
                        Some(l) if l.trim().is_empty() => continue,
                        Some(l) => break l.trim(),
                        None => break "",
                    }
                };
                let Some(name) = name.strip_prefix("MSG:") else {
                    return Err(DefError {
                        ty: root.to_string(),
                        line: 0,
                        message: format!("a `===` separator must be followed by `MSG: pkg/Type`, found `{name}`"),
                    });
                };
                sections.push((normalize_type(name).into(), Vec::new()));
            } else if let Some((_, body)) = sections.last_mut() {
                body.push(line);
            }
        }
        let mut defs = BTreeMap::new();
        for (name, body) in &sections {
            let def = parse_section(name, body, dialect)?;
            defs.entry(name.clone()).or_insert(def);
        }
        if dialect == Dialect::Ros2 {
            for t in ["builtin_interfaces/Time", "builtin_interfaces/Duration"] {
                if !defs.contains_key(t) {
                    let def = parse_section(t, &["int32 sec", "uint32 nanosec"], dialect)?;
                    defs.insert(t.into(), def);
                }
            }
        }
        let registry = Registry { root, dialect, defs };
        registry.check()?;
        Ok(registry)
    }

    /// The top-level type's definition.
    pub fn root_def(&self) -> Option<&MessageDef> {
        self.defs.get(&self.root)
    }

    /// A type's definition.
    pub fn get(&self, name: &str) -> Option<&MessageDef> {
        self.defs.get(name)
    }

    /// Every type used resolves, and no type contains itself.
    fn check(&self) -> Result<(), DefError> {
        for def in self.defs.values() {
            for f in &def.fields {
                if let FieldType::Message(t) = &f.ty
                    && !self.defs.contains_key(t)
                {
                    return Err(DefError {
                        ty: def.name.to_string(),
                        line: 0,
                        message: format!("field `{}` has type `{t}`, which has no `MSG: {t}` section", f.name),
                    });
                }
            }
        }
        // A type may not contain itself except through a sequence (which can be empty).
        fn visit<'a>(reg: &'a Registry, t: &'a str, stack: &mut Vec<&'a str>) -> Result<(), DefError> {
            if stack.contains(&t) {
                return Err(DefError {
                    ty: t.to_string(),
                    line: 0,
                    message: format!("contains itself: {} -> {t}", stack.join(" -> ")),
                });
            }
            stack.push(t);
            if let Some(def) = reg.defs.get(t) {
                for f in &def.fields {
                    if let (FieldType::Message(inner), Array::Scalar | Array::Fixed(_)) = (&f.ty, f.array) {
                        visit(reg, inner, stack)?;
                    }
                }
            }
            stack.pop();
            Ok(())
        }
        visit(self, &self.root, &mut Vec::new())
    }
}

fn parse_section(name: &str, body: &[&str], dialect: Dialect) -> Result<MessageDef, DefError> {
    let package = name.split('/').next().unwrap_or("");
    let err = |line: usize, message: String| DefError { ty: name.to_string(), line, message };
    let mut fields = Vec::new();
    for (i, raw) in body.iter().enumerate() {
        let line = i + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let mut tokens = trimmed.split_whitespace();
        let (Some(ty_token), Some(rest_first)) = (tokens.next(), tokens.next()) else {
            return Err(err(line, format!("expected `type name`, found `{trimmed}`")));
        };
        // Constants (`TYPE NAME=VALUE`, `string` ones take the rest of the line) are not on
        // the wire.
        let after_type = trimmed[ty_token.len()..].trim_start();
        let name_end = after_type.find(|c: char| c.is_whitespace() || c == '=' || c == '#').unwrap_or(after_type.len());
        if after_type[name_end..].trim_start().starts_with('=') {
            continue;
        }
        let field_name = &after_type[..name_end];
        if field_name.is_empty() || !field_name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(err(line, format!("`{rest_first}` is not a field name")));
        }
        let (base, array) = match ty_token.find('[') {
            None => (ty_token, Array::Scalar),
            Some(open) => {
                let Some(inner) = ty_token[open + 1..].strip_suffix(']') else {
                    return Err(err(line, format!("`{ty_token}`: an array type ends with `]`")));
                };
                let array = if inner.is_empty() || inner.starts_with("<=") {
                    Array::Sequence
                } else {
                    match inner.parse::<usize>() {
                        Ok(n) => Array::Fixed(n),
                        Err(_) => return Err(err(line, format!("`{ty_token}`: `{inner}` is not an array length"))),
                    }
                };
                (&ty_token[..open], array)
            }
        };
        let ty = if let Some(p) = Primitive::parse(base, dialect) {
            FieldType::Primitive(p)
        } else if base == "wstring" || base.starts_with("wstring<=") {
            return Err(err(line, "`wstring` fields are not supported".into()));
        } else if base.contains('/') {
            FieldType::Message(normalize_type(base).into())
        } else if base == "Header" && dialect == Dialect::Ros1 {
            FieldType::Message("std_msgs/Header".into())
        } else if base.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') && !base.is_empty() {
            FieldType::Message(format!("{package}/{base}").into())
        } else {
            return Err(err(line, format!("`{base}` is not a type")));
        };
        fields.push(Field { name: field_name.into(), ty, array });
    }
    Ok(MessageDef { name: name.into(), fields })
}

#[cfg(test)]
mod tests {
    use super::*;

    const IMAGE_ROS1: &str = "# a comment\nHeader header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n\n================================================================================\nMSG: std_msgs/Header\nuint32 seq\ntime stamp\nstring frame_id\n";

    #[test]
    fn ros1_image_with_its_header_section() {
        let r = Registry::parse("sensor_msgs/Image", IMAGE_ROS1, Dialect::Ros1).unwrap();
        let root = r.root_def().unwrap();
        assert_eq!(root.fields.len(), 7);
        assert_eq!(root.fields[0].ty, FieldType::Message("std_msgs/Header".into()));
        assert_eq!(root.fields[6].array, Array::Sequence);
        let header = r.get("std_msgs/Header").unwrap();
        assert_eq!(header.fields[1].ty, FieldType::Primitive(Primitive::Time));
    }

    #[test]
    fn constants_defaults_bounds_and_ros2_names() {
        let text = "uint8 DEBUG=1\nstring NAME = a # not a comment\nint32 x 5\nfloat64[9] k\nint16[<=4] small\nstring<=8 short\nfoo/Bar bar\n===\nMSG: foo/Bar\nbuiltin_interfaces/Time t\n";
        let r = Registry::parse("foo/msg/Thing", text, Dialect::Ros2).unwrap();
        assert_eq!(&*r.root, "foo/Thing");
        let names: Vec<_> = r.root_def().unwrap().fields.iter().map(|f| f.name.to_string()).collect();
        assert_eq!(names, ["x", "k", "small", "short", "bar"]);
        assert_eq!(r.root_def().unwrap().fields[1].array, Array::Fixed(9));
        assert!(r.get("builtin_interfaces/Time").is_some(), "known without a section");
    }

    #[test]
    fn unresolved_and_malformed_definitions_name_the_type_and_line() {
        let e = Registry::parse("a/B", "c/D d\n", Dialect::Ros1).unwrap_err();
        assert!(e.to_string().contains("`c/D`"), "{e}");
        let e = Registry::parse("a/B", "int32 x\nint32[x] y\n", Dialect::Ros1).unwrap_err();
        assert_eq!((e.line, e.ty.as_str()), (2, "a/B"));
        let e = Registry::parse("a/B", "a/B self\n", Dialect::Ros1).unwrap_err();
        assert!(e.message.contains("contains itself"), "{e}");
        assert!(Registry::parse("a/B", "a/B[] children\n", Dialect::Ros1).is_ok(), "a sequence may recurse");
    }
}
