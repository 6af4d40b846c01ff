//! The culling operators.

use std::sync::Arc;

use dynaflow_engine::msg::{
    Body, CameraInfo, DepthImage, Detection, Detections, LabelReason, Message, PointLabel, PointLabels, Pose, Scalars,
    SegmentationMask, Track, Tracks,
};
use dynaflow_engine::op::{
    Context, In, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Out, Outputs, Param, ParamMap, ParamType, Params,
    PortSpec, doc_line,
};
use dynaflow_engine::{param_enum, params};
use dynaflow_vision::geometry::RansacConfig;
use nalgebra::Isometry3;
use rand_core::Rng;

use super::rules::{self, Decision, LabelledBox};
use crate::inference::{ClassName, class_list};

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

// --- fundamental_ransac ----------------------------------------------------------------

params! {
    struct FConfig {
        /// RANSAC inlier threshold on the epipolar distances, pixels (chosen for sub-pixel LK tracks; OpenCV's default is 3)
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
        /// samples at most (fewer when the inlier ratio allows)
        max_iterations: u64 [1, 1_000_000] = 1000,
        /// refit on the inliers of each new best model (LO-RANSAC)
        local_optimisation: bool = true,
    }
}

const F_MODEL: Out<Scalars> = Out::new("model", "`f00`..`f22` (x2^T F x1 = 0), `inliers`, `tracks`, `iterations`");
const F_LABELS: Out<PointLabels> =
    Out::new("labels", "per track: outlier = dynamic, reason `epipolar`, score = distance");

pub const FUNDAMENTAL_RANSAC: OpSpec = OpSpec {
    name: "fundamental_ransac",
    family: "epipolar",
    doc: "The fundamental matrix of the previous-to-current tracks by LO-RANSAC over the 7-point solver (8-point refits), deterministic from the node's seed. `labels` marks RANSAC outliers dynamic with each track's epipolar distance (pixels, MG-SLAM's Eq. 4) as score.",
    kind: OpKind::Transform,
    inputs: &[TRACKS.spec],
    outputs: &[F_MODEL.spec, F_LABELS.spec],
    params: FConfig::PARAMS,
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let c = FConfig::from_params(p)?;
        Ok(Instance::Transform(Box::new(FundamentalOp(RansacConfig {
            threshold: c.ransac_threshold,
            confidence: c.confidence,
            max_iterations: c.max_iterations as usize,
            local_optimisation: c.local_optimisation,
        }))))
    },
};

struct FundamentalOp(RansacConfig);

impl Operator for FundamentalOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let mut out = Outputs::new();
        let Some((fit, dist)) = rules::epipolar_distances(&prev, &cur, &vec![true; prev.len()], &self.0, seed) else {
            // Too few tracks for a model: nothing is labelled.
            return Ok(out);
        };
        let mut values: Vec<(Arc<str>, f64)> =
            fit.f.transpose().iter().enumerate().map(|(i, v)| (format!("f{}{}", i / 3, i % 3).into(), *v)).collect();
        values.push(("inliers".into(), fit.inlier_count() as f64));
        values.push(("tracks".into(), prev.len() as f64));
        values.push(("iterations".into(), fit.iterations as f64));
        F_MODEL.push(&mut out, msg.header.clone(), Scalars { values });
        let decisions: Vec<Decision> = fit
            .inliers
            .iter()
            .zip(&dist)
            .map(|(&inlier, &d)| Decision {
                dynamic: !inlier,
                reason: if inlier { LabelReason::Static } else { LabelReason::Epipolar },
                score: d,
            })
            .collect();
        F_LABELS.push(&mut out, msg.header.clone(), labels(t, &decisions));
        Ok(out)
    }
}

// --- homography_prosac ----------------------------------------------------------------

params! {
    struct HConfig {
        /// inlier threshold on the transfer error, pixels
        threshold: f64 [0.01, 1000.0] = 1.0,
    }
}

const H_MODEL: Out<Scalars> = Out::new("model", "`h00`..`h22` (p2 ~ H p1), `inliers`, `tracks`, `iterations`");
const H_LABELS: Out<PointLabels> =
    Out::new("labels", "per track: outlier = dynamic, reason `flow`, score = transfer error (px)");

pub const HOMOGRAPHY_PROSAC: OpSpec = OpSpec {
    name: "homography_prosac",
    family: "epipolar",
    doc: "The homography of the previous-to-current tracks by PROSAC (samples from the best-ranked tracks first; rank = 1 / (1 + error), the tracker's residual or Hamming distance), for camera-motion compensation as in PSPNet-SLAM. `labels` marks tracks whose transfer error exceeds `threshold` pixels.",
    kind: OpKind::Transform,
    inputs: &[TRACKS.spec],
    outputs: &[H_MODEL.spec, H_LABELS.spec],
    params: HConfig::PARAMS,
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(HomographyOp(HConfig::from_params(p)?)))),
};

