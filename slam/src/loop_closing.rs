//! ORB-SLAM2's third thread, loop closing: SE(3) for maps with depth (RGB-D, stereo), Sim(3)
//! for a single camera's, whose scale drifts.
//! Why one file of this size: it mirrors one ORB-SLAM2 class (`LoopClosing`), step for step.
//!
//! Key frames arrive after local mapping with all their keypoints (descriptor, depth and the
//! map point each observes) and the refined local window. [`LoopCloser::insert`] keeps the
//! whole map (every key frame, point and observation, the covisibility graph and ORB-SLAM2's
//! spanning tree), and for each key frame:
//!
//! 1. **Detection** (`LoopClosing::DetectLoop`): its bag of words against the key-frame
//!    database, candidates scoring above the lowest score of its covisible key frames and not
//!    connected to it, accepted when consistent over three consecutive key frames; none within
//!    [`LoopConfig::min_keyframes_between`] key frames of the map's start or the last loop.
//! 2. **Geometry** (`ComputeSim3`): BoW-guided matches between the key frame and the
//!    candidate (`SearchByBoW`: same vocabulary node, Hamming <= 50, ratio 0.75), RANSAC on
//!    their 3-D points (Horn/Umeyama on three, inliers by reprojection in both images at chi2
//!    9.21 sigma^2, ORB-SLAM2's `Sim3Solver`; the scale fixed with depth, free for a single
//!    camera), then the candidate's and its covisible key frames' points projected into the
//!    key frame (`SearchByProjection`) and the pose refined on all of them (motion-only BA;
//!    ORB-SLAM2 refines the similarity with `OptimizeSim3` and searches again with it: here the
//!    scale stays RANSAC's, refitted on its inliers); accepted with at least 40 matches.
//! 3. **Correction** (`CorrectLoop`): the key frame and its covisible key frames moved by the
//!    loop's correction (a similarity: a single camera's points are rescaled), their points
//!    with them; the loop side's points fused into them
//!    (`SearchAndFuse`: a keypoint's duplicate point is replaced by the loop's); the essential
//!    graph (spanning tree, covisibility edges of weight >= 100, loop edges) optimised with the
//!    loop key frame fixed ([`crate::pose_graph`], in Sim(3) for a single camera); every point
//!    moved with its reference key frame's similarity; each key frame keeps the rotation and
//!    centre (ORB-SLAM2's `[R | t/s]`).
//! 4. **Global bundle adjustment** (`RunGlobalBundleAdjustment`): every key frame and every
//!    point seen twice, 10 iterations, the first key frame fixed; run in place (ORB-SLAM2 runs
//!    it in a thread and drops it for a new loop; in lockstep the next key frame waits).
//!
//! The result is the whole corrected map ([`LoopCloser::correction`]), which tracking and local
//! mapping apply (the `loop_close` node sends it over the graph's feedback edges).
//!
//! **The atlas** (ORB-SLAM3's `Atlas`, `MergeLocal`). When tracking is lost for good a new map
//! starts; the old one is kept, not forgotten. Each key frame of the current map is also
//! checked against the older maps' databases (candidates above the same score, consistent over
//! three key frames, the same geometric check). A place found in an older map merges the two:
//! the current map moves by the transform found (a similarity for a single camera) into the
//! older map's frame, takes in its key frames, points and words, and the revisit is corrected
//! as a loop (fusion, the essential graph with the older side's key frame fixed, global BA with
//! the older map's first key frame fixed), so the trajectory ends in one frame, the first
//! map's. ORB-SLAM3 optimises a welding window around the two key frames first; here the loop
//! correction's fusion and global BA play that part.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{Estimator, PoseObservation, RansacConfig, Sampler, SplitMix64, optimize_pose, ransac};
use nalgebra::{Isometry3, Point3, Unit, UnitQuaternion, Vector3};

use crate::ba::{BaObservation, BaPose, BaReport, bundle_adjust};
use crate::bow::{BowVector, Vocabulary, score};
use crate::eval::umeyama;
use crate::keyframe_db::LoopConsistency;
use crate::keyframe_map::KeyFrameMap;
use crate::map::{MapKeyFrame, MapKeypoint, MapObservation, SparseMap, sigma};
use crate::pose_graph::{Edge, PoseEdge, optimise, optimise_4dof, optimise_sim3};
use crate::sim3::Sim3;

