//! ORB-SLAM2's `LocalMapping`. Why one file of this size: it mirrors that one class.
//!
//! RGB-D and stereo: key frames arrive from tracking with their
//! observations and new points; each new key frame's covisible neighbours form the local
//! window, whose poses and points are refined by local BA (two stages, outliers dropped in
//! between, as ORB-SLAM's `LocalBundleAdjustment`), key frames outside the window that see its
//! points held fixed. Afterwards bad observations are erased and points culled (ORB-SLAM's
//! `MapPointCulling`: two key frames after creation a point must be seen by at least two key
//! frames). Key frames are culled as ORB-SLAM2's `KeyFrameCulling` does
//! ([`LocalMapper::cull_keyframes`]): one whose close points are nearly all seen by three
//! others goes; each culled key frame is named in the output with the key frame that stands in for it, so tracking and loop closing
//! drop it too. The window itself stays bounded: beyond `keep_keyframes` the oldest key frames
//! are forgotten here (loop closing keeps the whole map).
//!
//! Monocular (a batch that carries the key frame's unmatched keypoints): new points are
//! triangulated between the new key frame and its best covisible neighbours, as ORB-SLAM2's
//! `CreateNewMapPoints` (see [`LocalMapper::triangulate`]), and duplicates fused with the
//! neighbours' points (`SearchInNeighbors`, [`LocalMapper::fuse`]). A monocular map's first
//! batch holds the two key frames of the initialisation, adjusted together; the map returned
//! carries the new key frame's observations, from which tracking counts its reference points.
//!
//! With RGB-D and stereo, tracking creates points from depth at every key frame and nothing
//! is triangulated or fused (ORB-SLAM2 does both in every mode: not done here yet).

use std::collections::{BTreeMap, BTreeSet, HashMap};

use dynaflow_vision::camera::Pinhole;
use nalgebra::Point3;

use crate::ba::{BaObservation, BaPose, BaReport, bundle_adjust, chi2, chi2_bound};
use dynaflow_vision::geometry::{CHI2_1DOF, CHI2_2DOF, triangulate};
use dynaflow_vision::matching::hamming;

use crate::keyframe_map::COVISIBILITY_MIN;
use crate::map::{CulledKeyFrame, MapFeature, MapKeyFrame, MapObservation, MapPoint, SparseMap, sigma};
use crate::memory::{MapMemory, map_bytes, vec_bytes};

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
    /// A point is culled two key frames after its creation when its observation count (2 per
    /// observation with depth, 1 without) is at most this (ORB-SLAM2 `cnThObs`: 3, monocular 2).
    pub cull_observations: u32,
    /// Covisible neighbours a new monocular key frame triangulates against (ORB-SLAM2: 20).
    pub triangulation_neighbours: usize,
    /// Cull redundant key frames (ORB-SLAM2's `KeyFrameCulling`, [`LocalMapper::cull_keyframes`]).
    pub cull_keyframes: bool,
    /// With depth, only observations closer than this count in key-frame culling (ORB-SLAM2's
    /// `ThDepth`: 40 baselines; RGB-D: 40 x bf / fx).
    pub close_depth: f64,
}

impl LocalMapConfig {
    /// ORB-SLAM2's defaults for an RGB-D camera with focal length `fx` (bf 40 px, its TUM
    /// configurations' [`crate::tracker::RGBD_BF`]).
    pub fn rgbd(fx: f64) -> Self {
        Self {
            window: 10,
            keep_keyframes: 60,
            bf: crate::tracker::RGBD_BF,
            scale_factor: 1.2,
            iterations: (5, 10),
            cull_observations: 3,
            triangulation_neighbours: 20,
            cull_keyframes: true,
            close_depth: crate::tracker::CLOSE_BASELINES * crate::tracker::RGBD_BF / fx,
        }
    }

    /// ORB-SLAM2's monocular defaults: no depth residual, the monocular culling threshold.
    pub fn monocular(fx: f64) -> Self {
        Self { bf: 0.0, cull_observations: 2, close_depth: f64::INFINITY, ..Self::rgbd(fx) }
    }
}