struct HomographyOp(HConfig);

impl Operator for HomographyOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let quality: Vec<f64> = t.tracks.iter().map(|t| 1.0 / (1.0 + f64::from(t.error.max(0.0)))).collect();
        let seed = ctx.rng.next_u64();
        let mut out = Outputs::new();
        let Some((fit, residuals)) = rules::homography_residuals(&prev, &cur, &quality, self.0.threshold, seed) else {
            return Ok(out);
        };
        let mut values: Vec<(Arc<str>, f64)> =
            fit.h.transpose().iter().enumerate().map(|(i, v)| (format!("h{}{}", i / 3, i % 3).into(), *v)).collect();
        values.push(("inliers".into(), fit.inliers.iter().filter(|&&i| i).count() as f64));
        values.push(("tracks".into(), prev.len() as f64));
        values.push(("iterations".into(), fit.iterations as f64));
        H_MODEL.push(&mut out, msg.header.clone(), Scalars { values });
        let decisions = rules::flow_consistency(&residuals, self.0.threshold as f32);
        H_LABELS.push(&mut out, msg.header.clone(), labels(t, &decisions));
        Ok(out)
    }
}

// --- the rules: one operator each -----------------------------------------------------

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
/// beside this one (`docs/<name>.md`).
macro_rules! rule_op {
    ($spec:ident, $name:literal, $inputs:expr, $config:ident, $build:expr) => {
        pub const $spec: OpSpec = OpSpec {
            name: $name,
            family: "culling",
            doc: doc_line(include_str!(concat!("docs/", $name, ".md"))),
            kind: OpKind::Transform,
            inputs: $inputs,
            outputs: RULE_OUTPUTS,
            params: $config::PARAMS,
            cpu_heavy: true,
            ground_truth_outputs: None,
            build: |p: &Params| Ok(Instance::Transform(Box::new(($build)($config::from_params(p)?)))),
        };
    };
}

params! {
    struct EpipolarConfig {
        /// distance in pixels above which a point is dynamic (MG-SLAM's 0.40; sub-pixel LK tracks put static points well below it)
        threshold: f64 [0.0, 1000.0] = 0.4,
        /// RANSAC inlier threshold on the epipolar distances, pixels (chosen for sub-pixel LK tracks; OpenCV's default is 3)
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
        /// a track labelled dynamic stays dynamic while it is tracked (MG-SLAM's dynamic features tracked)
        sticky: bool = false,
        /// fit F only on the tracks not already labelled dynamic in the previous frame
        fit_static: bool = false,
        /// frames between the two views tested: 1 compares consecutive frames (MG-SLAM); k > 1 each track's pixel k frames ago with now, where it has been tracked that long (the rest: consecutive frames)
        baseline: u64 [1, 60] = 1,
        /// when the `baseline` test replaces the consecutive one: on every frame, or only where the consecutive pair has too little parallax for F (ORB-SLAM2's model selection: R_H > 0.40)
        long_baseline: LongBaseline = LongBaseline::Always,
        /// test the `baseline` pair against the model ORB-SLAM2's model selection picks for it: its homography's transfer error where R_H > 0.40 (a rotation: F is ill-posed), its epipolar distance otherwise
        select_model: bool = false,
    }
}

param_enum! {
    /// When the longer-baseline epipolar test runs.
    enum LongBaseline { Always = "always", LowParallax = "low_parallax" }
}

fn ransac(threshold: f64, confidence: f64) -> RansacConfig {
    RansacConfig { threshold, confidence, ..RansacConfig::default() }
}

rule_op!(CULL_EPIPOLAR, "cull_epipolar", &[TRACKS.spec], EpipolarConfig, |c: EpipolarConfig| {
    EpipolarOp(rules::EpipolarCull::new(rules::EpipolarOptions {
        threshold: c.threshold as f32,
        ransac: ransac(c.ransac_threshold, c.confidence),
        sticky: c.sticky,
        fit_static: c.fit_static,
        baseline: c.baseline as usize,
        long_baseline: match c.long_baseline {
            LongBaseline::Always => rules::LongBaseline::Always,
            LongBaseline::LowParallax => rules::LongBaseline::LowParallax,
        },
        select_model: c.select_model,
    }))
});