/// Loop-closing settings (ORB-SLAM2's values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopConfig {
    /// No loop is looked for within this many key frames of the map's start or the last loop
    /// (ORB-SLAM2: 10).
    pub min_keyframes_between: usize,
    /// Shared points of a covisibility edge in the essential graph (ORB-SLAM2: 100).
    pub essential_min: usize,
    /// BoW matches a candidate needs for RANSAC (ORB-SLAM2: 20), and RANSAC inliers (20).
    pub min_bow_matches: usize,
    /// RANSAC inliers a loop needs (ORB-SLAM2: 20).
    pub min_inliers: usize,
    /// RANSAC iterations (ORB-SLAM2's `Sim3Solver`: 300).
    pub ransac_iterations: usize,
    /// Matches after the projection search that accept a loop (ORB-SLAM2: 40).
    pub min_total_matches: usize,
    /// `fx` times the (virtual) baseline, for the depth term of the pose refinement.
    pub bf: f64,
    /// ORB pyramid scale factor.
    pub scale_factor: f64,
    /// Essential-graph iterations (ORB-SLAM2: 20).
    pub pose_graph_iterations: usize,
    /// Global bundle adjustment iterations after a loop (ORB-SLAM2: 10; 0: none).
    pub global_ba_iterations: usize,
    /// Image width, pixels.
    pub width: f64,
    /// Image height, pixels.
    pub height: f64,
}

impl LoopConfig {
    /// ORB-SLAM2's settings for a camera of `width` x `height` pixels with `bf`.
    pub fn new(bf: f64, width: f64, height: f64) -> Self {
        Self {
            min_keyframes_between: 10,
            essential_min: 100,
            min_bow_matches: 20,
            min_inliers: 20,
            ransac_iterations: 300,
            min_total_matches: 40,
            bf,
            scale_factor: 1.2,
            pose_graph_iterations: 20,
            global_ba_iterations: 10,
            width,
            height,
        }
    }
}

/// ORB-SLAM2's `Sim3Solver` inlier bound (chi2, 2 DOF, 99 %).
const CHI2_RANSAC: f64 = 9.21;
/// Projection search radii, pixels at level 0 (ORB-SLAM2: 10 for the loop's points, 4 for fusion).
const PROJECTION_RADIUS: f64 = 10.0;
const FUSION_RADIUS: f64 = 4.0;

/// A closed loop.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopClosure {
    /// The key frame that closed it.
    pub current: u64,
    /// The key frame it revisits.
    pub loop_keyframe: u64,
    /// The current key frame's stamp, seconds.
    pub current_stamp: f64,
    /// The revisited key frame's stamp, seconds.
    pub loop_stamp: f64,
    /// BoW matches.
    pub bow_matches: usize,
    /// RANSAC inliers.
    pub inliers: usize,
    /// Matches after the projection search.
    pub matches: usize,
    /// `loop_from_current` as estimated (the rigid part).
    pub loop_from_current: Isometry3<f64>,
    /// A merge: the older map the revisited key frame belonged to (its number), taken into
    /// the current one; `None` for a loop within the map.
    pub merged_map: Option<u32>,
    /// The current key frame's map units in the loop key frame's: 1 with depth; a single
    /// camera's scale drift along the loop (ORB-SLAM2's Sim(3) scale `s`).
    pub scale: f64,
    /// Translation (metres) the loop moved the current key frame by: the drift.
    pub correction_m: f64,
    /// Rotation (degrees) it moved it by.
    pub correction_deg: f64,
    /// Points fused (duplicates replaced by the loop side's).
    pub fused: usize,
    /// Key frames of the essential graph.
    pub keyframes: usize,
    /// Its edges.
    pub edges: usize,
    /// Its cost before the optimisation.
    pub cost_before: f64,
    /// And after.
    pub cost_after: f64,
    /// The global bundle adjustment after the loop (costs, iterations).
    pub global_ba: BaReport,
    /// Its wall time, milliseconds (for reports only: never in a message).
    pub global_ba_ms: f64,
}

/// Loop-closing state: the whole map and the loops found.
#[derive(Debug)]
pub struct LoopCloser {
    config: LoopConfig,
    map: KeyFrameMap,
    consistency: LoopConsistency,
    /// Key frames since the map's start or the last loop.
    since_loop: usize,
    rng: SplitMix64,
    /// Observations added and points removed by the last loop's fusion.
    fused_observations: Vec<MapObservation>,
    fused_removed: Vec<u64>,
    loops: Vec<LoopClosure>,
    /// Candidates accepted by the consistency check whose geometry failed, by [`Rejection`].
    rejected: [usize; 5],
    /// Older maps (tracking lost for good), oldest first, until a merge takes them in.
    atlas: Vec<KeyFrameMap>,
    /// Whether to look for the current map's places in the older ones.
    merge: bool,
    merge_consistency: LoopConsistency,
    /// The world's up axis where the map's gravity is known (a visual-inertial map): loops
    /// then correct yaw and position only ([`LoopCloser::set_up`]).
    up: Option<Unit<Vector3<f64>>>,
}

/// Why a consistent candidate's geometry was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rejection {
    /// Fewer than 20 BoW matches with points in both key frames.
    BowMatches,
    /// Fewer than 20 RANSAC inliers.
    RansacInliers,
    /// Fewer than 40 matches after projecting the loop side's points.
    ProjectionMatches,
    /// Fewer than 40 inliers after refining the pose on them.
    RefinedMatches,
    /// A visual-inertial map's loop would turn gravity ([`LOOP_MAX_TILT`]).
    Tilt,
}

