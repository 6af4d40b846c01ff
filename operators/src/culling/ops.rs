//! The culling operators.

use std::sync::Arc;

use dynaflow_engine::msg::{
    Body, Detection, Detections, LabelReason, PointLabel, PointLabels, PortType, Scalars, Track, Tracks,
};
use dynaflow_engine::op::{
    Context, Default, Inputs, Instance, OpError, OpKind, OpSpec, Operator, Outputs, ParamSpec, ParamType, Params,
    PortSpec,
};
use dynaflow_vision::geometry::RansacConfig;
use rand_core::Rng;

use super::rules::{self, Decision, LabelledBox};

fn tracks_of<'a>(
    inputs: &'a Inputs,
    port: &str,
) -> Result<(&'a Arc<dynaflow_engine::msg::Message>, &'a Tracks), OpError> {
    let msg = inputs.require(port)?;
    match &msg.body {
        Body::Tracks(t) => Ok((msg, t)),
        other => Err(OpError::Input(format!("`{port}` expects tracks, got {}", other.port_type()))),
    }
}

fn labels(decisions: &[Decision]) -> PointLabels {
    PointLabels {
        labels: decisions
            .iter()
            .enumerate()
            .map(|(i, d)| PointLabel { index: i as u32, dynamic: d.dynamic, reason: d.reason, score: d.score })
            .collect(),
    }
}

/// The three outputs of a labelling node: labels, the tracks kept, and counts (plus `extra`).
fn labelled(msg: &dynaflow_engine::msg::Message, t: &Tracks, decisions: &[Decision], extra: &[(&str, f64)]) -> Outputs {
    let kept: Vec<Track> = t.tracks.iter().zip(decisions).filter(|(_, d)| !d.dynamic).map(|(t, _)| *t).collect();
    let dynamic = decisions.iter().filter(|d| d.dynamic).count();
    let mut counts: Vec<(Arc<str>, f64)> = vec![
        ("dynamic".into(), dynamic as f64),
        ("static".into(), kept.len() as f64),
        ("total".into(), decisions.len() as f64),
    ];
    counts.extend(extra.iter().map(|(k, v)| ((*k).into(), *v)));
    Outputs::new()
        .with("labels", msg.header.clone(), Body::PointLabels(labels(decisions)))
        .with("static", msg.header.clone(), Body::Tracks(Tracks { prev_seq: t.prev_seq, tracks: kept }))
        .with("counts", msg.header.clone(), Body::Scalars(Scalars { values: counts }))
}

const RANSAC_PARAMS: [ParamSpec; 2] = [
    ParamSpec {
        name: "ransac_threshold",
        ty: ParamType::Float { min: 0.01, max: 100.0 },
        default: Default::Float(1.0),
        doc: "RANSAC inlier threshold on the epipolar distances, pixels (chosen for sub-pixel LK tracks; OpenCV's default is 3)",
    },
    ParamSpec {
        name: "confidence",
        ty: ParamType::Float { min: 0.5, max: 0.999_999 },
        default: Default::Float(0.99),
        doc: "RANSAC confidence",
    },
];

// --- fundamental_ransac ----------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct FConfig {
    ransac_threshold: f64,
    confidence: f64,
    max_iterations: u64,
    local_optimisation: bool,
}