/// ORB-SLAM2's `KeyFrameCulling`: a key frame goes when more than this share of its (close)
/// points are each seen by at least [`REDUNDANT_OBSERVERS`] other key frames at the same or a
/// finer scale (its octave + 1 at most).
const REDUNDANT_SHARE: f64 = 0.9;
const REDUNDANT_OBSERVERS: usize = 3;

/// Ids of points made by local mapping start here (tracking counts from 0).
const MAPPING_POINT_IDS: u64 = 1 << 48;
/// ORB-SLAM2's triangulation gates: rays closer than this cosine have too little parallax.
const MAX_COS_PARALLAX: f64 = 0.9998;
/// A pair whose baseline is under this share of the neighbour's median scene depth is skipped.
const MIN_BASELINE_RATIO: f64 = 0.01;
/// Hamming distance and ratio of the triangulation search (ORB-SLAM2: `TH_LOW` 50, 0.6).
const TRIANGULATION_MAX_DISTANCE: u32 = 50;
const TRIANGULATION_RATIO: f32 = 0.6;

#[derive(Clone, Debug)]
struct Kf {
    info: MapKeyFrame,
    obs: Vec<MapObservation>,
    /// Monocular: keypoints no point explains yet (triangulation candidates).
    features: Vec<MapFeature>,
}

#[derive(Clone, Debug)]
struct Mp {
    point: MapPoint,
    /// Key frames observing it.
    kfs: Vec<u64>,
    /// ORB-SLAM's observation count: 2 for an RGB-D observation, 1 for a pixel alone.
    weight: u32,
}

impl Mp {
    /// Key frame `kf`'s observation (with a depth or not) is gone for good: it leaves the
    /// observers and the observation count.
    fn erase(&mut self, kf: u64, with_depth: bool) {
        let before = self.kfs.len();
        self.kfs.retain(|&k| k != kf);
        if self.kfs.len() < before {
            self.weight = self.weight.saturating_sub(if with_depth { 2 } else { 1 }).max(self.kfs.len() as u32);
        }
    }
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
    next_point: u64,
    triangulated: usize,
    fused: usize,
    /// The current map's first key frame (never culled, as ORB-SLAM2's key frame 0).
    first: Option<u64>,
    /// Key frames culled, in all.
    culled_keyframes: usize,
    /// Points culled (`MapPointCulling`, and left without a key frame by key-frame culling).
    culled_points: usize,
}

impl LocalMapper {
    /// An empty map.
    pub fn new(config: LocalMapConfig, cam: Pinhole) -> Self {
        Self {
            config,
            cam,
            map_id: 0,
            kfs: BTreeMap::new(),
            points: BTreeMap::new(),
            last: BaReport::default(),
            next_point: MAPPING_POINT_IDS,
            triangulated: 0,
            fused: 0,
            first: None,
            culled_keyframes: 0,
            culled_points: 0,
        }
    }

    /// Bytes per component ([`crate::memory`]): the window's key frames (observations and
    /// triangulation candidates) and its points.
    pub fn memory(&self) -> MapMemory {
        let keyframes =
            map_bytes(&self.kfs) + self.kfs.values().map(|k| vec_bytes(&k.obs) + vec_bytes(&k.features)).sum::<usize>();
        let points = map_bytes(&self.points) + self.points.values().map(|p| vec_bytes(&p.kfs)).sum::<usize>();
        MapMemory { keyframes, points, bow_index: 0 }
    }

    /// Key frames culled as redundant so far.
    pub fn culled_keyframes(&self) -> usize {
        self.culled_keyframes
    }

    /// Points culled so far (observation test, or left unobserved by a culled key frame).
    pub fn culled_points(&self) -> usize {
        self.culled_points
    }

    /// Points triangulated by the last insertion (monocular).
    pub fn last_triangulated(&self) -> usize {
        self.triangulated
    }

