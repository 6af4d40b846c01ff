//! The table of known operators. Validation, `dynaflow ops` and the runtime all read it.

use std::collections::BTreeMap;

use super::OpSpec;

/// Operators by name.
#[derive(Clone, Debug, Default)]
pub struct Registry {
    ops: BTreeMap<&'static str, OpSpec>,
    retired: BTreeMap<&'static str, &'static str>,
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
    /// Record that operator `name` no longer exists and what replaces it: a graph naming it
    /// gets `migration` as the hint of its error.
    pub fn retire(&mut self, name: &'static str, migration: &'static str) {
        self.retired.insert(name, migration);
    }
    /// What replaces a retired operator, if `name` is one.
    pub fn migration(&self, name: &str) -> Option<&'static str> {
        self.retired.get(name).copied()
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
