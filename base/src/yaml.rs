//! A YAML document tree that remembers where every node came from.
//!
//! Graph validation must point at `file:line:col` for *every* error at once, so we cannot
//! deserialize straight into typed structs (serde stops at the first error). Instead the
//! file is parsed once into this small spanned tree and the spec layer walks it, collecting
//! diagnostics as it goes.

use saphyr_parser::{Event, Parser, ScalarStyle};

/// A byte range in the source text (`offset..offset + len`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Span {
    /// Byte offset of the first character.
    pub offset: usize,
    /// Length in bytes (0 for a point).
    pub len: usize,
}

impl Span {
    /// A span from byte offsets.
    pub fn new(offset: usize, len: usize) -> Self {
        Self { offset, len }
    }
}

/// One node of the tree.
#[derive(Clone, Debug, PartialEq)]
pub struct Yaml {
    /// What the node holds.
    pub kind: YamlKind,
    /// Where it was written.
    pub span: Span,
}

/// The content of a [`Yaml`] node.
#[derive(Clone, Debug, PartialEq)]
pub enum YamlKind {
    /// A scalar as written; `quoted` is true for `'…'`/`"…"` and block scalars, which are
    /// always strings.
    Scalar {
        /// The scalar text after YAML unescaping.
        text: String,
        /// Whether the scalar was quoted (so `"1"` stays a string).
        quoted: bool,
    },
    /// A sequence.
    Seq(Vec<Yaml>),
    /// A mapping, in source order. Keys are scalars.
    Map(Vec<(Key, Yaml)>),
}

/// A mapping key with its span.
#[derive(Clone, Debug, PartialEq)]
pub struct Key {
    /// The key text.
    pub text: String,
    /// Where the key was written.
    pub span: Span,
}

/// A YAML syntax error.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntaxError {
    /// What the parser said.
    pub message: String,
    /// Where.
    pub span: Span,
}

impl Yaml {
    /// A plain (unquoted) scalar, used for values given on the command line.
    pub fn scalar(text: impl Into<String>, span: Span) -> Self {
        Self { kind: YamlKind::Scalar { text: text.into(), quoted: false }, span }
    }

    /// A quoted scalar (always a string), e.g. a mapping key checked as a value.
    pub fn quoted(text: impl Into<String>, span: Span) -> Self {
        Self { kind: YamlKind::Scalar { text: text.into(), quoted: true }, span }
    }

    /// Look up a key of a mapping.
    pub fn get(&self, key: &str) -> Option<&Yaml> {
        match &self.kind {
            YamlKind::Map(entries) => entries.iter().find(|(k, _)| k.text == key).map(|(_, v)| v),
            _ => None,
        }
    }

    /// The scalar text, if this is a scalar.
    pub fn as_str(&self) -> Option<&str> {
        match &self.kind {
            YamlKind::Scalar { text, .. } => Some(text),
            _ => None,
        }
    }

    /// Whether this is a YAML null (`~`, `null`, or an empty value).
    pub fn is_null(&self) -> bool {
        matches!(&self.kind, YamlKind::Scalar { text, quoted: false } if matches!(text.as_str(), "" | "~" | "null" | "Null" | "NULL"))
    }

    /// A short noun for error messages ("a mapping", "a string", …).
    pub fn type_name(&self) -> &'static str {
        match &self.kind {
            YamlKind::Map(_) => "a mapping",
            YamlKind::Seq(_) => "a sequence",
            YamlKind::Scalar { .. } if self.is_null() => "null",
            YamlKind::Scalar { .. } => match self.to_json() {
                serde_json::Value::Bool(_) => "a boolean",
                serde_json::Value::Number(_) => "a number",
                _ => "a string",
            },
        }
    }

    /// Convert to JSON with YAML 1.2 core-schema scalar resolution.
    pub fn to_json(&self) -> serde_json::Value {
        use serde_json::Value;
        match &self.kind {
            YamlKind::Scalar { text, quoted: true } => Value::String(text.clone()),
            YamlKind::Scalar { text, quoted: false } => resolve_plain(text),
            YamlKind::Seq(items) => Value::Array(items.iter().map(Yaml::to_json).collect()),
            YamlKind::Map(entries) => {
                Value::Object(entries.iter().map(|(k, v)| (k.text.clone(), v.to_json())).collect())
            }
        }
    }
}

