//! Dynamic-point culling: which tracked points lie on moving things.
//!
//! - `rules`: the seed papers' rules as plain functions on points, boxes and masks (no engine
//!   types), each returning a decision, its reason and the measure it compared.
//! - `ops`: the operators `fundamental_ransac`, `homography_prosac`, `cull`, `combine_labels` (one operator, a `mode` per rule) and
//!   `oracle_boxes` (ground-truth boxes from the generator's masks, for developing the
//!   semantic rules before a detector exists).

mod ops;
pub mod rules;

pub use ops::{COMBINE_LABELS, CULL, FUNDAMENTAL_RANSAC, HOMOGRAPHY_PROSAC, ORACLE_BOXES};
