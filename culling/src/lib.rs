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

/// F from the correspondences with `use_point[i]`, and every point's distance (pixels) from
/// its epipolar line `F p1` (MG-SLAM's Eq. 4). `None` when fewer than 8 usable points or no
/// model.
pub fn epipolar_distances(
    prev: &[[f32; 2]],
    cur: &[[f32; 2]],
    use_point: &[bool],
    ransac: &RansacConfig,
    seed: u64,
) -> Option<(FundamentalFit, Vec<f32>)> {
    let (p1, p2): (Vec<[f32; 2]>, Vec<[f32; 2]>) =
        prev.iter().zip(cur).zip(use_point).filter(|(_, u)| **u).map(|((a, b), _)| (*a, *b)).unzip();
    let fit = fit_fundamental(&to64(&p1), &to64(&p2), ransac, &mut SplitMix64::new(seed))?;
    let d = prev
        .iter()
        .zip(cur)
        .map(|(a, b)| {
            epipolar_distance(&fit.f, [f64::from(a[0]), f64::from(a[1])], [f64::from(b[0]), f64::from(b[1])]) as f32
        })
        .collect();
    Some((fit, d))
}

/// The camera-induced motion as a homography by PROSAC, ranked by `quality` (PSPNet-SLAM's
/// `1 / (beta * d_min)`; here `1 / (1 + error)` of each track), and every point's transfer
/// error `|H p1 - p2|` in pixels.
pub fn homography_residuals(
    prev: &[[f32; 2]],
    cur: &[[f32; 2]],
    quality: &[f64],
    threshold: f64,
    seed: u64,
) -> Option<(HomographyFit, Vec<f32>)> {
    let (p1, p2) = (to64(prev), to64(cur));
    let fit = fit_homography_prosac(&p1, &p2, quality, threshold, 1000, &mut SplitMix64::new(seed))?;
    let r = p1.iter().zip(&p2).map(|(a, b)| transfer_error(&fit.h, *a, *b) as f32).collect();
    Some((fit, r))
}

/// PSPNet-SLAM's first screening: dynamic where the track disagrees with the camera-induced
/// motion (residual in pixels from the homography or the epipolar line) by more than
/// `threshold`.
pub fn flow_consistency(residuals: &[f32], threshold: f32) -> Vec<Decision> {
    residuals
        .iter()
        .map(|&r| {
            let dynamic = exceeds(r, threshold);
            Decision { dynamic, reason: if dynamic { LabelReason::Flow } else { LabelReason::Static }, score: r }
        })
        .collect()
}

/// YOEC-DSLAM's multi-view depth check: each point of a key frame, back-projected with its
/// depth and moved into the current camera frame (`predicted[i]`, `None` when it had no depth),
/// is projected into the current image; where the depth measured there (`depth_cur`, metres,
/// 0 or NaN: none) differs from the predicted depth by more than `threshold` metres, the point
/// did not stay where the camera motion alone would put it: dynamic. A walking person's point
/// lands where the person was, on the background now. Points that cannot be judged (no depth,
/// behind the camera, outside the image) stay static with score NaN.
pub fn depth_consistency(
    predicted: &[Option<nalgebra::Point3<f64>>],
    camera: Pinhole,
    depth_cur: impl Fn(f32, f32) -> f32,
    threshold: f32,
) -> Vec<Decision> {
    predicted
        .iter()
        .map(|x| {
            let Some(x) = x.filter(|x| x.z > 1e-6) else {
                return Decision::keep(LabelReason::Static, f32::NAN);
            };
            let [u, v] = camera.project(&x).map_or([f32::NAN; 2], |uv| uv.map(|c| c as f32));
            let z2 = depth_cur(u, v);
            // No measurement (0, or NaN from outside the image).
            if z2.is_nan() || z2 <= 0.0 {
                return Decision::keep(LabelReason::Static, f32::NAN);
            }
            let r = (x.z as f32 - z2).abs();
            let dynamic = exceeds(r, threshold);
            Decision { dynamic, reason: if dynamic { LabelReason::Depth } else { LabelReason::Static }, score: r }
        })
        .collect()
}

/// YOEC-DSLAM's depth check over a sequence: the anchoring state of [`depth_consistency`].
/// Each track is anchored in the world when first seen (at its previous position, with the
/// previous frame's depth and pose); each frame predicts every anchored track's point in the
/// current view and compares its depth with the measured one. Tracks that end are forgotten.
#[derive(Debug, Default)]
pub struct DepthAnchors {
    anchors: std::collections::HashMap<u64, nalgebra::Point3<f64>>,
}

/// MG-SLAM's "dynamic features tracked": a track labelled dynamic stays dynamic for as long
/// as it is tracked (its id keeps coming back), so a walker's point that moves along its
/// epipolar line for a frame is not let back in. Tracks that end are forgotten.
#[derive(Debug, Default)]
pub struct StickyLabels {
    dynamic: std::collections::HashSet<u64>,
}

impl StickyLabels {
    /// Whether track `id` was labelled dynamic in an earlier frame and is still tracked.
    pub fn was_dynamic(&self, id: u64) -> bool {
        self.dynamic.contains(&id)
    }

