//! ORB-SLAM2's tracking of RGB-D, stereo and monocular frames against a local map.
//!
//! Per frame ([`tracking`]): predict the pose with a constant-velocity model (or the IMU).
//! With [`TrackerConfig::two_stage`] (ORB-SLAM2's stereo settings; the tracking operators'
//! `two_stage`, off by default) it then searches as ORB-SLAM2 does, twice:
//! the previous frame's points projected and matched to the nearest keypoint within 7 px
//! times its level's scale, on neighbouring levels, orientations consistent
//! (`TrackWithMotionModel`), motion-only BA (pixels plus depth as ORB-SLAM2's virtual right
//! coordinate, Huber, four re-classification rounds); then the rest of the local map at that
//! pose within 2.5-4 px at the level each point's distance predicts, ratio test between two of
//! one level (`TrackLocalMap`), and BA on all. Otherwise (and when the previous frame's points
//! do not carry the pose) the whole local map is searched once around
//! the prediction: the best keypoint within 15 px (Hamming distance, ratio test), widened 3x
//! when too few survive, then motion-only BA. When that still fails ([`relocalise`]),
//! with a vocabulary, ORB-SLAM2's `Relocalization`: every key frame of the map by bag of words,
//! then P3P RANSAC on the BoW matches of the likeliest; without one, descriptor matches against
//! the whole local map (the recent key frames) and P3P. A relocalised pose, and every pose in
//! the second after it, needs [`RELOCALISATION_MIN_INLIERS`] (ORB-SLAM2's 50; `min_inliers` if set higher). A frame with too few inliers is *lost*: its pose follows the motion model (the tracking
//! operators leave it out of the trajectory); after `reset_after` lost frames in a row that show something (at least `min_init_points`
//! static keypoints) a new map starts at the dead-reckoned pose (so the trajectory stays in one
//! frame, and the jump is reported). A loaded map ([`Tracker::use_map`]) is localised in
//! first; with mapping off no key frames are made.
//!
//! Key frames ([`keyframe`]) follow ORB-SLAM2's rules (tracked points fall below 75 % of the
//! reference key frame's, or too few close points are tracked while many are not; time alone
//! makes none, as local mapping is always idle in lockstep); with depth a key frame creates
//! map points for its unmatched keypoints (all of them for RGB-D, ORB-SLAM2's close-point rule for stereo), and is handed to local
//! mapping as a [`SparseMap`] batch, whose triangulation adds the rest. A single camera starts
//! its map from two views ([`monocular`]). Every observation with a depth is an RGB-D
//! observation in BA (pixel plus virtual right coordinate), as in ORB-SLAM2.
//!
//! With an IMU ([`Tracker::with_imu`], [`inertial`]) the trackers follow ORB-SLAM3's
//! visual-inertial modes: IMU initialisation (a single camera's map made metric by it), IMU
//! prediction, and IMU-only propagation through frames vision cannot track.

mod inertial;
mod keyframe;
mod monocular;
mod relocalise;
mod tracking;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{
    PoseObservation, RansacConfig, SplitMix64, TwoViewConfig, TwoViewInit, initialise, optimize_pose, p3p_ransac,
    renormalised,
};
use dynaflow_vision::matching::{GridIndex, MatchConfig, match_brute_force, nearest_two};
use nalgebra::{Isometry3, Point3};

use crate::bow::Vocabulary;
use crate::keyframe_map::KeyFrameMap;
use crate::map::{Feature, MapFeature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, SparseMap, sigma};

pub use inertial::{
    IMU_ONLY_LIMIT, INERTIAL_CHI2_9DOF_99, INERTIAL_KEYFRAME_INTERVAL, INERTIAL_WINDOW, INIT_KEYFRAME_INTERVAL,
    INIT_MIN_KEYFRAMES, INIT_MIN_SPAN, InertialEstimate, InertialInitInfo, InitMethod, SCALE_REFINEMENT_MAX_KEYFRAMES,
    SCALE_REFINEMENT_UNTIL,
};

/// Inliers a relocalised pose needs, and every pose in the second after it (ORB-SLAM2:
/// `Relocalization` accepts 50, and `TrackLocalMap` wants 50 for `mMaxFrames`, a second of
/// frames, after a relocalisation). A view never mapped can match a repeated texture (the same
/// brick on two walls) with 30.
pub const RELOCALISATION_MIN_INLIERS: usize = 50;
/// Seconds after a relocalisation in which [`RELOCALISATION_MIN_INLIERS`] holds (ORB-SLAM2's
/// `mMaxFrames` = the frame rate).
const RELOCALISATION_PROBATION_S: f64 = 1.0;

