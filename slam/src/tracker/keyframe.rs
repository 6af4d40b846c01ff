//! Key frames: ORB-SLAM2's decision (`NeedNewKeyFrame`), the key frame with its new points
//! (`CreateNewKeyFrame`), and a new map started from one frame with depth.

use super::*;

impl Tracker {
    pub(super) fn need_keyframe(&self, stamp: f64, features: &[Feature], fit: &Fit) -> bool {
        let visual = self.need_visual_keyframe(features, fit);
        self.inertial_keyframe_rule(stamp, visual).unwrap_or(visual)
    }

    /// ORB-SLAM2's rules.
    fn need_visual_keyframe(&self, features: &[Feature], fit: &Fit) -> bool {
        if self.config.sensor == Sensor::Monocular {
            // ORB-SLAM2, monocular: fewer than 90 % of the reference's points tracked (local
            // mapping is always idle in lockstep, so its other conditions hold).
            return (fit.inliers as f64) < 0.9 * self.ref_tracked as f64 && fit.inliers > 15;
        }
        let close = |f: &Feature| f.depth.is_some_and(|d| d > 0.0 && d <= self.config.th_depth) && !f.dynamic;
        let tracked_close = features.iter().zip(&fit.matched).filter(|(f, m)| m.is_some() && close(f)).count();
        let untracked_close = features.iter().zip(&fit.matched).filter(|(f, m)| m.is_none() && close(f)).count();
        let need_close = tracked_close < 100 && untracked_close > 70;
        // ORB-SLAM2's `(c1a || c1b || c1c) && c2`: c1b (local mapping idle, `mMinFrames` 0)
        // always holds in lockstep, so c2 decides: fewer than 75 % of the reference's points
        // tracked, or too few close ones. `max_frames` (c1a) alone makes no key frame: a camera
        // that keeps seeing the same place adds none.
        let fewer = (fit.inliers as f64) < 0.75 * self.ref_tracked as f64;
        (fewer || need_close) && fit.inliers > 15
    }

    /// A key frame's static keypoints as the whole map keeps them, each with its point.
    pub(super) fn map_keypoints(&self, id: u64, features: &[Feature], point_of: &[Option<u64>]) -> Vec<MapKeypoint> {
        features
            .iter()
            .zip(point_of)
            .filter(|(f, _)| !f.dynamic)
            .map(|(f, p)| MapKeypoint {
                keyframe: id,
                uv: f.uv,
                octave: f.octave,
                depth: f.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth),
                descriptor: f.descriptor,
                point: *p,
            })
            .collect()
    }

    /// The whole map (relocalisation, the inertial window) takes a batch: its points and
    /// observations, then each key frame with its keypoints (`None`: the batch's own), whose
    /// words go into the key-frame database.
    pub(super) fn remember<const N: usize>(&mut self, batch: &SparseMap, keypoints: [Option<Vec<MapKeypoint>>; N]) {
        let Some(places) = &mut self.places else { return };
        places.switch_map(self.map_id);
        places.apply_refinements(batch);
        for keypoints in keypoints {
            let added = match keypoints {
                None => places.add_keyframe(batch),
                Some(keypoints) => places.add_keyframe(&SparseMap { keypoints, ..batch.clone() }),
            };
            if let Some((kf, bow)) = added {
                places.db.add(kf, bow);
            }
        }
    }

    /// A key frame: observations of the matched points, new points from depth.
    pub(super) fn make_keyframe(&mut self, stamp: f64, features: &[Feature], fit: &Fit) -> SparseMap {
        let id = self.next_keyframe;
        self.next_keyframe += 1;
        self.keyframe_poses.insert(id, fit.world_from_cam);
        self.reference = Some(id);
        let info = MapKeyFrame { id, stamp, world_from_cam: fit.world_from_cam };
        let depth_of = |f: &Feature| f.depth.filter(|&d| d > 0.0 && d <= self.config.max_depth);
        let mut observations = Vec::new();
        for (f, m) in features.iter().zip(&fit.matched) {
            if let Some(pid) = m {
                observations.push(MapObservation {
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
            let max_distance = pc.coords.norm() * sigma(self.config.scale_factor, f.octave);
            self.points.insert(pid, TPoint { position, descriptor: f.descriptor, first_keyframe: id, max_distance });
            points.push(MapPoint { id: pid, position, descriptor: f.descriptor, observations: 1, first_keyframe: id });
            observations.push(MapObservation {
                keyframe: id,
                point: pid,
                uv: f.uv,
                depth: depth_of(f),
                octave: f.octave,
            });
            point_of[i] = Some(pid);
        }
        let keypoints = self.map_keypoints(id, features, &point_of);
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
            culled: Vec::new(),
        };
        self.remember(&batch, [None]);
        self.imu_keyframe(id, stamp);
        // A monocular map just made metric goes to local mapping whole.
        self.imu_rescale().unwrap_or(batch)
    }

    /// Start a map at `world_from_cam` from this frame's points with depth.
    pub(super) fn start_map(
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
            world_from_cam: Some(world_from_cam),
            state,
            matches: 0,
            inliers: 0,
            map_points: self.points.len(),
            map_id: self.map_id,
            keyframe,
            matched: vec![None; features.len()],
        }
    }
}
