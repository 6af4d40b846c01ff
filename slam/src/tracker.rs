//! ORB-SLAM-style tracking of RGB-D frames against a local map.
//!
//! Per frame: predict the pose with a constant-velocity model; project the local map points
//! and match each to the best keypoint within a search radius (Hamming distance, ratio test;
//! ORB-SLAM's `SearchByProjection`), widening the radius once when too few survive; refine by
//! motion-only BA (pixels plus depth as ORB-SLAM2's virtual right coordinate, Huber, four
//! re-classification rounds). When that still fails, match descriptors against the whole
//! local map and solve P3P inside RANSAC (relocalisation against the recent key frames), and
//! with a vocabulary then against every key frame of the map by bag of words (ORB-SLAM2's
//! `Relocalization`). A frame with too few inliers is *lost*: its pose follows the motion
//! model; after `reset_after` lost frames in a row that show something (at least
//! `min_init_points` static keypoints) a new map starts at the dead-reckoned pose (so the
//! trajectory stays in one frame, and the jump is reported). A loaded map ([`Tracker::use_map`])
//! is localised in first; with mapping off no key frames are made.
//!
//! Key frames follow ORB-SLAM2's rules for RGB-D (tracked points fall below 75 % of the
//! reference key frame's, or too few close points are tracked while many are not, or
//! `max_frames` passed); a key frame creates map points from depth for its unmatched
//! keypoints (ORB-SLAM2's `CreateNewKeyFrame` makes only the close ones and triangulates the
//! rest in local mapping; there is no triangulation here, so depth gives all of them) and is
//! handed to local mapping as a [`SparseMap`] batch. Every observation with a depth is an
//! RGB-D observation in BA (pixel plus virtual right coordinate), as in ORB-SLAM2.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{
    PoseObservation, SplitMix64, TwoViewConfig, TwoViewInit, initialise, optimize_pose, p3p_ransac, renormalised,
};
use dynaflow_vision::matching::{GridIndex, MatchConfig, match_brute_force, nearest_two};
use nalgebra::{Isometry3, Point3};

use crate::bow::Vocabulary;
use crate::keyframe_map::KeyFrameMap;
use crate::map::{Feature, KeyFrameFeature, KeyFrameInfo, KeyFrameKeypoint, MapPoint, Observation, SparseMap, sigma};

/// Tracking settings (defaults: ORB-SLAM2's for an RGB-D camera, see [`TrackerConfig::rgbd`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackerConfig {
    /// `fx` times the virtual baseline (ORB-SLAM2 `bf`; TUM configs: 40 = 525 px x 7.6 cm).
    pub bf: f64,
    /// "Close" depth for the key-frame rule (ORB-SLAM2 `ThDepth` x baseline: 40 x 8 cm = 3.2 m).
    pub th_depth: f64,
    /// Depths beyond this are not used at all (Kinect noise grows with the square).
    pub max_depth: f64,
    /// ORB pyramid scale factor.
    pub scale_factor: f64,
    /// Projection search radius, pixels at level 0 (ORB-SLAM2's motion-model search: 15).
    pub search_radius: f64,
    /// Largest Hamming distance of a match (ORB-SLAM `TH_HIGH`).
    pub max_distance: u32,
    /// Ratio of best to second-best distance in the projection search.
    pub ratio: f32,
    /// Fewer inliers than this after motion-only BA: the frame is not tracked (ORB-SLAM: 30).
    pub min_inliers: usize,
    /// P3P RANSAC reprojection threshold, pixels at level 0.
    pub ransac_threshold: f64,
    /// Points with depth a frame needs to start a map (ORB-SLAM2 wants 500 keypoints).
    pub min_init_points: usize,
    /// A key frame at least this often, frames (ORB-SLAM: the frame rate).
    pub max_frames: u64,
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
    /// ORB-SLAM2's RGB-D settings for focal length `fx` (virtual baseline 8 cm).
    pub fn rgbd(fx: f64) -> Self {
        Self {
            bf: fx * 0.08,
            th_depth: 40.0 * 0.08,
            max_depth: 6.0,
            scale_factor: 1.2,
            search_radius: 15.0,
            max_distance: 100,
            ratio: 0.8,
            min_inliers: 30,
            ransac_threshold: 3.0,
            min_init_points: 100,
            max_frames: 30,
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
            th_depth: STEREO_CLOSE_BASELINES * baseline,
            max_depth: f64::INFINITY,
            sensor: Sensor::Stereo,
            ..Self::rgbd(fx)
        }
    }

    /// ORB-SLAM2's monocular settings for focal length `fx`: no depth (`bf` 0), a map from
    /// two views with at least 100 matches (its `Tracking::MonocularInitialization`), key
    /// frames when tracked points fall below 90 % of the reference key frame's.
    pub fn monocular(fx: f64) -> Self {
        Self { bf: 0.0, th_depth: 0.0, max_depth: 0.0, sensor: Sensor::Monocular, ..Self::rgbd(fx) }
    }
}

