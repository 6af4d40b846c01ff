//! One frame tracked: the motion model's prediction, the previous frame's points searched
//! around it (ORB-SLAM2's `TrackWithMotionModel`), motion-only BA, the local map searched
//! tightly around that pose (`TrackLocalMap`), motion-only BA again.

use super::*;
use dynaflow_vision::matching::hamming;

/// ORB-SLAM2's `TrackWithMotionModel`: fewer matches than this with the previous frame and
/// the search is widened twice; still fewer, the motion model fails.
const MOTION_MODEL_MIN_MATCHES: usize = 20;
/// ORB-SLAM2's `TrackWithMotionModel`: inliers after the first motion-only BA.
const MOTION_MODEL_MIN_INLIERS: usize = 10;
/// ORB-SLAM2's `SearchLocalPoints` just after a relocalisation (`th = 5`).
const RELOCALISED_LOCAL_SEARCH: f64 = 5.0;
/// ORB-SLAM2's `isInFrustum`: a point seen more than 60 degrees off its viewing direction is
/// not searched.
const VIEWING_COS_MIN: f64 = 0.5;
/// ORB-SLAM2's `RadiusByViewingCos`: within 3.6 degrees of its viewing direction a point's
/// search radius is 2.5 px, else 4.
const VIEWING_COS_FRONTAL: f64 = 0.998;

/// ORB-SLAM2's rotation-consistency check (`HISTO_LENGTH` 30, used as `1/HISTO_LENGTH` of a
/// degree: 30-degree bins): matches whose keypoints turned by an amount in one of the three
/// fullest bins are kept (the second and third only with a tenth of the first's count);
/// matches without both orientations are kept.
fn rotation_consistent(turns: &[Option<f32>]) -> Vec<bool> {
    const BIN_DEGREES: f32 = 30.0;
    const BINS: usize = 12;
    let bin = |t: f32| ((t / BIN_DEGREES).round() as usize) % BINS;
    let mut counts = [0usize; BINS];
    for t in turns.iter().flatten() {
        counts[bin(*t)] += 1;
    }
    let mut order: Vec<usize> = (0..BINS).collect();
    order.sort_by(|&a, &b| counts[b].cmp(&counts[a]).then(a.cmp(&b)));
    let top = counts[order[0]];
    let mut good = [false; BINS];
    for (rank, &b) in order.iter().take(3).enumerate() {
        good[b] = counts[b] > 0 && (rank == 0 || 10 * counts[b] >= top);
    }
    turns.iter().map(|t| t.is_none_or(|t| good[bin(t)])).collect()
}

/// ORB-SLAM2's pyramid levels (`nLevels`; the `orb_extract` operator's default).
const ORB_LEVELS: i32 = 8;

/// Where a point should be seen from a distance.
enum Level {
    /// Beyond the distances its levels cover (ORB-SLAM2's `isInFrustum`: 0.8 of the nearest,
    /// 1.2 of the farthest).
    Outside,
    /// On this level (ORB-SLAM2's `PredictScale`).
    At(u8),
}

/// The level a point with level-0 distance `max_distance` is seen on at distance `dist`;
/// `None` for a point of unknown scale.
fn predicted_level(max_distance: f64, dist: f64, scale: f64) -> Option<Level> {
    if max_distance <= 0.0 || scale <= 1.0 {
        return None;
    }
    let min_distance = max_distance / scale.powi(ORB_LEVELS - 1);
    if !(dist >= 0.8 * min_distance && dist <= 1.2 * max_distance) {
        return Some(Level::Outside);
    }
    let level = ((max_distance / dist).ln() / scale.ln()).ceil().clamp(0.0, f64::from(ORB_LEVELS - 1));
    Some(Level::At(level as u8))
}

/// A frame's static keypoints in a grid, for the projection searches.
struct FrameIndex {
    static_idx: Vec<usize>,
    grid: GridIndex,
}

impl FrameIndex {
    fn new(features: &[Feature], width: f64, height: f64) -> Self {
        let static_idx: Vec<usize> = (0..features.len()).filter(|&i| !features[i].dynamic).collect();
        let pts: Vec<[f32; 2]> =
            static_idx.iter().map(|&i| [features[i].uv[0] as f32, features[i].uv[1] as f32]).collect();
        Self { static_idx, grid: GridIndex::new(&pts, width.ceil() as usize, height.ceil() as usize, 32.0) }
    }
}

