//! Dynamic-point culling: which tracked points lie on moving things.
//!
//! - the rules themselves are the `dynaflow-culling` library (re-exported as `rules`): plain
//!   functions and structs on points, boxes and masks, each returning a decision, its reason
//!   and the measure it compared.
//! - the operators, a module each: `models` (`fundamental_ransac`, `homography_prosac`), one
//!   operator per rule (`epipolar`: `cull_epipolar`, `cull_epipolar_adaptive`; `semantic`:
//!   `cull_mask`, `cull_semantic_prior`; `flow`: `cull_flow`; `depth`: `cull_depth`; each with
//!   its doc in `docs/`), `combine` (`combine_labels`) and `oracle` (`oracle_boxes`: ground-truth
//!   boxes from the generator's masks, for developing the semantic rules before a detector
//!   exists). What the rule operators share (ports, outputs, the `rule_op!` macro) is here.

pub use dynaflow_culling as rules;

use std::sync::Arc;

use dynaflow_engine::msg::{
    Body, CameraInfo, DepthImage, Detection, Detections, LabelReason, Message, PointLabel, PointLabels, Pose, Scalars,
    SegmentationMask, Track, Tracks,
};
use dynaflow_engine::op::{
    Context, In, Inputs, Instance, OpError, OpSpec, Operator, Out, Outputs, Param, ParamMap, ParamType, Params,
    PortSpec, doc_line,
};
use dynaflow_engine::{param_enum, params};
use dynaflow_vision::geometry::RansacConfig;
use nalgebra::Isometry3;
use rand_core::Rng;

use crate::inference::{ClassName, class_list};
use rules::{Decision, LabelledBox};

/// The labels of `t`'s tracks, each at its track's current pixel.
fn labels(t: &Tracks, decisions: &[Decision]) -> PointLabels {
    PointLabels {
        labels: decisions
            .iter()
            .zip(&t.tracks)
            .enumerate()
            .map(|(i, (d, tr))| PointLabel {
                index: i as u32,
                dynamic: d.dynamic,
                reason: d.reason,
                score: d.score,
                at: tr.cur,
            })
            .collect(),
    }
}

const TRACKS: In<Tracks> = In::required("tracks", "point correspondences, previous -> current");
const LABELS: Out<PointLabels> = Out::new("labels", "per track: dynamic, reason, score");
const STATIC: Out<Tracks> = Out::new("static", "the tracks labelled static");
const COUNTS: Out<Scalars> =
    Out::new("counts", "`dynamic`, `static`, `total`, and the rule's `threshold` where it has one");
const RULE_OUTPUTS: &[PortSpec] = &[LABELS.spec, STATIC.spec, COUNTS.spec];

/// What every rule operator emits: labels, the tracks kept, and counts (plus `extra`).
fn labelled(msg: &Message, t: &Tracks, decisions: &[Decision], extra: &[(&str, f64)]) -> Outputs {
    let kept: Vec<Track> = t.tracks.iter().zip(decisions).filter(|(_, d)| !d.dynamic).map(|(t, _)| *t).collect();
    let dynamic = decisions.iter().filter(|d| d.dynamic).count();
    let mut counts: Vec<(Arc<str>, f64)> = vec![
        ("dynamic".into(), dynamic as f64),
        ("static".into(), kept.len() as f64),
        ("total".into(), decisions.len() as f64),
    ];
    counts.extend(extra.iter().map(|(k, v)| ((*k).into(), *v)));
    Outputs::new()
        .send(&LABELS, msg.header.clone(), labels(t, decisions))
        .send(&STATIC, msg.header.clone(), Tracks { prev_seq: t.prev_seq, tracks: kept })
        .send(&COUNTS, msg.header.clone(), Scalars { values: counts })
}

/// Every track static: what a rule says when it cannot judge a frame.
fn all_static(n: usize, score: f32) -> Vec<Decision> {
    vec![Decision { dynamic: false, reason: LabelReason::Static, score }; n]
}

fn endpoints(t: &Tracks) -> (Vec<[f32; 2]>, Vec<[f32; 2]>) {
    t.tracks.iter().map(|t| (t.prev, t.cur)).unzip()
}

fn boxes(d: Option<&Detections>) -> Vec<LabelledBox> {
    d.map_or_else(Vec::new, |d| {
        d.detections.iter().map(|d| LabelledBox { bbox: d.bbox, label: d.label.to_string() }).collect()
    })
}

/// Declares a rule operator: its `OpSpec` from the inputs, the params struct and a doc file
/// beside this one (`docs/<name>.md`); `tunable: &[..]` names the parameters that may change while
/// running (the operator implements `set_params`).
macro_rules! rule_op {
    ($spec:ident, $name:literal, $inputs:expr, $config:ident, $build:expr) => {
        rule_op!($spec, $name, $inputs, $config, $build, tunable: &[]);
    };
    ($spec:ident, $name:literal, $inputs:expr, $config:ident, $build:expr, tunable: $tunable:expr) => {
        #[doc = concat!("The `", $name, "` operator (its doc: `dynaflow ops ", $name, "`).")]
        pub const $spec: OpSpec = OpSpec::transform(
            $name,
            "culling",
            doc_line(include_str!(concat!("docs/", $name, ".md"))),
            |p: &Params| Ok(Instance::Transform(Box::new(($build)($config::from_params(p)?)))),
        )
        .inputs($inputs)
        .outputs(RULE_OUTPUTS)
        .params($config::PARAMS)
        .tunable($tunable)
        .cpu_heavy();
    };
}

fn ransac(threshold: f64, confidence: f64) -> RansacConfig {
    RansacConfig { threshold, confidence, ..RansacConfig::default() }
}

mod combine;
mod depth;
mod epipolar;
mod flow;
mod models;
mod oracle;
mod semantic;

pub use combine::COMBINE_LABELS;
pub use depth::CULL_DEPTH;
pub use epipolar::{CULL_EPIPOLAR, CULL_EPIPOLAR_ADAPTIVE};
pub use flow::CULL_FLOW;
pub use models::{FUNDAMENTAL_RANSAC, HOMOGRAPHY_PROSAC};
pub use oracle::ORACLE_BOXES;
pub use semantic::{CULL_MASK, CULL_SEMANTIC_PRIOR};

/// Where the operator `cull` (one operator, a `mode` per rule) went: one operator per rule.
pub const CULL_MIGRATION: &str = "`cull` is one operator per rule now: `mode: epipolar_fixed` -> `op: cull_epipolar`, `epipolar_adaptive` -> `cull_epipolar_adaptive`, `mask` -> `cull_mask`, `semantic_prior` -> `cull_semantic_prior`, `flow_consistency` -> `cull_flow`, `depth_consistency` -> `cull_depth`; drop `mode` and keep that rule's own parameters (docs/graph-spec.md, \"Migrating from `cull`\")";