    /// Observations added or points merged by the last insertion's fusion (monocular).
    pub fn last_fused(&self) -> usize {
        self.fused
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

    /// Take loop closing's corrected map (ignored if it is of another map): the poses of the
    /// key frames held and the positions of the points held are replaced; points fusion
    /// removed are dropped, and its new observations added (with their point, which may be
    /// one this window had forgotten).
    pub fn apply_correction(&mut self, correction: &SparseMap) {
        if correction.map_id != self.map_id {
            return;
        }
        for k in &correction.keyframes {
            if let Some(kf) = self.kfs.get_mut(&k.id) {
                kf.info.world_from_cam = k.world_from_cam;
            }
        }
        let by_id: BTreeMap<u64, &MapPoint> = correction.points.iter().map(|p| (p.id, p)).collect();
        for (id, mp) in &mut self.points {
            if let Some(p) = by_id.get(id) {
                mp.point.position = p.position;
            }
        }
        for id in &correction.removed {
            if self.points.remove(id).is_some() {
                for kf in self.kfs.values_mut() {
                    kf.obs.retain(|o| o.point != *id);
                }
            }
        }
        for o in &correction.observations {
            let Some(kf) = self.kfs.get_mut(&o.keyframe) else { continue };
            let Some(p) = by_id.get(&o.point) else { continue };
            let mp = self.points.entry(o.point).or_insert(Mp { point: **p, kfs: Vec::new(), weight: 0 });
            if !mp.kfs.contains(&o.keyframe) {
                mp.kfs.push(o.keyframe);
                mp.weight += if o.depth.is_some() { 2 } else { 1 };
                kf.obs.push(*o);
            }
        }
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
            self.first = None;
        }
        let Some(info) = batch.keyframes.last().copied() else {
            return SparseMap { map_id: self.map_id, ..SparseMap::default() };
        };
        for p in &batch.points {
            self.points.entry(p.id).or_insert(Mp { point: *p, kfs: Vec::new(), weight: 0 });
        }
        // Every key frame of the batch (one; two for a monocular map's start), oldest first.
        if self.first.is_none() {
            self.first = batch.keyframes.first().map(|k| k.id);
        }
        for kinfo in &batch.keyframes {
            let mut obs = Vec::new();
            for o in batch.observations.iter().filter(|o| o.keyframe == kinfo.id) {
                if let Some(mp) = self.points.get_mut(&o.point)
                    && !mp.kfs.contains(&kinfo.id)
                {
                    mp.kfs.push(kinfo.id);
                    mp.weight += if o.depth.is_some() { 2 } else { 1 };
                    obs.push(*o);
                }
            }
            let features = batch.features.iter().filter(|f| f.keyframe == kinfo.id).copied().collect();
            self.kfs.insert(kinfo.id, Kf { info: *kinfo, obs, features });
        }
        self.triangulated = 0;
        self.fused = 0;
        if self.kfs.get(&info.id).is_some_and(|k| !k.features.is_empty()) {
            self.triangulated = self.triangulate(info.id);
            let (fused, replaced) = self.fuse(info.id);
            self.fused = fused;
            removed.extend(replaced);
        }

        // The window: the new key frame and its best covisible neighbours.
        let mut window: Vec<u64> = vec![info.id];
        window.extend(self.covisible(info.id, self.config.window.saturating_sub(1)));
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
            .filter(|(_, m)| {
                m.kfs.is_empty()
                    || (newest.saturating_sub(m.point.first_keyframe) == 2 && m.weight <= self.config.cull_observations)
            })
            .map(|(&id, _)| id)
            .collect();
        self.culled_points += culled.len();
        for id in culled {
            self.remove_point(id);
            removed.push(id);
        }
        let culled_keyframes =
            if self.config.cull_keyframes { self.cull_keyframes(newest, &mut removed) } else { Vec::new() };
        // Bounded memory: forget the oldest key frames (their observations stand in the whole
        // map, so the points keep their observation counts).
        while self.kfs.len() > self.config.keep_keyframes.max(self.config.window) {
            let Some((&old, _)) = self.kfs.iter().next() else { break };
            self.drop_keyframe(old, false, &mut removed);
        }

        let keyframes = window.iter().filter_map(|k| self.kfs.get(k)).map(|kf| kf.info).collect();
        let points = local
            .iter()
            .filter_map(|p| self.points.get(p))
            .map(|m| MapPoint { observations: m.kfs.len() as u32, ..m.point })
            .collect();
        removed.sort_unstable();
        removed.dedup();
        // Monocular: the window's observations go back too (the points triangulated here are
        // seen by the new key frame and its neighbours), so that tracking counts its reference
        // key frame's points as ORB-SLAM2 does (`TrackedMapPoints(nMinObs)`) and loop closing's
        // key frames know the points their keypoints see (ORB-SLAM2's threads share one map).
        let observations = if batch.features.is_empty() {
            Vec::new()
        } else {
            window.iter().filter_map(|k| self.kfs.get(k)).flat_map(|k| k.obs.iter().copied()).collect()
        };
        // The new key frame's keypoints go on to loop closing.
        let keypoints = batch.keypoints.clone();
        SparseMap {
            map_id: self.map_id,
            keyframes,
            points,
            observations,
            removed,
            features: Vec::new(),
            keypoints,
            culled: culled_keyframes,
        }
    }