    /// This frame's decisions for the tracks `ids`, with every remembered dynamic track kept
    /// dynamic (reason and score as decided); the memory becomes this frame's dynamic tracks.
    pub fn apply(&mut self, ids: &[u64], decisions: &mut [Decision]) {
        for (id, d) in ids.iter().zip(decisions.iter_mut()) {
            if self.dynamic.contains(id) {
                d.dynamic = true;
            }
        }
        self.remember(ids, decisions);
    }

    /// Remember this frame's dynamic tracks without changing the decisions.
    pub fn remember(&mut self, ids: &[u64], decisions: &[Decision]) {
        self.dynamic = ids.iter().zip(decisions).filter(|(_, d)| d.dynamic).map(|(id, _)| *id).collect();
    }
}

/// Where each tracked point was `k` frames ago, for an epipolar test over a longer baseline
/// than consecutive frames: the positions of the tracks still tracked, forgotten when a
/// track ends.
#[derive(Debug)]
pub struct TrackHistory {
    k: usize,
    positions: std::collections::HashMap<u64, std::collections::VecDeque<[f32; 2]>>,
}

impl TrackHistory {
    /// A history `k` frames deep (`k >= 1`; 1 is the previous frame).
    pub fn new(k: usize) -> Self {
        Self { k: k.max(1), positions: std::collections::HashMap::new() }
    }

    /// Record this frame's tracks (`ids`, previous and current pixels); tracks not in `ids`
    /// are forgotten.
    pub fn update(&mut self, ids: &[u64], prev: &[[f32; 2]], cur: &[[f32; 2]]) {
        let mut next = std::collections::HashMap::with_capacity(ids.len());
        for ((id, p), c) in ids.iter().zip(prev).zip(cur) {
            let mut q = self.positions.remove(id).unwrap_or_else(|| std::collections::VecDeque::from([*p]));
            q.push_back(*c);
            while q.len() > self.k + 1 {
                q.pop_front();
            }
            next.insert(*id, q);
        }
        self.positions = next;
    }

    /// Track `id`'s pixel `k` frames before the last update's current frame, if it was
    /// tracked that long.
    pub fn back(&self, id: u64) -> Option<[f32; 2]> {
        self.positions.get(&id).filter(|q| q.len() == self.k + 1).and_then(|q| q.front().copied())
    }
}

/// When [`EpipolarCull`] tests over its longer baseline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LongBaseline {
    /// On every frame, for every track tracked that long.
    Always,
    /// Only on frames whose consecutive pair has too little parallax for F: where ORB-SLAM2's
    /// model selection prefers a homography (`R_H > 0.40`, its initialiser's rule; a rotation,
    /// or a translation short against the scene's depth).
    LowParallax,
}

/// The options of MG-SLAM's epipolar test as [`EpipolarCull`] runs it frame after frame.
#[derive(Clone, Debug)]
pub struct EpipolarOptions {
    /// Distance from the epipolar line above which a track is dynamic, pixels (MG-SLAM: 0.40).
    pub threshold: f32,
    /// F's LO-RANSAC.
    pub ransac: RansacConfig,
    /// A track labelled dynamic stays so while it is tracked (MG-SLAM's tracked dynamic features).
    pub sticky: bool,
    /// F fitted only on the tracks not labelled dynamic the frame before.
    pub fit_static: bool,
    /// Frames between the two views of the longer test (1: consecutive frames only).
    pub baseline: usize,
    /// When the longer test replaces the consecutive one.
    pub long_baseline: LongBaseline,
    /// Test the longer pair against the model ORB-SLAM2's model selection picks for it: where
    /// its `R_H > 0.40` (a rotation, or too little translation for the scene's depth: F is
    /// ill-posed and any epipole fits the static points) each track's transfer error from the
    /// pair's homography is compared with the same threshold instead of its epipolar distance.
    pub select_model: bool,
}

/// What [`EpipolarCull::label`] decided for one frame.
#[derive(Clone, Debug)]
pub struct EpipolarFrame {
    /// Per track.
    pub decisions: Vec<Decision>,
    /// ORB-SLAM2's `R_H` of the consecutive pair (computed for `LongBaseline::LowParallax`).
    pub homography_ratio: Option<f64>,
    /// Tracks tested over the longer baseline.
    pub long: usize,
    /// ORB-SLAM2's `R_H` of the longer pair (computed with `select_model`).
    pub long_homography_ratio: Option<f64>,
    /// Whether the longer pair was tested against its homography (`select_model`, `R_H > 0.40`).
    pub long_homography: bool,
}

/// MG-SLAM's epipolar test (LK tracks, F by LO-RANSAC, dynamic above the threshold) over a
/// sequence, with the options the paper describes and its one-frame form leaves out (see
/// [`EpipolarOptions`]). Deterministic from the seeds it is given.
#[derive(Debug)]
pub struct EpipolarCull {
    options: EpipolarOptions,
    sticky: StickyLabels,
    history: TrackHistory,
}

impl EpipolarCull {
    /// A test with `options`, before its first frame.
    pub fn new(options: EpipolarOptions) -> Self {
        let history = TrackHistory::new(options.baseline);
        Self { options, sticky: StickyLabels::default(), history }
    }

    /// The options it runs with.
    pub fn options(&self) -> &EpipolarOptions {
        &self.options
    }

