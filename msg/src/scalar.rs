//! Named scalar metrics.

use std::sync::Arc;

use super::Digest;

/// Named `f64` values, e.g. `{"dynamic_count": 12}`; order is kept.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Scalars {
    /// `(name, value)` pairs.
    pub values: Vec<(Arc<str>, f64)>,
}

impl Scalars {
    /// One named value.
    pub fn one(name: &str, value: f64) -> Self {
        Self { values: vec![(name.into(), value)] }
    }
    /// The value of `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        self.values.iter().find(|(k, _)| &**k == name).map(|(_, v)| *v)
    }
    pub(super) fn digest_into(&self, d: &mut Digest) {
        d.u64(self.values.len() as u64);
        for (k, v) in &self.values {
            d.str(k);
            d.f64(*v);
        }
    }
}
