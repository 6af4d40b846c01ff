//! The table of known operators. Validation, `dynaflow ops` and the runtime all read it.

use std::collections::BTreeMap;

use super::OpSpec;

/// Operators by name.
#[derive(Clone, Debug, Default)]
pub struct Registry {
    ops: BTreeMap<&'static str, OpSpec>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }
    /// Add an operator; a later registration of the same name replaces the earlier one.
    pub fn register(&mut self, spec: OpSpec) {
        self.ops.insert(spec.name, spec);
    }
    /// Look up by name.
    pub fn get(&self, name: &str) -> Option<&OpSpec> {
        self.ops.get(name)
    }
    /// All operators, sorted by name.
    pub fn iter(&self) -> impl Iterator<Item = &OpSpec> {
        self.ops.values()
    }
    /// All names, sorted.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.ops.keys().copied()
    }
}
