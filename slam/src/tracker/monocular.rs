//! Monocular initialisation (ORB-SLAM2's `MonocularInitialization`): two views with enough
//! matches and parallax, H or F by score ratio, the first points triangulated.

use super::*;

impl Tracker {
    /// Monocular: why the last attempt to initialise failed (`None` after a success).
    pub fn init_failure(&self) -> Option<&str> {
        self.init_failure.as_deref()
    }

    /// A monocular key frame's keypoints for triangulation: static and unmatched.
    pub(super) fn candidates(keyframe: u64, features: &[Feature], matched: &[Option<u64>]) -> Vec<MapFeature> {
        features
            .iter()
            .zip(matched)
            .filter(|(f, m)| m.is_none() && !f.dynamic)
            .map(|(f, _)| MapFeature { keyframe, uv: f.uv, octave: f.octave, descriptor: f.descriptor })
            .collect()
    }

    /// ORB-SLAM2's `SearchForInitialization`: each reference keypoint's best match among the
    /// current frame's within a 100 px window (Hamming <= 50, ratio 0.9), one-to-one (a
    /// current keypoint keeps its closest reference). Dynamic keypoints take no part.
    /// Deviations: every pyramid level takes part (ORB-SLAM2 extracts twice the features
    /// before initialising and matches level 0 only) and there is no orientation check (the
    /// keypoint angle does not reach tracking).
    pub(super) fn initial_matches(&self, reference: &[Feature], current: &[Feature]) -> Vec<(usize, usize)> {
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
    pub(super) fn two_view_map(&mut self, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> Result<(TwoViewInit, f64), String> {
        let init = initialise(p1, p2, &self.cam, &TwoViewConfig::default(), &mut self.rng.initialise)
            .map_err(|e| e.to_string())?;
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
    pub(super) fn start_monocular(
        &mut self,
        stamp: f64,
        features: &[Feature],
        origin: Isometry3<f64>,
    ) -> TrackingResult {
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
            let max_distance = (position - world_from_c2.translation.vector).coords.norm()
                * sigma(self.config.scale_factor, fc.octave);
            self.points.insert(pid, TPoint { position, descriptor: fc.descriptor, first_keyframe: k0, max_distance });
            points.push(MapPoint { id: pid, position, descriptor: fc.descriptor, observations: 2, first_keyframe: k0 });
            observations.push(MapObservation { keyframe: k0, point: pid, uv: fr.uv, depth: None, octave: fr.octave });
            observations.push(MapObservation { keyframe: k1, point: pid, uv: fc.uv, depth: None, octave: fc.octave });
            matched0[r] = Some(pid);
            matched1[c] = Some(pid);
        }
        self.ref_tracked = points.len();
        let mut candidates = Self::candidates(k0, &reference, &matched0);
        candidates.extend(Self::candidates(k1, features, &matched1));
        let keyframes = vec![
            MapKeyFrame { id: k0, stamp: ref_stamp, world_from_cam: world_from_c1 },
            MapKeyFrame { id: k1, stamp, world_from_cam: world_from_c2 },
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
            culled: Vec::new(),
        };
        // The whole map keeps both key frames (relocalisation, the inertial window), as
        // ORB-SLAM2's key-frame database does.
        if self.places.is_some() {
            let keypoints = [
                Some(self.map_keypoints(k0, &reference, &matched0)),
                Some(self.map_keypoints(k1, features, &matched1)),
            ];
            self.remember(&batch, keypoints);
        }
        // (Two key frames are too few for the IMU's initialisation: no rescaling here.)
        self.imu_monocular_map((k0, ref_stamp), (k1, stamp));
        TrackingResult {
            world_from_cam: Some(world_from_c2),
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