pub const FUNDAMENTAL_RANSAC: OpSpec = OpSpec {
    name: "fundamental_ransac",
    family: "epipolar",
    doc: "The fundamental matrix of the previous-to-current tracks by LO-RANSAC over the 7-point solver (8-point refits), deterministic from the node's seed. `labels` marks RANSAC outliers dynamic with each track's epipolar distance (pixels, MG-SLAM's Eq. 4) as score.",
    kind: OpKind::Transform,
    inputs: &[PortSpec::input("tracks", PortType::Tracks, "point correspondences, previous -> current")],
    outputs: &[
        PortSpec::output("model", PortType::Scalars, "`f00`..`f22` (x2^T F x1 = 0), `inliers`, `tracks`, `iterations`"),
        PortSpec::output(
            "labels",
            PortType::PointLabels,
            "per track: outlier = dynamic, reason `epipolar`, score = distance",
        ),
    ],
    params: &[
        RANSAC_PARAMS[0],
        RANSAC_PARAMS[1],
        ParamSpec {
            name: "max_iterations",
            ty: ParamType::Int { min: 1, max: 1_000_000 },
            default: Default::Int(1000),
            doc: "samples at most (fewer when the inlier ratio allows)",
        },
        ParamSpec {
            name: "local_optimisation",
            ty: ParamType::Bool,
            default: Default::Bool(true),
            doc: "refit on the inliers of each new best model (LO-RANSAC)",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let c: FConfig = p.parse()?;
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
        let (msg, t) = tracks_of(inputs, "tracks")?;
        let (prev, cur): (Vec<[f32; 2]>, Vec<[f32; 2]>) = t.tracks.iter().map(|t| (t.prev, t.cur)).unzip();
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
        out.push("model", msg.header.clone(), Body::Scalars(Scalars { values }));
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
        out.push("labels", msg.header.clone(), Body::PointLabels(labels(&decisions)));
        Ok(out)
    }
}

// --- homography_prosac ----------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct HConfig {
    threshold: f64,
}

pub const HOMOGRAPHY_PROSAC: OpSpec = OpSpec {
    name: "homography_prosac",
    family: "epipolar",
    doc: "The homography of the previous-to-current tracks by PROSAC (samples from the best-ranked tracks first; rank = 1 / (1 + error), the tracker's residual or Hamming distance), for camera-motion compensation as in PSPNet-SLAM. `labels` marks tracks whose transfer error exceeds `threshold` pixels.",
    kind: OpKind::Transform,
    inputs: &[PortSpec::input("tracks", PortType::Tracks, "point correspondences, previous -> current")],
    outputs: &[
        PortSpec::output("model", PortType::Scalars, "`h00`..`h22` (p2 ~ H p1), `inliers`, `tracks`, `iterations`"),
        PortSpec::output(
            "labels",
            PortType::PointLabels,
            "per track: outlier = dynamic, reason `flow`, score = transfer error (px)",
        ),
    ],
    params: &[ParamSpec {
        name: "threshold",
        ty: ParamType::Float { min: 0.01, max: 1000.0 },
        default: Default::Float(1.0),
        doc: "inlier threshold on the transfer error, pixels",
    }],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(HomographyOp(p.parse()?)))),
};

struct HomographyOp(HConfig);

impl Operator for HomographyOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = tracks_of(inputs, "tracks")?;
        let (prev, cur): (Vec<[f32; 2]>, Vec<[f32; 2]>) = t.tracks.iter().map(|t| (t.prev, t.cur)).unzip();
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
        out.push("model", msg.header.clone(), Body::Scalars(Scalars { values }));
        let decisions = rules::flow_consistency(&residuals, self.0.threshold as f32);
        out.push("labels", msg.header.clone(), Body::PointLabels(labels(&decisions)));
        Ok(out)
    }
}

// --- cull --------------------------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CullConfig {
    mode: String,
    threshold: f64,
    ransac_threshold: f64,
    confidence: f64,
    classes: String,
    values: String,
    motion_model: String,
    flow_threshold: f64,
    depth_threshold: f64,
}

