//! Diagnostics: everything that is wrong with a graph, each pointing at `file:line:col`.
//!
//! Validation never stops at the first problem; it collects [`Diagnostic`]s and the CLI renders
//! them all with `miette` (snippet, label, hint). The plain `file:line:col: message` form is
//! also available for logs and tests.

use std::fmt;
use std::sync::Arc;

use crate::yaml::{Span, line_col};

/// How bad a finding is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Severity {
    /// The graph still runs (e.g. an unused output).
    Warning,
    /// The graph cannot run.
    Error,
}

/// One finding about a graph file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Diagnostic {
    /// Error or warning.
    pub severity: Severity,
    /// A stable machine-readable code such as `unknown-op`.
    pub code: &'static str,
    /// What is wrong, naming the node/port/param in backticks.
    pub message: String,
    /// Where (absent for problems with no place in the file, e.g. a `--set` flag).
    #[serde(skip)]
    pub span: Option<Span>,
    /// A suggestion to fix it ("did you mean `orb_extract`?").
    pub hint: Option<String>,
}

impl Diagnostic {
    /// An error at `span`.
    pub fn error(code: &'static str, span: impl Into<Option<Span>>, message: impl Into<String>) -> Self {
        Self { severity: Severity::Error, code, message: message.into(), span: span.into(), hint: None }
    }

    /// A warning at `span`.
    pub fn warning(code: &'static str, span: impl Into<Option<Span>>, message: impl Into<String>) -> Self {
        Self { severity: Severity::Warning, code, message: message.into(), span: span.into(), hint: None }
    }

    /// Attach a hint.
    #[must_use]
    pub fn with_hint(mut self, hint: impl Into<String>) -> Self {
        self.hint = Some(hint.into());
        self
    }

    /// Attach a hint if there is one.
    #[must_use]
    pub fn with_opt_hint(mut self, hint: Option<String>) -> Self {
        if hint.is_some() {
            self.hint = hint;
        }
        self
    }

    /// Whether this is an error.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

/// The source text a set of diagnostics refers to.
#[derive(Clone, Debug)]
pub struct Source {
    /// Display name (the path as given).
    pub name: String,
    /// The whole text.
    pub text: Arc<str>,
}

impl Source {
    /// A named source.
    pub fn new(name: impl Into<String>, text: impl Into<Arc<str>>) -> Self {
        Self { name: name.into(), text: text.into() }
    }

    /// `file:line:col` of a span.
    pub fn location(&self, span: Option<Span>) -> String {
        match span {
            Some(span) => {
                let (line, col) = line_col(&self.text, span.offset);
                format!("{}:{line}:{col}", self.name)
            }
            None => self.name.clone(),
        }
    }

    /// One line per diagnostic: `file:line:col: error[code]: message (hint: …)`.
    pub fn plain(&self, d: &Diagnostic) -> String {
        let sev = match d.severity {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        let mut out = format!("{}: {sev}[{}]: {}", self.location(d.span), d.code, d.message);
        if let Some(hint) = &d.hint {
            out.push_str(&format!(" (hint: {hint})"));
        }
        out
    }

    /// A `miette` report for rich terminal rendering.
    pub fn report(&self, d: &Diagnostic) -> miette::Report {
        miette::Report::new(Rendered {
            diag: d.clone(),
            location: self.location(d.span),
            source: miette::NamedSource::new(self.name.clone(), self.text.to_string()),
        })
    }

    /// The diagnostics as JSON objects with `file`, `line`, `col`.
    pub fn to_json(&self, diags: &[Diagnostic]) -> serde_json::Value {
        serde_json::Value::Array(
            diags
                .iter()
                .map(|d| {
                    let (line, col) = d.span.map_or((0, 0), |s| line_col(&self.text, s.offset));
                    let mut v = serde_json::to_value(d).unwrap_or_default();
                    if let Some(obj) = v.as_object_mut() {
                        obj.insert("file".into(), self.name.clone().into());
                        obj.insert("line".into(), line.into());
                        obj.insert("col".into(), col.into());
                    }
                    v
                })
                .collect(),
        )
    }
}

#[derive(Debug)]
struct Rendered {
    diag: Diagnostic,
    location: String,
    source: miette::NamedSource<String>,
}

impl fmt::Display for Rendered {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.diag.message, self.location)
    }
}

impl std::error::Error for Rendered {}

impl miette::Diagnostic for Rendered {
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(self.diag.code))
    }
    fn severity(&self) -> Option<miette::Severity> {
        Some(match self.diag.severity {
            Severity::Error => miette::Severity::Error,
            Severity::Warning => miette::Severity::Warning,
        })
    }
    fn help<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        self.diag.hint.as_ref().map(|h| Box::new(h) as Box<dyn fmt::Display>)
    }
    fn source_code(&self) -> Option<&dyn miette::SourceCode> {
        self.diag.span.map(|_| &self.source as &dyn miette::SourceCode)
    }
    fn labels(&self) -> Option<Box<dyn Iterator<Item = miette::LabeledSpan> + '_>> {
        let span = self.diag.span?;
        Some(Box::new(std::iter::once(miette::LabeledSpan::new_with_span(
            Some("here".into()),
            miette::SourceSpan::new(span.offset.into(), span.len.max(1)),
        ))))
    }
}

/// The closest candidate by edit distance, if it is close enough to be a plausible typo.
pub fn did_you_mean<'a>(given: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<String> {
    let best = candidates.into_iter().map(|c| (edit_distance(given, c), c)).min_by_key(|(d, c)| (*d, c.len()))?;
    let limit = (given.chars().count().max(best.1.chars().count()) / 3).max(2);
    (best.0 <= limit).then(|| format!("did you mean `{}`?", best.1))
}

/// Levenshtein distance (characters).
pub fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggestions() {
        assert_eq!(
            did_you_mean("orb_extrct", ["orb_extract", "lk_flow"]).as_deref(),
            Some("did you mean `orb_extract`?")
        );
        assert_eq!(did_you_mean("zzzzzz", ["orb_extract", "lk_flow"]), None);
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }
}
