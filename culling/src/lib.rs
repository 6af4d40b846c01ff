//! The seed papers' dynamic-point culling rules, as plain functions and structs with no
//! engine or async dependency (the `cull_*` operators wrap them). Each labels every point
//! (dynamic or not, why, and the measure compared with the threshold), so runs with
//! different rules can be diffed.

#![warn(missing_docs)]

use dynaflow_msg::LabelReason;
pub use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{
    CHI2_2DOF, FundamentalFit, HOMOGRAPHY_RATIO, HomographyFit, RansacConfig, SplitMix64, epipolar_distance,
    fit_fundamental, fit_homography_prosac, homography_ratio, transfer_error,
};

mod combine;
mod depth;
mod epipolar;
mod flow;
mod semantic;

pub use combine::*;
pub use depth::*;
pub use epipolar::*;
pub use flow::*;
pub use semantic::*;

/// One point's decision.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// Whether the point is taken as moving.
    pub dynamic: bool,
    /// The rule that decided.
    pub reason: LabelReason,
    /// The measure the rule compared (pixels for epipolar rules, the class's dynamic value for
    /// the semantic prior, 1/0 for masks).
    pub score: f32,
}

impl Decision {
    fn keep(reason: LabelReason, score: f32) -> Self {
        Self { dynamic: false, reason, score }
    }
}

/// An axis-aligned box `[x_min, y_min, x_max, y_max]` with a class name.
#[derive(Clone, Debug, PartialEq)]
pub struct LabelledBox {
    /// Pixels.
    pub bbox: [f32; 4],
    /// Class name (COCO's, e.g. `person`).
    pub label: String,
}

fn inside(b: &[f32; 4], p: [f32; 2]) -> bool {
    p[0] >= b[0] && p[0] <= b[2] && p[1] >= b[1] && p[1] <= b[3]
}

/// Above the threshold, or not a number (no epipolar line): a point that cannot be shown
/// static is taken as dynamic.
fn exceeds(d: f32, threshold: f32) -> bool {
    d.partial_cmp(&threshold) != Some(std::cmp::Ordering::Less) && d != threshold
}

fn to64(p: &[[f32; 2]]) -> Vec<[f64; 2]> {
    p.iter().map(|q| [f64::from(q[0]), f64::from(q[1])]).collect()
}

#[cfg(test)]
mod tests;