pub const CULL: OpSpec = OpSpec {
    name: "cull",
    family: "epipolar",
    doc: "Labels each track dynamic or static by one of the seed papers' rules (`mode`): `epipolar_fixed` (MG-SLAM: epipolar distance above `threshold` pixels), `epipolar_adaptive` (YSAG-VINS: F from points outside `detections` boxes, threshold = their mean distance, points inside boxes tested against it), `mask` (points on a `mask` pixel of a class in `classes`), `semantic_prior` (YG-SLAM: dynamic values per class, 0.4-0.8 only on frames where `key_frame` has a message), `flow_consistency` (PSPNet-SLAM: the track disagrees with the camera-induced motion, a PROSAC homography or F, by more than `flow_threshold` pixels; chain a `mask` node after it for the second screening), `depth_consistency` (YOEC-DSLAM: each track's point, placed in the world with its depth and `pose` when first seen, has a predicted depth in the current view; dynamic where the measured `depth` differs by more than `depth_threshold` metres: a static point stays put, a walking person's drifts away over the frames). Every label carries its reason and measure; `static` forwards the tracks kept, `counts` the numbers (chain `cull` nodes through `static` to combine rules).",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("tracks", PortType::Tracks, "point correspondences, previous -> current"),
        PortSpec::optional(
            "detections",
            PortType::Detections,
            "boxes of potentially dynamic objects (adaptive, semantic_prior)",
        ),
        PortSpec::optional("mask", PortType::Mask, "segmentation of dynamic classes (mask)"),
        PortSpec::optional("key_frame", PortType::Any, "present on key frames (semantic_prior's 0.4-0.8 band)"),
        PortSpec::optional("depth", PortType::Depth, "depth in metres (depth_consistency)"),
        PortSpec::optional("camera_info", PortType::CameraInfo, "intrinsics (depth_consistency)"),
        PortSpec::optional("pose", PortType::Pose, "camera pose, from the tracker or ground truth (depth_consistency)"),
    ],
    outputs: &[
        PortSpec::output("labels", PortType::PointLabels, "per track: dynamic, reason, score"),
        PortSpec::output("static", PortType::Tracks, "the tracks labelled static"),
        PortSpec::output(
            "counts",
            PortType::Scalars,
            "`dynamic`, `static`, `total`, `threshold` (pixels; adaptive's is computed)",
        ),
    ],
    params: &[
        ParamSpec {
            name: "mode",
            ty: ParamType::Enum {
                values: &[
                    "epipolar_fixed",
                    "epipolar_adaptive",
                    "mask",
                    "semantic_prior",
                    "flow_consistency",
                    "depth_consistency",
                ],
            },
            default: Default::Str("epipolar_fixed"),
            doc: "the rule",
        },
        ParamSpec {
            name: "threshold",
            ty: ParamType::Float { min: 0.0, max: 1000.0 },
            default: Default::Float(0.4),
            doc: "epipolar_fixed: distance in pixels above which a point is dynamic (MG-SLAM's 0.40; sub-pixel LK tracks put static points well below it)",
        },
        RANSAC_PARAMS[0],
        RANSAC_PARAMS[1],
        ParamSpec {
            name: "classes",
            ty: ParamType::Str,
            default: Default::Str("person"),
            doc: "mask: comma-separated class names that count as dynamic",
        },
        ParamSpec {
            name: "values",
            ty: ParamType::Str,
            default: Default::Str(""),
            doc: "semantic_prior: `class=value` pairs overriding YG-SLAM's table (person 1.0; cup, cell phone, keyboard, mouse 0.7; chair 0.6; tv 0.5; dining table 0.2; book 0.1)",
        },
        ParamSpec {
            name: "motion_model",
            ty: ParamType::Enum { values: &["homography", "fundamental"] },
            default: Default::Str("homography"),
            doc: "flow_consistency: the camera-induced motion, a homography by PROSAC (PSPNet-SLAM; exact for rotation or a distant scene) or F (allows parallax)",
        },
        ParamSpec {
            name: "flow_threshold",
            ty: ParamType::Float { min: 0.0, max: 1000.0 },
            default: Default::Float(1.0),
            doc: "flow_consistency: residual in pixels above which a track is dynamic",
        },
        ParamSpec {
            name: "depth_threshold",
            ty: ParamType::Float { min: 0.0, max: 100.0 },
            default: Default::Float(0.1),
            doc: "depth_consistency: predicted-vs-measured depth difference in metres above which a point is dynamic (4 sigma of Kinect depth noise at 4 m)",
        },
    ],
    cpu_heavy: true,
    ground_truth_outputs: None,
    build: |p: &Params| {
        let c: CullConfig = p.parse()?;
        let mut values: Vec<(String, f32)> =
            rules::DEFAULT_DYNAMIC_VALUES.iter().map(|(n, v)| ((*n).to_owned(), *v)).collect();
        for pair in c.values.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (name, v) = pair.split_once('=').ok_or_else(|| OpError::Config {
                key: "values".into(),
                message: format!("`{pair}` is not `class=value`"),
            })?;
            let v: f32 = v.trim().parse().map_err(|_| OpError::Config {
                key: "values".into(),
                message: format!("`{v}` in `{pair}` is not a number"),
            })?;
            values.retain(|(n, _)| n != name.trim());
            values.push((name.trim().to_owned(), v));
        }
        let classes = crate::inference::known_classes("classes", &c.classes)?;
        Ok(Instance::Transform(Box::new(CullOp {
            config: c,
            values,
            classes,
            last: None,
            anchors: std::collections::HashMap::new(),
        })))
    },
};