/// Tracking settings (defaults: ORB-SLAM2's for an RGB-D camera, see [`TrackerConfig::rgbd`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerConfig {
    /// `fx` times the virtual baseline (ORB-SLAM2 `bf`; its TUM configs: 40, [`RGBD_BF`]).
    pub bf: f64,
    /// "Close" depth for the key-frame rule (ORB-SLAM2 `ThDepth` x baseline: 40 x bf / fx; 2.99 m
    /// at the TUM fr3 camera's fx 535.4).
    pub th_depth: f64,
    /// Depths beyond this are not used at all (Kinect noise grows with the square).
    pub max_depth: f64,
    /// ORB pyramid scale factor.
    pub scale_factor: f64,
    /// Projection search radius, pixels: with [`two_stage`](Self::two_stage) the previous
    /// frame's points', at the pyramid level of the keypoint that saw each (ORB-SLAM2's
    /// `TrackWithMotionModel`: stereo 7; doubled once when fewer than 20 match); otherwise the
    /// whole local map's (ORB-SLAM2's motion-model 15; widened 3x once).
    pub search_radius: f64,
    /// ORB-SLAM2's two searches (the previous frame's points, then the local map; see
    /// [`tracking`]; [`TrackerConfig::stereo`] sets it). False: one search of the local map at
    /// `search_radius`, widened 3x once (what the tracking operators do unless asked: on the
    /// rooms the two searches drift more, on the street scene only they keep tracking;
    /// docs/benchmarks.md).
    pub two_stage: bool,
    /// The local map's search at the refined pose, as ORB-SLAM2's `SearchLocalPoints` scales
    /// its radius of 2.5 px (4 where the view is oblique) at a keypoint's pyramid level: 1; a
    /// depth camera 3; 5 just after a relocalisation.
    pub local_search: f64,
    /// Largest Hamming distance of a match (ORB-SLAM `TH_HIGH`).
    pub max_distance: u32,
    /// Ratio of best to second-best distance in the projection search.
    pub ratio: f32,
    /// Fewer inliers than this after motion-only BA: the frame is not tracked (ORB-SLAM: 30;
    /// a relocalisation and the second after it need [`RELOCALISATION_MIN_INLIERS`]).
    pub min_inliers: usize,
    /// P3P RANSAC reprojection threshold, pixels at level 0.
    pub ransac_threshold: f64,
    /// Points with depth a frame needs to start a map (ORB-SLAM2 wants 500 keypoints).
    pub min_init_points: usize,
    /// Lost frames in a row after which a new map starts.
    pub reset_after: u32,
    /// Which of ORB-SLAM2's three sensor modes.
    pub sensor: Sensor,
}

/// ORB-SLAM2's sensor modes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    /// Depth from a depth camera; a key frame creates points for every keypoint with a depth
    /// up to `max_depth` ([`TrackerConfig::rgbd`]).
    Rgbd,
    /// Depth from a rectified pair: every matched depth is used (no `max_depth`), and a key
    /// frame creates points for its close keypoints, at least the 100 nearest (ORB-SLAM2's
    /// `CreateNewKeyFrame`; the first key frame takes all) ([`TrackerConfig::stereo`]).
    Stereo,
    /// A single camera: no depth; the map starts from two views (ORB-SLAM2's monocular
    /// initialisation) and local mapping triangulates new points ([`TrackerConfig::monocular`]).
    Monocular,
}

impl TrackerConfig {
    /// ORB-SLAM2's RGB-D settings for focal length `fx` (bf 40 px, [`RGBD_BF`]).
    pub fn rgbd(fx: f64) -> Self {
        Self {
            bf: RGBD_BF,
            th_depth: CLOSE_BASELINES * RGBD_BF / fx,
            max_depth: 6.0,
            scale_factor: 1.2,
            search_radius: 15.0,
            two_stage: false,
            local_search: 3.0,
            max_distance: 100,
            ratio: 0.8,
            min_inliers: 30,
            ransac_threshold: 3.0,
            min_init_points: 100,
            reset_after: 5,
            sensor: Sensor::Rgbd,
        }
    }