/// The largest turn of gravity's direction (roll and pitch, radians) a visual-inertial map's
/// loop correction may carry: ORB-SLAM3's `LoopClosing` refuses a loop whose correction has
/// 0.008 rad or more about either horizontal axis ("BAD LOOP"); here on the two together.
pub const LOOP_MAX_TILT: f64 = 0.008;

impl Rejection {
    /// Names, in order, for reports.
    pub const NAMES: [&'static str; 5] =
        ["bow_matches", "ransac_inliers", "projection_matches", "refined_matches", "tilt"];
}

impl LoopCloser {
    /// An empty map; `seed` drives RANSAC.
    pub fn new(config: LoopConfig, cam: Pinhole, vocabulary: Arc<Vocabulary>, seed: u64) -> Self {
        Self {
            map: KeyFrameMap::new(cam, config.width, config.height, config.scale_factor, vocabulary),
            config,
            consistency: LoopConsistency::new(),
            since_loop: 0,
            rng: SplitMix64::named(seed, "loop_closing/se3"),
            fused_observations: Vec::new(),
            fused_removed: Vec::new(),
            loops: Vec::new(),
            rejected: [0; 5],
            atlas: Vec::new(),
            merge: true,
            merge_consistency: LoopConsistency::new(),
            up: None,
        }
    }

    /// The world's up axis of a visual-inertial map (against gravity, in the first key frame's
    /// frame), once its IMU is initialised: its roll and pitch are observable, so a loop then
    /// corrects yaw and position only (ORB-SLAM3, VINS-Fusion): the correction's tilt is taken
    /// out (a loop with more than [`LOOP_MAX_TILT`] is refused) and the essential graph is
    /// [`optimise_4dof`]. `None`: a visual map (SE(3), or Sim(3) for a single camera).
    pub fn set_up(&mut self, up: Option<Unit<Vector3<f64>>>) {
        self.up = up;
    }

    /// Whether a new map's places are looked for in the older maps and merged (default on;
    /// off, each map after a loss stays in its own frame).
    #[must_use]
    pub fn with_merging(mut self, merge: bool) -> Self {
        self.merge = merge;
        self
    }

    /// Maps held: the current one and the older ones not merged.
    pub fn maps(&self) -> usize {
        1 + self.atlas.len()
    }

    /// Key frames held.
    pub fn keyframes(&self) -> usize {
        self.map.kfs.len()
    }

    /// Points held.
    pub fn points(&self) -> usize {
        self.map.points.len()
    }

    /// Bytes per component of the whole map it keeps, older maps included ([`crate::memory`]).
    pub fn memory(&self) -> crate::memory::MapMemory {
        self.atlas.iter().fold(self.map.memory(), |m, a| m + a.memory())
    }

    /// Every loop closed so far.
    pub fn loops(&self) -> &[LoopClosure] {
        &self.loops
    }

    /// Consistent candidates whose geometric check failed, by [`Rejection`] (in its order).
    pub fn rejected(&self) -> [usize; 5] {
        self.rejected
    }

    /// Every key frame's pose.
    pub fn keyframe_poses(&self) -> impl Iterator<Item = &MapKeyFrame> {
        self.map.kfs.values().map(|k| &k.info)
    }

    /// Take local mapping's update: the refined window (poses, points, removed points) and the
    /// new key frame's keypoints (`update.keypoints`). Returns the loop it closed, if any.
    pub fn insert(&mut self, update: &SparseMap) -> Option<LoopClosure> {
        if update.map_id != self.map.map_id {
            // A new map (tracking was lost for good): the old one goes to the atlas.
            let old = self.map.start_map(update.map_id);
            if !old.kfs.is_empty() {
                self.atlas.push(old);
            }
            self.consistency = LoopConsistency::new();
            self.merge_consistency = LoopConsistency::new();
            self.since_loop = 0;
        }
        self.map.apply_refinements(update);
        let added = self.map.add_keyframe(update);
        self.map.cull_keyframes(update);
        let (id, bow) = added?;
        self.since_loop += 1;
        let closed = self.detect(id, &bow);
        self.map.db.add(id, bow);
        closed
    }

