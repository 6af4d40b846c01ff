//! Relocalisation (ORB-SLAM2's `Relocalization`): P3P RANSAC against the recent key frames,
//! then by bag of words against every key frame of the map; and localisation in a loaded map.

use super::*;

impl Tracker {
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
    pub(super) fn follow_loaded_map(&mut self, matched: &[Option<u64>]) {
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

    /// ORB-SLAM2's `Relocalization` against every key frame of the map: candidates from the
    /// key-frame database by the frame's bag of words; for each, `SearchByBoW` (15 matches
    /// needed), P3P RANSAC and motion-only BA (10 inliers), then the candidate's and its
    /// covisible key frames' points projected for more matches and BA again; accepted with 50
    /// inliers. The tracker's local map becomes those key frames' points, and the candidate
    /// its reference key frame.
    pub(super) fn relocalise_in_map(&mut self, features: &[Feature]) -> Option<Fit> {
        let places = self.places.take()?;
        let found = self.relocalise_with(&places, features);
        self.places = Some(places);
        found
    }

    pub(super) fn relocalise_with(&mut self, places: &KeyFrameMap, features: &[Feature]) -> Option<Fit> {
        if places.map_id != self.map_id || places.kfs.is_empty() {
            return None;
        }
        let static_idx: Vec<usize> = (0..features.len()).filter(|&i| !features[i].dynamic).collect();
        let descriptors: Vec<[u8; 32]> = static_idx.iter().map(|&i| features[i].descriptor).collect();
        let (bow, index) = places.transform(&descriptors);
        let candidates = places.db.relocalisation_candidates(&bow, &|k| places.covisible(k));
        let ransac = relocalisation_ransac(self.config.ransac_threshold);
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
            let Some((pose, mask)) = p3p_ransac(&world, &pixels, &self.cam, &ransac, &mut self.rng.relocalise_map)
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

    /// Descriptor matching against every local point (cross-checked, ratio 0.9, `TH_HIGH`),
    /// P3P RANSAC and motion-only BA; then, as ORB-SLAM's relocalisation does, a projection
    /// search from that pose for the matches descriptors alone missed, and BA again.
    pub(super) fn relocalise(&mut self, features: &[Feature]) -> Option<Fit> {
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
        let ransac = relocalisation_ransac(self.config.ransac_threshold);
        let (pose, mask) = p3p_ransac(&world, &pixels, &self.cam, &ransac, &mut self.rng.relocalise_local)?;
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
}