    /// ORB-SLAM2's stereo settings for focal length `fx` and a rig `baseline` metres wide: bf
    /// from the rig, points closer than 40 baselines are close (its `ThDepth`), every matched
    /// depth is used.
    pub fn stereo(fx: f64, baseline: f64) -> Self {
        Self {
            bf: fx * baseline,
            th_depth: CLOSE_BASELINES * baseline,
            max_depth: f64::INFINITY,
            search_radius: 7.0,
            two_stage: true,
            local_search: 1.0,
            sensor: Sensor::Stereo,
            ..Self::rgbd(fx)
        }
    }

    /// ORB-SLAM2's monocular settings for focal length `fx`: no depth (`bf` 0), a map from
    /// two views with at least 100 matches (its `Tracking::MonocularInitialization`), key
    /// frames when tracked points fall below 90 % of the reference key frame's.
    pub fn monocular(fx: f64) -> Self {
        Self { bf: 0.0, th_depth: 0.0, max_depth: 0.0, local_search: 1.0, sensor: Sensor::Monocular, ..Self::rgbd(fx) }
    }
}

/// ORB-SLAM2's monocular initialisation: matches between the reference and the current
/// frame needed to try (`SearchForInitialization` < 100 restarts from the current frame).
pub const MONO_INIT_MATCHES: usize = 100;
/// ORB-SLAM2's `ThDepth`: points closer than 40 baselines (RGB-D: the virtual one) are close.
pub const CLOSE_BASELINES: f64 = 40.0;
/// ORB-SLAM2's `Camera.bf` for a depth camera, pixels: fx times a virtual baseline (its TUM
/// RGB-D configurations, `TUM1/2/3.yaml`: 40 whatever fx, so the baseline is 40 / fx).
pub const RGBD_BF: f64 = 40.0;
/// ORB-SLAM2's `CreateNewKeyFrame` (stereo): at least this many new points, nearest first.
const STEREO_MIN_NEW_POINTS: usize = 100;
/// Search window of the initial matching, pixels (ORB-SLAM2: 100).
const MONO_INIT_WINDOW: f32 = 100.0;
/// Hamming distance and ratio of the initial matching (ORB-SLAM2: `TH_LOW` 50, 0.9).
const MONO_INIT_MAX_DISTANCE: u32 = 50;
const MONO_INIT_RATIO: f32 = 0.9;

/// How a frame was tracked.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackState {
    /// No map yet and this frame could not start one (too few points with depth).
    NotInitialised,
    /// This frame started a map (the first, or a new one after tracking was lost).
    NewMap,
    /// Tracked by projection search from the motion model.
    Tracked,
    /// Tracked by descriptor matching and P3P RANSAC against the local map.
    Relocalised,
    /// Not tracked: the pose follows the motion model.
    Lost,
    /// Not tracked by vision: the pose is the IMU's propagation (an initialised
    /// visual-inertial tracker, for up to [`IMU_ONLY_LIMIT`] seconds).
    Inertial,
}

impl TrackState {
    /// A number for plots: 0 not initialised, 1 new map, 2 tracked, 3 relocalised, 4 lost,
    /// 5 propagated by the IMU.
    pub fn code(self) -> f64 {
        match self {
            TrackState::NotInitialised => 0.0,
            TrackState::NewMap => 1.0,
            TrackState::Tracked => 2.0,
            TrackState::Relocalised => 3.0,
            TrackState::Lost => 4.0,
            TrackState::Inertial => 5.0,
        }
    }
}

/// What [`Tracker::track`] found for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackingResult {
    /// The camera's pose, `world_from_cam`; `None` before the first map.
    pub world_from_cam: Option<Isometry3<f64>>,
    /// Outcome.
    pub state: TrackState,
    /// Map points matched to keypoints.
    pub matches: usize,
    /// Matches that are inliers after motion-only BA.
    pub inliers: usize,
    /// Map points the tracker holds.
    pub map_points: usize,
    /// Map number (increments with each new map).
    pub map_id: u32,
    /// A new key frame for local mapping.
    pub keyframe: Option<SparseMap>,
    /// Per feature: the map point it was matched to as an inlier.
    pub matched: Vec<Option<u64>>,
}

/// A point the previous frame saw, with its keypoint's level and orientation.
#[derive(Clone, Copy, Debug)]
struct LastMatch {
    point: u64,
    octave: u8,
    angle: f32,
}