struct EpipolarOp(rules::EpipolarCull);

impl Operator for EpipolarOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let ids: Vec<u64> = t.tracks.iter().map(|t| t.id).collect();
        let frame = self.0.label(&ids, &prev, &cur, ctx.rng.next_u64());
        let threshold = f64::from(self.0.options().threshold);
        let mut extra = vec![("threshold", threshold), ("long_baseline", frame.long as f64)];
        if let Some(r) = frame.homography_ratio {
            extra.push(("homography_ratio", r));
        }
        if let Some(r) = frame.long_homography_ratio {
            extra.push(("long_homography_ratio", r));
            extra.push(("long_homography", f64::from(u8::from(frame.long_homography))));
        }
        Ok(labelled(msg, t, &frame.decisions, &extra))
    }
}

params! {
    struct AdaptiveConfig {
        /// RANSAC inlier threshold on the epipolar distances of the points outside the boxes, pixels
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence
        confidence: f64 [0.5, 0.999_999] = 0.99,
    }
}

const ADAPTIVE_DETECTIONS: In<Detections> =
    In::wired("detections", "boxes of potentially dynamic objects (a frame without: no box)");

rule_op!(
    CULL_EPIPOLAR_ADAPTIVE,
    "cull_epipolar_adaptive",
    &[TRACKS.spec, ADAPTIVE_DETECTIONS.spec],
    AdaptiveConfig,
    AdaptiveOp
);

struct AdaptiveOp(AdaptiveConfig);

impl Operator for AdaptiveOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let in_box = rules::in_any_box(&cur, &boxes(ADAPTIVE_DETECTIONS.get(inputs)?));
        let outside: Vec<bool> = in_box.iter().map(|b| !b).collect();
        let ransac = ransac(self.0.ransac_threshold, self.0.confidence);
        Ok(match rules::epipolar_distances(&prev, &cur, &outside, &ransac, seed) {
            Some((_, d)) => {
                let (decisions, threshold) = rules::epipolar_adaptive(&d, &in_box);
                labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))])
            }
            // No F from the points outside the boxes: no threshold either.
            None => labelled(msg, t, &all_static(prev.len(), 0.0), &[]),
        })
    }
}

params! {
    struct MaskConfig {
        /// class names that count as dynamic
        classes: Vec<ClassName> = class_list(&["person"]),
    }
}

const MASK: In<SegmentationMask> =
    In::wired("mask", "segmentation of dynamic classes (a frame without: every track static)");

rule_op!(CULL_MASK, "cull_mask", &[TRACKS.spec, MASK.spec], MaskConfig, MaskOp);

struct MaskOp(MaskConfig);

impl Operator for MaskOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (_, cur) = endpoints(t);
        let decisions = match MASK.get(inputs)? {
            Some(m) => {
                let dynamic_ids: Vec<u16> = m
                    .class_names
                    .iter()
                    .enumerate()
                    .filter(|(_, n)| self.0.classes.iter().any(|c| c.as_str() == &***n))
                    .map(|(i, _)| i as u16)
                    .collect();
                let (w, h) = (m.width as usize, m.height as usize);
                rules::mask_rule(&cur, |x, y| {
                    x < w && y < h && m.classes.get(y * w + x).is_some_and(|c| dynamic_ids.contains(c))
                })
            }
            None => all_static(cur.len(), 0.0),
        };
        Ok(labelled(msg, t, &decisions, &[]))
    }
}

/// A class's dynamic value (YG-SLAM's scale: 0 static .. 1 always moving).
#[derive(Clone, Copy, Debug)]
struct DynamicValue(f64);

impl Param for DynamicValue {
    const TYPE: ParamType = ParamType::Float { min: 0.0, max: 1.0 };
    fn from_json(value: &serde_json::Value, params: &Params) -> Result<Self, String> {
        f64::from_json(value, params).map(DynamicValue)
    }
    fn to_json(&self) -> serde_json::Value {
        self.0.into()
    }
}

params! {
    struct PriorConfig {
        /// dynamic values per class overriding YG-SLAM's table (person 1.0; cup, cell phone, keyboard, mouse 0.7; chair 0.6; tvmonitor 0.5; diningtable 0.2; book 0.1), e.g. `{ chair: 1.0 }`
        values: ParamMap<ClassName, DynamicValue> = ParamMap(Vec::new()),
    }
}

const PRIOR_DETECTIONS: In<Detections> =
    In::wired("detections", "boxes with class names (a frame without: no box, every track static)");
const KEY_FRAME: In<Body> = In::optional("key_frame", "present on key frames (the 0.4-0.8 band counts only there)");

