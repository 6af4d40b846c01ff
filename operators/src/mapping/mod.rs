//! Mapping: `octomap` (a semantic OctoMap over `dynaflow-octomap`).

mod octomap;

pub use octomap::OCTOMAP;
