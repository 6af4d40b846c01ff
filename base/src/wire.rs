//! The protobuf wire format, read (varints, fixed64, length-delimited, fixed32): what the
//! MCAP recordings' protobuf images and ONNX model files are encoded in. One reader for both;
//! no code generator.

/// A malformed encoding: what was wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WireError(pub String);

impl std::fmt::Display for WireError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for WireError {}

/// One field's value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'a> {
    /// A varint (any integer type).
    Varint(u64),
    /// A `fixed64`/`double`.
    Fixed64(u64),
    /// Bytes, a string, an embedded message or a packed repeated field.
    Bytes(&'a [u8]),
    /// A `fixed32`/`float`.
    Fixed32(u32),
}

/// A cursor over an encoded message.
#[derive(Clone, Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A reader of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }
    /// Whether every byte was read.
    pub fn done(&self) -> bool {
        self.pos >= self.buf.len()
    }
    /// The next varint.
    pub fn varint(&mut self) -> Result<u64, WireError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = *self.buf.get(self.pos).ok_or_else(|| WireError("truncated varint".into()))?;
            self.pos += 1;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(WireError("varint longer than 10 bytes".into()))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], WireError> {
        let left = self.buf.len() - self.pos.min(self.buf.len());
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.buf.len())
            .ok_or_else(|| WireError(format!("field of {n} bytes, {left} left")))?;
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    /// The next field: its number and value.
    pub fn field(&mut self) -> Result<(u32, Value<'a>), WireError> {
        let key = self.varint()?;
        let num = u32::try_from(key >> 3).map_err(|_| WireError("field number out of range".into()))?;
        let v = match key & 7 {
            0 => Value::Varint(self.varint()?),
            1 => Value::Fixed64(u64::from_le_bytes(self.take(8)?.try_into().unwrap_or_default())),
            2 => {
                let n = usize::try_from(self.varint()?).map_err(|_| WireError("length out of range".into()))?;
                Value::Bytes(self.take(n)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(self.take(4)?.try_into().unwrap_or_default())),
            w => return Err(WireError(format!("unsupported wire type {w} (field {num})"))),
        };
        Ok((num, v))
    }
}

/// Every field of an encoded message, in order.
pub fn fields(data: &[u8]) -> Result<Vec<(u32, Value<'_>)>, WireError> {
    let mut r = Reader::new(data);
    let mut out = Vec::new();
    while !r.done() {
        out.push(r.field()?);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::{Value, fields};

    #[test]
    fn every_wire_type_reads_and_truncation_is_an_error() {
        // field 1 varint 300, field 2 bytes "hi", field 3 fixed32 7, field 4 fixed64 9
        let msg = [0x08, 0xac, 0x02, 0x12, 2, b'h', b'i', 0x1d, 7, 0, 0, 0, 0x21, 9, 0, 0, 0, 0, 0, 0, 0];
        let f = fields(&msg).unwrap_or_default();
        assert_eq!(
            f,
            [(1, Value::Varint(300)), (2, Value::Bytes(b"hi")), (3, Value::Fixed32(7)), (4, Value::Fixed64(9))]
        );
        assert!(fields(&msg[..5]).is_err());
        assert!(fields(&[0x0b]).is_err()); // wire type 3 (groups) is not read
    }
}
