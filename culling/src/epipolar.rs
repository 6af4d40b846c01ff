//! The epipolar rules (MG-SLAM's fixed threshold, YSAG-VINS's adaptive one) and the
//! multi-frame long-baseline epipolar cull with its sticky labels and track history.

use super::*;

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

    /// A new distance above which a point is dynamic, from the next frame on (a parameter
    /// tuned while running; the rest of the state carries on).
    pub fn set_threshold(&mut self, threshold: f32) {
        self.options.threshold = threshold;
    }

    /// Label this frame's tracks (`ids`, previous and current pixels).
    pub fn label(&mut self, ids: &[u64], prev: &[[f32; 2]], cur: &[[f32; 2]], seed: u64) -> EpipolarFrame {
        let o = &self.options;
        let mut fit_on: Vec<bool> = ids.iter().map(|&id| !(o.fit_static && self.sticky.was_dynamic(id))).collect();
        if fit_on.iter().filter(|u| **u).count() < 8 {
            fit_on = vec![true; ids.len()];
        }
        // One stream per call site: the consecutive pair's F draws from the frame's seed, every
        // other fit from a stream derived from it by name.
        let stream = |name: &str| SplitMix64::named(seed, name).next_u64();
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
                        .and_then(|(fit, _)| {
                            homography_if_selected(prev, cur, &fit_on, fit, stream("epipolar/consecutive/homography"))
                        })
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
                if let Some((fit_f, d)) = epipolar_distances(&back, &now, &fit, &ransac, stream("epipolar/long")) {
                    let mut tested = epipolar_fixed(&d, threshold);
                    if o.select_model {
                        let selected =
                            homography_if_selected(&back, &now, &fit, &fit_f, stream("epipolar/long/homography"));
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
    let config = RansacConfig { threshold: CHI2_2DOF.sqrt(), local_optimisation: false, ..RansacConfig::default() };
    let h = fit_homography_prosac(&p1, &p2, &quality, &config, &mut SplitMix64::new(seed))?;
    let ratio = homography_ratio(&h.h, &f.f, &p1, &p2);
    Some((ratio, (ratio > HOMOGRAPHY_RATIO).then_some(h.h)))
}