#[derive(Clone, Copy, Debug)]
struct TPoint {
    position: Point3<f64>,
    descriptor: [u8; 32],
    first_keyframe: u64,
    /// The distance at which it would be seen on level 0 (ORB-SLAM2's `mfMaxDistance`: the
    /// distance it was made at, times the scale of the keypoint's level); 0 where the tracker
    /// did not make it (local mapping's triangulated points).
    max_distance: f64,
}

/// The tracker's random streams, one per call site ([`SplitMix64::named`]).
#[derive(Debug)]
struct Streams {
    /// P3P against the recent key frames' points.
    relocalise_local: SplitMix64,
    /// P3P against a key frame found by bag of words.
    relocalise_map: SplitMix64,
    /// Monocular two-view initialisation.
    initialise: SplitMix64,
}

impl Streams {
    fn new(seed: u64) -> Self {
        Self {
            relocalise_local: SplitMix64::named(seed, "tracker/relocalise/local"),
            relocalise_map: SplitMix64::named(seed, "tracker/relocalise/map"),
            initialise: SplitMix64::named(seed, "tracker/initialise"),
        }
    }
}

/// RANSAC for P3P relocalisation: ORB-SLAM2's PnP solver settings (300 iterations, 99 %).
fn relocalisation_ransac(threshold: f64) -> RansacConfig {
    RansacConfig { threshold, confidence: 0.99, max_iterations: 300, local_optimisation: false }
}

/// Tracking state across frames.
#[derive(Debug)]
pub struct Tracker {
    config: TrackerConfig,
    cam: Pinhole,
    width: f64,
    height: f64,
    /// One random stream per call site, each derived from the seed by its name.
    rng: Streams,
    map_id: u32,
    initialised: bool,
    points: BTreeMap<u64, TPoint>,
    next_point: u64,
    next_keyframe: u64,
    /// `world_from_cam` of the previous frame.
    last: Option<Isometry3<f64>>,
    /// `prev_from_cur` of the last tracked motion.
    velocity: Isometry3<f64>,
    ref_tracked: usize,
    /// First key frame of the current map.
    first_keyframe: u64,
    lost_run: u32,
    /// Stamp of the last relocalisation: for a second after it a pose needs
    /// [`RELOCALISATION_MIN_INLIERS`].
    relocalised_at: Option<f64>,
    /// Monocular: the reference frame of the initialisation (its stamp and features).
    init_ref: Option<(f64, Vec<Feature>)>,
    /// Monocular: why the last initialisation attempt failed.
    init_failure: Option<String>,
    /// Every key frame's latest pose (from tracking, then local mapping and loop closing).
    keyframe_poses: BTreeMap<u64, Isometry3<f64>>,
    /// Per posed frame: its stamp, reference key frame and `ref_from_frame` (ORB-SLAM2's
    /// relative frame poses, from which the final trajectory is rebuilt).
    anchors: Vec<(f64, u64, Isometry3<f64>)>,
    /// The newest key frame (or the one relocalisation found).
    reference: Option<u64>,
    /// The previous frame's map points with the pyramid level of the keypoint that saw each
    /// (ORB-SLAM2's last frame, searched first by the motion model; a key frame's new points
    /// included).
    last_matched: Vec<LastMatch>,
    /// The previous frame was relocalised: the local map is searched wider (ORB-SLAM2).
    last_relocalised: bool,
    /// With a vocabulary: every key frame and point, for relocalisation in the whole map.
    places: Option<KeyFrameMap>,
    relocalisations: usize,
    /// False: ORB-SLAM2's localisation mode (a loaded map, no key frames).
    mapping: bool,
    /// A loaded map the tracker has not yet found itself in.
    unlocated: bool,
    /// With an IMU ([`Tracker::with_imu`]): its pre-integration and inertial state.
    imu: Option<Box<inertial::Inertial>>,
}

/// The points the key frames `kfs` of the whole map see, as tracking holds its local map.
fn local_points(places: &KeyFrameMap, kfs: &[u64]) -> BTreeMap<u64, TPoint> {
    places
        .points_of(kfs)
        .into_iter()
        .filter_map(|id| {
            let p = places.points.get(&id)?;
            Some((
                id,
                TPoint {
                    position: p.position,
                    descriptor: p.descriptor,
                    first_keyframe: p.first_keyframe,
                    max_distance: 0.0,
                },
            ))
        })
        .collect()
}