    fn detect(&mut self, kf: u64, bow: &BowVector) -> Option<LoopClosure> {
        if self.since_loop <= self.config.min_keyframes_between {
            return None;
        }
        let connected_list = self.map.covisible(kf);
        let min_score = connected_list
            .iter()
            .filter_map(|c| self.map.kfs.get(c).map(|k| score(bow, &k.bow)))
            .fold(f64::INFINITY, f64::min);
        let min_score = if min_score.is_finite() { min_score } else { 0.0 };
        let connected: BTreeSet<u64> = connected_list.into_iter().collect();
        let covis = |k: u64| self.map.covisible(k);
        let candidates = self.map.db.loop_candidates(kf, bow, &connected, min_score, &covis);
        let groups: Vec<(u64, BTreeSet<u64>)> = candidates
            .iter()
            .map(|&(c, _)| {
                let mut g: BTreeSet<u64> = self.map.covisible(c).into_iter().collect();
                g.insert(c);
                (c, g)
            })
            .collect();
        let accepted = self.consistency.update(&groups);
        for candidate in accepted {
            match self.compute_se3(kf, candidate, None).and_then(|found| self.upright(kf, found)) {
                Ok(found) => return Some(self.correct(kf, candidate, &found)),
                Err(why) => self.rejected[why as usize] += 1,
            }
        }
        self.detect_merge(kf, bow, min_score)
    }

    /// ORB-SLAM3's merge detection: the key frame's words against each older map's database,
    /// with the loop's score bound and consistency; the first candidate whose geometry holds
    /// merges its map into the current one.
    fn detect_merge(&mut self, kf: u64, bow: &BowVector, min_score: f64) -> Option<LoopClosure> {
        if !self.merge || self.atlas.is_empty() {
            return None;
        }
        let mut groups: Vec<(u64, BTreeSet<u64>)> = Vec::new();
        let mut home: BTreeMap<u64, usize> = BTreeMap::new();
        for (i, m) in self.atlas.iter().enumerate() {
            let covis = |k: u64| m.covisible(k);
            for (c, _) in m.db.loop_candidates(kf, bow, &BTreeSet::new(), min_score, &covis) {
                let mut g: BTreeSet<u64> = m.covisible(c).into_iter().collect();
                g.insert(c);
                groups.push((c, g));
                home.insert(c, i);
            }
        }
        let accepted = self.merge_consistency.update(&groups);
        for candidate in accepted {
            let Some(&i) = home.get(&candidate) else { continue };
            match self.compute_se3(kf, candidate, Some(i)) {
                Ok(found) => return Some(self.merge(kf, candidate, i, found)),
                Err(why) => self.rejected[why as usize] += 1,
            }
        }
        None
    }

    /// Merge older map `i` into the current one at the revisit `current` -> `candidate`: the
    /// current map moved into the older map's frame, the older map taken in, then the revisit
    /// corrected as a loop.
    fn merge(&mut self, current: u64, candidate: u64, i: usize, found: Found) -> LoopClosure {
        let old_cur =
            self.map.kfs.get(&current).map_or(Sim3::identity(), |k| Sim3::from_isometry(&k.info.world_from_cam));
        let new_cur = Sim3 { scale: found.scale, ..Sim3::from_isometry(&found.world_from_cur) };
        let correction_m = (new_cur.translation - old_cur.translation).norm();
        let correction_deg = (new_cur.rotation * old_cur.rotation.inverse()).angle().to_degrees();
        self.map.move_by(&(new_cur * old_cur.inverse()));
        let older = self.atlas.remove(i);
        let merged_map = older.map_id;
        self.map.absorb(older);
        self.merge_consistency = LoopConsistency::new();
        // The scale went into the move: the loop correction itself is rigid.
        let scale = found.scale;
        let mut closure = self.correct(current, candidate, &Found { scale: 1.0, ..found });
        closure.merged_map = Some(merged_map);
        closure.scale = scale;
        closure.correction_m = correction_m;
        closure.correction_deg = correction_deg;
        if let Some(last) = self.loops.last_mut() {
            *last = closure.clone();
        }
        closure
    }

    fn reprojects(&self, pose: &Sim3, x: &Point3<f64>, kp: &MapKeypoint) -> bool {
        let Some(uv) = self.map.cam.project(&pose.transform_point(x)) else { return false };
        let s = sigma(self.config.scale_factor, kp.octave);
        let (du, dv) = (uv[0] - kp.uv[0], uv[1] - kp.uv[1]);
        du * du + dv * dv <= CHI2_RANSAC * s * s
    }