impl Tracker {
    pub(super) fn track_frame(&mut self, stamp: f64, features: &[Feature]) -> TrackingResult {
        if self.unlocated {
            // A loaded map: no pose until the camera is found in it.
            let Some(f) = self.relocalise_in_map(features).filter(|f| f.inliers >= self.relocalisation_min()) else {
                return self.untracked(None, TrackState::Lost, features.len());
            };
            self.unlocated = false;
            self.lost_run = 0;
            self.relocalised_at = Some(stamp);
            self.velocity = Isometry3::identity();
            self.last = Some(f.world_from_cam);
            if !self.mapping {
                self.follow_loaded_map(&f.matched);
            }
            return TrackingResult {
                world_from_cam: Some(f.world_from_cam),
                state: TrackState::Relocalised,
                matches: f.matches,
                inliers: f.inliers,
                map_points: self.points.len(),
                map_id: self.map_id,
                keyframe: None,
                matched: f.matched,
            };
        }
        // With an initialised IMU its prediction; otherwise the constant-velocity model.
        let predicted = self.imu_prediction().or_else(|| self.last.map(|l| renormalised(&(l * self.velocity))));
        if !self.initialised {
            let origin = predicted.unwrap_or_else(Isometry3::identity);
            if self.config.sensor == Sensor::Monocular {
                return self.start_monocular(stamp, features, origin);
            }
            return self.start_map(stamp, features, origin, TrackState::NewMap);
        }
        let predicted = predicted.unwrap_or_else(Isometry3::identity);
        let mut fit = if self.config.two_stage {
            let mut fit = self.track_motion_model(stamp, features, &predicted);
            // When the previous frame's points do not carry the pose: the whole local map
            // around the prediction, then three times as wide (ORB-SLAM2 falls back on its
            // reference key frame's bag of words here).
            for radius in [1.0, 3.0].map(|k| k * self.config.search_radius) {
                if fit.as_ref().is_some_and(|f| f.inliers >= self.config.min_inliers) {
                    break;
                }
                let wide = self.track_projection(features, &predicted, radius);
                if wide.as_ref().is_some_and(|w| fit.as_ref().is_none_or(|f| w.inliers > f.inliers)) {
                    fit = wide;
                }
            }
            fit
        } else {
            // One search of the whole local map around the prediction, widened once.
            let fit = self.track_projection(features, &predicted, self.config.search_radius);
            if fit.as_ref().is_none_or(|f| f.inliers < self.config.min_inliers) {
                self.track_projection(features, &predicted, 3.0 * self.config.search_radius)
            } else {
                fit
            }
        };
        let mut state = TrackState::Tracked;
        // Within a second of a relocalisation a pose needs more support (ORB-SLAM2).
        let probation = self.relocalised_at.is_some_and(|t| stamp - t < RELOCALISATION_PROBATION_S);
        let tracked_min = if probation { self.relocalisation_min() } else { self.config.min_inliers };
        // Without a vocabulary: P3P on descriptor matches against the local map. With one,
        // ORB-SLAM2's relocalisation only: key frames that look alike by their words first (a
        // brute-force match against every point lets a repeated texture, the same brick on
        // another wall, pass for the place).
        if fit.as_ref().is_none_or(|f| f.inliers < tracked_min) {
            state = TrackState::Relocalised;
            if self.places.is_none() {
                fit = self.relocalise(features);
            }
        }
        if fit.as_ref().is_none_or(|f| f.inliers < self.relocalisation_min()) {
            // ORB-SLAM2's relocalisation: the whole map's key frames by bag of words.
            if let Some(f) = self.relocalise_in_map(features)
                && fit.as_ref().is_none_or(|g| f.inliers > g.inliers)
            {
                fit = Some(f);
            }
        }
        let finite = |f: &Fit| {
            let (t, q) = (f.world_from_cam.translation.vector, f.world_from_cam.rotation.coords);
            t.iter().chain(q.iter()).all(|v| v.is_finite())
        };
        let needed = if state == TrackState::Relocalised { self.relocalisation_min() } else { tracked_min };
        match fit.filter(|f| f.inliers >= needed && finite(f)) {
            Some(mut f) => {
                if state == TrackState::Relocalised {
                    self.relocalised_at = Some(stamp);
                }
                self.inertial_follow(&mut f, features, stamp);
                self.lost_run = 0;
                // After a relocalisation the motion since the last frame is unknown (ORB-SLAM
                // tracks the next frame against the reference key frame, without velocity).
                self.velocity = match (state, self.last) {
                    (TrackState::Tracked, Some(last)) => renormalised(&(last.inverse() * f.world_from_cam)),
                    _ => Isometry3::identity(),
                };
                self.last = Some(f.world_from_cam);
                if !self.mapping {
                    self.follow_loaded_map(&f.matched);
                }
                let keyframe = (self.mapping && self.need_keyframe(stamp, features, &f))
                    .then(|| self.make_keyframe(stamp, features, &f));
                TrackingResult {
                    world_from_cam: Some(f.world_from_cam),
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
                // An initialised IMU carries the pose through what vision cannot track.
                if let Some(r) = self.imu_only(stamp, features.len()) {
                    return r;
                }
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

    /// ORB-SLAM2's `TrackWithMotionModel` then `TrackLocalMap`: the previous frame's points
    /// searched around the predicted pose, motion-only BA; then the local map's other points
    /// searched tightly around that pose, and BA on all the matches.
    pub(super) fn track_motion_model(
        &self,
        stamp: f64,
        features: &[Feature],
        predicted: &Isometry3<f64>,
    ) -> Option<Fit> {
        if self.last_matched.is_empty() {
            return None;
        }
        let index = FrameIndex::new(features, self.width, self.height);
        let th = self.config.search_radius;
        let mut pairs = self.search_last_frame(features, &index, predicted, th);
        if pairs.len() < MOTION_MODEL_MIN_MATCHES {
            pairs = self.search_last_frame(features, &index, predicted, 2.0 * th);
        }
        if pairs.len() < MOTION_MODEL_MIN_MATCHES {
            return None;
        }
        let first = self.optimise(features, &pairs, &predicted.inverse(), None);
        if first.inliers < MOTION_MODEL_MIN_INLIERS {
            return None;
        }
        let mut pairs: Vec<(usize, u64)> =
            first.matched.iter().enumerate().filter_map(|(i, m)| m.map(|id| (i, id))).collect();
        let th = if self.last_relocalised {
            RELOCALISED_LOCAL_SEARCH
        } else {
            self.inertial_local_search(stamp).unwrap_or(self.config.local_search)
        };
        let more = self.search_local_points(features, &index, &first.world_from_cam, &pairs, th);
        pairs.extend(more);
        Some(self.optimise(features, &pairs, &first.world_from_cam.inverse(), None))
    }

    /// ORB-SLAM2's `SearchByProjection` of the last frame: each of its points projected at the
    /// predicted pose, the nearest descriptor within `radius` times the scale of the level that
    /// saw it, on that level and its neighbours (moving forward, that level and coarser ones;
    /// backward, it and finer ones), under `TH_HIGH`; no ratio test.
    fn search_last_frame(
        &self,
        features: &[Feature],
        index: &FrameIndex,
        predicted: &Isometry3<f64>,
        radius: f64,
    ) -> Vec<(usize, u64)> {
        let cam_from_world = predicted.inverse();
        // The camera's motion along its last axis, against the baseline (ORB-SLAM2's `tlc.z`
        // against `mb`); a single camera has none to judge it by.
        let along = self.last.map_or(0.0, |l| (l.inverse() * predicted).translation.vector.z);
        let baseline = if self.config.bf > 0.0 { self.config.bf / self.cam.fx } else { f64::INFINITY };
        let (forward, backward) = (along > baseline, along < -baseline);
        let mut best: Vec<Option<(u64, u32, f32)>> = vec![None; features.len()];
        for &LastMatch { point: id, octave, angle } in &self.last_matched {
            let Some(position) = self.point_position(id) else { continue };
            let Some(uv) = self.in_image(&(cam_from_world * position)) else { continue };
            let (lo, hi) = if forward {
                (octave, u8::MAX)
            } else if backward {
                (0, octave)
            } else {
                (octave.saturating_sub(1), octave.saturating_add(1))
            };
            let r = radius * sigma(self.config.scale_factor, octave);
            let Some(descriptor) = self.point_descriptor(id) else { continue };
            let mut nearest: Option<(usize, u32)> = None;
            for c in index.grid.within([uv[0] as f32, uv[1] as f32], r as f32) {
                let i = index.static_idx[c as usize];
                if !(lo..=hi).contains(&features[i].octave) {
                    continue;
                }
                let d = hamming(descriptor, &features[i].descriptor);
                if nearest.is_none_or(|(_, b)| d < b) {
                    nearest = Some((i, d));
                }
            }
            if let Some((i, d)) = nearest.filter(|&(_, d)| d <= self.config.max_distance)
                && best[i].is_none_or(|(_, b, _)| d < b)
            {
                best[i] = Some((id, d, angle));
            }
        }
        let pairs: Vec<(usize, u64, f32)> =
            best.iter().enumerate().filter_map(|(i, b)| b.map(|(id, _, a)| (i, id, a))).collect();
        let turns: Vec<Option<f32>> = pairs
            .iter()
            .map(|&(i, _, last)| {
                let now = features[i].angle;
                (last >= 0.0 && now >= 0.0).then(|| (last - now).rem_euclid(360.0))
            })
            .collect();
        let keep = rotation_consistent(&turns);
        pairs.iter().zip(keep).filter(|(_, k)| *k).map(|(&(i, id, _), _)| (i, id)).collect()
    }

    /// ORB-SLAM2's `SearchLocalPoints`: each local-map point not yet matched, projected at the
    /// refined pose, matched to the nearest keypoint within `th` x 2.5 px (4 when the point is
    /// seen more than 3.6 degrees off the ray it was made from, which stands in for ORB-SLAM2's
    /// mean viewing direction; none beyond 60 degrees) times the scale of the keypoint's level;
    /// the ratio test only between two keypoints of one level, as ORB-SLAM2 applies it.
    fn search_local_points(
        &self,
        features: &[Feature],
        index: &FrameIndex,
        world_from_cam: &Isometry3<f64>,
        taken: &[(usize, u64)],
        th: f64,
    ) -> Vec<(usize, u64)> {
        let cam_from_world = world_from_cam.inverse();
        let centre = world_from_cam.translation.vector;
        let mut used = vec![false; features.len()];
        for &(i, _) in taken {
            used[i] = true;
        }
        let matched: BTreeSet<u64> = taken.iter().map(|&(_, id)| id).collect();
        let scale = self.config.scale_factor;
        let coarsest = features.iter().map(|f| f.octave).max().unwrap_or(0);
        let mut best: Vec<Option<(u64, u32)>> = vec![None; features.len()];
        for (&id, p) in &self.points {
            if matched.contains(&id) {
                continue;
            }
            let Some(uv) = self.in_image(&(cam_from_world * p.position)) else { continue };
            let ray = p.position.coords - centre;
            let made = self.keyframe_poses.get(&p.first_keyframe).map(|k| p.position.coords - k.translation.vector);
            let cos = made.map_or(0.0, |m| ray.dot(&m) / (ray.norm() * m.norm()).max(f64::MIN_POSITIVE));
            if made.is_some() && cos < VIEWING_COS_MIN {
                continue;
            }
            let r = th * if cos > VIEWING_COS_FRONTAL { 2.5 } else { 4.0 };
            // The level it should be seen on from here (ORB-SLAM2's `PredictScale`), and only
            // within the distances its levels cover; a point of unknown scale is looked for on
            // every level, each at its own radius.
            let levels = match predicted_level(p.max_distance, ray.norm(), scale) {
                Some(Level::Outside) => continue,
                Some(Level::At(l)) => Some((l.saturating_sub(1), l)),
                None => None,
            };
            let widest = levels.map_or(coarsest, |(_, hi)| hi);
            // (feature, distance, level) of the nearest; (distance, level) of the next.
            let mut first: Option<(usize, u32, u8)> = None;
            let mut second: Option<(u32, u8)> = None;
            for c in index.grid.within([uv[0] as f32, uv[1] as f32], (r * sigma(scale, widest)) as f32) {
                let i = index.static_idx[c as usize];
                let f = &features[i];
                let reach = r * sigma(scale, levels.map_or(f.octave, |(_, hi)| hi));
                if used[i]
                    || levels.is_some_and(|(lo, hi)| !(lo..=hi).contains(&f.octave))
                    || (f.uv[0] - uv[0]).powi(2) + (f.uv[1] - uv[1]).powi(2) > reach * reach
                {
                    continue;
                }
                let d = hamming(&p.descriptor, &f.descriptor);
                if first.is_none_or(|(_, b, _)| d < b) {
                    second = first.map(|(_, b, o)| (b, o));
                    first = Some((i, d, f.octave));
                } else if second.is_none_or(|(b, _)| d < b) {
                    second = Some((d, f.octave));
                }
            }
            let Some((i, d1, o1)) = first else { continue };
            if d1 > self.config.max_distance {
                continue;
            }
            if let Some((d2, o2)) = second
                && o1 == o2
                && d1 as f32 > self.config.ratio * d2 as f32
            {
                continue;
            }
            if best[i].is_none_or(|(_, b)| d1 < b) {
                best[i] = Some((id, d1));
            }
        }
        best.iter().enumerate().filter_map(|(i, b)| b.map(|(id, _)| (i, id))).collect()
    }

    /// A camera-frame point's pixel, if it lies in front of the camera and in the image.
    fn in_image(&self, pc: &Point3<f64>) -> Option<[f64; 2]> {
        let uv = self.cam.project(pc)?;
        (uv[0] >= 0.0 && uv[0] < self.width && uv[1] >= 0.0 && uv[1] < self.height).then_some(uv)
    }

    /// A map point's position: the local map's, else the whole map's.
    fn point_position(&self, id: u64) -> Option<Point3<f64>> {
        self.points.get(&id).map(|p| p.position).or_else(|| self.places.as_ref()?.points.get(&id).map(|p| p.position))
    }

    /// A map point's descriptor: the local map's, else the whole map's.
    fn point_descriptor(&self, id: u64) -> Option<&[u8; 32]> {
        self.points
            .get(&id)
            .map(|p| &p.descriptor)
            .or_else(|| self.places.as_ref()?.points.get(&id).map(|p| &p.descriptor))
    }

    /// This frame's points as the next frame's motion model searches them: a key frame's
    /// keypoints with their points (its new ones included), else the tracked matches.
    pub(super) fn remember_last_frame(&mut self, features: &[Feature], r: &TrackingResult) {
        self.last_relocalised = r.state == TrackState::Relocalised;
        if !self.config.two_stage {
            // Only the two searches read it.
            return;
        }
        let last = |f: &Feature, p: u64| LastMatch { point: p, octave: f.octave, angle: f.angle };
        let newest = r.keyframe.as_ref().and_then(|k| k.keyframes.iter().map(|k| k.id).max());
        let kept: Vec<&MapKeypoint> = match (&r.keyframe, newest) {
            (Some(batch), Some(newest)) => batch.keypoints.iter().filter(|k| k.keyframe == newest).collect(),
            _ => Vec::new(),
        };
        let statics: Vec<&Feature> = features.iter().filter(|f| !f.dynamic).collect();
        self.last_matched = if !kept.is_empty() && kept.len() == statics.len() {
            // A key frame's keypoints are its static features, in order.
            statics.iter().zip(kept).filter_map(|(f, k)| k.point.map(|p| last(f, p))).collect()
        } else {
            features.iter().zip(&r.matched).filter_map(|(f, m)| m.map(|p| last(f, p))).collect()
        };
    }

    /// Guided search around the predicted pose, then motion-only BA.
    pub(super) fn track_projection(
        &self,
        features: &[Feature],
        predicted: &Isometry3<f64>,
        radius: f64,
    ) -> Option<Fit> {
        let cam_from_world = predicted.inverse();
        let index = FrameIndex::new(features, self.width, self.height);
        // Best map point per feature: (point id, distance).
        let mut best: Vec<Option<(u64, u32)>> = vec![None; features.len()];
        for (&id, p) in &self.points {
            let Some(uv) = self.in_image(&(cam_from_world * p.position)) else { continue };
            let near = index.grid.within([uv[0] as f32, uv[1] as f32], radius as f32);
            let candidates = near.iter().map(|&c| index.static_idx[c as usize]).map(|i| (i, &features[i].descriptor));
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

    pub(super) fn optimise(
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
                Some(self.observation(p.position, f.uv, f.octave, f.depth))
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
        Fit { world_from_cam: renormalised(&fit.cam_from_world.inverse()), matches: pairs.len(), inliers, matched }
    }

    /// A keypoint's observation of a map point at `point`: its sigma by pyramid level, its
    /// measured depth where the sensor's range allows (`max_depth`).
    pub(super) fn observation(
        &self,
        point: Point3<f64>,
        uv: [f64; 2],
        octave: u8,
        depth: Option<f64>,
    ) -> PoseObservation {
        PoseObservation {
            point,
            uv,
            sigma: sigma(self.config.scale_factor, octave),
            depth: depth.filter(|&d| d > 0.0 && d <= self.config.max_depth),
        }
    }

    /// The result of a frame that was not tracked.
    pub(super) fn untracked(
        &self,
        world_from_cam: Option<Isometry3<f64>>,
        state: TrackState,
        features: usize,
    ) -> TrackingResult {
        TrackingResult {
            world_from_cam,
            state,
            matches: 0,
            inliers: 0,
            map_points: self.points.len(),
            map_id: self.map_id,
            keyframe: None,
            matched: vec![None; features],
        }
    }

    /// Inliers a relocalised pose needs: ORB-SLAM2's [`RELOCALISATION_MIN_INLIERS`], or the
    /// tracking minimum where that is set higher.
    fn relocalisation_min(&self) -> usize {
        RELOCALISATION_MIN_INLIERS.max(self.config.min_inliers)
    }

    pub(super) fn usable(&self, f: &Feature) -> Option<f64> {
        f.depth.filter(|&d| !f.dynamic && d > 0.0 && d <= self.config.max_depth)
    }
}