/// ORB-SLAM2's relocalisation: BoW matches to try a candidate, inliers after the first BA, and
/// inliers to accept (`Tracking::Relocalization`: 15, 10, 50).
const RELOCALISATION_BOW_MATCHES: usize = 15;
const RELOCALISATION_MIN_BA_INLIERS: usize = 10;
const RELOCALISATION_INLIERS: usize = 50;

impl Tracker {
    /// A tracker for images `width` x `height` from camera `cam`; `seed` drives RANSAC.
    pub fn new(config: TrackerConfig, cam: Pinhole, width: usize, height: usize, seed: u64) -> Self {
        Self {
            config,
            cam,
            width: width as f64,
            height: height as f64,
            rng: Streams::new(seed),
            map_id: 0,
            initialised: false,
            points: BTreeMap::new(),
            next_point: 0,
            next_keyframe: 0,
            last: None,
            velocity: Isometry3::identity(),
            ref_tracked: 0,
            first_keyframe: 0,
            lost_run: 0,
            relocalised_at: None,
            init_ref: None,
            init_failure: None,
            keyframe_poses: BTreeMap::new(),
            anchors: Vec::new(),
            reference: None,
            last_matched: Vec::new(),
            last_relocalised: false,
            places: None,
            relocalisations: 0,
            mapping: true,
            unlocated: false,
            imu: None,
        }
    }

    /// Bytes per component ([`crate::memory`]): the key frames' poses and each frame's anchor
    /// (key frames), the local map's points, and with a vocabulary the whole map it keeps for
    /// relocalisation.
    pub fn memory(&self) -> crate::memory::MapMemory {
        use crate::memory::{MapMemory, map_bytes, vec_bytes};
        let own = MapMemory {
            keyframes: map_bytes(&self.keyframe_poses) + vec_bytes(&self.anchors),
            points: map_bytes(&self.points),
            bow_index: 0,
        };
        own + self.places.as_ref().map(KeyFrameMap::memory).unwrap_or_default()
    }

    /// The whole map kept for relocalisation (with a vocabulary), e.g. to save it.
    pub fn places(&self) -> Option<&KeyFrameMap> {
        self.places.as_ref()
    }

    /// Keep every key frame and point with their words, and relocalise in the whole map when
    /// tracking is lost (ORB-SLAM2's key-frame database), with this vocabulary.
    pub fn with_vocabulary(mut self, vocabulary: Arc<Vocabulary>) -> Self {
        self.places = Some(KeyFrameMap::new(self.cam, self.width, self.height, self.config.scale_factor, vocabulary));
        self
    }

    /// The trajectory as ORB-SLAM2 saves it at the end (`SaveTrajectoryTUM`): each frame's pose
    /// relative to its reference key frame, composed with that key frame's latest pose (refined
    /// by local mapping, corrected by loop closing). Frames before the first key frame are left
    /// out.
    pub fn keyframe_trajectory(&self) -> Vec<(f64, Isometry3<f64>)> {
        self.anchors
            .iter()
            .filter_map(|(t, k, rel)| self.keyframe_poses.get(k).map(|p| (*t, renormalised(&(p * rel)))))
            .collect()
    }

    /// Take loop closing's corrected map (ignored if it is of another map): key-frame poses,
    /// point positions and the points fusion removed. The last pose moves with the newest key
    /// frame's correction (ORB-SLAM2 re-anchors its last frame to its reference key frame), and
    /// points loop closing does not know move with the key frame that made them.
    pub fn apply_correction(&mut self, correction: &SparseMap) {
        if correction.map_id != self.map_id || !self.initialised {
            return;
        }
        let mut delta: BTreeMap<u64, Isometry3<f64>> = BTreeMap::new();
        for k in &correction.keyframes {
            // (A key frame culled since loop closing sent this is not brought back.)
            if let Some(slot) = self.keyframe_poses.get_mut(&k.id) {
                delta.insert(k.id, k.world_from_cam * slot.inverse());
                *slot = k.world_from_cam;
            }
        }
        let newest = self.reference.and_then(|r| delta.get(&r).copied());
        if let (Some(d), Some(last)) = (newest, self.last) {
            self.last = Some(renormalised(&(d * last)));
        }
        self.imu_correct(&delta, newest);
        let corrected: BTreeMap<u64, Point3<f64>> = correction.points.iter().map(|p| (p.id, p.position)).collect();
        for (id, p) in &mut self.points {
            if let Some(c) = corrected.get(id) {
                p.position = *c;
            } else if let Some(d) = delta.get(&p.first_keyframe).copied().or(newest) {
                p.position = d * p.position;
            }
        }
        for id in &correction.removed {
            self.points.remove(id);
        }
        if let Some(places) = &mut self.places {
            places.apply_correction(correction);
        }
    }