    /// The current key frame's corrected pose with the matches that support it, or why the
    /// candidate was refused.
    /// `older`: the candidate is of that map of the atlas (a merge), not of the current one.
    fn compute_se3(&mut self, current: u64, candidate: u64, older: Option<usize>) -> Result<Found, Rejection> {
        let loop_map = older.and_then(|i| self.atlas.get(i)).unwrap_or(&self.map);
        let (Some(a), Some(b)) = (self.map.kfs.get(&current), loop_map.kfs.get(&candidate)) else {
            return Err(Rejection::BowMatches);
        };
        let matches = self.map.search_by_bow(a, b);
        if matches.len() < self.config.min_bow_matches {
            return Err(Rejection::BowMatches);
        }
        // 3-D points in each camera.
        let pairs: Vec<(Point3<f64>, Point3<f64>, usize, usize)> = matches
            .iter()
            .filter_map(|&(i, j)| {
                Some((self.map.point_in(a, &a.keypoints[i])?, loop_map.point_in(b, &b.keypoints[j])?, i, j))
            })
            .collect();
        if pairs.len() < self.config.min_bow_matches {
            return Err(Rejection::BowMatches);
        }
        // The transform between the two key frames' 3-D points by RANSAC (ORB-SLAM2's
        // Sim3Solver: 3-point samples, both-way reprojection within the chi-square bound), with
        // the scale fixed where depth gives it (RGB-D, stereo) and free for a single camera.
        let monocular = self.monocular(a);
        let estimator = Sim3Estimator {
            pairs: &pairs,
            with_scale: monocular,
            agrees: |(t, inv): &(Sim3, Sim3), k: usize| {
                let (xa, xb, i, j) = &pairs[k];
                self.reprojects(t, xa, &b.keypoints[*j]) && self.reprojects(inv, xb, &a.keypoints[*i])
            },
        };
        let config = RansacConfig {
            threshold: 1.0,
            confidence: 0.99,
            max_iterations: self.config.ransac_iterations,
            local_optimisation: false,
        };
        let mut rng = self.rng.clone();
        let consensus = ransac(&estimator, &config, Sampler::Uniform, &mut rng);
        self.rng = rng;
        let Some(consensus) = consensus.filter(|c| c.count >= self.config.min_inliers) else {
            return Err(Rejection::RansacInliers);
        };
        let (cand_from_cur, count) = (consensus.model.0, consensus.count);
        // The loop side's points (the candidate and its covisible key frames) projected into
        // the current key frame at the estimated pose; the pose refined on every match (the
        // scale between the two sides' maps stays the solver's: a single camera's projections
        // do not see it).
        let world_from_cur = b.info.world_from_cam * cand_from_cur.rigid();
        let mut group: Vec<u64> = vec![candidate];
        group.extend(loop_map.covisible(candidate));
        let loop_points = loop_map.points_of(&group);
        let found = loop_map.search_by_projection(&a.keypoints, &world_from_cur, &loop_points, PROJECTION_RADIUS);
        if found.len() < self.config.min_total_matches {
            return Err(Rejection::ProjectionMatches);
        }
        let obs: Vec<PoseObservation> = found
            .iter()
            .filter_map(|&(i, p)| {
                let kp = &a.keypoints[i];
                Some(PoseObservation {
                    point: loop_map.points.get(&p)?.position,
                    uv: kp.uv,
                    sigma: sigma(self.config.scale_factor, kp.octave),
                    depth: kp.depth,
                })
            })
            .collect();
        let refined = optimize_pose(&obs, &self.map.cam, self.config.bf, &world_from_cur.inverse(), None);
        let good: Vec<(usize, u64)> =
            found.iter().zip(&refined.inliers).filter(|(_, ok)| **ok).map(|(m, _)| *m).collect();
        if good.len() < self.config.min_total_matches {
            return Err(Rejection::RefinedMatches);
        }
        Ok(Found {
            world_from_cur: refined.cam_from_world.inverse(),
            scale: cand_from_cur.scale,
            bow_matches: matches.len(),
            inliers: count,
            matches: good,
            group,
            upright: false,
        })
    }

    /// A visual-inertial map's loop (the up axis known, depth giving scale): the correction of
    /// the current key frame's pose without its tilt, so that gravity stays where the IMU put it
    /// (ORB-SLAM3 zeroes the correction's roll and pitch); refused beyond [`LOOP_MAX_TILT`].
    fn upright(&self, current: u64, mut found: Found) -> Result<Found, Rejection> {
        let (Some(up), Some(kf)) = (self.up, self.map.kfs.get(&current)) else { return Ok(found) };
        if self.monocular(kf) {
            return Ok(found);
        }
        let old = kf.info.world_from_cam.rotation;
        let phi = (found.world_from_cur.rotation * old.inverse()).scaled_axis();
        let yaw = phi.dot(&up);
        if (phi - up.into_inner() * yaw).norm() > LOOP_MAX_TILT {
            return Err(Rejection::Tilt);
        }
        found.world_from_cur.rotation = UnitQuaternion::from_axis_angle(&up, yaw) * old;
        found.upright = true;
        Ok(found)
    }

    /// A single camera's key frame: none of its keypoints has a depth.
    fn monocular(&self, kf: &crate::keyframe_map::PlaceKeyFrame) -> bool {
        !kf.keypoints.iter().any(|k| k.depth.is_some())
    }