struct CullOp {
    config: CullConfig,
    values: Vec<(String, f32)>,
    classes: Vec<String>,
    /// depth_consistency: the previous frame's depth and pose, and each track's position in
    /// the world when it was first seen (its key frame), by track id.
    last: Option<(dynaflow_engine::msg::DepthImage, nalgebra::Isometry3<f64>)>,
    anchors: std::collections::HashMap<u64, nalgebra::Point3<f64>>,
}

fn boxes(inputs: &Inputs) -> Vec<LabelledBox> {
    match inputs.get("detections").map(|m| &m.body) {
        Some(Body::Detections(d)) => {
            d.detections.iter().map(|d| LabelledBox { bbox: d.bbox, label: d.label.to_string() }).collect()
        }
        _ => Vec::new(),
    }
}

impl Operator for CullOp {
    fn process(&mut self, ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = tracks_of(inputs, "tracks")?;
        let (prev, cur): (Vec<[f32; 2]>, Vec<[f32; 2]>) = t.tracks.iter().map(|t| (t.prev, t.cur)).unzip();
        let ransac = RansacConfig {
            threshold: self.config.ransac_threshold,
            confidence: self.config.confidence,
            ..RansacConfig::default()
        };
        // Drawn every frame, used or not, so the stream of seeds does not depend on the mode.
        let seed = ctx.rng.next_u64();
        let mut threshold = self.config.threshold as f32;
        let decisions: Vec<Decision> = match self.config.mode.as_str() {
            "epipolar_fixed" => match rules::epipolar_distances(&prev, &cur, &vec![true; prev.len()], &ransac, seed) {
                Some((_, d)) => rules::epipolar_fixed(&d, threshold),
                None => vec![Decision { dynamic: false, reason: LabelReason::Static, score: 0.0 }; prev.len()],
            },
            "epipolar_adaptive" => {
                let in_box = rules::in_any_box(&cur, &boxes(inputs));
                let outside: Vec<bool> = in_box.iter().map(|b| !b).collect();
                match rules::epipolar_distances(&prev, &cur, &outside, &ransac, seed) {
                    Some((_, d)) => {
                        let (dec, thr) = rules::epipolar_adaptive(&d, &in_box);
                        threshold = thr;
                        dec
                    }
                    None => vec![Decision { dynamic: false, reason: LabelReason::Static, score: 0.0 }; prev.len()],
                }
            }
            "flow_consistency" => {
                let all = vec![true; prev.len()];
                let residuals = if self.config.motion_model == "fundamental" {
                    rules::epipolar_distances(&prev, &cur, &all, &ransac, seed).map(|(_, d)| d)
                } else {
                    let quality: Vec<f64> =
                        t.tracks.iter().map(|t| 1.0 / (1.0 + f64::from(t.error.max(0.0)))).collect();
                    rules::homography_residuals(&prev, &cur, &quality, self.config.ransac_threshold, seed)
                        .map(|(_, r)| r)
                };
                threshold = self.config.flow_threshold as f32;
                match residuals {
                    Some(r) => rules::flow_consistency(&r, threshold),
                    None => vec![Decision { dynamic: false, reason: LabelReason::Static, score: 0.0 }; prev.len()],
                }
            }
            "depth_consistency" => {
                let depth = match inputs.get("depth").map(|m| &m.body) {
                    Some(Body::Depth(d)) => Some(d.clone()),
                    _ => None,
                };
                let pose = match inputs.get("pose").map(|m| &m.body) {
                    Some(Body::Pose(p)) => Some(p.world_from_cam),
                    _ => None,
                };
                let camera = match inputs.get("camera_info").map(|m| &m.body) {
                    Some(Body::CameraInfo(k)) => Some(rules::Pinhole { fx: k.fx, fy: k.fy, cx: k.cx, cy: k.cy }),
                    _ => None,
                };
                threshold = self.config.depth_threshold as f32;
                let decisions = match (&depth, pose, camera) {
                    (Some(cur_depth), Some(world_from_cur), Some(camera)) => {
                        // Anchor tracks seen for the first time at their previous position,
                        // with the previous frame's depth and pose; forget tracks that ended.
                        let ids: std::collections::HashSet<u64> = t.tracks.iter().map(|t| t.id).collect();
                        self.anchors.retain(|id, _| ids.contains(id));
                        if let Some((prev_depth, world_from_prev)) = &self.last {
                            for tr in &t.tracks {
                                let z = prev_depth.at_nearest(tr.prev[0], tr.prev[1]);
                                if z > 0.0 && !self.anchors.contains_key(&tr.id) {
                                    let x = world_from_prev * rules::back_project(camera, tr.prev, f64::from(z));
                                    self.anchors.insert(tr.id, x);
                                }
                            }
                        }
                        let cur_from_world = world_from_cur.inverse();
                        let predicted: Vec<Option<nalgebra::Point3<f64>>> =
                            t.tracks.iter().map(|tr| self.anchors.get(&tr.id).map(|x| cur_from_world * x)).collect();
                        rules::depth_consistency(&predicted, camera, |x, y| cur_depth.at_nearest(x, y), threshold)
                    }
                    // An input missing: nothing can be judged.
                    _ => vec![Decision { dynamic: false, reason: LabelReason::Static, score: f32::NAN }; prev.len()],
                };
                self.last = depth.zip(pose);
                decisions
            }
            "mask" => match inputs.get("mask").map(|m| &m.body) {
                Some(Body::Mask(m)) => {
                    let dynamic_ids: Vec<u16> = m
                        .class_names
                        .iter()
                        .enumerate()
                        .filter(|(_, n)| self.classes.iter().any(|c| c.as_str() == &***n))
                        .map(|(i, _)| i as u16)
                        .collect();
                    let (w, h) = (m.width as usize, m.height as usize);
                    rules::mask_rule(&cur, |x, y| {
                        x < w && y < h && m.classes.get(y * w + x).is_some_and(|c| dynamic_ids.contains(c))
                    })
                }
                // No mask this frame: nothing can be said.
                _ => vec![Decision { dynamic: false, reason: LabelReason::Static, score: 0.0 }; prev.len()],
            },
            _ => {
                let key = inputs.get("key_frame").is_some();
                let values = &self.values;
                let value_of = |l: &str| values.iter().find(|(n, _)| n == l).map_or(0.0, |(_, v)| *v);
                rules::semantic_prior(&cur, &boxes(inputs), value_of, key)
            }
        };
        Ok(labelled(msg, t, &decisions, &[("threshold", f64::from(threshold))]))
    }
}