    /// The settings.
    pub fn config(&self) -> &TrackerConfig {
        &self.config
    }

    /// The current map number.
    pub fn map_id(&self) -> u32 {
        self.map_id
    }

    /// Take local mapping's refined local map (ignored if it is of an older map).
    pub fn apply_map_update(&mut self, update: &SparseMap) {
        if update.map_id != self.map_id || !self.initialised {
            return;
        }
        let newest = update.keyframes.iter().map(|k| k.id).max().unwrap_or(0);
        for k in &update.keyframes {
            self.keyframe_poses.insert(k.id, k.world_from_cam);
        }
        if let Some(places) = &mut self.places
            && places.map_id == update.map_id
        {
            places.apply_refinements(update);
            places.cull_keyframes(update);
        }
        self.cull_keyframes(update);
        let incoming: BTreeSet<u64> = update.points.iter().map(|p| p.id).collect();
        for p in &update.points {
            let max_distance = self.points.get(&p.id).map_or(0.0, |t| t.max_distance);
            self.points.insert(
                p.id,
                TPoint {
                    position: p.position,
                    descriptor: p.descriptor,
                    first_keyframe: p.first_keyframe,
                    max_distance,
                },
            );
        }
        // Keep what local mapping holds in its window, and what it has not seen yet.
        self.points.retain(|id, p| incoming.contains(id) || p.first_keyframe > newest);
        for id in &update.removed {
            self.points.remove(id);
        }
        // Monocular: the reference key frame's tracked points as ORB-SLAM2 counts them for its
        // key-frame rule: those seen by at least 3 key frames (2 while the map has two).
        if self.config.sensor == Sensor::Monocular && !update.observations.is_empty() {
            let min_obs = if newest <= self.first_keyframe + 1 { 2 } else { 3 };
            let seen: BTreeMap<u64, u32> = update.points.iter().map(|p| (p.id, p.observations)).collect();
            self.ref_tracked = update
                .observations
                .iter()
                .filter(|o| o.keyframe == newest && seen.get(&o.point).is_some_and(|&n| n >= min_obs))
                .count();
        }
    }

    /// Forget the key frames local mapping culled: the frames anchored to one are anchored to
    /// the key frame standing in for it, through the relative pose local mapping gave (they
    /// follow that key frame's later corrections, as ORB-SLAM2's frames follow a culled key
    /// frame's parent).
    fn cull_keyframes(&mut self, update: &SparseMap) {
        for c in &update.culled {
            if !self.keyframe_poses.contains_key(&c.anchor) {
                continue;
            }
            for a in self.anchors.iter_mut().filter(|a| a.1 == c.id) {
                *a = (a.0, c.anchor, renormalised(&(c.anchor_from_culled * a.2)));
            }
            self.keyframe_poses.remove(&c.id);
            if self.reference == Some(c.id) {
                self.reference = Some(c.anchor);
            }
        }
    }

    /// Track one frame.
    pub fn track(&mut self, stamp: f64, features: &[Feature]) -> TrackingResult {
        self.imu_advance(stamp);
        let r = self.track_frame(stamp, features);
        if matches!(r.state, TrackState::Tracked | TrackState::Relocalised | TrackState::NewMap) {
            self.imu_try_static(stamp);
        }
        self.imu_reference(stamp);
        self.remember_last_frame(features, &r);
        // Lost frames (a dead-reckoned guess) stay out of the trajectory, as in ORB-SLAM2.
        if let (Some(pose), Some(k), false) = (r.world_from_cam, self.reference, r.state == TrackState::Lost)
            && let Some(kp) = self.keyframe_poses.get(&k)
        {
            self.anchors.push((stamp, k, kp.inverse() * pose));
        }
        r
    }
}

#[derive(Clone, Debug)]
struct Fit {
    world_from_cam: Isometry3<f64>,
    matches: usize,
    inliers: usize,
    matched: Vec<Option<u64>>,
}
