//! Resolved parameter values.

use std::path::{Path, PathBuf};

use super::{OpError, Param};

/// A node's parameters after validation: every declared key present (defaults filled in),
/// relative paths resolved against the graph file's folder.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Params {
    values: serde_json::Map<String, serde_json::Value>,
    base_dir: Option<PathBuf>,
}

impl Params {
    /// Parameters from a JSON object.
    pub fn new(values: serde_json::Map<String, serde_json::Value>, base_dir: Option<PathBuf>) -> Self {
        Self { values, base_dir }
    }

    /// The value of `key` as `T`; an error names the key. A key validation left unset (a
    /// seeded parameter without a value) reads as JSON `null`.
    pub fn value<T: Param>(&self, key: &str) -> Result<T, OpError> {
        let v = self.values.get(key).unwrap_or(&serde_json::Value::Null);
        T::from_json(v, self).map_err(|message| OpError::Config { key: key.to_owned(), message })
    }

    /// The raw value of `key`.
    pub fn get(&self, key: &str) -> Option<&serde_json::Value> {
        self.values.get(key)
    }

    /// All values.
    pub fn as_map(&self) -> &serde_json::Map<String, serde_json::Value> {
        &self.values
    }

    /// These parameters with `key` set to `value`, and the value it had.
    pub fn with(&self, key: &str, value: serde_json::Value) -> (Self, Option<serde_json::Value>) {
        let mut next = self.clone();
        let old = next.values.insert(key.to_owned(), value);
        (next, old)
    }

    /// Resolve a path parameter against the graph file's folder.
    pub fn resolve_path(&self, path: &str) -> PathBuf {
        let p = Path::new(path);
        match &self.base_dir {
            Some(base) if p.is_relative() => base.join(p),
            _ => p.to_path_buf(),
        }
    }
}
