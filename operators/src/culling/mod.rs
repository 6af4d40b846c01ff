//! Dynamic-point culling: which tracked points lie on moving things.
//!
//! - the rules themselves are the `dynaflow-culling` library (re-exported as `rules`): plain
//!   functions and structs on points, boxes and masks, each returning a decision, its reason
//!   and the measure it compared.
//! - `ops`: the operators: `fundamental_ransac` and `homography_prosac` (the models), one
//!   operator per rule (`cull_epipolar`, `cull_epipolar_adaptive`, `cull_mask`,
//!   `cull_semantic_prior`, `cull_flow`, `cull_depth`, each with its doc in `docs/`),
//!   `combine_labels`, and `oracle_boxes` (ground-truth boxes from the generator's masks, for
//!   developing the semantic rules before a detector exists).

mod ops;
pub use dynaflow_culling as rules;

pub use ops::{
    COMBINE_LABELS, CULL_DEPTH, CULL_EPIPOLAR, CULL_EPIPOLAR_ADAPTIVE, CULL_FLOW, CULL_MASK, CULL_SEMANTIC_PRIOR,
    FUNDAMENTAL_RANSAC, HOMOGRAPHY_PROSAC, ORACLE_BOXES,
};

/// Where the operator `cull` (one operator, a `mode` per rule) went: one operator per rule.
pub const CULL_MIGRATION: &str = "`cull` is one operator per rule now: `mode: epipolar_fixed` -> `op: cull_epipolar`, `epipolar_adaptive` -> `cull_epipolar_adaptive`, `mask` -> `cull_mask`, `semantic_prior` -> `cull_semantic_prior`, `flow_consistency` -> `cull_flow`, `depth_consistency` -> `cull_depth`; drop `mode` and keep that rule's own parameters (docs/graph-spec.md, \"Migrating from `cull`\")";