    fn correct(&mut self, current: u64, candidate: u64, found: &Found) -> LoopClosure {
        let old: BTreeMap<u64, Sim3> =
            self.map.kfs.iter().map(|(&k, kf)| (k, Sim3::from_isometry(&kf.info.world_from_cam))).collect();
        let monocular = self.map.kfs.get(&current).is_some_and(|k| self.monocular(k));
        // The current key frame's corrected pose, as a similarity from its camera (in its
        // map's units) to the world (the loop side's units).
        let old_cur = old[&current];
        let new_cur = Sim3 { scale: found.scale, ..Sim3::from_isometry(&found.world_from_cur) };
        let delta = new_cur * old_cur.inverse();
        let correction_m = (new_cur.translation - old_cur.translation).norm();
        let correction_deg = (new_cur.rotation * old_cur.rotation.inverse()).angle().to_degrees();
        // The current key frame and its covisible ones move with the loop's correction.
        let mut connected = vec![current];
        connected.extend(self.map.covisible(current));
        let mut corrected: BTreeMap<u64, Sim3> = BTreeMap::new();
        for k in &connected {
            corrected.insert(*k, delta * old[k]);
        }
        self.move_points(&corrected, &old);
        // Fusion: the loop side's points into the corrected key frames.
        let loop_points = self.map.points_of(&found.group);
        self.fused_observations.clear();
        self.fused_removed.clear();
        let mut fused = 0;
        for k in &connected {
            let Some(kf) = self.map.kfs.get(k) else { continue };
            let pose = corrected[k].rigid();
            let pairs = if *k == current {
                found.matches.clone()
            } else {
                self.map.search_by_projection(&kf.keypoints, &pose, &loop_points, FUSION_RADIUS)
            };
            for (i, p) in pairs {
                fused += usize::from(self.fuse(*k, i, p));
            }
        }
        // Spanning tree, strong covisibility and loop edges; relative poses from before the
        // correction, except between the corrected key frames and the loop side (after it).
        if let Some(kf) = self.map.kfs.get_mut(&current) {
            kf.loops.insert(candidate);
        }
        if let Some(kf) = self.map.kfs.get_mut(&candidate) {
            kf.loops.insert(current);
        }
        let ids: Vec<u64> = self.map.kfs.keys().copied().collect();
        let index: BTreeMap<u64, usize> = ids.iter().enumerate().map(|(i, &k)| (k, i)).collect();
        let mut poses: Vec<Sim3> = ids.iter().map(|k| corrected.get(k).copied().unwrap_or(old[k])).collect();
        let mut edges: Vec<Edge<Sim3>> = Vec::new();
        let mut seen = BTreeSet::new();
        let group: BTreeSet<u64> = found.group.iter().copied().collect();
        let connected_set: BTreeSet<u64> = connected.iter().copied().collect();
        let mut edge = |a: u64, b: u64, after: bool, edges: &mut Vec<Edge<Sim3>>| {
            let key = (a.min(b), a.max(b));
            if a == b || !seen.insert(key) {
                return;
            }
            let (Some(&ia), Some(&ib)) = (index.get(&a), index.get(&b)) else { return };
            let pose = |k: u64| if after { corrected.get(&k).copied().unwrap_or(old[&k]) } else { old[&k] };
            edges.push(Edge { a: ia, b: ib, a_from_b: pose(a).inverse() * pose(b) });
        };
        // The loop connections first (they are measured after the correction).
        for &k in &connected {
            for (o, _) in self.map.covisibility(k) {
                if group.contains(&o) && !connected_set.contains(&o) {
                    edge(k, o, true, &mut edges);
                }
            }
        }
        edge(current, candidate, true, &mut edges);
        for (&k, kf) in &self.map.kfs {
            if let Some(p) = kf.parent {
                edge(k, p, false, &mut edges);
            }
            for &l in &kf.loops {
                edge(k, l, false, &mut edges);
            }
            for (o, w) in self.map.covisibility(k) {
                if w >= self.config.essential_min {
                    edge(k, o, false, &mut edges);
                }
            }
        }
        let mut fixed = vec![false; ids.len()];
        if let Some(&i) = index.get(&candidate) {
            fixed[i] = true;
        }
        // A single camera's scale drifts: the essential graph in Sim(3) corrects it along the
        // loop; with depth the scale is known and the graph is SE(3) (ORB-SLAM2 fixes the scale).
        // With gravity known (a visual-inertial map), in yaw and position only.
        let report = if monocular {
            optimise_sim3(&mut poses, &fixed, &edges, self.config.pose_graph_iterations)
        } else {
            let mut rigid: Vec<Isometry3<f64>> = poses.iter().map(Sim3::rigid).collect();
            let rigid_edges: Vec<PoseEdge> =
                edges.iter().map(|e| PoseEdge { a: e.a, b: e.b, a_from_b: e.a_from_b.rigid() }).collect();
            let iterations = self.config.pose_graph_iterations;
            let report = match (&self.up, found.upright) {
                (Some(up), true) => optimise_4dof(&mut rigid, up, &fixed, &rigid_edges, iterations),
                _ => optimise(&mut rigid, &fixed, &rigid_edges, iterations),
            };
            poses = rigid.iter().map(Sim3::from_isometry).collect();
            report
        };
        let final_poses: BTreeMap<u64, Sim3> = ids.iter().copied().zip(poses).collect();
        // Points move with their reference key frame: back to before the first step, then on.
        let mut start = old.clone();
        for (k, p) in &corrected {
            start.insert(*k, *p);
        }
        self.move_points(&final_poses, &start);
        // Each key frame's pose: the similarity's rotation and camera centre (its scale went
        // into the points).
        for (k, p) in &final_poses {
            if let Some(kf) = self.map.kfs.get_mut(k) {
                kf.info.world_from_cam = p.rigid();
            }
        }
        let t0 = std::time::Instant::now();
        let global = self.global_ba();
        let global_ba_ms = t0.elapsed().as_secs_f64() * 1e3;
        self.since_loop = 0;
        self.consistency = LoopConsistency::new();
        let closure = LoopClosure {
            current,
            loop_keyframe: candidate,
            current_stamp: self.map.kfs.get(&current).map_or(0.0, |k| k.info.stamp),
            loop_stamp: self.map.kfs.get(&candidate).map_or(0.0, |k| k.info.stamp),
            bow_matches: found.bow_matches,
            inliers: found.inliers,
            matches: found.matches.len(),
            loop_from_current: old[&candidate].rigid().inverse() * found.world_from_cur,
            merged_map: None,
            scale: found.scale,
            correction_m,
            correction_deg,
            fused,
            keyframes: ids.len(),
            edges: edges.len(),
            cost_before: report.initial_cost,
            cost_after: report.final_cost,
            global_ba: global,
            global_ba_ms,
        };
        self.loops.push(closure.clone());
        closure
    }