    /// Label this frame's tracks (`ids`, previous and current pixels).
    pub fn label(&mut self, ids: &[u64], prev: &[[f32; 2]], cur: &[[f32; 2]], seed: u64) -> EpipolarFrame {
        let o = &self.options;
        let mut fit_on: Vec<bool> = ids.iter().map(|&id| !(o.fit_static && self.sticky.was_dynamic(id))).collect();
        if fit_on.iter().filter(|u| **u).count() < 8 {
            fit_on = vec![true; ids.len()];
        }
        let consecutive = epipolar_distances(prev, cur, &fit_on, &o.ransac, seed);
        let mut decisions = match &consecutive {
            Some((_, d)) => epipolar_fixed(d, o.threshold),
            None => vec![Decision::keep(LabelReason::Static, 0.0); prev.len()],
        };
        let (mut homography_ratio_of_pair, mut long_tested) = (None, 0);
        let (mut long_ratio, mut long_homography) = (None, false);
        if o.baseline > 1 {
            self.history.update(ids, prev, cur);
            let wanted = match o.long_baseline {
                LongBaseline::Always => true,
                LongBaseline::LowParallax => {
                    let ratio = consecutive
                        .as_ref()
                        .and_then(|(fit, _)| homography_if_selected(prev, cur, &fit_on, fit, seed ^ 2))
                        .map(|(r, _)| r);
                    homography_ratio_of_pair = ratio;
                    // No F at all is the least parallax there is.
                    ratio.is_none_or(|r| r > HOMOGRAPHY_RATIO)
                }
            };
            if wanted {
                // The tracks tracked `baseline` frames, with their pixel then.
                let long: Vec<(usize, [f32; 2])> =
                    (0..ids.len()).filter_map(|i| Some((i, self.history.back(ids[i])?))).collect();
                let back: Vec<[f32; 2]> = long.iter().map(|(_, p)| *p).collect();
                let now: Vec<[f32; 2]> = long.iter().map(|(i, _)| cur[*i]).collect();
                let fit: Vec<bool> = long.iter().map(|(i, _)| fit_on[*i]).collect();
                // A track over k frames is the sum of k one-frame LK steps with independent
                // errors: its error grows as sqrt(k), and so do both thresholds.
                let grow = (o.baseline as f64).sqrt();
                let ransac = RansacConfig { threshold: o.ransac.threshold * grow, ..o.ransac.clone() };
                let threshold = o.threshold * grow as f32;
                if let Some((fit_f, d)) = epipolar_distances(&back, &now, &fit, &ransac, seed ^ 1) {
                    let mut tested = epipolar_fixed(&d, threshold);
                    if o.select_model {
                        let selected = homography_if_selected(&back, &now, &fit, &fit_f, seed ^ 3);
                        long_ratio = selected.as_ref().map(|(r, _)| *r);
                        if let Some((_, Some(h))) = selected {
                            let (b, n) = (to64(&back), to64(&now));
                            let r: Vec<f32> =
                                b.iter().zip(&n).map(|(p, q)| transfer_error(&h, *p, *q) as f32).collect();
                            tested = epipolar_fixed(&r, threshold);
                            long_homography = true;
                        }
                    }
                    for ((j, _), decision) in long.iter().zip(tested) {
                        decisions[*j] = decision;
                    }
                    long_tested = long.len();
                }
            }
        }
        if o.sticky {
            self.sticky.apply(ids, &mut decisions);
        } else {
            self.sticky.remember(ids, &decisions);
        }
        EpipolarFrame {
            decisions,
            homography_ratio: homography_ratio_of_pair,
            long: long_tested,
            long_homography_ratio: long_ratio,
            long_homography,
        }
    }
}

/// ORB-SLAM2's model selection on a pair: the PROSAC homography of the points `fit_on`,
/// `R_H` against the fitted `F`, and the homography when `R_H > 0.40` (the pair is explained
/// by a homography better than F is conditioned: a rotation, or too little translation).
/// `None` when no homography could be fitted.
fn homography_if_selected(
    prev: &[[f32; 2]],
    cur: &[[f32; 2]],
    fit_on: &[bool],
    f: &FundamentalFit,
    seed: u64,
) -> Option<(f64, Option<dynaflow_vision::geometry::Mat3>)> {
    let (p1, p2): (Vec<[f32; 2]>, Vec<[f32; 2]>) =
        prev.iter().zip(cur).zip(fit_on).filter(|(_, u)| **u).map(|((a, b), _)| (*a, *b)).unzip();
    let (p1, p2) = (to64(&p1), to64(&p2));
    let quality = vec![1.0; p1.len()];
    let h = fit_homography_prosac(&p1, &p2, &quality, CHI2_2DOF.sqrt(), 1000, &mut SplitMix64::new(seed))?;
    let ratio = homography_ratio(&h.h, &f.f, &p1, &p2);
    Some((ratio, (ratio > HOMOGRAPHY_RATIO).then_some(h.h)))
}

/// One track for [`DepthAnchors`]: its id and its previous and current pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackedPoint {
    /// Stable track id.
    pub id: u64,
    /// Pixel in the previous frame.
    pub prev: [f32; 2],
    /// Pixel in this frame.
    pub cur: [f32; 2],
}

impl DepthAnchors {
    /// No anchors.
    pub fn new() -> Self {
        Self::default()
    }

