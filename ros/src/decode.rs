//! Serialised ROS messages into [`Value`] trees, walking a [`Registry`]: the ROS 1 wire format
//! (little-endian, packed, `uint32` lengths) and CDR as ROS 2 writes it (a 4-byte encapsulation
//! header, then XCDR1 with each primitive aligned to its size, at most 8, from the end of that
//! header; strings carry their NUL). Byte arrays stay one `Vec<u8>` (images); every length is
//! checked against the bytes left before anything is allocated, so a corrupt message is an
//! error naming the field and the byte offset, never a panic or a huge allocation.

use std::sync::Arc;

use crate::msgdef::{Array, Field, FieldType, MessageDef, Primitive, Registry};

/// How the bytes are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 1 (`.bag`).
    Ros1,
    /// CDR (ROS 2); the byte order comes from the encapsulation header.
    Cdr,
}

/// A decoded value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `bool`.
    Bool(bool),
    /// Signed integers.
    Int(i64),
    /// Unsigned integers.
    UInt(u64),
    /// `float32`/`float64`.
    Float(f64),
    /// `string`.
    String(String),
    /// ROS 1 `time`/`duration`: seconds and nanoseconds.
    Time {
        /// Seconds.
        sec: i64,
        /// Nanoseconds.
        nsec: i64,
    },
    /// An array of `uint8`/`int8` (image data, compressed bytes).
    Bytes(Vec<u8>),
    /// Any other array.
    Array(Vec<Value>),
    /// A message.
    Message(Message),
}

/// A decoded message: its type and its fields in wire order.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// `pkg/Type`.
    pub ty: Arc<str>,
    /// Name and value of each field.
    pub fields: Vec<(Arc<str>, Value)>,
}

impl Message {
    /// A field by name.
    pub fn get(&self, name: &str) -> Option<&Value> {
        self.fields.iter().find(|(n, _)| &**n == name).map(|(_, v)| v)
    }
}

/// What a message cannot be decoded for.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{ty}: field `{field}` at byte {offset}: {message}")]
pub struct DecodeError {
    /// The top-level type.
    pub ty: String,
    /// The field path (`header.frame_id`).
    pub field: String,
    /// Byte offset in the serialised message.
    pub offset: usize,
    /// What is wrong.
    pub message: String,
}

/// Nesting deeper than this is refused (a self-referencing sequence in a crafted file).
const MAX_DEPTH: usize = 64;

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
    encoding: Encoding,
    big_endian: bool,
    /// CDR aligns from here (the end of the encapsulation header).
    origin: usize,
    path: Vec<Arc<str>>,
    root: &'a str,
}

impl<'a> Reader<'a> {
    fn error(&self, message: impl Into<String>) -> DecodeError {
        DecodeError {
            ty: self.root.to_string(),
            field: self.path.iter().fold(String::new(), |mut acc, s| {
                if !acc.is_empty() && !s.starts_with('[') {
                    acc.push('.');
                }
                acc.push_str(s);
                acc
            }),
            offset: self.pos.min(self.buf.len()),
            message: message.into(),
        }
    }

    fn align(&mut self, n: usize) {
        if self.encoding == Encoding::Cdr && n > 1 {
            let rel = self.pos - self.origin;
            self.pos += (n - rel % n) % n;
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let left = self.buf.len().saturating_sub(self.pos);
        if n > left {
            return Err(self.error(format!("needs {n} bytes, {left} left (truncated message?)")));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        self.align(N.min(8));
        let s = self.take(N)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        if self.big_endian {
            a.reverse();
        }
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.fixed::<4>()?))
    }

    /// A length prefix, checked against what is left at `min_size` bytes per element.
    fn length(&mut self, min_size: usize) -> Result<usize, DecodeError> {
        let n = self.u32()? as usize;
        let left = self.buf.len().saturating_sub(self.pos);
        if n.saturating_mul(min_size.max(1)) > left {
            return Err(self
                .error(format!("length {n} needs at least {} bytes, {left} left", n.saturating_mul(min_size.max(1)))));
        }
        Ok(n)
    }

    fn string(&mut self) -> Result<String, DecodeError> {
        let n = self.length(1)?;
        let mut bytes = self.take(n)?;
        if self.encoding == Encoding::Cdr {
            // CDR counts the terminating NUL.
            match bytes.split_last() {
                Some((0, rest)) => bytes = rest,
                _ if n == 0 => {}
                _ => return Err(self.error("CDR string without its terminating NUL")),
            }
        }
        String::from_utf8(bytes.to_vec()).map_err(|_| self.error("string is not UTF-8"))
    }