/// ORB-SLAM2's monocular initialisation: matches between the reference and the current
/// frame needed to try (`SearchForInitialization` < 100 restarts from the current frame).
pub const MONO_INIT_MATCHES: usize = 100;
/// ORB-SLAM2's `ThDepth` for stereo cameras: points closer than 40 baselines are close.
const STEREO_CLOSE_BASELINES: f64 = 40.0;
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
}

impl TrackState {
    /// A number for plots: 0 not initialised, 1 new map, 2 tracked, 3 relocalised, 4 lost.
    pub fn code(self) -> f64 {
        match self {
            TrackState::NotInitialised => 0.0,
            TrackState::NewMap => 1.0,
            TrackState::Tracked => 2.0,
            TrackState::Relocalised => 3.0,
            TrackState::Lost => 4.0,
        }
    }
}

/// What [`Tracker::track`] found for one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackingResult {
    /// `world_from_cam`, `None` before the first map.
    pub pose: Option<Isometry3<f64>>,
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

#[derive(Clone, Copy, Debug)]
struct TPoint {
    position: Point3<f64>,
    descriptor: [u8; 32],
    first_keyframe: u64,
}

/// Tracking state across frames.
#[derive(Debug)]
pub struct Tracker {
    config: TrackerConfig,
    cam: Pinhole,
    width: f64,
    height: f64,
    rng: SplitMix64,
    map_id: u32,
    initialised: bool,
    points: BTreeMap<u64, TPoint>,
    next_point: u64,
    next_keyframe: u64,
    /// `world_from_cam` of the previous frame.
    last: Option<Isometry3<f64>>,
    /// `prev_from_cur` of the last tracked motion.
    velocity: Isometry3<f64>,
    frames_since_kf: u64,
    ref_tracked: usize,
    /// First key frame of the current map.
    first_keyframe: u64,
    lost_run: u32,
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
    /// With a vocabulary: every key frame and point, for relocalisation in the whole map.
    places: Option<KeyFrameMap>,
    relocalisations: usize,
    /// False: ORB-SLAM2's localisation mode (a loaded map, no key frames).
    mapping: bool,
    /// A loaded map the tracker has not yet found itself in.
    unlocated: bool,
}