    /// Label this frame's tracks. `previous`: the previous frame's depth lookup (metres, 0:
    /// none) and `world_from_cam`, when this node saw it; `current`: this frame's.
    pub fn label(
        &mut self,
        tracks: &[TrackedPoint],
        camera: Pinhole,
        previous: Option<(impl Fn(f32, f32) -> f32, nalgebra::Isometry3<f64>)>,
        current: (impl Fn(f32, f32) -> f32, nalgebra::Isometry3<f64>),
        threshold: f32,
    ) -> Vec<Decision> {
        let ids: std::collections::HashSet<u64> = tracks.iter().map(|t| t.id).collect();
        self.anchors.retain(|id, _| ids.contains(id));
        if let Some((prev_depth, world_from_prev)) = previous {
            for t in tracks {
                let z = prev_depth(t.prev[0], t.prev[1]);
                if z > 0.0 && !self.anchors.contains_key(&t.id) {
                    self.anchors.insert(
                        t.id,
                        world_from_prev * camera.unproject([f64::from(t.prev[0]), f64::from(t.prev[1])], f64::from(z)),
                    );
                }
            }
        }
        let (cur_depth, world_from_cur) = current;
        let cur_from_world = world_from_cur.inverse();
        let predicted: Vec<Option<nalgebra::Point3<f64>>> =
            tracks.iter().map(|t| self.anchors.get(&t.id).map(|x| cur_from_world * x)).collect();
        depth_consistency(&predicted, camera, cur_depth, threshold)
    }

    /// Tracks anchored.
    pub fn len(&self) -> usize {
        self.anchors.len()
    }

    /// Whether no track is anchored.
    pub fn is_empty(&self) -> bool {
        self.anchors.is_empty()
    }
}

/// MG-SLAM: dynamic where the epipolar distance exceeds `threshold` pixels.
pub fn epipolar_fixed(distances: &[f32], threshold: f32) -> Vec<Decision> {
    distances
        .iter()
        .map(|&d| Decision { dynamic: exceeds(d, threshold), reason: LabelReason::Epipolar, score: d })
        .collect()
}

/// YSAG-VINS: the threshold is the mean epipolar distance of the points outside every box
/// (F was estimated from those); points inside a box are dynamic above it, points outside
/// are static. Returns the decisions and the threshold.
pub fn epipolar_adaptive(distances: &[f32], in_box: &[bool]) -> (Vec<Decision>, f32) {
    let outside: Vec<f32> =
        distances.iter().zip(in_box).filter(|(d, b)| !**b && d.is_finite()).map(|(d, _)| *d).collect();
    let threshold = if outside.is_empty() { f32::INFINITY } else { outside.iter().sum::<f32>() / outside.len() as f32 };
    let decisions = distances
        .iter()
        .zip(in_box)
        .map(|(&d, &b)| {
            if b {
                Decision { dynamic: exceeds(d, threshold), reason: LabelReason::Epipolar, score: d }
            } else {
                Decision::keep(LabelReason::Static, d)
            }
        })
        .collect();
    (decisions, threshold)
}

/// DynaSLAM / MG-SLAM masks: dynamic where the point lies on a pixel of a dynamic class.
/// `dynamic_at(x, y)` answers for a pixel.
pub fn mask_rule(points: &[[f32; 2]], dynamic_at: impl Fn(usize, usize) -> bool) -> Vec<Decision> {
    points
        .iter()
        .map(|p| {
            let on = p[0] >= 0.0 && p[1] >= 0.0 && dynamic_at(p[0].round() as usize, p[1].round() as usize);
            if on {
                Decision { dynamic: true, reason: LabelReason::Semantic, score: 1.0 }
            } else {
                Decision::keep(LabelReason::Static, 0.0)
            }
        })
        .collect()
}

/// YG-SLAM's dynamic values per COCO class (as the vendored detectors name them: `tvmonitor`,
/// `diningtable`); unlisted classes are 0 (static).
pub const DEFAULT_DYNAMIC_VALUES: &[(&str, f32)] = &[
    ("person", 1.0),
    ("cup", 0.7),
    ("cell phone", 0.7),
    ("keyboard", 0.7),
    ("mouse", 0.7),
    ("chair", 0.6),
    ("tvmonitor", 0.5),
    ("diningtable", 0.2),
    ("book", 0.1),
];

/// YG-SLAM's semantic prior. A point takes the largest dynamic value m of the boxes holding
/// it: m > 0.8 is dynamic; 0.4 < m <= 0.8 dynamic only on key frames; m <= 0.4 static. A point
/// that also lies in a static object's box (m <= 0.4) is kept: the static object is in front.
pub fn semantic_prior(
    points: &[[f32; 2]],
    boxes: &[LabelledBox],
    value_of: impl Fn(&str) -> f32,
    key_frame: bool,
) -> Vec<Decision> {
    let values: Vec<f32> = boxes.iter().map(|b| value_of(&b.label)).collect();
    points
        .iter()
        .map(|&p| {
            let holding: Vec<f32> =
                boxes.iter().zip(&values).filter(|(b, _)| inside(&b.bbox, p)).map(|(_, v)| *v).collect();
            let m = holding.iter().copied().fold(0.0f32, f32::max);
            let in_static_box = holding.iter().any(|&v| v <= 0.4);
            let dynamic = !in_static_box && (m > 0.8 || (m > 0.4 && key_frame));
            Decision { dynamic, reason: if dynamic { LabelReason::Semantic } else { LabelReason::Static }, score: m }
        })
        .collect()
}