/// YAML 1.2 core schema resolution of a plain scalar.
fn resolve_plain(text: &str) -> serde_json::Value {
    use serde_json::Value;
    match text {
        "" | "~" | "null" | "Null" | "NULL" => return Value::Null,
        "true" | "True" | "TRUE" => return Value::Bool(true),
        "false" | "False" | "FALSE" => return Value::Bool(false),
        _ => {}
    }
    let is_int = {
        let digits = text.strip_prefix(['-', '+']).unwrap_or(text);
        !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit())
    };
    if is_int && let Ok(i) = text.parse::<i64>() {
        return Value::from(i);
    }
    // Seeds and other unsigned values up to u64::MAX.
    if is_int && let Ok(u) = text.strip_prefix('+').unwrap_or(text).parse::<u64>() {
        return Value::from(u);
    }
    let looks_float = text.bytes().any(|b| b.is_ascii_digit())
        && text.bytes().all(|b| b.is_ascii_digit() || matches!(b, b'-' | b'+' | b'.' | b'e' | b'E'));
    if looks_float
        && let Ok(f) = text.parse::<f64>()
        && let Some(n) = serde_json::Number::from_f64(f)
    {
        return Value::Number(n);
    }
    Value::String(text.to_owned())
}

/// Maps saphyr's character indices to byte offsets.
struct CharToByte {
    starts: Vec<usize>,
    total: usize,
}

impl CharToByte {
    fn new(src: &str) -> Self {
        Self { starts: src.char_indices().map(|(b, _)| b).collect(), total: src.len() }
    }
    fn byte(&self, char_index: usize) -> usize {
        self.starts.get(char_index).copied().unwrap_or(self.total)
    }
}

/// Deepest nesting of collections accepted. Graphs need a handful of levels; the limit keeps
/// recursive walks of the tree (and dropping it) far from the stack's end.
pub const MAX_DEPTH: usize = 64;
/// Most nodes a document may expand to, aliases counted at their expanded size. Real graphs
/// have a few thousand; the bound stops "billion laughs" alias bombs before they take memory.
pub const MAX_NODES: usize = 1_000_000;

