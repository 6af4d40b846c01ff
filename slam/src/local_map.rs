//! ORB-SLAM's local mapping for RGB-D: key frames arrive from tracking with their
//! observations and new points; each new key frame's covisible neighbours form the local
//! window, whose poses and points are refined by local BA (two stages, outliers dropped in
//! between, as ORB-SLAM's `LocalBundleAdjustment`), key frames outside the window that see its
//! points held fixed. Afterwards bad observations are erased and points culled (ORB-SLAM's
//! `MapPointCulling`: two key frames after creation a point must be seen by at least two key
//! frames). Memory stays bounded: the oldest key frames are forgotten beyond `keep_keyframes`
//! (there is no loop closing to need them).
//!
//! Not done (yet): ORB-SLAM's triangulation of new points between neighbours and the fusion
//! of duplicate points; with RGB-D, tracking creates points from depth at every key frame.

use std::collections::{BTreeMap, BTreeSet};

use dynaflow_vision::camera::Pinhole;
use nalgebra::Point3;

use crate::ba::{BaObservation, BaPose, BaReport, bundle_adjust, chi2, chi2_bound};
use crate::map::{KeyFrameInfo, MapPoint, Observation, SparseMap, sigma};

/// Local-mapping settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalMapConfig {
    /// Key frames in the local window (the new one and its best covisible neighbours).
    pub window: usize,
    /// Key frames remembered at most (oldest forgotten first).
    pub keep_keyframes: usize,
    /// `fx` times the virtual baseline (ORB-SLAM2's `bf`), for the depth residual.
    pub bf: f64,
    /// ORB pyramid scale factor (observation sigma `scale^octave`).
    pub scale_factor: f64,
    /// LM iterations of the first and of the second BA stage (ORB-SLAM: 5 and 10).
    pub iterations: (usize, usize),
}

impl LocalMapConfig {
    /// ORB-SLAM2's defaults for an RGB-D camera with focal length `fx` (virtual baseline 8 cm).
    pub fn rgbd(fx: f64) -> Self {
        Self { window: 10, keep_keyframes: 60, bf: fx * 0.08, scale_factor: 1.2, iterations: (5, 10) }
    }
}

#[derive(Clone, Debug)]
struct Kf {
    info: KeyFrameInfo,
    obs: Vec<Observation>,
}

#[derive(Clone, Debug)]
struct Mp {
    point: MapPoint,
    /// Key frames observing it.
    kfs: Vec<u64>,
    /// ORB-SLAM's observation count: 2 for an RGB-D observation, 1 for a pixel alone.
    weight: u32,
}

/// Local mapping state.
#[derive(Debug)]
pub struct LocalMapper {
    config: LocalMapConfig,
    cam: Pinhole,
    map_id: u32,
    kfs: BTreeMap<u64, Kf>,
    points: BTreeMap<u64, Mp>,
    last: BaReport,
}

impl LocalMapper {
    /// An empty map.
    pub fn new(config: LocalMapConfig, cam: Pinhole) -> Self {
        Self { config, cam, map_id: 0, kfs: BTreeMap::new(), points: BTreeMap::new(), last: BaReport::default() }
    }

    /// Key frames held.
    pub fn keyframes(&self) -> usize {
        self.kfs.len()
    }

    /// Points held.
    pub fn points(&self) -> usize {
        self.points.len()
    }

    /// The last local BA.
    pub fn last_ba(&self) -> BaReport {
        self.last
    }

    /// Every point held.
    pub fn all_points(&self) -> impl Iterator<Item = &MapPoint> {
        self.points.values().map(|m| &m.point)
    }