/// One box per instance of an instance mask (`instances`, 0 = none) with its class (from
/// `classes`, 0 = background, skipped), in instance order; instances under `min_pixels` pixels
/// are left out. What `oracle_boxes` reports.
pub fn instance_boxes(instances: &[u16], classes: &[u16], width: usize, min_pixels: u64) -> Vec<([f32; 4], u16)> {
    let w = width.max(1);
    // Per instance: bounding box, pixel count, class.
    let mut found: std::collections::BTreeMap<u16, ([usize; 4], u64, u16)> = std::collections::BTreeMap::new();
    for (i, (&inst, &class)) in instances.iter().zip(classes).enumerate() {
        if inst == 0 || class == 0 {
            continue;
        }
        let (x, y) = (i % w, i / w);
        let e = found.entry(inst).or_insert(([x, y, x, y], 0, class));
        e.0 = [e.0[0].min(x), e.0[1].min(y), e.0[2].max(x), e.0[3].max(y)];
        e.1 += 1;
    }
    found.into_values().filter(|(_, n, _)| *n >= min_pixels).map(|(b, _, class)| (b.map(|v| v as f32), class)).collect()
}

/// Whether each point lies inside any box.
pub fn in_any_box(points: &[[f32; 2]], boxes: &[LabelledBox]) -> Vec<bool> {
    points.iter().map(|&p| boxes.iter().any(|b| inside(&b.bbox, p))).collect()
}

/// Per pixel of a `width x height` depth image: the index + 1 of the box whose object it
/// belongs to, 0 for none. A box's object is its dominant foreground depth: the depths
/// inside it histogrammed in `bin` metre bins, the nearest bin holding at least half as many
/// pixels as the fullest one (a person in front of a wall: the person, not the wall behind);
/// pixels within `tolerance` metres of that depth are the object's. Pixels without depth
/// stay 0. Later boxes overwrite earlier ones where they overlap (callers pass boxes in
/// ascending score, so the best box wins).
pub fn box_depth_mask(
    boxes: &[[f32; 4]],
    depth: &[f32],
    width: usize,
    height: usize,
    bin: f32,
    tolerance: f32,
) -> Vec<u16> {
    let mut mask = vec![0u16; width * height];
    if depth.len() < width * height || bin <= 0.0 || bin.is_nan() {
        return mask;
    }
    for (k, b) in boxes.iter().enumerate() {
        let x0 = (b[0].max(0.0) as usize).min(width);
        let y0 = (b[1].max(0.0) as usize).min(height);
        let x1 = (b[2].max(0.0).ceil() as usize).min(width);
        let y1 = (b[3].max(0.0).ceil() as usize).min(height);
        let mut hist: Vec<u32> = Vec::new();
        for y in y0..y1 {
            for &d in &depth[y * width + x0..y * width + x1] {
                if d > 0.0 && d.is_finite() {
                    let i = (d / bin) as usize;
                    if i < 4096 {
                        if hist.len() <= i {
                            hist.resize(i + 1, 0);
                        }
                        hist[i] += 1;
                    }
                }
            }
        }
        let Some(&top) = hist.iter().max() else { continue };
        if top == 0 {
            continue;
        }
        let Some(front) = hist.iter().position(|&c| 2 * c >= top) else { continue };
        let centre = (front as f32 + 0.5) * bin;
        let id = u16::try_from(k + 1).unwrap_or(u16::MAX);
        for y in y0..y1 {
            for x in x0..x1 {
                let d = depth[y * width + x];
                if d > 0.0 && (d - centre).abs() <= tolerance {
                    mask[y * width + x] = id;
                }
            }
        }
    }
    mask
}

/// How [`combine`] joins two decisions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Combine {
    /// Dynamic if either says so (MG-SLAM's S+G).
    Or,
    /// Dynamic only if both do.
    And,
}

/// Two rules' decisions about one point, `(dynamic, reason, score)` each, `None` where a rule
/// left the point unlabelled (it then counts as static). The combined decision takes the
/// reason and score of the rule that decided: `a`'s when `a` agrees with the result, else
/// `b`'s (falling back to the other's measure when the decider gave none); a static result
/// has reason `Static`.
pub fn combine(a: Option<Decision>, b: Option<Decision>, how: Combine) -> Decision {
    let (da, db) = (a.is_some_and(|l| l.dynamic), b.is_some_and(|l| l.dynamic));
    let dynamic = match how {
        Combine::Or => da || db,
        Combine::And => da && db,
    };
    let decider = if dynamic == da { a.or(b) } else { b.or(a) };
    Decision {
        dynamic,
        reason: if dynamic { decider.map_or(LabelReason::Static, |l| l.reason) } else { LabelReason::Static },
        score: decider.map_or(f32::NAN, |l| l.score),
    }
}

/// Labels scored against a reference (the generator's masks): counts of true and false
/// positives and negatives, "positive" meaning dynamic. For evaluation only; no rule reads it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Confusion {
    /// Labelled dynamic and truly dynamic.
    pub tp: u64,
    /// Labelled dynamic but static.
    pub fp: u64,
    /// Labelled static but dynamic.
    pub fn_: u64,
    /// Labelled static and static.
    pub tn: u64,
}

impl Confusion {
    /// Count one point.
    pub fn add(&mut self, predicted: bool, truth: bool) {
        match (predicted, truth) {
            (true, true) => self.tp += 1,
            (true, false) => self.fp += 1,
            (false, true) => self.fn_ += 1,
            (false, false) => self.tn += 1,
        }
    }