// --- combine_labels ------------------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct CombineConfig {
    mode: String,
}

pub const COMBINE_LABELS: OpSpec = OpSpec {
    name: "combine_labels",
    family: "epipolar",
    doc: "Combines two label sets of the same tracks: `or` (dynamic if either rule says so, e.g. MG-SLAM's S+G) or `and` (dynamic only if both do, e.g. a box AND a geometric check). The deciding label (reason, score) is `a`'s where it decides, else `b`'s. Chaining `cull` nodes through `static` is the sequence form.",
    kind: OpKind::Transform,
    inputs: &[
        PortSpec::input("tracks", PortType::Tracks, "the tracks both label sets index"),
        PortSpec::input("a", PortType::PointLabels, "first rule's labels"),
        PortSpec::input("b", PortType::PointLabels, "second rule's labels"),
    ],
    outputs: &[
        PortSpec::output("labels", PortType::PointLabels, "combined labels"),
        PortSpec::output("static", PortType::Tracks, "the tracks labelled static"),
        PortSpec::output("counts", PortType::Scalars, "`dynamic`, `static`, `total`"),
    ],
    params: &[ParamSpec {
        name: "mode",
        ty: ParamType::Enum { values: &["or", "and"] },
        default: Default::Str("or"),
        doc: "how the two decisions combine",
    }],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(CombineOp(p.parse()?)))),
};