/// Parse one YAML document into a spanned tree.
///
/// Anchors/aliases are resolved by copying the anchored node, within [`MAX_NODES`]; nesting
/// is limited to [`MAX_DEPTH`]. An empty document yields a null scalar. Several documents in
/// one file are an error: a graph is one document.
pub fn parse(src: &str) -> Result<Yaml, SyntaxError> {
    let map = CharToByte::new(src);
    let mut stack: Vec<Frame> = Vec::new();
    // Anchored nodes with their expanded size.
    let mut anchors: std::collections::HashMap<usize, (Yaml, usize)> = std::collections::HashMap::new();
    let mut total_nodes = 0usize;
    let mut root: Option<Yaml> = None;
    let mut documents = 0usize;
    for item in Parser::new_from_str(src) {
        let (event, span) = item.map_err(|e| {
            let at = map.byte(e.marker().index());
            SyntaxError { message: e.info().to_owned(), span: Span::new(at, 0) }
        })?;
        let start = map.byte(span.start.index());
        let end = map.byte(span.end.index()).max(start);
        let here = Span::new(start, end - start);
        let finished: Option<(Yaml, usize, usize)> = match event {
            Event::DocumentStart(_) => {
                documents += 1;
                if documents > 1 {
                    return Err(SyntaxError {
                        message: "a graph file holds one YAML document; found a second `---`".into(),
                        span: here,
                    });
                }
                None
            }
            Event::Scalar(text, style, anchor, _tag) => {
                let quoted = !matches!(style, ScalarStyle::Plain);
                total_nodes += 1;
                Some((Yaml { kind: YamlKind::Scalar { text: text.into_owned(), quoted }, span: here }, anchor, 1))
            }
            Event::Alias(id) => match anchors.get(&id) {
                Some((node, size)) => {
                    // Check before copying: the copy is what would exhaust memory.
                    if total_nodes.saturating_add(*size) > MAX_NODES {
                        return Err(SyntaxError {
                            message: format!(
                                "aliases expand this document beyond {MAX_NODES} nodes; a graph needs far fewer (is this an alias bomb?)"
                            ),
                            span: here,
                        });
                    }
                    total_nodes += size;
                    Some((Yaml { kind: node.kind.clone(), span: here }, 0, *size))
                }
                None => return Err(SyntaxError { message: "alias to an unknown anchor".into(), span: here }),
            },
            Event::SequenceStart(anchor, _) | Event::MappingStart(anchor, _) => {
                if stack.len() >= MAX_DEPTH {
                    return Err(SyntaxError {
                        message: format!("collections nested deeper than {MAX_DEPTH} levels"),
                        span: here,
                    });
                }
                let kind = if matches!(event, Event::SequenceStart(..)) {
                    FrameKind::Seq(Vec::new())
                } else {
                    FrameKind::Map(Vec::new())
                };
                total_nodes += 1;
                stack.push(Frame { kind, start, anchor, pending_key: None, size: 1 });
                None
            }
            Event::SequenceEnd | Event::MappingEnd => match stack.pop() {
                Some(frame) => {
                    let kind = match frame.kind {
                        FrameKind::Seq(items) => YamlKind::Seq(items),
                        FrameKind::Map(entries) => YamlKind::Map(entries),
                    };
                    Some((
                        Yaml { kind, span: Span::new(frame.start, end.saturating_sub(frame.start)) },
                        frame.anchor,
                        frame.size,
                    ))
                }
                None => return Err(SyntaxError { message: "unbalanced collection end".into(), span: here }),
            },
            Event::StreamStart | Event::StreamEnd | Event::DocumentEnd | Event::Nothing => None,
        };
        if let Some((node, anchor, size)) = finished {
            if anchor != 0 {
                anchors.insert(anchor, (node.clone(), size));
            }
            match stack.last_mut() {
                None => root = Some(node),
                Some(frame) => {
                    frame.size = frame.size.saturating_add(size);
                    frame.push(node)?;
                }
            }
        }
    }
    Ok(root.unwrap_or_else(|| Yaml::scalar("", Span::default())))
}

struct Frame {
    kind: FrameKind,
    start: usize,
    anchor: usize,
    pending_key: Option<Key>,
    /// Nodes in this collection so far, itself included.
    size: usize,
}

enum FrameKind {
    Seq(Vec<Yaml>),
    Map(Vec<(Key, Yaml)>),
}

impl Frame {
    fn push(&mut self, node: Yaml) -> Result<(), SyntaxError> {
        match &mut self.kind {
            FrameKind::Seq(items) => items.push(node),
            FrameKind::Map(entries) => match self.pending_key.take() {
                Some(key) => entries.push((key, node)),
                None => {
                    let YamlKind::Scalar { text, .. } = node.kind else {
                        return Err(SyntaxError {
                            message: "mapping keys must be plain strings, not collections".into(),
                            span: node.span,
                        });
                    };
                    // Duplicate keys are kept: the spec layer reports them with context
                    // ("duplicate node id") and keeps validating.
                    self.pending_key = Some(Key { text, span: node.span });
                }
            },
        }
        Ok(())
    }
}