    /// Both counts together.
    pub fn merge(&mut self, other: &Self) {
        self.tp += other.tp;
        self.fp += other.fp;
        self.fn_ += other.fn_;
        self.tn += other.tn;
    }

    /// Of the points labelled dynamic, the share truly dynamic (1 when none is labelled).
    pub fn precision(&self) -> f64 {
        ratio(self.tp, self.tp + self.fp)
    }

    /// Of the truly dynamic points, the share labelled dynamic (1 when there is none).
    pub fn recall(&self) -> f64 {
        ratio(self.tp, self.tp + self.fn_)
    }

    /// Harmonic mean of precision and recall (0 when both are 0).
    pub fn f1(&self) -> f64 {
        let (p, r) = (self.precision(), self.recall());
        if p + r > 0.0 { 2.0 * p * r / (p + r) } else { 0.0 }
    }
}

fn ratio(n: u64, d: u64) -> f64 {
    if d == 0 { 1.0 } else { n as f64 / d as f64 }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every point's pixel in each of `frames` frames of a camera moving by `step` (rotation,
    /// translation) a frame in a room 2-6 m deep; a fifth of the points (a walker) drift 0.6 px
    /// a frame sideways.
    fn frames_of(frames: usize, step: (f64, f64)) -> Vec<Vec<[f32; 2]>> {
        let mut rng = SplitMix64::new(5);
        let points: Vec<nalgebra::Point3<f64>> = (0..400)
            .map(|_| {
                nalgebra::Point3::new(rng.uniform() * 3.0 - 1.5, rng.uniform() * 2.0 - 1.0, 2.0 + 4.0 * rng.uniform())
            })
            .collect();
        let camera = Pinhole::new(525.0, 525.0, 320.0, 240.0);
        (0..frames)
            .map(|f| {
                let k = f as f64;
                let pose = nalgebra::Isometry3::new(
                    nalgebra::Vector3::new(step.1 * k, 0.0, 0.0),
                    nalgebra::Vector3::new(0.0, step.0.to_radians() * k, 0.0),
                );
                let drift = |i: usize| if i.is_multiple_of(5) { 0.6 * k } else { 0.0 };
                let project = |(i, x): (usize, &nalgebra::Point3<f64>)| {
                    let p = camera.project(&(pose * x)).unwrap_or([0.0, 0.0]);
                    [(p[0] + drift(i)) as f32, p[1] as f32]
                };
                points.iter().enumerate().map(project).collect()
            })
            .collect()
    }

    /// The ten-frame epipolar rule (0.4 px) over `frames`, one result per frame pair.
    fn label_frames(frames: &[Vec<[f32; 2]>], long_baseline: LongBaseline, select_model: bool) -> Vec<EpipolarFrame> {
        let options = EpipolarOptions {
            threshold: 0.4,
            ransac: RansacConfig { threshold: 0.4, ..RansacConfig::default() },
            sticky: false,
            fit_static: false,
            baseline: 10,
            long_baseline,
            select_model,
        };
        let ids: Vec<u64> = (0..frames[0].len() as u64).collect();
        let mut cull = EpipolarCull::new(options);
        (1..frames.len()).map(|f| cull.label(&ids, &frames[f - 1], &frames[f], f as u64)).collect()
    }

    #[test]
    fn the_longer_baseline_runs_where_orbslam2_finds_no_parallax() {
        let run = |frames: &[Vec<[f32; 2]>], long_baseline| label_frames(frames, long_baseline, false);
        // A camera that only rotates: no parallax, ORB-SLAM2 would take the homography, so
        // every track tracked ten frames is tested over them, as without the gate.
        let rotating = frames_of(12, (0.3, 0.0));
        let (gated, always) = (run(&rotating, LongBaseline::LowParallax), run(&rotating, LongBaseline::Always));
        let last = gated.last().unwrap();
        assert!(last.homography_ratio.is_some_and(|r| r > HOMOGRAPHY_RATIO), "{:?}", last.homography_ratio);
        assert_eq!(last.long, 400);
        assert!(gated.iter().zip(&always).all(|(g, a)| g.decisions == a.decisions && g.long == a.long));
        // 20 cm sideways a frame: tens of pixels of parallax, F is well posed, and the gated
        // rule keeps to consecutive frames (the ungated one does not).
        let wide = frames_of(12, (0.0, 0.2));
        let (gated, always) = (run(&wide, LongBaseline::LowParallax), run(&wide, LongBaseline::Always));
        let last = gated.last().unwrap();
        assert!(last.homography_ratio.is_some_and(|r| r < HOMOGRAPHY_RATIO), "{:?}", last.homography_ratio);
        assert_eq!((last.long, always.last().unwrap().long), (0, 400));
    }

    #[test]
    fn model_selection_tests_a_rotation_against_its_homography() {
        let last = |frames: &[Vec<[f32; 2]>], select_model| {
            label_frames(frames, LongBaseline::Always, select_model).pop().unwrap()
        };
        // A rotating camera: the ten-frame pair is a homography (R_H > 0.40), so the walkers
        // (every fifth point, 6 px off over ten frames) are judged by their transfer error,
        // which no epipole can explain away: every one flagged, no static point.
        let rotating = frames_of(12, (0.3, 0.0));
        let f = last(&rotating, true);
        assert!(f.long_homography && f.long_homography_ratio.is_some_and(|r| r > HOMOGRAPHY_RATIO));
        let flagged: Vec<bool> = f.decisions.iter().map(|d| d.dynamic).collect();
        assert!(flagged.iter().enumerate().all(|(i, d)| *d == i.is_multiple_of(5)), "{flagged:?}");
        // 20 cm a frame: parallax, F is selected and the decisions are the epipolar test's.
        let wide = frames_of(12, (0.0, 0.2));
        let (selected, plain) = (last(&wide, true), last(&wide, false));
        assert!(!selected.long_homography && selected.long_homography_ratio.is_some_and(|r| r < HOMOGRAPHY_RATIO));
        assert_eq!(selected.decisions, plain.decisions);
    }

    #[test]
    fn the_history_gives_a_tracks_pixel_k_frames_back_while_it_is_tracked() {
        let mut h = TrackHistory::new(2);
        h.update(&[1], &[[0.0, 0.0]], &[[1.0, 0.0]]);
        assert_eq!(h.back(1), None, "one frame of history for k = 2");
        h.update(&[1, 2], &[[1.0, 0.0], [5.0, 5.0]], &[[2.0, 0.0], [6.0, 5.0]]);
        assert_eq!(h.back(1), Some([0.0, 0.0]));
        assert_eq!(h.back(2), None);
        h.update(&[1, 2], &[[2.0, 0.0], [6.0, 5.0]], &[[3.0, 0.0], [7.0, 5.0]]);
        assert_eq!(h.back(1), Some([1.0, 0.0]));
        assert_eq!(h.back(2), Some([5.0, 5.0]));
        h.update(&[2], &[[7.0, 5.0]], &[[8.0, 5.0]]);
        assert_eq!(h.back(1), None, "a track that ended is forgotten");
    }

    #[test]
    fn a_dynamic_track_stays_dynamic_while_tracked_and_is_forgotten_when_it_ends() {
        let d = |dynamic: bool| Decision { dynamic, reason: LabelReason::Epipolar, score: 0.0 };
        let mut sticky = StickyLabels::default();
        // Frame 1: track 7 is dynamic, 8 static.
        let mut f1 = vec![d(true), d(false)];
        sticky.apply(&[7, 8], &mut f1);
        assert!(sticky.was_dynamic(7) && !sticky.was_dynamic(8));
        // Frame 2: 7 under the threshold (moving along its epipolar line) stays dynamic; 8 too.
        let mut f2 = vec![d(false), d(false), d(false)];
        sticky.apply(&[7, 8, 9], &mut f2);
        assert_eq!(f2.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false]);
        // Frame 3: track 7 is lost; frame 4: a new track with another id is not dynamic.
        let mut f3 = vec![d(false)];
        sticky.apply(&[8], &mut f3);
        assert!(!sticky.was_dynamic(7));
        // `remember` records without changing decisions.
        let f4 = vec![d(true)];
        sticky.remember(&[11], &f4);
        let mut f5 = vec![d(false)];
        sticky.apply(&[11], &mut f5);
        assert!(f5[0].dynamic);
    }

    #[test]
    fn combine_labels_decision_table() {
        let s = |score| Some(Decision { dynamic: false, reason: LabelReason::Static, score });
        let sem = Some(Decision { dynamic: true, reason: LabelReason::Semantic, score: 1.0 });
        let epi = Some(Decision { dynamic: true, reason: LabelReason::Epipolar, score: 0.9 });
        // (a, b, mode) -> (dynamic, reason, score): every combination of static, dynamic and
        // unlabelled on both sides, for both modes.
        let table = [
            (s(0.1), s(0.2), Combine::Or, false, LabelReason::Static, 0.1),
            (sem, s(0.2), Combine::Or, true, LabelReason::Semantic, 1.0),
            (s(0.1), epi, Combine::Or, true, LabelReason::Epipolar, 0.9),
            (sem, epi, Combine::Or, true, LabelReason::Semantic, 1.0),
            (None, epi, Combine::Or, true, LabelReason::Epipolar, 0.9),
            (sem, None, Combine::Or, true, LabelReason::Semantic, 1.0),
            (None, s(0.2), Combine::Or, false, LabelReason::Static, 0.2),
            (s(0.1), s(0.2), Combine::And, false, LabelReason::Static, 0.1),
            (sem, s(0.2), Combine::And, false, LabelReason::Static, 0.2),
            (s(0.1), epi, Combine::And, false, LabelReason::Static, 0.1),
            (sem, epi, Combine::And, true, LabelReason::Semantic, 1.0),
            (None, epi, Combine::And, false, LabelReason::Static, 0.9),
            (sem, None, Combine::And, false, LabelReason::Static, 1.0),
        ];
        for (k, (a, b, how, dynamic, reason, score)) in table.into_iter().enumerate() {
            let d = combine(a, b, how);
            assert_eq!((d.dynamic, d.reason, d.score), (dynamic, reason, score), "row {k}: {a:?} {how:?} {b:?}");
        }
        assert!(combine(None, None, Combine::Or).score.is_nan() && !combine(None, None, Combine::Or).dynamic);
    }

    #[test]
    fn fixed_and_adaptive_epipolar_rules() {
        let d = [0.1, 0.5, 3.0, f32::NAN];
        let fixed = epipolar_fixed(&d, 0.4);
        assert_eq!(fixed.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, true, true, true]);
        // Outside boxes: 0.1 and 0.5 -> threshold 0.3; inside: 3.0 dynamic, NaN dynamic.
        let (adaptive, thr) = epipolar_adaptive(&d, &[false, false, true, true]);
        assert!((thr - 0.3).abs() < 1e-6);
        assert_eq!(adaptive.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, false, true, true]);
        assert_eq!(adaptive[0].reason, LabelReason::Static);
    }

    #[test]
    fn semantic_prior_follows_yg_slam() {
        let boxes = vec![
            LabelledBox { bbox: [0.0, 0.0, 10.0, 10.0], label: "person".into() },
            LabelledBox { bbox: [20.0, 0.0, 30.0, 10.0], label: "chair".into() },
            LabelledBox { bbox: [5.0, 5.0, 8.0, 8.0], label: "book".into() },
        ];
        let value = |l: &str| DEFAULT_DYNAMIC_VALUES.iter().find(|(n, _)| *n == l).map_or(0.0, |(_, v)| *v);
        let pts = [[2.0, 2.0], [25.0, 5.0], [6.0, 6.0], [50.0, 50.0]];
        let normal = semantic_prior(&pts, &boxes, value, false);
        assert_eq!(normal.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false, false]);
        let key = semantic_prior(&pts, &boxes, value, true);
        // The chair (0.6) counts on key frames; the point on the book inside the person is kept.
        assert_eq!(key.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, true, false, false]);
    }

    #[test]
    fn depth_consistency_flags_points_whose_depth_does_not_follow_the_camera() {
        let cam = Pinhole::new(500.0, 500.0, 320.0, 240.0);
        // The camera moved 0.1 m forward since the key frame: static points came 0.1 m closer.
        let cur_from_key = nalgebra::Isometry3::translation(0.0, 0.0, -0.1);
        let pts = [[320.0, 240.0], [100.0, 100.0], [200.0, 300.0], [50.0, 50.0]];
        let predicted: Vec<Option<nalgebra::Point3<f64>>> =
            pts.iter().enumerate().map(|(i, p)| (i != 3).then(|| cur_from_key * cam.unproject(*p, 2.0))).collect();
        // Moving straight forward keeps the centre pixel and pulls the others outwards: the
        // second point now projects near (88, 93), where something 0.5 m nearer is seen (it
        // moved); the third near (194, 303), with no measurement; the fourth had no key depth.
        let depth_cur = |x: f32, y: f32| {
            if (x - 320.0).abs() < 0.5 && (y - 240.0).abs() < 0.5 {
                1.9
            } else if x < 150.0 && y < 150.0 {
                1.4
            } else {
                0.0
            }
        };
        let d = depth_consistency(&predicted, cam, depth_cur, 0.1);
        assert_eq!(d.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![false, true, false, false]);
        assert!(d[0].score < 1e-5 && (d[1].score - 0.5).abs() < 1e-5 && d[2].score.is_nan());
        assert_eq!(d[1].reason, LabelReason::Depth);
    }

    #[test]
    fn mask_rule_uses_the_point_position() {
        let d = mask_rule(&[[1.0, 1.0], [5.0, 5.0], [-3.0, 2.0]], |x, y| x < 3 && y < 3);
        assert_eq!(d.iter().map(|x| x.dynamic).collect::<Vec<_>>(), vec![true, false, false]);
    }

    #[test]
    fn depth_anchors_keep_a_static_point_and_flag_one_that_moved() {
        // A camera 2 m in front of a wall moves 0.1 m sideways; track 1 sits on the wall,
        // track 2 on a person 1 m away who walks with the camera (same pixel, same depth).
        let camera = Pinhole::new(500.0, 500.0, 320.0, 240.0);
        let wall = |_: f32, _: f32| 2.0f32;
        let person = |x: f32, _: f32| if (x - 320.0).abs() < 1.0 { 1.0f32 } else { 2.0 };
        let world_from_prev = nalgebra::Isometry3::identity();
        let world_from_cur = nalgebra::Isometry3::translation(0.1, 0.0, 0.0);
        // The wall point shifts by fx * 0.1 / 2 = 25 px; the person stays at the centre.
        let tracks = [
            TrackedPoint { id: 1, prev: [300.0, 240.0], cur: [275.0, 240.0] },
            TrackedPoint { id: 2, prev: [320.0, 240.0], cur: [320.0, 240.0] },
        ];
        let mut anchors = DepthAnchors::new();
        // First frame: nothing anchored yet, nothing judged.
        let first = anchors.label(&tracks, camera, None::<(fn(f32, f32) -> f32, _)>, (person, world_from_prev), 0.1);
        assert!(first.iter().all(|d| !d.dynamic && d.score.is_nan()) && anchors.is_empty());
        let second = anchors.label(&tracks, camera, Some((person, world_from_prev)), (person, world_from_cur), 0.1);
        assert_eq!(anchors.len(), 2);
        assert!(!second[0].dynamic && second[0].score < 1e-3, "{:?}", second[0]);
        // The person's anchor (1 m ahead at x = 0) is seen at x = -0.1 m, 50 px left of the
        // centre, where the wall (2 m) is measured: 1 m off, dynamic.
        assert!(second[1].dynamic && (second[1].score - 1.0).abs() < 1e-3, "{:?}", second[1]);
        // A track that ends is forgotten.
        let _ = anchors.label(&tracks[..1], camera, Some((wall, world_from_cur)), (wall, world_from_cur), 0.1);
        assert_eq!(anchors.len(), 1);
    }
}