struct CombineOp(CombineConfig);

impl Operator for CombineOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let (msg, t) = tracks_of(inputs, "tracks")?;
        let get = |port: &str| -> Result<&PointLabels, OpError> {
            match &inputs.require(port)?.body {
                Body::PointLabels(l) => Ok(l),
                other => Err(OpError::Input(format!("`{port}` expects point labels, got {}", other.port_type()))),
            }
        };
        let (a, b) = (get("a")?, get("b")?);
        let find = |l: &PointLabels, i: usize| {
            l.labels.iter().find(|x| x.index as usize == i).map(|x| Decision {
                dynamic: x.dynamic,
                reason: x.reason,
                score: x.score,
            })
        };
        let how = if self.0.mode == "and" { rules::Combine::And } else { rules::Combine::Or };
        let decisions: Vec<Decision> =
            (0..t.tracks.len()).map(|i| rules::combine(find(a, i), find(b, i), how)).collect();
        Ok(labelled(msg, t, &decisions, &[]))
    }
}

// --- oracle_boxes ------------------------------------------------------------------------

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct OracleConfig {
    min_pixels: u64,
}

pub const ORACLE_BOXES: OpSpec = OpSpec {
    name: "oracle_boxes",
    family: "epipolar",
    doc: "ORACLE, not a detector: turns a ground-truth instance mask (the `synth` source's `gt_mask`) into one box per instance with its class name and score 1, so the semantic rules can be developed and measured before a detector exists. Never use it to claim detection results.",
    kind: OpKind::Transform,
    inputs: &[PortSpec::input("mask", PortType::Mask, "ground-truth class and instance mask")],
    outputs: &[PortSpec::output("detections", PortType::Detections, "one box per instance (score 1.0)")],
    params: &[ParamSpec {
        name: "min_pixels",
        ty: ParamType::Int { min: 1, max: 100_000_000 },
        default: Default::Int(50),
        doc: "instances smaller than this are left out (a detector would not see them)",
    }],
    cpu_heavy: false,
    ground_truth_outputs: None,
    build: |p: &Params| Ok(Instance::Transform(Box::new(OracleOp(p.parse()?)))),
};

struct OracleOp(OracleConfig);

impl Operator for OracleOp {
    fn process(&mut self, _ctx: &mut Context, inputs: &Inputs) -> Result<Outputs, OpError> {
        let msg = inputs.require("mask")?;
        let Body::Mask(m) = &msg.body else {
            return Err(OpError::Input(format!("`mask` expects a mask, got {}", msg.body.port_type())));
        };
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
        Ok(Outputs::new().with("detections", msg.header.clone(), Body::Detections(Detections { detections })))
    }
}