    /// ORB-SLAM2's global bundle adjustment after a loop (`RunGlobalBundleAdjustment`, 10
    /// iterations, the map's first key frame fixed, Huber): every key frame and every point
    /// seen twice, then the map takes the result. Run in place here (ORB-SLAM2 runs it in a
    /// thread and drops it when a new loop comes; in lockstep the next key frame waits for it).
    fn global_ba(&mut self) -> BaReport {
        let ids: Vec<u64> = self.map.kfs.keys().copied().collect();
        let first = ids.first().copied();
        let mut poses: Vec<BaPose> = ids
            .iter()
            .map(|k| BaPose { cam_from_world: self.map.kfs[k].info.world_from_cam.inverse(), fixed: Some(*k) == first })
            .collect();
        let point_ids: Vec<u64> = self
            .map
            .points
            .keys()
            .copied()
            .filter(|p| self.map.observers.get(p).is_some_and(|o| o.len() >= 2))
            .collect();
        let index: BTreeMap<u64, usize> = point_ids.iter().enumerate().map(|(i, &p)| (p, i)).collect();
        let mut points: Vec<Point3<f64>> = point_ids.iter().map(|p| self.map.points[p].position).collect();
        let mut obs = Vec::new();
        for (pi, k) in ids.iter().enumerate() {
            for kp in &self.map.kfs[k].keypoints {
                if let Some(&j) = kp.point.and_then(|p| index.get(&p)) {
                    obs.push(BaObservation {
                        pose: pi,
                        point: j,
                        uv: kp.uv,
                        depth: kp.depth,
                        sigma: sigma(self.config.scale_factor, kp.octave),
                    });
                }
            }
        }
        if obs.is_empty() {
            return BaReport::default();
        }
        let active = vec![true; obs.len()];
        let report = bundle_adjust(
            &self.map.cam,
            self.config.bf,
            &mut poses,
            &mut points,
            &obs,
            &active,
            self.config.global_ba_iterations,
        );
        for (k, p) in ids.iter().zip(&poses) {
            if let Some(kf) = self.map.kfs.get_mut(k) {
                kf.info.world_from_cam = p.cam_from_world.inverse();
            }
        }
        for (id, x) in point_ids.iter().zip(points) {
            if let Some(p) = self.map.points.get_mut(id) {
                p.position = x;
            }
        }
        report
    }

    /// Move every point with its reference key frame (the one that created it, or the first
    /// observer) from pose `from` to pose `to`, for key frames in `to`.
    fn move_points(&mut self, to: &BTreeMap<u64, Sim3>, from: &BTreeMap<u64, Sim3>) {
        for (id, p) in &mut self.map.points {
            let first = p.first_keyframe;
            let reference = if self.map.kfs.contains_key(&first) {
                Some(first)
            } else {
                self.map.observers.get(id).and_then(|o| o.iter().next().copied())
            };
            let Some(r) = reference else { continue };
            if let (Some(t), Some(f)) = (to.get(&r), from.get(&r)) {
                p.position = t.transform_point(&f.inverse().transform_point(&p.position));
            }
        }
    }