rule_op!(
    CULL_SEMANTIC_PRIOR,
    "cull_semantic_prior",
    &[TRACKS.spec, PRIOR_DETECTIONS.spec, KEY_FRAME.spec],
    PriorConfig,
    |c: PriorConfig| {
        let mut values: Vec<(String, f32)> =
            rules::DEFAULT_DYNAMIC_VALUES.iter().map(|(n, v)| ((*n).to_owned(), *v)).collect();
        for (name, v) in c.values.0 {
            values.retain(|(n, _)| *n != name.0);
            values.push((name.0, v.0 as f32));
        }
        PriorOp { values }
    }
);

struct PriorOp {
    values: Vec<(String, f32)>,
}

impl Operator for PriorOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (_, cur) = endpoints(t);
        let key = KEY_FRAME.message(inputs)?.is_some();
        let value_of = |l: &str| self.values.iter().find(|(n, _)| n == l).map_or(0.0, |(_, v)| *v);
        let decisions = rules::semantic_prior(&cur, &boxes(PRIOR_DETECTIONS.get(inputs)?), value_of, key);
        Ok(labelled(msg, t, &decisions, &[]))
    }
}

param_enum! {
    /// The camera-induced motion a flow-consistency rule compares with.
    enum MotionModel { Homography = "homography", Fundamental = "fundamental" }
}

params! {
    struct FlowConfig {
        /// the camera-induced motion, a homography by PROSAC (PSPNet-SLAM; exact for rotation or a distant scene) or F (allows parallax)
        motion_model: MotionModel = MotionModel::Homography,
        /// residual in pixels above which a track is dynamic
        flow_threshold: f64 [0.0, 1000.0] = 1.0,
        /// RANSAC (or PROSAC) inlier threshold of the motion model, pixels
        ransac_threshold: f64 [0.01, 100.0] = 1.0,
        /// RANSAC confidence (`fundamental`)
        confidence: f64 [0.5, 0.999_999] = 0.99,
    }
}

rule_op!(CULL_FLOW, "cull_flow", &[TRACKS.spec], FlowConfig, FlowOp);

struct FlowOp(FlowConfig);

impl Operator for FlowOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let (prev, cur) = endpoints(t);
        let seed = ctx.rng.next_u64();
        let residuals = match self.0.motion_model {
            MotionModel::Fundamental => {
                let ransac = ransac(self.0.ransac_threshold, self.0.confidence);
                rules::epipolar_distances(&prev, &cur, &vec![true; prev.len()], &ransac, seed).map(|(_, d)| d)
            }
            MotionModel::Homography => {
                let quality: Vec<f64> = t.tracks.iter().map(|t| 1.0 / (1.0 + f64::from(t.error.max(0.0)))).collect();
                rules::homography_residuals(&prev, &cur, &quality, self.0.ransac_threshold, seed).map(|(_, r)| r)
            }
        };
        let threshold = self.0.flow_threshold as f32;
        let decisions = match residuals {
            Some(r) => rules::flow_consistency(&r, threshold),
            None => all_static(prev.len(), 0.0),
        };
        Ok(labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))]))
    }
}

params! {
    struct DepthConfig {
        /// predicted-vs-measured depth difference in metres above which a point is dynamic (4 sigma of Kinect depth noise at 4 m)
        depth_threshold: f64 [0.0, 100.0] = 0.1,
    }
}

const DEPTH: In<DepthImage> = In::wired("depth", "depth in metres (a frame without: nothing is judged)");
const CAMERA_INFO: In<CameraInfo> = In::wired("camera_info", "intrinsics");
const POSE: In<Pose> = In::wired(
    "pose",
    "world_from_cam, from the tracker (`delay: 1`) or ground truth (a frame without: nothing is judged)",
);

rule_op!(CULL_DEPTH, "cull_depth", &[TRACKS.spec, DEPTH.spec, CAMERA_INFO.spec, POSE.spec], DepthConfig, |c| DepthOp {
    config: c,
    last: None,
    anchors: rules::DepthAnchors::new()
});

struct DepthOp {
    config: DepthConfig,
    /// The previous frame's depth and pose, when this node saw both.
    last: Option<(DepthImage, Isometry3<f64>)>,
    anchors: rules::DepthAnchors,
}

