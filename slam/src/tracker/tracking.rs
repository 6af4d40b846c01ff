//! One frame tracked: the motion model's prediction, projection search against the local map
//! (ORB-SLAM2's `TrackWithMotionModel`, `TrackLocalMap`), motion-only BA.

use super::*;

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
        let mut fit = self.track_projection(features, &predicted, self.config.search_radius);
        if fit.as_ref().is_none_or(|f| f.inliers < self.config.min_inliers) {
            fit = self.track_projection(features, &predicted, 3.0 * self.config.search_radius);
        }
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

    /// Guided search around the predicted pose, then motion-only BA.
    pub(super) fn track_projection(
        &self,
        features: &[Feature],
        predicted: &Isometry3<f64>,
        radius: f64,
    ) -> Option<Fit> {
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