    /// ORB-SLAM2's `KeyFrameCulling` after key frame `current`'s insertion: each of its
    /// covisible key frames (best first; never the map's first) goes when more than 90 % of
    /// the points it observes (with depth: only those closer than `close_depth`) are each seen
    /// by at least three other key frames at the same or a finer scale (octave + 1 at most), and
    /// only where its points are seen more than three times (ORB-SLAM2's observation count: 2
    /// per observation with depth). A culled key frame's observations leave its points; a point
    /// left without any key frame is removed (its id in `removed`). Returns the culled key
    /// frames, each with its best covisible key frame, which stands in for it downstream.
    pub fn cull_keyframes(&mut self, current: u64, removed: &mut Vec<u64>) -> Vec<CulledKeyFrame> {
        let mut out = Vec::new();
        // ORB-SLAM2's covisible key frames: those sharing at least 15 points (the best one
        // when none does).
        let all = self.covisibility(current);
        let mut candidates: Vec<u64> = all.iter().filter(|&&(_, c)| c >= COVISIBILITY_MIN).map(|&(k, _)| k).collect();
        if candidates.is_empty() {
            candidates.extend(all.first().map(|&(k, _)| k));
        }
        if candidates.is_empty() {
            return out;
        }
        // Each observation's octave, by (key frame, point).
        let mut octave: HashMap<(u64, u64), u8> = HashMap::new();
        for (&id, kf) in &self.kfs {
            for o in &kf.obs {
                octave.insert((id, o.point), o.octave);
            }
        }
        let with_depth = self.config.bf > 0.0;
        for k in candidates {
            if Some(k) == self.first {
                continue;
            }
            let Some(kf) = self.kfs.get(&k) else { continue };
            let (mut points, mut redundant) = (0usize, 0usize);
            for o in &kf.obs {
                let Some(mp) = self.points.get(&o.point) else { continue };
                if with_depth && o.depth.is_none_or(|d| d <= 0.0 || d > self.config.close_depth) {
                    continue;
                }
                points += 1;
                if mp.weight as usize > REDUNDANT_OBSERVERS {
                    let finer = mp
                        .kfs
                        .iter()
                        .filter(|&&x| x != k)
                        .filter(|&&x| {
                            octave.get(&(x, o.point)).is_some_and(|&l| u16::from(l) <= u16::from(o.octave) + 1)
                        })
                        .take(REDUNDANT_OBSERVERS)
                        .count();
                    if finer >= REDUNDANT_OBSERVERS {
                        redundant += 1;
                    }
                }
            }
            if (redundant as f64) <= REDUNDANT_SHARE * points as f64 {
                continue;
            }
            let Some(anchor) = self.covisible(k, 1).first().copied() else { continue };
            let Some(anchor_pose) = self.kfs.get(&anchor).map(|a| a.info.world_from_cam) else { continue };
            let before = removed.len();
            let Some(kf) = self.drop_keyframe(k, true, removed) else { continue };
            let anchor_from_culled = anchor_pose.inverse() * kf.info.world_from_cam;
            self.culled_points += removed.len() - before;
            self.culled_keyframes += 1;
            out.push(CulledKeyFrame { id: k, anchor, anchor_from_culled });
        }
        out
    }