    /// Take one key frame from tracking (`batch`: one key frame, its observations, new
    /// points), run local BA and culling, and return the local map: the window's key frames
    /// and points with refined positions, and the ids of removed points.
    pub fn insert(&mut self, batch: &SparseMap) -> SparseMap {
        let mut removed = Vec::new();
        if batch.map_id != self.map_id {
            self.kfs.clear();
            self.points.clear();
            self.map_id = batch.map_id;
        }
        let Some(info) = batch.keyframes.first().copied() else {
            return SparseMap { map_id: self.map_id, ..SparseMap::default() };
        };
        for p in &batch.points {
            self.points.entry(p.id).or_insert(Mp { point: *p, kfs: Vec::new(), weight: 0 });
        }
        let mut obs = Vec::new();
        for o in batch.observations.iter().filter(|o| o.keyframe == info.id) {
            if let Some(mp) = self.points.get_mut(&o.point)
                && !mp.kfs.contains(&info.id)
            {
                mp.kfs.push(info.id);
                mp.weight += if o.depth.is_some() { 2 } else { 1 };
                obs.push(*o);
            }
        }
        self.kfs.insert(info.id, Kf { info, obs });

        // Covisibility of the new key frame; the window is it and its best neighbours.
        let mut shared: BTreeMap<u64, usize> = BTreeMap::new();
        if let Some(kf) = self.kfs.get(&info.id) {
            for o in &kf.obs {
                if let Some(mp) = self.points.get(&o.point) {
                    for &k in mp.kfs.iter().filter(|&&k| k != info.id) {
                        *shared.entry(k).or_default() += 1;
                    }
                }
            }
        }
        let mut neighbours: Vec<(u64, usize)> = shared.into_iter().collect();
        neighbours.sort_by_key(|&(k, n)| (std::cmp::Reverse(n), std::cmp::Reverse(k)));
        let mut window: Vec<u64> = vec![info.id];
        window.extend(neighbours.iter().take(self.config.window.saturating_sub(1)).map(|&(k, _)| k));
        let window_set: BTreeSet<u64> = window.iter().copied().collect();
        let mut local: BTreeSet<u64> = BTreeSet::new();
        for k in &window {
            if let Some(kf) = self.kfs.get(k) {
                local.extend(kf.obs.iter().map(|o| o.point).filter(|p| self.points.contains_key(p)));
            }
        }
        let mut fixed: BTreeSet<u64> = BTreeSet::new();
        for p in &local {
            if let Some(mp) = self.points.get(p) {
                fixed.extend(mp.kfs.iter().filter(|k| !window_set.contains(k)));
            }
        }
        // Gauge: with no key frame outside the window, the oldest one is held.
        let oldest = window.iter().min().copied();

        // Build and solve the BA problem.
        let mut pose_ids: Vec<u64> = window.clone();
        pose_ids.extend(fixed.iter().copied());
        let pose_index: BTreeMap<u64, usize> = pose_ids.iter().enumerate().map(|(i, &k)| (k, i)).collect();
        let mut poses: Vec<BaPose> = pose_ids
            .iter()
            .filter_map(|k| self.kfs.get(k))
            .map(|kf| BaPose {
                cam_from_world: kf.info.world_from_cam.inverse(),
                fixed: !window_set.contains(&kf.info.id) || (fixed.is_empty() && Some(kf.info.id) == oldest),
            })
            .collect();
        let point_ids: Vec<u64> = local.iter().copied().collect();
        let point_index: BTreeMap<u64, usize> = point_ids.iter().enumerate().map(|(i, &p)| (p, i)).collect();
        let mut positions: Vec<Point3<f64>> =
            point_ids.iter().filter_map(|p| self.points.get(p)).map(|m| m.point.position).collect();
        let mut ba_obs = Vec::new();
        let mut ba_src = Vec::new();
        for &k in &pose_ids {
            let Some(kf) = self.kfs.get(&k) else { continue };
            for o in &kf.obs {
                if let (Some(&pi), Some(&li)) = (pose_index.get(&k), point_index.get(&o.point)) {
                    ba_obs.push(BaObservation {
                        pose: pi,
                        point: li,
                        uv: o.uv,
                        depth: o.depth,
                        sigma: sigma(self.config.scale_factor, o.octave),
                    });
                    ba_src.push((k, o.point));
                }
            }
        }
        let (cam, bf) = (self.cam, self.config.bf);
        let mut active = vec![true; ba_obs.len()];
        let first = bundle_adjust(&cam, bf, &mut poses, &mut positions, &ba_obs, &active, self.config.iterations.0);
        let is_bad = |poses: &[BaPose], positions: &[Point3<f64>], o: &BaObservation| {
            chi2(&cam, bf, &poses[o.pose].cam_from_world, &positions[o.point], o)
                .is_none_or(|c| c > chi2_bound(o.depth, bf))
        };
        for (a, o) in active.iter_mut().zip(&ba_obs) {
            *a = !is_bad(&poses, &positions, o);
        }
        let second = bundle_adjust(&cam, bf, &mut poses, &mut positions, &ba_obs, &active, self.config.iterations.1);
        self.last = BaReport {
            initial_cost: first.initial_cost,
            final_cost: second.final_cost,
            iterations: first.iterations + second.iterations,
        };

        // Write back, erase bad observations.
        for (k, p) in pose_ids.iter().zip(&poses) {
            if window_set.contains(k)
                && let Some(kf) = self.kfs.get_mut(k)
            {
                kf.info.world_from_cam = p.cam_from_world.inverse();
            }
        }
        for (id, x) in point_ids.iter().zip(&positions) {
            if let Some(mp) = self.points.get_mut(id)
                && x.coords.iter().all(|v| v.is_finite())
            {
                mp.point.position = *x;
            }
        }
        for (o, (k, p)) in ba_obs.iter().zip(&ba_src) {
            if is_bad(&poses, &positions, o) {
                self.erase_observation(*k, *p);
            }
        }

        // Point culling (ORB-SLAM's MapPointCulling, RGB-D threshold).
        let newest = info.id;
        let culled: Vec<u64> = self
            .points
            .iter()
            .filter(|(_, m)| m.kfs.is_empty() || (newest.saturating_sub(m.point.first_keyframe) == 2 && m.weight <= 3))
            .map(|(&id, _)| id)
            .collect();
        for id in culled {
            self.remove_point(id);
            removed.push(id);
        }
        // Bounded memory: forget the oldest key frames.
        while self.kfs.len() > self.config.keep_keyframes.max(self.config.window) {
            let Some((&old, _)) = self.kfs.iter().next() else { break };
            if let Some(kf) = self.kfs.remove(&old) {
                for o in kf.obs {
                    if let Some(mp) = self.points.get_mut(&o.point) {
                        mp.kfs.retain(|&k| k != old);
                        if mp.kfs.is_empty() {
                            self.points.remove(&o.point);
                            removed.push(o.point);
                        }
                    }
                }
            }
        }

        let keyframes = window.iter().filter_map(|k| self.kfs.get(k)).map(|kf| kf.info).collect();
        let points = local
            .iter()
            .filter_map(|p| self.points.get(p))
            .map(|m| MapPoint { observations: m.kfs.len() as u32, ..m.point })
            .collect();
        removed.sort_unstable();
        removed.dedup();
        SparseMap { map_id: self.map_id, keyframes, points, observations: Vec::new(), removed }
    }

    fn erase_observation(&mut self, kf: u64, point: u64) {
        if let Some(k) = self.kfs.get_mut(&kf) {
            k.obs.retain(|o| o.point != point);
        }
        if let Some(mp) = self.points.get_mut(&point) {
            let before = mp.kfs.len();
            mp.kfs.retain(|&k| k != kf);
            if mp.kfs.len() < before {
                mp.weight = mp.weight.saturating_sub(2).max(mp.kfs.len() as u32);
            }
        }
    }

    fn remove_point(&mut self, id: u64) {
        if let Some(mp) = self.points.remove(&id) {
            for k in mp.kfs {
                if let Some(kf) = self.kfs.get_mut(&k) {
                    kf.obs.retain(|o| o.point != id);
                }
            }
        }
    }
}