    fn primitive(&mut self, p: Primitive) -> Result<Value, DecodeError> {
        Ok(match p {
            Primitive::Bool => Value::Bool(self.fixed::<1>()?[0] != 0),
            Primitive::I8 => Value::Int(i8::from_le_bytes(self.fixed::<1>()?) as i64),
            Primitive::U8 => Value::UInt(self.fixed::<1>()?[0] as u64),
            Primitive::I16 => Value::Int(i16::from_le_bytes(self.fixed::<2>()?) as i64),
            Primitive::U16 => Value::UInt(u16::from_le_bytes(self.fixed::<2>()?) as u64),
            Primitive::I32 => Value::Int(i32::from_le_bytes(self.fixed::<4>()?) as i64),
            Primitive::U32 => Value::UInt(self.u32()? as u64),
            Primitive::I64 => Value::Int(i64::from_le_bytes(self.fixed::<8>()?)),
            Primitive::U64 => Value::UInt(u64::from_le_bytes(self.fixed::<8>()?)),
            Primitive::F32 => Value::Float(f32::from_le_bytes(self.fixed::<4>()?) as f64),
            Primitive::F64 => Value::Float(f64::from_le_bytes(self.fixed::<8>()?)),
            Primitive::String => Value::String(self.string()?),
            Primitive::Time => {
                let (sec, nsec) = (self.u32()?, self.u32()?);
                Value::Time { sec: sec as i64, nsec: nsec as i64 }
            }
            Primitive::Duration => {
                let sec = i32::from_le_bytes(self.fixed::<4>()?);
                let nsec = i32::from_le_bytes(self.fixed::<4>()?);
                Value::Time { sec: sec as i64, nsec: nsec as i64 }
            }
        })
    }

    fn element(&mut self, reg: &Registry, ty: &FieldType, depth: usize) -> Result<Value, DecodeError> {
        match ty {
            FieldType::Primitive(p) => self.primitive(*p),
            FieldType::Message(name) => {
                let def = reg.get(name).ok_or_else(|| self.error(format!("type `{name}` is not defined")))?;
                Ok(Value::Message(self.message(reg, def, depth + 1)?))
            }
        }
    }

    fn field(&mut self, reg: &Registry, f: &Field, depth: usize) -> Result<Value, DecodeError> {
        let count = match f.array {
            Array::Scalar => return self.element(reg, &f.ty, depth),
            Array::Fixed(n) => n,
            Array::Sequence => {
                let min = match &f.ty {
                    FieldType::Primitive(p) => p.size(),
                    FieldType::Message(_) => 0,
                };
                self.length(min)?
            }
        };
        if let FieldType::Primitive(Primitive::U8 | Primitive::I8) = f.ty {
            return Ok(Value::Bytes(self.take(count)?.to_vec()));
        }
        let left = self.buf.len().saturating_sub(self.pos);
        let mut items = Vec::with_capacity(count.min(left));
        for i in 0..count {
            self.path.push(format!("[{i}]").into());
            let v = self.element(reg, &f.ty, depth);
            self.path.pop();
            items.push(v?);
        }
        Ok(Value::Array(items))
    }

    fn message(&mut self, reg: &Registry, def: &MessageDef, depth: usize) -> Result<Message, DecodeError> {
        if depth > MAX_DEPTH {
            return Err(self.error(format!("nested deeper than {MAX_DEPTH} messages")));
        }
        let mut fields = Vec::with_capacity(def.fields.len());
        for f in &def.fields {
            self.path.push(f.name.clone());
            let v = self.field(reg, f, depth);
            self.path.pop();
            fields.push((f.name.clone(), v?));
        }
        Ok(Message { ty: def.name.clone(), fields })
    }
}

/// Decodes one serialised message of `registry`'s top-level type.
pub fn decode(registry: &Registry, encoding: Encoding, data: &[u8]) -> Result<Message, DecodeError> {
    let root: &str = &registry.root;
    let mut r = Reader { buf: data, pos: 0, encoding, big_endian: false, origin: 0, path: Vec::new(), root };
    if encoding == Encoding::Cdr {
        let header = r.take(4)?;
        r.big_endian = match header[1] {
            0x00 | 0x02 => true,
            0x01 | 0x03 => false,
            k => return Err(r.error(format!("unknown CDR encapsulation kind {k:#04x}"))),
        };
        if header[1] >= 0x02 {
            return Err(r.error("parameter-list CDR (PL_CDR) is not a ROS 2 message encoding"));
        }
        r.origin = 4;
    }
    let def = registry.root_def().ok_or_else(|| r.error("the top-level type has no definition"))?;
    r.message(registry, def, 0)
}

#[cfg(test)]
mod tests;