/// 1-based line and column (in characters) of a byte offset.
pub fn line_col(src: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(src.len());
    let before = src.get(..offset).unwrap_or(src);
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let col = before.get(line_start..).map_or(0, |s| s.chars().count()) + 1;
    (line, col)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_point_at_values() {
        let src = "name: g\nnodes:\n  a: { op: x }\n";
        let doc = parse(src).unwrap();
        let op = doc.get("nodes").unwrap().get("a").unwrap().get("op").unwrap();
        assert_eq!(op.as_str(), Some("x"));
        assert_eq!(line_col(src, op.span.offset), (3, 12));
    }

    #[test]
    fn scalars_resolve_like_yaml_1_2() {
        let doc = parse("a: 1\nb: '1'\nc: 1.5\nd: true\ne: ~\nf: 1e3\ng: abc\n").unwrap();
        let j = doc.to_json();
        assert_eq!(j["a"], serde_json::json!(1));
        assert_eq!(j["b"], serde_json::json!("1"));
        assert_eq!(j["c"], serde_json::json!(1.5));
        assert_eq!(j["d"], serde_json::json!(true));
        assert!(j["e"].is_null());
        assert_eq!(j["f"], serde_json::json!(1000.0));
        assert_eq!(j["g"], serde_json::json!("abc"));
    }

    #[test]
    fn duplicate_keys_are_kept_and_syntax_errors_have_positions() {
        let src = "a: 1\na: 2\n";
        let YamlKind::Map(entries) = parse(src).unwrap().kind else { panic!() };
        assert_eq!(entries.len(), 2);
        assert_eq!(line_col(src, entries[1].0.span.offset), (2, 1));
        let src = "a: [1, 2\nb: 3\n";
        let err = parse(src).unwrap_err();
        assert!(line_col(src, err.span.offset).0 >= 2, "{err:?}");
    }

    #[test]
    fn multibyte_text_keeps_byte_offsets() {
        let src = "é: 1\nb: x\n";
        let doc = parse(src).unwrap();
        let b = doc.get("b").unwrap();
        assert_eq!(&src[b.span.offset..b.span.offset + b.span.len], "x");
    }

    #[test]
    fn alias_bomb_is_refused_with_a_position_before_it_takes_memory() {
        // Nine levels of ten aliases each: 10^9 nodes if expanded.
        let mut src = String::from("x0: &a0 [lol]\n");
        for i in 1..10 {
            let refs = vec![format!("*a{}", i - 1); 10].join(",");
            src.push_str(&format!("x{i}: &a{i} [{refs}]\n"));
        }
        let t = std::time::Instant::now();
        let err = parse(&src).unwrap_err();
        assert!(err.message.contains("alias bomb"), "{err:?}");
        assert!(line_col(&src, err.span.offset).0 >= 6, "{err:?}");
        // Refused early, not after expanding: well under a second even in a debug build.
        assert!(t.elapsed() < std::time::Duration::from_secs(5));
        // Ordinary alias use is fine.
        assert!(parse("a: &x {k: 1}\nb: *x\n").is_ok());
    }

    #[test]
    fn deep_nesting_is_an_error_in_block_and_flow_style() {
        let block = format!("frames:\n{}1\n", "- ".repeat(50_000));
        let err = parse(&block).unwrap_err();
        assert!(err.message.contains("nested deeper"), "{err:?}");
        let flow = format!("frames: {}1{}\n", "[".repeat(50_000), "]".repeat(50_000));
        assert!(parse(&flow).is_err());
        let ok = format!("frames: {}1{}\n", "[".repeat(MAX_DEPTH - 2), "]".repeat(MAX_DEPTH - 2));
        assert!(parse(&ok).is_ok());
    }

    #[test]
    fn unsigned_integers_up_to_u64_max_stay_integers() {
        let doc = parse("a: 18446744073709551615\nb: 18446744073709551616\nc: -9223372036854775808\n").unwrap();
        let j = doc.to_json();
        assert_eq!(j["a"].as_u64(), Some(u64::MAX));
        assert_eq!(j["b"].as_u64(), None, "beyond u64 is a float");
        assert_eq!(j["c"].as_i64(), Some(i64::MIN));
    }
}