/// The points the key frames `kfs` of the whole map see, as tracking holds its local map.
fn local_points(places: &KeyFrameMap, kfs: &[u64]) -> BTreeMap<u64, TPoint> {
    places
        .points_of(kfs)
        .into_iter()
        .filter_map(|id| {
            let p = places.points.get(&id)?;
            Some((id, TPoint { position: p.position, descriptor: p.descriptor, first_keyframe: p.first_keyframe }))
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
            rng: SplitMix64::new(seed),
            map_id: 0,
            initialised: false,
            points: BTreeMap::new(),
            next_point: 0,
            next_keyframe: 0,
            last: None,
            velocity: Isometry3::identity(),
            frames_since_kf: 0,
            ref_tracked: 0,
            first_keyframe: 0,
            lost_run: 0,
            init_ref: None,
            init_failure: None,
            keyframe_poses: BTreeMap::new(),
            anchors: Vec::new(),
            reference: None,
            places: None,
            relocalisations: 0,
            mapping: true,
            unlocated: false,
        }
    }

    /// The whole map kept for relocalisation (with a vocabulary), e.g. to save it.
    pub fn places(&self) -> Option<&KeyFrameMap> {
        self.places.as_ref()
    }

    /// Work in a loaded map: the first frames relocalise in it (no pose until one does). With
    /// `mapping` false this is ORB-SLAM2's localisation mode: no key frames are made, the local
    /// map follows the camera through the loaded key frames, and a lost camera relocalises
    /// again (no new map). With `mapping` true new key frames extend the loaded map. The map
    /// takes this tracker's camera (a saved map does not hold one).
    pub fn use_map(&mut self, mut map: KeyFrameMap, mapping: bool) {
        map.cam = self.cam;
        map.width = self.width;
        map.height = self.height;
        map.scale_factor = self.config.scale_factor;
        self.map_id = map.map_id;
        self.next_keyframe = map.kfs.keys().next_back().map_or(0, |k| k + 1);
        // Tracking's point ids are below local mapping's (1 << 48).
        self.next_point = map.points.keys().rfind(|&&id| id < 1 << 48).map_or(0, |p| p + 1);
        for (id, k) in &map.kfs {
            self.keyframe_poses.insert(*id, k.info.world_from_cam);
        }
        self.first_keyframe = map.kfs.keys().next().copied().unwrap_or(0);
        self.places = Some(map);
        self.initialised = true;
        self.unlocated = true;
        self.mapping = mapping;
        self.last = None;
        self.points.clear();
    }

    /// ORB-SLAM2's `UpdateLocalMap` in localisation mode: the key frames that see the
    /// matched points (the one seeing most is the reference) and their covisible key frames
    /// give the points to track next.
    fn follow_loaded_map(&mut self, matched: &[Option<u64>]) {
        let Some(places) = &self.places else { return };
        let mut votes: BTreeMap<u64, usize> = BTreeMap::new();
        for id in matched.iter().flatten() {
            for k in places.observers.get(id).into_iter().flatten() {
                *votes.entry(*k).or_default() += 1;
            }
        }
        let Some((&reference, _)) = votes.iter().max_by_key(|(k, n)| (**n, std::cmp::Reverse(**k))) else { return };
        let mut group: Vec<u64> = votes.keys().copied().collect();
        group.extend(places.covisible(reference).into_iter().take(10));
        group.sort_unstable();
        group.dedup();
        self.points = local_points(places, &group);
        self.reference = Some(reference);
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
            if let Some(old) = self.keyframe_poses.insert(k.id, k.world_from_cam) {
                delta.insert(k.id, k.world_from_cam * old.inverse());
            }
        }
        let newest = self.reference.and_then(|r| delta.get(&r).copied());
        if let (Some(d), Some(last)) = (newest, self.last) {
            self.last = Some(renormalised(&(d * last)));
        }
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

    /// Monocular: why the last attempt to initialise failed (`None` after a success).
    pub fn init_failure(&self) -> Option<&str> {
        self.init_failure.as_deref()
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
        }
        let incoming: BTreeSet<u64> = update.points.iter().map(|p| p.id).collect();
        for p in &update.points {
            self.points.insert(
                p.id,
                TPoint { position: p.position, descriptor: p.descriptor, first_keyframe: p.first_keyframe },
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

    /// Track one frame.
    pub fn track(&mut self, stamp: f64, features: &[Feature]) -> TrackingResult {
        let r = self.track_frame(stamp, features);
        // Lost frames (a dead-reckoned guess) stay out of the trajectory, as in ORB-SLAM2.
        if let (Some(pose), Some(k), false) = (r.pose, self.reference, r.state == TrackState::Lost)
            && let Some(kp) = self.keyframe_poses.get(&k)
        {
            self.anchors.push((stamp, k, kp.inverse() * pose));
        }
        r
    }

    fn track_frame(&mut self, stamp: f64, features: &[Feature]) -> TrackingResult {
        if self.unlocated {
            // A loaded map: no pose until the camera is found in it.
            let Some(f) = self.relocalise_in_map(features).filter(|f| f.inliers >= self.config.min_inliers) else {
                return self.untracked(None, TrackState::Lost, features.len());
            };
            self.unlocated = false;
            self.lost_run = 0;
            self.velocity = Isometry3::identity();
            self.last = Some(f.world_from_cam);
            if !self.mapping {
                self.follow_loaded_map(&f.matched);
            }
            return TrackingResult {
                pose: Some(f.world_from_cam),
                state: TrackState::Relocalised,
                matches: f.matches,
                inliers: f.inliers,
                map_points: self.points.len(),
                map_id: self.map_id,
                keyframe: None,
                matched: f.matched,
            };
        }
        let predicted = self.last.map(|l| renormalised(&(l * self.velocity)));
        if !self.initialised {
            let origin = predicted.unwrap_or_else(Isometry3::identity);
            if self.config.sensor == Sensor::Monocular {
                return self.start_monocular(stamp, features, origin);
            }
            return self.start_map(stamp, features, origin, TrackState::NewMap);
        }
        let predicted = predicted.unwrap_or_else(Isometry3::identity);
        let mut fit = self.track_projection(features, &predicted, self.config.search_radius);
        if fit.as_ref().is_none_or(|f| f.inliers < self.config.min_inliers) {
            fit = self.track_projection(features, &predicted, 3.0 * self.config.search_radius);
        }
        let mut state = TrackState::Tracked;
        if fit.as_ref().is_none_or(|f| f.inliers < self.config.min_inliers) {
            fit = self.relocalise(features);
            state = TrackState::Relocalised;
        }
        if fit.as_ref().is_none_or(|f| f.inliers < self.config.min_inliers) {
            // ORB-SLAM2's relocalisation: the whole map's key frames by bag of words.
            if let Some(f) = self.relocalise_in_map(features) {
                fit = Some(f);
            }
        }
        let finite = |f: &Fit| {
            let (t, q) = (f.world_from_cam.translation.vector, f.world_from_cam.rotation.coords);
            t.iter().chain(q.iter()).all(|v| v.is_finite())
        };
        match fit.filter(|f| f.inliers >= self.config.min_inliers && finite(f)) {
            Some(f) => {
                self.lost_run = 0;
                // After a relocalisation the motion since the last frame is unknown (ORB-SLAM
                // tracks the next frame against the reference key frame, without velocity).
                self.velocity = match (state, self.last) {
                    (TrackState::Tracked, Some(last)) => renormalised(&(last.inverse() * f.world_from_cam)),
                    _ => Isometry3::identity(),
                };
                self.last = Some(f.world_from_cam);
                self.frames_since_kf += 1;
                if !self.mapping {
                    self.follow_loaded_map(&f.matched);
                }
                let keyframe =
                    (self.mapping && self.need_keyframe(features, &f)).then(|| self.make_keyframe(stamp, features, &f));
                TrackingResult {
                    pose: Some(f.world_from_cam),
                    state,
                    matches: f.matches,
                    inliers: f.inliers,
                    map_points: self.points.len(),
                    map_id: self.map_id,
                    keyframe,
                    matched: f.matched,
                }
            }
            None => {
                // Only frames that show something count towards a new map: a blacked-out or
                // covered camera keeps trying to relocalise in the map it has.
                if features.iter().filter(|f| !f.dynamic).count() >= self.config.min_init_points {
                    self.lost_run += 1;
                }
                self.last = Some(predicted);
                if !self.mapping {
                    // Localisation mode: keep looking for the camera in the loaded map.
                } else if self.lost_run > self.config.reset_after && self.config.sensor == Sensor::Monocular {
                    // A single view cannot start a map: initialise again from two views (the
                    // new map at the dead-reckoned pose, in a scale of its own).
                    self.initialised = false;
                    self.init_ref = None;
                    self.points.clear();
                } else if self.lost_run > self.config.reset_after {
                    let r = self.start_map(stamp, features, predicted, TrackState::NewMap);
                    if r.state == TrackState::NewMap {
                        return r;
                    }
                }
                self.untracked(Some(predicted), TrackState::Lost, features.len())
            }
        }
    }

    /// ORB-SLAM2's `Relocalization` against every key frame of the map: candidates from the
    /// key-frame database by the frame's bag of words; for each, `SearchByBoW` (15 matches
    /// needed), P3P RANSAC and motion-only BA (10 inliers), then the candidate's and its
    /// covisible key frames' points projected for more matches and BA again; accepted with 50
    /// inliers. The tracker's local map becomes those key frames' points, and the candidate
    /// its reference key frame.
    fn relocalise_in_map(&mut self, features: &[Feature]) -> Option<Fit> {
        let places = self.places.take()?;
        let found = self.relocalise_with(&places, features);
        self.places = Some(places);
        found
    }

    fn relocalise_with(&mut self, places: &KeyFrameMap, features: &[Feature]) -> Option<Fit> {
        if places.map_id != self.map_id || places.kfs.is_empty() {
            return None;
        }
        let static_idx: Vec<usize> = (0..features.len()).filter(|&i| !features[i].dynamic).collect();
        let descriptors: Vec<[u8; 32]> = static_idx.iter().map(|&i| features[i].descriptor).collect();
        let (bow, index) = places.transform(&descriptors);
        let candidates = places.db.relocalisation_candidates(&bow, &|k| places.covisible(k));
        for (candidate, _) in candidates {
            let Some(kf) = places.kfs.get(&candidate) else { continue };
            let pairs = places.search_frame_by_bow(kf, features, &index, &static_idx);
            if pairs.len() < RELOCALISATION_BOW_MATCHES {
                continue;
            }
            let world: Vec<Point3<f64>> =
                pairs.iter().filter_map(|(_, id)| places.points.get(id).map(|p| p.position)).collect();
            if world.len() != pairs.len() {
                continue;
            }
            let pixels: Vec<[f64; 2]> = pairs.iter().map(|&(i, _)| features[i].uv).collect();
            let Some((pose, mask)) =
                p3p_ransac(&world, &pixels, &self.cam, self.config.ransac_threshold, 300, &mut self.rng)
            else {
                continue;
            };
            let mut group = vec![candidate];
            group.extend(places.covisible(candidate));
            let saved = std::mem::replace(&mut self.points, local_points(places, &group));
            let fit = self.optimise(features, &pairs, &pose, Some(mask));
            if fit.inliers >= RELOCALISATION_MIN_BA_INLIERS {
                let guided = self.track_projection(features, &fit.world_from_cam, 0.5 * self.config.search_radius);
                let best = match guided {
                    Some(g) if g.inliers > fit.inliers => g,
                    _ => fit,
                };
                if best.inliers >= RELOCALISATION_INLIERS {
                    self.reference = Some(candidate);
                    self.relocalisations += 1;
                    return Some(best);
                }
            }
            self.points = saved;
        }
        None
    }

    /// Relocalisations against the whole map so far.
    pub fn map_relocalisations(&self) -> usize {
        self.relocalisations
    }

    /// The result of a frame that was not tracked.
    fn untracked(&self, pose: Option<Isometry3<f64>>, state: TrackState, features: usize) -> TrackingResult {
        TrackingResult {
            pose,
            state,
            matches: 0,
            inliers: 0,
            map_points: self.points.len(),
            map_id: self.map_id,
            keyframe: None,
            matched: vec![None; features],
        }
    }

    fn usable(&self, f: &Feature) -> Option<f64> {
        f.depth.filter(|&d| !f.dynamic && d > 0.0 && d <= self.config.max_depth)
    }

    /// Start a map at `world_from_cam` from this frame's points with depth.
    fn start_map(
        &mut self,
        stamp: f64,
        features: &[Feature],
        world_from_cam: Isometry3<f64>,
        state: TrackState,
    ) -> TrackingResult {
        let with_depth = features.iter().filter(|f| self.usable(f).is_some()).count();
        if with_depth < self.config.min_init_points {
            let state = if self.initialised { TrackState::Lost } else { TrackState::NotInitialised };
            return self.untracked(self.last, state, features.len());
        }
        self.map_id += 1;
        self.points.clear();
        self.first_keyframe = self.next_keyframe;
        self.initialised = true;
        self.lost_run = 0;
        self.last = Some(world_from_cam);
        self.velocity = Isometry3::identity();
        let fit = Fit { world_from_cam, matches: 0, inliers: 0, matched: vec![None; features.len()] };
        let keyframe = Some(self.make_keyframe(stamp, features, &fit));
        TrackingResult {
            pose: Some(world_from_cam),
            state,
            matches: 0,
            inliers: 0,
            map_points: self.points.len(),
            map_id: self.map_id,
            keyframe,
            matched: vec![None; features.len()],
        }
    }

    /// Guided search around the predicted pose, then motion-only BA.
    fn track_projection(&self, features: &[Feature], predicted: &Isometry3<f64>, radius: f64) -> Option<Fit> {
        let cam_from_world = predicted.inverse();
        let static_idx: Vec<usize> = (0..features.len()).filter(|&i| !features[i].dynamic).collect();
        let pts: Vec<[f32; 2]> =
            static_idx.iter().map(|&i| [features[i].uv[0] as f32, features[i].uv[1] as f32]).collect();
        let grid = GridIndex::new(&pts, self.width.ceil() as usize, self.height.ceil() as usize, 32.0);
        // Best map point per feature: (point id, distance).
        let mut best: Vec<Option<(u64, u32)>> = vec![None; features.len()];
        for (&id, p) in &self.points {
            let pc = cam_from_world * p.position;
            let Some(uv) = self.cam.project(&pc) else { continue };
            if !(uv[0] >= 0.0 && uv[0] < self.width && uv[1] >= 0.0 && uv[1] < self.height) {
                continue;
            }
            let near = grid.within([uv[0] as f32, uv[1] as f32], radius as f32);
            let candidates = near.iter().map(|&c| static_idx[c as usize]).map(|i| (i, &features[i].descriptor));
            let Some((i1, d1, d2)) = nearest_two(&p.descriptor, candidates) else { continue };
            if d1 > self.config.max_distance {
                continue;
            }
            if d2 != u32::MAX && d1 as f32 > self.config.ratio * d2 as f32 {
                continue;
            }
            if best[i1].is_none_or(|(_, d)| d1 < d) {
                best[i1] = Some((id, d1));
            }
        }
        let pairs: Vec<(usize, u64)> = best.iter().enumerate().filter_map(|(i, b)| b.map(|(id, _)| (i, id))).collect();
        if pairs.len() < 4 {
            return None;
        }
        Some(self.optimise(features, &pairs, &cam_from_world, None))
    }

    /// Descriptor matching against every local point (cross-checked, ratio 0.9, `TH_HIGH`),
    /// P3P RANSAC and motion-only BA; then, as ORB-SLAM's relocalisation does, a projection
    /// search from that pose for the matches descriptors alone missed, and BA again.
    fn relocalise(&mut self, features: &[Feature]) -> Option<Fit> {
        let static_idx: Vec<usize> = (0..features.len()).filter(|&i| !features[i].dynamic).collect();
        let query: Vec<[u8; 32]> = static_idx.iter().map(|&i| features[i].descriptor).collect();
        let ids: Vec<u64> = self.points.keys().copied().collect();
        let train: Vec<[u8; 32]> = self.points.values().map(|p| p.descriptor).collect();
        let config = MatchConfig {
            ratio: 0.9,
            max_distance: self.config.max_distance,
            cross_check: true,
            ..MatchConfig::default()
        };
        let matches = match_brute_force(&query, &train, None, &config);
        let pairs: Vec<(usize, u64)> =
            matches.iter().map(|m| (static_idx[m.query as usize], ids[m.train as usize])).collect();
        // ORB-SLAM tries PnP from 15 matches on.
        if pairs.len() < 15 {
            return None;
        }
        let world: Vec<Point3<f64>> =
            pairs.iter().filter_map(|(_, id)| self.points.get(id).map(|p| p.position)).collect();
        let pixels: Vec<[f64; 2]> = pairs.iter().map(|&(i, _)| features[i].uv).collect();
        let (pose, mask) = p3p_ransac(&world, &pixels, &self.cam, self.config.ransac_threshold, 300, &mut self.rng)?;
        let fit = self.optimise(features, &pairs, &pose, Some(mask));
        if fit.inliers < 10 {
            return Some(fit);
        }
        let guided = self.track_projection(features, &fit.world_from_cam, 0.5 * self.config.search_radius);
        Some(match guided {
            Some(g) if g.inliers > fit.inliers => g,
            _ => fit,
        })
    }

    fn optimise(
        &self,
        features: &[Feature],
        pairs: &[(usize, u64)],
        cam_from_world: &Isometry3<f64>,
        mask: Option<Vec<bool>>,
    ) -> Fit {
        let obs: Vec<PoseObservation> = pairs
            .iter()
            .filter_map(|&(i, id)| {
                let f = &features[i];
                let p = self.points.get(&id)?;
                Some(PoseObservation {
                    point: p.position,
                    uv: f.uv,
                    sigma: sigma(self.config.scale_factor, f.octave),
                    depth: f.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth),
                })
            })
            .collect();
        let fit = optimize_pose(&obs, &self.cam, self.config.bf, cam_from_world, mask);
        let mut matched = vec![None; features.len()];
        let mut inliers = 0;
        for (&(i, id), &ok) in pairs.iter().zip(&fit.inliers) {
            if ok {
                matched[i] = Some(id);
                inliers += 1;
            }
        }
        Fit { world_from_cam: renormalised(&fit.pose.inverse()), matches: pairs.len(), inliers, matched }
    }

    fn need_keyframe(&self, features: &[Feature], fit: &Fit) -> bool {
        if self.config.sensor == Sensor::Monocular {
            // ORB-SLAM2, monocular: fewer than 90 % of the reference's points tracked (local
            // mapping is always idle in lockstep, so its other conditions hold).
            return (fit.inliers as f64) < 0.9 * self.ref_tracked as f64 && fit.inliers > 15;
        }
        let close = |f: &Feature| f.depth.is_some_and(|d| d > 0.0 && d <= self.config.th_depth) && !f.dynamic;
        let tracked_close = features.iter().zip(&fit.matched).filter(|(f, m)| m.is_some() && close(f)).count();
        let untracked_close = features.iter().zip(&fit.matched).filter(|(f, m)| m.is_none() && close(f)).count();
        let need_close = tracked_close < 100 && untracked_close > 70;
        // ORB-SLAM2 also asks whether local mapping is idle; in lockstep it always is.
        let fewer = (fit.inliers as f64) < 0.75 * self.ref_tracked as f64;
        (fewer || need_close || self.frames_since_kf >= self.config.max_frames) && fit.inliers > 15
    }

    /// A key frame: observations of the matched points, new points from depth.
    fn make_keyframe(&mut self, stamp: f64, features: &[Feature], fit: &Fit) -> SparseMap {
        let id = self.next_keyframe;
        self.next_keyframe += 1;
        self.keyframe_poses.insert(id, fit.world_from_cam);
        self.reference = Some(id);
        self.frames_since_kf = 0;
        let info = KeyFrameInfo { id, stamp, world_from_cam: fit.world_from_cam };
        let depth_of = |f: &Feature| f.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth);
        let mut observations = Vec::new();
        for (f, m) in features.iter().zip(&fit.matched) {
            if let Some(pid) = m {
                observations.push(Observation {
                    keyframe: id,
                    point: *pid,
                    uv: f.uv,
                    depth: depth_of(f),
                    octave: f.octave,
                });
            }
        }
        // New points: every unmatched keypoint with depth. ORB-SLAM2 creates only the close ones
        // here (at least 100) and triangulates the rest between key frames in local mapping;
        // with no triangulation step, depth gives all of them (as its RGB-D initialisation does).
        let mut candidates: Vec<(f64, usize)> = features
            .iter()
            .enumerate()
            .filter(|(i, _)| fit.matched[*i].is_none())
            .filter_map(|(i, f)| self.usable(f).map(|d| (d, i)))
            .collect();
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        if self.config.sensor == Sensor::Stereo && id > self.first_keyframe {
            let close = candidates.iter().take_while(|c| c.0 <= self.config.th_depth).count();
            candidates.truncate(close.max(STEREO_MIN_NEW_POINTS));
        }
        let mut points = Vec::new();
        let mut point_of: Vec<Option<u64>> = fit.matched.clone();
        for &(d, i) in &candidates {
            let f = &features[i];
            let pc =
                Point3::new((f.uv[0] - self.cam.cx) / self.cam.fx * d, (f.uv[1] - self.cam.cy) / self.cam.fy * d, d);
            let position = fit.world_from_cam * pc;
            let pid = self.next_point;
            self.next_point += 1;
            self.points.insert(pid, TPoint { position, descriptor: f.descriptor, first_keyframe: id });
            points.push(MapPoint { id: pid, position, descriptor: f.descriptor, observations: 1, first_keyframe: id });
            observations.push(Observation { keyframe: id, point: pid, uv: f.uv, depth: depth_of(f), octave: f.octave });
            point_of[i] = Some(pid);
        }
        let keypoints = features
            .iter()
            .zip(&point_of)
            .filter(|(f, _)| !f.dynamic)
            .map(|(f, p)| KeyFrameKeypoint {
                keyframe: id,
                uv: f.uv,
                octave: f.octave,
                depth: depth_of(f),
                descriptor: f.descriptor,
                point: *p,
            })
            .collect();
        // The reference for the next decision: points of this key frame seen twice (ORB-SLAM2's
        // `TrackedMapPoints(nMinObs)`), all of them while the map has at most two key frames.
        self.ref_tracked = fit.inliers + if id <= self.first_keyframe + 1 { points.len() } else { 0 };
        let features = if self.config.sensor == Sensor::Monocular {
            Self::candidates(id, features, &fit.matched)
        } else {
            Vec::new()
        };
        // The points it matched go along too: local mapping may have forgotten an old one that
        // relocalisation brought back (it keeps the ones it holds).
        for pid in fit.matched.iter().flatten() {
            if let Some(p) = self.points.get(pid) {
                points.push(MapPoint {
                    id: *pid,
                    position: p.position,
                    descriptor: p.descriptor,
                    observations: 0,
                    first_keyframe: p.first_keyframe,
                });
            }
        }
        let batch = SparseMap {
            map_id: self.map_id,
            keyframes: vec![info],
            points,
            observations,
            removed: Vec::new(),
            features,
            keypoints,
        };
        if let Some(places) = &mut self.places {
            places.switch_map(self.map_id);
            places.apply_refinements(&batch);
            if let Some((kf, bow)) = places.add_keyframe(&batch) {
                places.db.add(kf, bow);
            }
        }
        batch
    }

    /// A monocular key frame's keypoints for triangulation: static and unmatched.
    fn candidates(keyframe: u64, features: &[Feature], matched: &[Option<u64>]) -> Vec<KeyFrameFeature> {
        features
            .iter()
            .zip(matched)
            .filter(|(f, m)| m.is_none() && !f.dynamic)
            .map(|(f, _)| KeyFrameFeature { keyframe, uv: f.uv, octave: f.octave, descriptor: f.descriptor })
            .collect()
    }

    /// ORB-SLAM2's `SearchForInitialization`: each reference keypoint's best match among the
    /// current frame's within a 100 px window (Hamming <= 50, ratio 0.9), one-to-one (a
    /// current keypoint keeps its closest reference). Dynamic keypoints take no part.
    /// Deviations: every pyramid level takes part (ORB-SLAM2 extracts twice the features
    /// before initialising and matches level 0 only) and there is no orientation check (the
    /// keypoint angle does not reach tracking).
    fn initial_matches(&self, reference: &[Feature], current: &[Feature]) -> Vec<(usize, usize)> {
        let idx: Vec<usize> = (0..current.len()).filter(|&i| !current[i].dynamic).collect();
        let pts: Vec<[f32; 2]> = idx.iter().map(|&i| [current[i].uv[0] as f32, current[i].uv[1] as f32]).collect();
        let grid = GridIndex::new(&pts, self.width.ceil() as usize, self.height.ceil() as usize, 32.0);
        let mut best: Vec<Option<(usize, u32)>> = vec![None; current.len()];
        for (ri, r) in reference.iter().enumerate().filter(|(_, r)| !r.dynamic) {
            let near = grid.within([r.uv[0] as f32, r.uv[1] as f32], MONO_INIT_WINDOW);
            let candidates = near.iter().map(|&c| idx[c as usize]).map(|i| (i, &current[i].descriptor));
            let Some((i1, d1, d2)) = nearest_two(&r.descriptor, candidates) else { continue };
            if d1 > MONO_INIT_MAX_DISTANCE {
                continue;
            }
            if d2 != u32::MAX && d1 as f32 >= MONO_INIT_RATIO * d2 as f32 {
                continue;
            }
            if best[i1].is_none_or(|(_, d)| d1 < d) {
                best[i1] = Some((ri, d1));
            }
        }
        best.iter().enumerate().filter_map(|(ci, b)| b.map(|(ri, _)| (ri, ci))).collect()
    }

    /// ORB-SLAM2's two-view map of matched pixels: the motion and points, and the scale that
    /// sets the first view's median depth to 1; or why not (fewer than 100 points survive, as
    /// ORB-SLAM2 requires, or no positive median depth).
    fn two_view_map(&mut self, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> Result<(TwoViewInit, f64), String> {
        let init =
            initialise(p1, p2, &self.cam, &TwoViewConfig::default(), &mut self.rng).map_err(|e| e.to_string())?;
        let mut depths: Vec<f64> = init.points.iter().flatten().map(|p| p.z).collect();
        if depths.len() < MONO_INIT_MATCHES {
            return Err(format!("{} points triangulated; a monocular map needs {MONO_INIT_MATCHES}", depths.len()));
        }
        depths.sort_by(f64::total_cmp);
        let median = depths[depths.len() / 2];
        if !(median > 0.0 && median.is_finite()) {
            return Err(format!("median depth {median} of the initial points"));
        }
        Ok((init, 1.0 / median))
    }

    /// Monocular: try to start a map from the reference frame and this one.
    fn start_monocular(&mut self, stamp: f64, features: &[Feature], origin: Isometry3<f64>) -> TrackingResult {
        let state = if self.map_id > 0 { TrackState::Lost } else { TrackState::NotInitialised };
        let keypoints = features.iter().filter(|f| !f.dynamic).count();
        let Some((ref_stamp, reference)) = self.init_ref.take() else {
            if keypoints > MONO_INIT_MATCHES {
                self.init_ref = Some((stamp, features.to_vec()));
                self.init_failure = Some("waiting for a second view".into());
            } else {
                self.init_failure = Some(format!(
                    "{keypoints} static keypoints; a reference frame for initialisation needs more than {MONO_INIT_MATCHES}"
                ));
            }
            return self.untracked(None, state, features.len());
        };
        let matches = self.initial_matches(&reference, features);
        if matches.len() < MONO_INIT_MATCHES {
            // ORB-SLAM2: the current frame becomes the new reference.
            self.init_failure = Some(format!(
                "{} matches with the reference frame; initialisation needs {MONO_INIT_MATCHES}",
                matches.len()
            ));
            self.init_ref = (keypoints > MONO_INIT_MATCHES).then(|| (stamp, features.to_vec()));
            return self.untracked(None, state, features.len());
        }
        let p1: Vec<[f64; 2]> = matches.iter().map(|&(r, _)| reference[r].uv).collect();
        let p2: Vec<[f64; 2]> = matches.iter().map(|&(_, c)| features[c].uv).collect();
        let (init, scale) = match self.two_view_map(&p1, &p2) {
            Ok(m) => m,
            Err(why) => {
                // ORB-SLAM2 keeps the reference and tries again with the next frame.
                self.init_failure = Some(why);
                self.init_ref = Some((ref_stamp, reference));
                return self.untracked(None, state, features.len());
            }
        };
        let mut c2_from_c1 = init.cam2_from_cam1;
        c2_from_c1.translation.vector *= scale;
        let world_from_c1 = origin;
        let world_from_c2 = renormalised(&(world_from_c1 * c2_from_c1.inverse()));

        self.map_id += 1;
        self.points.clear();
        self.initialised = true;
        self.init_failure = None;
        self.lost_run = 0;
        self.velocity = Isometry3::identity();
        self.last = Some(world_from_c2);
        let (k0, k1) = (self.next_keyframe, self.next_keyframe + 1);
        self.next_keyframe += 2;
        self.keyframe_poses.insert(k0, world_from_c1);
        self.keyframe_poses.insert(k1, world_from_c2);
        self.reference = Some(k1);
        self.first_keyframe = k0;
        self.frames_since_kf = 0;
        let mut points = Vec::new();
        let mut observations = Vec::new();
        let mut matched0 = vec![None; reference.len()];
        let mut matched1 = vec![None; features.len()];
        for (&(r, c), p) in matches.iter().zip(&init.points) {
            let Some(p) = p else { continue };
            let position = world_from_c1 * Point3::from(p.coords * scale);
            let pid = self.next_point;
            self.next_point += 1;
            let (fr, fc) = (&reference[r], &features[c]);
            self.points.insert(pid, TPoint { position, descriptor: fc.descriptor, first_keyframe: k0 });
            points.push(MapPoint { id: pid, position, descriptor: fc.descriptor, observations: 2, first_keyframe: k0 });
            observations.push(Observation { keyframe: k0, point: pid, uv: fr.uv, depth: None, octave: fr.octave });
            observations.push(Observation { keyframe: k1, point: pid, uv: fc.uv, depth: None, octave: fc.octave });
            matched0[r] = Some(pid);
            matched1[c] = Some(pid);
        }
        self.ref_tracked = points.len();
        let mut candidates = Self::candidates(k0, &reference, &matched0);
        candidates.extend(Self::candidates(k1, features, &matched1));
        let keyframes = vec![
            KeyFrameInfo { id: k0, stamp: ref_stamp, world_from_cam: world_from_c1 },
            KeyFrameInfo { id: k1, stamp, world_from_cam: world_from_c2 },
        ];
        let inliers = points.len();
        let batch = SparseMap {
            map_id: self.map_id,
            keyframes,
            points,
            observations,
            removed: Vec::new(),
            features: candidates,
            // (Loop closing takes no monocular map: it would need Sim(3).)
            keypoints: Vec::new(),
        };
        TrackingResult {
            pose: Some(world_from_c2),
            state: TrackState::NewMap,
            matches: matches.len(),
            inliers,
            map_points: self.points.len(),
            map_id: self.map_id,
            keyframe: Some(batch),
            matched: matched1,
        }
    }
}

#[derive(Clone, Debug)]
struct Fit {
    world_from_cam: Isometry3<f64>,
    matches: usize,
    inliers: usize,
    matched: Vec<Option<u64>>,
}