    /// Take key frame `k` out of the window: its observations leave their points (`erase`: for
    /// good, so each point's observation count drops too; otherwise only forgotten here), and
    /// a point left without any key frame here leaves the window. Only a culled key frame's
    /// point whose observation count falls to 2 or less goes from the whole map (its id pushed
    /// on `removed`: ORB-SLAM2's `EraseObservation`); a forgotten key frame's points stay in it
    /// (loop closing's and relocalisation's whole map still sees them). Returns it.
    fn drop_keyframe(&mut self, k: u64, erase: bool, removed: &mut Vec<u64>) -> Option<Kf> {
        let kf = self.kfs.remove(&k)?;
        for o in &kf.obs {
            let Some(mp) = self.points.get_mut(&o.point) else { continue };
            if erase {
                mp.erase(k, o.depth.is_some());
            } else {
                mp.kfs.retain(|&x| x != k);
            }
            if mp.kfs.is_empty() {
                let weight = mp.weight;
                self.points.remove(&o.point);
                if erase && weight <= 2 {
                    removed.push(o.point);
                }
            }
        }
        Some(kf)
    }

    /// Key frame `kf`'s `n` best covisible key frames: most points shared first, then the
    /// newest.
    fn covisible(&self, kf: u64, n: usize) -> Vec<u64> {
        self.covisibility(kf).into_iter().take(n).map(|(k, _)| k).collect()
    }

    /// Key frame `kf`'s covisible key frames with the points each shares, most first (then
    /// the newest).
    fn covisibility(&self, kf: u64) -> Vec<(u64, usize)> {
        let mut shared: BTreeMap<u64, usize> = BTreeMap::new();
        for o in self.kfs.get(&kf).map_or(&[][..], |k| k.obs.as_slice()) {
            if let Some(mp) = self.points.get(&o.point) {
                for &other in mp.kfs.iter().filter(|&&x| x != kf) {
                    *shared.entry(other).or_default() += 1;
                }
            }
        }
        let mut v: Vec<(u64, usize)> = shared.into_iter().collect();
        v.sort_by_key(|&(k, c)| (std::cmp::Reverse(c), std::cmp::Reverse(k)));
        v
    }

    fn erase_observation(&mut self, kf: u64, point: u64) {
        let mut with_depth = false;
        if let Some(k) = self.kfs.get_mut(&kf) {
            with_depth = k.obs.iter().any(|o| o.point == point && o.depth.is_some());
            k.obs.retain(|o| o.point != point);
        }
        if let Some(mp) = self.points.get_mut(&point) {
            mp.erase(kf, with_depth);
        }
    }