    /// Key frame `kf`'s keypoint `i` observes point `p`: a different point there is replaced by
    /// `p` everywhere. True when something changed.
    fn fuse(&mut self, kf: u64, i: usize, p: u64) -> bool {
        let Some(k) = self.map.kfs.get(&kf) else { return false };
        let Some(kp) = k.keypoints.get(i).copied() else { return false };
        if kp.point == Some(p) {
            return false;
        }
        if self.map.observers.get(&p).is_some_and(|o| o.contains(&kf)) {
            // The key frame already sees `p` through another keypoint.
            return false;
        }
        if let Some(q) = kp.point {
            // Replace `q` by `p` in every key frame that sees `q`.
            let holders = self.map.observers.remove(&q).unwrap_or_default();
            for h in holders {
                let sees_p = self.map.observers.get(&p).is_some_and(|o| o.contains(&h));
                let Some(hk) = self.map.kfs.get_mut(&h) else { continue };
                for kpj in &mut hk.keypoints {
                    if kpj.point == Some(q) {
                        kpj.point = if sees_p { None } else { Some(p) };
                        if !sees_p {
                            self.fused_observations.push(MapObservation {
                                keyframe: h,
                                point: p,
                                uv: kpj.uv,
                                depth: kpj.depth,
                                octave: kpj.octave,
                            });
                        }
                    }
                }
                if !sees_p {
                    self.map.observers.entry(p).or_default().insert(h);
                }
            }
            self.map.points.remove(&q);
            self.fused_removed.push(q);
        } else {
            if let Some(hk) = self.map.kfs.get_mut(&kf) {
                hk.keypoints[i].point = Some(p);
            }
            self.map.observers.entry(p).or_default().insert(kf);
            self.fused_observations.push(MapObservation {
                keyframe: kf,
                point: p,
                uv: kp.uv,
                depth: kp.depth,
                octave: kp.octave,
            });
        }
        if let Some(pt) = self.map.points.get_mut(&p) {
            pt.observations = self.map.observers.get(&p).map_or(0, |o| o.len() as u32);
        }
        true
    }

    /// The corrected map after a loop: every key frame's pose, every point, the observations
    /// fusion added and the points it removed.
    pub fn correction(&self) -> SparseMap {
        SparseMap {
            map_id: self.map.map_id,
            keyframes: self.map.kfs.values().map(|k| k.info).collect(),
            points: self.map.points.values().copied().collect(),
            observations: self.fused_observations.clone(),
            removed: self.fused_removed.clone(),
            features: Vec::new(),
            keypoints: Vec::new(),
            culled: Vec::new(),
        }
    }
}

#[derive(Clone)]
struct Found {
    world_from_cur: Isometry3<f64>,
    /// The current key frame's map units in the loop side's (1 with depth).
    scale: f64,
    bow_matches: usize,
    inliers: usize,
    matches: Vec<(usize, u64)>,
    group: Vec<u64>,
    /// The correction's tilt was taken out ([`LoopCloser::upright`]): the essential graph
    /// moves yaw and position only.
    upright: bool,
}

/// Sim(3) from 3-D point pairs as a RANSAC estimator: 3-point samples solved by Umeyama's
/// method (the scale fixed to 1 unless `with_scale`), a pair agreeing when it reprojects both
/// ways (`agrees`: residual 0, else infinite), Umeyama on all agreeing pairs as refit. A model
/// is the transform and its inverse (each pair is checked both ways, so the inverse is computed
/// once per model, not once per pair).
struct Sim3Estimator<'a, F: Fn(&(Sim3, Sim3), usize) -> bool> {
    /// `(x in the current key frame, x in the candidate, keypoint there, keypoint here)`.
    pairs: &'a [(Point3<f64>, Point3<f64>, usize, usize)],
    with_scale: bool,
    agrees: F,
}

impl<F: Fn(&(Sim3, Sim3), usize) -> bool> Sim3Estimator<'_, F> {
    fn solve(&self, idx: &[usize]) -> Option<(Sim3, Sim3)> {
        let xa: Vec<Vector3<f64>> = idx.iter().map(|&k| self.pairs[k].0.coords).collect();
        let xb: Vec<Vector3<f64>> = idx.iter().map(|&k| self.pairs[k].1.coords).collect();
        let (r, t, scale) = umeyama(&xa, &xb, self.with_scale)?;
        if !(scale.is_finite() && scale > 0.0) {
            return None;
        }
        let t = Sim3 { rotation: UnitQuaternion::from_matrix(&r), translation: t, scale };
        Some((t, t.inverse()))
    }
}

impl<F: Fn(&(Sim3, Sim3), usize) -> bool> Estimator for Sim3Estimator<'_, F> {
    type Model = (Sim3, Sim3);
    const SAMPLE_SIZE: usize = 3;
    fn len(&self) -> usize {
        self.pairs.len()
    }
    fn fit(&self, sample: &[usize]) -> Vec<(Sim3, Sim3)> {
        self.solve(sample).into_iter().collect()
    }
    fn residual(&self, t: &(Sim3, Sim3), i: usize) -> f64 {
        if (self.agrees)(t, i) { 0.0 } else { f64::INFINITY }
    }
    fn refit(&self, inliers: &[usize]) -> Option<(Sim3, Sim3)> {
        self.solve(inliers)
    }
}
