//! Resolved parameter values.

use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

use super::OpError;

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

    /// Deserialize into an operator's typed config. The error names the offending key.
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T, OpError> {
        serde_json::from_value(serde_json::Value::Object(self.values.clone())).map_err(|e| OpError::Config {
            key: e.to_string().split('`').nth(1).unwrap_or("?").to_owned(),
            message: e.to_string(),
        })
    }

    /// The raw value of `key`.
    pub fn get(&self, key: &str) -> Option<&serde_json::Value> {
        self.values.get(key)
    }

    /// All values.
    pub fn as_map(&self) -> &serde_json::Map<String, serde_json::Value> {
        &self.values
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