    /// ORB-SLAM2's `CreateNewMapPoints` for a monocular key frame `id`: against each of its
    /// best covisible neighbours whose baseline is at least 1 % of the neighbour's median scene
    /// depth, the unmatched keypoints are matched by descriptor (Hamming <= 50, ratio 0.6,
    /// one-to-one) under the epipolar constraint (squared distance to the line within 3.84
    /// sigma^2 of the neighbour's octave, not within 10 sigma of the epipole), then
    /// triangulated (linear) where the rays' parallax cosine is in (0, 0.9998), the point lies
    /// in front of both cameras, reprojects within 5.991 sigma^2 in both, and its distance
    /// ratio agrees with the octaves' (factor 1.5 x scale). Returns the points made.
    /// Deviations: brute-force matching in place of the BoW vocabulary's, no orientation check.
    pub fn triangulate(&mut self, id: u64) -> usize {
        let Some(kf1) = self.kfs.get(&id).cloned() else { return 0 };
        let scale = self.config.scale_factor;
        let cam = self.cam;
        let neighbours = self.covisible(id, self.config.triangulation_neighbours);
        let pose1 = kf1.info.world_from_cam;
        let c1w = pose1.inverse();
        let mut used1 = vec![false; kf1.features.len()];
        let mut made = 0;
        for nb in neighbours {
            let Some(kf2) = self.kfs.get(&nb).cloned() else { continue };
            let pose2 = kf2.info.world_from_cam;
            let c2w = pose2.inverse();
            let baseline = (pose1.translation.vector - pose2.translation.vector).norm();
            let mut depths: Vec<f64> =
                kf2.obs.iter().filter_map(|o| self.points.get(&o.point)).map(|m| (c2w * m.point.position).z).collect();
            if depths.is_empty() {
                continue;
            }
            depths.sort_by(f64::total_cmp);
            let median = depths[depths.len() / 2];
            if median.is_nan() || median <= 0.0 || baseline / median < MIN_BASELINE_RATIO {
                continue;
            }
            // F21: x2^T F x1 = 0, from cam2_from_cam1 = (R, t).
            let c2_from_c1 = c2w * pose1;
            let (r, t) = (c2_from_c1.rotation.to_rotation_matrix().into_inner(), c2_from_c1.translation.vector);
            let tx = nalgebra::Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0);
            let k = nalgebra::Matrix3::new(cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0);
            let Some(kinv) = k.try_inverse() else { continue };
            let f21 = kinv.transpose() * tx * r * kinv;
            // Epipole in image 2: the projection of camera 1's centre.
            let epipole = cam.project(&(c2w * Point3::from(pose1.translation.vector)));
            let mut best2: Vec<Option<(usize, u32)>> = vec![None; kf2.features.len()];
            for (i1, f1) in kf1.features.iter().enumerate() {
                if used1[i1] {
                    continue;
                }
                let line = f21 * nalgebra::Vector3::new(f1.uv[0], f1.uv[1], 1.0);
                let norm2 = line.x * line.x + line.y * line.y;
                if norm2 <= 0.0 {
                    continue;
                }
                let (mut d1, mut d2, mut j1) = (u32::MAX, u32::MAX, usize::MAX);
                for (j, f2) in kf2.features.iter().enumerate() {
                    let d = hamming(&f1.descriptor, &f2.descriptor);
                    if d > TRIANGULATION_MAX_DISTANCE || d >= d2 {
                        continue;
                    }
                    let s2 = sigma(scale, f2.octave).powi(2);
                    if let Some(e) = epipole
                        && (e[0] - f2.uv[0]).powi(2) + (e[1] - f2.uv[1]).powi(2) < 100.0 * s2.sqrt()
                    {
                        continue;
                    }
                    let num = line.x * f2.uv[0] + line.y * f2.uv[1] + line.z;
                    if num * num / norm2 >= CHI2_1DOF * s2 {
                        continue;
                    }
                    if d < d1 {
                        (d2, d1, j1) = (d1, d, j);
                    } else {
                        d2 = d;
                    }
                }
                if j1 == usize::MAX || (d2 != u32::MAX && d1 as f32 >= TRIANGULATION_RATIO * d2 as f32) {
                    continue;
                }
                if best2[j1].is_none_or(|(_, d)| d1 < d) {
                    best2[j1] = Some((i1, d1));
                }
            }
            let mut new_points = Vec::new();
            for (j, b) in best2.iter().enumerate() {
                let Some((i1, _)) = *b else { continue };
                let (f1, f2) = (&kf1.features[i1], &kf2.features[j]);
                let ray = |pose: &nalgebra::Isometry3<f64>, uv: [f64; 2]| {
                    let [x, y] = cam.normalised(uv);
                    pose.rotation * nalgebra::Vector3::new(x, y, 1.0)
                };
                let (r1, r2) = (ray(&pose1, f1.uv), ray(&pose2, f2.uv));
                let cos = r1.dot(&r2) / (r1.norm() * r2.norm());
                if !(cos > 0.0 && cos < MAX_COS_PARALLAX) {
                    continue;
                }
                let Some(x) = triangulate(&cam, &c1w, &c2w, f1.uv, f2.uv) else { continue };
                let (x1, x2) = (c1w * x, c2w * x);
                if x1.z <= 0.0 || x2.z <= 0.0 {
                    continue;
                }
                let reproj = |pc: &Point3<f64>, uv: [f64; 2], octave: u8| {
                    cam.project(pc).is_some_and(|q| {
                        (q[0] - uv[0]).powi(2) + (q[1] - uv[1]).powi(2) <= CHI2_2DOF * sigma(scale, octave).powi(2)
                    })
                };
                if !reproj(&x1, f1.uv, f1.octave) || !reproj(&x2, f2.uv, f2.octave) {
                    continue;
                }
                let dist1 = (x.coords - pose1.translation.vector).norm();
                let dist2 = (x.coords - pose2.translation.vector).norm();
                if dist1 <= 0.0 || dist2 <= 0.0 {
                    continue;
                }
                let ratio_dist = dist2 / dist1;
                let ratio_octave = sigma(scale, f1.octave) / sigma(scale, f2.octave);
                let factor = 1.5 * scale;
                if ratio_dist * factor < ratio_octave || ratio_dist > ratio_octave * factor {
                    continue;
                }
                new_points.push((i1, j, x));
            }
            let mut used2 = Vec::new();
            for (i1, j, x) in new_points {
                let (f1, f2) = (kf1.features[i1], kf2.features[j]);
                let pid = self.next_point;
                self.next_point += 1;
                let point =
                    MapPoint { id: pid, position: x, descriptor: f1.descriptor, observations: 2, first_keyframe: id };
                self.points.insert(pid, Mp { point, kfs: vec![id, nb], weight: 2 });
                let obs = |kf: u64, f: &MapFeature| MapObservation {
                    keyframe: kf,
                    point: pid,
                    uv: f.uv,
                    depth: None,
                    octave: f.octave,
                };
                if let Some(k) = self.kfs.get_mut(&id) {
                    k.obs.push(obs(id, &f1));
                }
                if let Some(k) = self.kfs.get_mut(&nb) {
                    k.obs.push(obs(nb, &f2));
                }
                used1[i1] = true;
                used2.push(j);
                made += 1;
            }
            if let Some(k) = self.kfs.get_mut(&nb) {
                let mut keep = vec![true; k.features.len()];
                for j in used2 {
                    keep[j] = false;
                }
                let mut it = keep.iter();
                k.features.retain(|_| *it.next().unwrap_or(&true));
            }
        }
        if let Some(k) = self.kfs.get_mut(&id) {
            let mut it = used1.iter();
            k.features.retain(|_| !*it.next().unwrap_or(&false));
        }
        made
    }

    /// ORB-SLAM2's `SearchInNeighbors` for a monocular key frame `id`: its points are
    /// projected into its covisible key frames (the 20 best and their 5 best each) and theirs
    /// into it; a projection that lands within `3 x scale^octave` px of a keypoint of the
    /// predicted octave (or the one below), reprojects within 5.991 sigma^2 and matches its
    /// descriptor (Hamming <= 50) either adds an observation (the keypoint had no point) or
    /// merges two points (the one with more observations stays): ORB-SLAM2's `Fuse`. A map
    /// re-observed from a new key frame then keeps one point per place, and one scale.
    /// Returns the fusions and the ids of the points merged away. Deviation: a keypoint that
    /// already has a point is compared through that point's descriptor (key frames here keep
    /// the descriptors of their unmatched keypoints only).
    pub fn fuse(&mut self, id: u64) -> (usize, Vec<u64>) {
        let mut targets: Vec<u64> = Vec::new();
        for k in self.covisible(id, self.config.triangulation_neighbours) {
            if !targets.contains(&k) {
                targets.push(k);
            }
            for k2 in self.covisible(k, 5) {
                if k2 != id && !targets.contains(&k2) {
                    targets.push(k2);
                }
            }
        }
        let mut fused = 0;
        let mut replaced = Vec::new();
        // The new key frame's points into each target.
        for &t in &targets {
            let ids: Vec<u64> = self.kfs.get(&id).map(|k| k.obs.iter().map(|o| o.point).collect()).unwrap_or_default();
            let (f, r) = self.fuse_into(t, &ids);
            fused += f;
            replaced.extend(r);
        }
        // The targets' points into the new key frame.
        let mut ids: Vec<u64> = Vec::new();
        for &t in &targets {
            if let Some(k) = self.kfs.get(&t) {
                ids.extend(k.obs.iter().map(|o| o.point));
            }
        }
        ids.sort_unstable();
        ids.dedup();
        let (f, r) = self.fuse_into(id, &ids);
        fused += f;
        replaced.extend(r);
        replaced.sort_unstable();
        replaced.dedup();
        replaced.retain(|p| !self.points.contains_key(p));
        (fused, replaced)
    }

    /// ORB-SLAM2's `ORBmatcher::Fuse` of `points` into key frame `kf`.
    fn fuse_into(&mut self, kf: u64, points: &[u64]) -> (usize, Vec<u64>) {
        let scale = self.config.scale_factor;
        let cam = self.cam;
        let mut fused = 0;
        let mut replaced = Vec::new();
        for &pid in points {
            let Some(k) = self.kfs.get(&kf) else { break };
            let Some(mp) = self.points.get(&pid) else { continue };
            if mp.kfs.contains(&kf) {
                continue;
            }
            let pose = k.info.world_from_cam;
            let pc = pose.inverse() * mp.point.position;
            let Some(uv) = cam.project(&pc) else { continue };
            // The octave the point's distance predicts, from its first observation's.
            let first = mp.kfs.iter().find_map(|&o| {
                let ok = self.kfs.get(&o)?;
                let ob = ok.obs.iter().find(|x| x.point == pid)?;
                let d = (mp.point.position.coords - ok.info.world_from_cam.translation.vector).norm();
                Some((d, ob.octave))
            });
            let Some((d0, oct0)) = first else { continue };
            let dist = (mp.point.position.coords - pose.translation.vector).norm();
            if !(dist > 0.0 && d0 > 0.0) {
                continue;
            }
            let predicted = (f64::from(oct0) + (d0 / dist).ln() / scale.ln()).round().clamp(0.0, 7.0) as u8;
            let radius = 3.0 * sigma(scale, predicted);
            let descriptor = mp.point.descriptor;
            // Candidates: keypoints with a point (through that point's descriptor) and without.
            let mut best: Option<(u32, Option<u64>, usize)> = None;
            let ok_octave = |o: u8| o + 1 >= predicted && o <= predicted;
            let near = |q: [f64; 2], o: u8| {
                let e2 = (q[0] - uv[0]).powi(2) + (q[1] - uv[1]).powi(2);
                e2 <= radius * radius && e2 <= CHI2_2DOF * sigma(scale, o).powi(2)
            };
            for (i, o) in k.obs.iter().enumerate() {
                if !ok_octave(o.octave) || !near(o.uv, o.octave) {
                    continue;
                }
                let Some(other) = self.points.get(&o.point) else { continue };
                let d = hamming(&descriptor, &other.point.descriptor);
                if d <= TRIANGULATION_MAX_DISTANCE && best.is_none_or(|b| d < b.0) {
                    best = Some((d, Some(o.point), i));
                }
            }
            for (i, f) in k.features.iter().enumerate() {
                if !ok_octave(f.octave) || !near(f.uv, f.octave) {
                    continue;
                }
                let d = hamming(&descriptor, &f.descriptor);
                if d <= TRIANGULATION_MAX_DISTANCE && best.is_none_or(|b| d < b.0) {
                    best = Some((d, None, i));
                }
            }
            match best {
                Some((_, Some(other), _)) if other != pid => {
                    let (keep, drop) = {
                        let (a, b) = (self.points.get(&pid), self.points.get(&other));
                        match (a, b) {
                            (Some(a), Some(b)) if b.kfs.len() > a.kfs.len() => (other, pid),
                            (Some(_), Some(_)) => (pid, other),
                            _ => continue,
                        }
                    };
                    self.replace_point(drop, keep);
                    replaced.push(drop);
                    fused += 1;
                }
                Some((_, None, i)) => {
                    let Some(k) = self.kfs.get_mut(&kf) else { continue };
                    let f = k.features.swap_remove(i);
                    k.obs.push(MapObservation { keyframe: kf, point: pid, uv: f.uv, depth: None, octave: f.octave });
                    if let Some(mp) = self.points.get_mut(&pid) {
                        mp.kfs.push(kf);
                        mp.weight += 1;
                    }
                    fused += 1;
                }
                _ => {}
            }
        }
        (fused, replaced)
    }

    /// Merge point `drop` into `keep`: every key frame observing `drop` observes `keep` there
    /// (unless it already observes `keep`), and `drop` is removed.
    fn replace_point(&mut self, drop: u64, keep: u64) {
        let Some(old) = self.points.remove(&drop) else { return };
        for k in old.kfs {
            let Some(kf) = self.kfs.get_mut(&k) else { continue };
            let already = kf.obs.iter().any(|o| o.point == keep);
            if already {
                kf.obs.retain(|o| o.point != drop);
                continue;
            }
            let mut depth = false;
            for o in kf.obs.iter_mut().filter(|o| o.point == drop) {
                o.point = keep;
                depth = o.depth.is_some();
            }
            if let Some(mp) = self.points.get_mut(&keep) {
                mp.kfs.push(k);
                mp.weight += if depth { 2 } else { 1 };
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

#[cfg(test)]
mod tests;