impl Operator for DepthOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let depth = DEPTH.get(inputs)?;
        let pose = POSE.get(inputs)?.map(|p| p.world_from_cam);
        let camera = CAMERA_INFO.get(inputs)?.map(|k| rules::Pinhole::new(k.fx, k.fy, k.cx, k.cy));
        let threshold = self.config.depth_threshold as f32;
        let decisions = match (depth, pose, camera) {
            (Some(cur_depth), Some(world_from_cur), Some(camera)) => {
                let tracks: Vec<rules::TrackedPoint> =
                    t.tracks.iter().map(|t| rules::TrackedPoint { id: t.id, prev: t.prev, cur: t.cur }).collect();
                let previous = self.last.as_ref().map(|(d, pose)| (|x, y| d.at_nearest(x, y), *pose));
                self.anchors.label(
                    &tracks,
                    camera,
                    previous,
                    (|x, y| cur_depth.at_nearest(x, y), world_from_cur),
                    threshold,
                )
            }
            // An input absent this frame: nothing can be judged.
            _ => all_static(t.tracks.len(), f32::NAN),
        };
        self.last = depth.cloned().zip(pose);
        Ok(labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))]))
    }
}

// --- combine_labels ------------------------------------------------------------------------

param_enum! {
    /// How two label sets combine.
    enum CombineMode { Or = "or", And = "and" }
}

params! {
    struct CombineConfig {
        /// how the two decisions combine
        mode: CombineMode = CombineMode::Or,
    }
}

const LABELS_A: In<PointLabels> = In::required("a", "first rule's labels");
const LABELS_B: In<PointLabels> = In::required("b", "second rule's labels");

pub const COMBINE_LABELS: OpSpec = OpSpec {
    name: "combine_labels",
    family: "culling",
    doc: doc_line(include_str!("docs/combine_labels.md")),
    kind: OpKind::Transform,
    inputs: &[In::<Tracks>::required("tracks", "the tracks both label sets index").spec, LABELS_A.spec, LABELS_B.spec],
    outputs: &[LABELS.spec, STATIC.spec, Out::<Scalars>::new("counts", "`dynamic`, `static`, `total`").spec],
    params: CombineConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(CombineOp(CombineConfig::from_params(p)?)))),
};

struct CombineOp(CombineConfig);

impl Operator for CombineOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = TRACKS.require(inputs)?;
        let ((_, a), (_, b)) = (LABELS_A.require(inputs)?, LABELS_B.require(inputs)?);
        let find = |l: &PointLabels, i: usize| {
            l.labels.iter().find(|x| x.index as usize == i).map(|x| Decision {
                dynamic: x.dynamic,
                reason: x.reason,
                score: x.score,
            })
        };
        let how = match self.0.mode {
            CombineMode::And => rules::Combine::And,
            CombineMode::Or => rules::Combine::Or,
        };
        let decisions: Vec<Decision> =
            (0..t.tracks.len()).map(|i| rules::combine(find(a, i), find(b, i), how)).collect();
        Ok(labelled(msg, t, &decisions, &[]))
    }
}

// --- oracle_boxes ------------------------------------------------------------------------

params! {
    struct OracleConfig {
        /// instances smaller than this are left out (a detector would not see them)
        min_pixels: u64 [1, 100_000_000] = 50,
    }
}

const GT_MASK: In<SegmentationMask> = In::required("mask", "ground-truth class and instance mask");
const ORACLE_DETECTIONS: Out<Detections> = Out::new("detections", "one box per instance (score 1.0)");

pub const ORACLE_BOXES: OpSpec = OpSpec {
    name: "oracle_boxes",
    family: "culling",
    doc: "ORACLE, not a detector: turns a ground-truth instance mask (the `synth` source's `gt_mask`) into one box per instance with its class name and score 1, so the semantic rules can be developed and measured before a detector exists. Never use it to claim detection results.",
    kind: OpKind::Transform,
    inputs: &[GT_MASK.spec],
    outputs: &[ORACLE_DETECTIONS.spec],
    params: OracleConfig::PARAMS,
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(OracleOp(OracleConfig::from_params(p)?)))),
};

struct OracleOp(OracleConfig);

impl Operator for OracleOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, m) = GT_MASK.require(inputs)?;
        let ids = m.instances.as_deref().unwrap_or(&m.classes);
        let detections = rules::instance_boxes(ids, &m.classes, m.width as usize, self.0.min_pixels)
            .into_iter()
            .map(|(bbox, class)| Detection {
                bbox,
                class_id: u32::from(class),
                label: m.class_names.get(usize::from(class)).cloned().unwrap_or_else(|| "object".into()),
                score: 1.0,
            })
            .collect();
        Ok(Outputs::new().send(&ORACLE_DETECTIONS, msg.header.clone(), Detections { detections }))
    }
}
