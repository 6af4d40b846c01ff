//! The whole key-frame map as place recognition sees it: every key frame with all its
//! keypoints (descriptor, depth, map point), its bag of words and the key-frame database, every
//! point, and the covisibility graph derived from the observations. Loop closing keeps one
//! ([`crate::loop_closing`]) and tracking keeps one for relocalisation ([`crate::tracker`]);
//! both are fed the same batches (tracking's key frames, local mapping's refinements, loop
//! closing's corrections), so they agree.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::matching::{GridIndex, hamming, nearest_two};
use nalgebra::{Isometry3, Point3};

use crate::bow::{BowVector, Descriptor, FeatureVector, Vocabulary};
use crate::keyframe_db::KeyFrameDatabase;
use crate::map::{Feature, MapKeyFrame, MapKeypoint, MapObservation, MapPoint, SparseMap, sigma};
use crate::memory::{MapMemory, map_bytes, set_bytes, vec_bytes};
use crate::sim3::Sim3;

/// Hamming distance of a BoW or projection match (ORB-SLAM2 `TH_LOW`) and the BoW ratio.
pub const MAX_DISTANCE: u32 = 50;
/// The nearest-to-second distance ratio a BoW match must beat (ORB-SLAM2: 0.75).
pub const BOW_RATIO: f32 = 0.75;
/// Shared points that make two key frames covisible (ORB-SLAM2's connections: 15).
pub const COVISIBILITY_MIN: usize = 15;

/// A key frame with everything place recognition needs.
#[derive(Clone, Debug)]
pub struct PlaceKeyFrame {
    /// Its id, stamp and pose.
    pub info: MapKeyFrame,
    /// Its static keypoints, with the map point each observes.
    pub keypoints: Vec<MapKeypoint>,
    /// Its bag of words.
    pub bow: BowVector,
    /// Keypoint indices by vocabulary node (the direct index).
    pub features: FeatureVector,
    /// Spanning-tree parent (the key frame it shared most points with when it came).
    pub parent: Option<u64>,
    /// Key frames it closed a loop with.
    pub loops: BTreeSet<u64>,
}

/// The map.
#[derive(Debug)]
pub struct KeyFrameMap {
    /// The camera.
    pub cam: Pinhole,
    /// Image width, pixels.
    pub width: f64,
    /// Image height, pixels.
    pub height: f64,
    /// ORB's pyramid scale factor (sigma per octave).
    pub scale_factor: f64,
    vocabulary: Arc<Vocabulary>,
    levels_up: usize,
    /// The map's number (a new map after a loss for good).
    pub map_id: u32,
    /// Key frames by id.
    pub kfs: BTreeMap<u64, PlaceKeyFrame>,
    /// Map points by id.
    pub points: BTreeMap<u64, MapPoint>,
    /// Point id -> key frames observing it.
    pub observers: BTreeMap<u64, BTreeSet<u64>>,
    /// The key-frame database (inverted index of words) for place recognition.
    pub db: KeyFrameDatabase,
}

impl KeyFrameMap {
    /// An empty map for a camera of `width` x `height` pixels.
    pub fn new(cam: Pinhole, width: f64, height: f64, scale_factor: f64, vocabulary: Arc<Vocabulary>) -> Self {
        // ORB-SLAM2 groups features by the node 4 levels above the words of its 6-level
        // vocabulary: the second level from the root. The same level of any vocabulary.
        let levels_up = vocabulary.levels().saturating_sub(2);
        Self {
            cam,
            width,
            height,
            scale_factor,
            vocabulary,
            levels_up,
            map_id: 0,
            kfs: BTreeMap::new(),
            points: BTreeMap::new(),
            observers: BTreeMap::new(),
            db: KeyFrameDatabase::new(),
        }
    }

    /// Bytes per component ([`crate::memory`]): key frames with their keypoints, points with
    /// their observers, and the words (each key frame's bag of words and direct index, the
    /// database).
    pub fn memory(&self) -> MapMemory {
        let mut m = MapMemory { bow_index: self.db.memory(), ..MapMemory::default() };
        m.keyframes = map_bytes(&self.kfs);
        for k in self.kfs.values() {
            m.keyframes += vec_bytes(&k.keypoints) + set_bytes(&k.loops);
            m.bow_index +=
                map_bytes(&k.bow) + map_bytes(&k.features) + k.features.values().map(vec_bytes).sum::<usize>();
        }
        m.points = map_bytes(&self.points)
            + map_bytes(&self.observers)
            + self.observers.values().map(set_bytes).sum::<usize>();
        m
    }

    /// The vocabulary.
    pub fn vocabulary(&self) -> &Arc<Vocabulary> {
        &self.vocabulary
    }

    /// Bag of words and direct index of a set of descriptors.
    pub fn transform(&self, descriptors: &[Descriptor]) -> (BowVector, FeatureVector) {
        self.vocabulary.transform(descriptors, self.levels_up)
    }

    /// Forget everything (a new map starts) when `map_id` is not the current one; true then.
    pub fn switch_map(&mut self, map_id: u32) -> bool {
        if map_id == self.map_id {
            return false;
        }
        self.start_map(map_id);
        true
    }

    /// Start map `map_id`, empty, and hand back the map held until now (loop closing's atlas
    /// keeps it).
    pub fn start_map(&mut self, map_id: u32) -> KeyFrameMap {
        let fresh = KeyFrameMap {
            cam: self.cam,
            width: self.width,
            height: self.height,
            scale_factor: self.scale_factor,
            vocabulary: self.vocabulary.clone(),
            levels_up: self.levels_up,
            map_id,
            kfs: BTreeMap::new(),
            points: BTreeMap::new(),
            observers: BTreeMap::new(),
            db: KeyFrameDatabase::new(),
        };
        std::mem::replace(self, fresh)
    }

    /// Move the whole map by a similarity (another map's frame after a merge): every point
    /// `x -> t x`, every key frame's pose to `t` times it, keeping the rotation and the camera
    /// centre (the scale goes into the points, as loop closing's `[R | t/s]`).
    pub fn move_by(&mut self, t: &Sim3) {
        for kf in self.kfs.values_mut() {
            kf.info.world_from_cam = (*t * Sim3::from_isometry(&kf.info.world_from_cam)).rigid();
        }
        for p in self.points.values_mut() {
            p.position = t.transform_point(&p.position);
        }
    }

    /// Take in `other`, a map of the atlas in this map's frame (ORB-SLAM3's merge): its key
    /// frames (into the database), points and observations. Ids are unique across maps (the
    /// tracker numbers key frames and points over the whole run).
    pub fn absorb(&mut self, other: KeyFrameMap) {
        for (id, kf) in other.kfs {
            self.db.add(id, kf.bow.clone());
            self.kfs.insert(id, kf);
        }
        self.points.extend(other.points);
        for (p, set) in other.observers {
            self.observers.entry(p).or_default().extend(set);
        }
    }

    /// Take a batch's points (new or refined), key-frame poses and removed points.
    pub fn apply_refinements(&mut self, batch: &SparseMap) {
        for p in &batch.points {
            self.points.insert(p.id, *p);
        }
        for k in &batch.keyframes {
            if let Some(kf) = self.kfs.get_mut(&k.id) {
                kf.info.world_from_cam = k.world_from_cam;
            }
        }
        for id in &batch.removed {
            self.remove_point(*id);
        }
        self.link_observations(&batch.observations);
    }

    /// Observations of known key frames and points: the keypoint at the observation's pixel
    /// and octave sees that point (a single camera's points triangulated in local mapping,
    /// fusion's observations after a loop).
    fn link_observations(&mut self, observations: &[MapObservation]) {
        for o in observations {
            if !self.points.contains_key(&o.point) {
                continue;
            }
            let Some(kf) = self.kfs.get_mut(&o.keyframe) else { continue };
            let Some(kp) = kf.keypoints.iter_mut().find(|k| k.uv == o.uv && k.octave == o.octave) else { continue };
            if kp.point == Some(o.point) {
                continue;
            }
            if let Some(old) = kp.point.replace(o.point)
                && let Some(set) = self.observers.get_mut(&old)
            {
                set.remove(&o.keyframe);
            }
            self.observers.entry(o.point).or_default().insert(o.keyframe);
        }
    }

    /// Take a loop correction: poses, positions, removed points and fusion's observations.
    pub fn apply_correction(&mut self, c: &SparseMap) {
        if c.map_id != self.map_id {
            return;
        }
        self.apply_refinements(c);
    }

    /// Add the new key frame of `batch` (its `keypoints`); returns its bag of words, or `None`
    /// when the batch carries no key frame's keypoints or the key frame is known. The key frame
    /// is not yet in the database (loop closing queries first, then adds it).
    pub fn add_keyframe(&mut self, batch: &SparseMap) -> Option<(u64, BowVector)> {
        let id = batch.keypoints.first().map(|k| k.keyframe)?;
        let info = batch.keyframes.iter().find(|k| k.id == id).copied()?;
        if self.kfs.contains_key(&id) {
            return None;
        }
        let keypoints: Vec<MapKeypoint> = batch
            .keypoints
            .iter()
            .filter(|k| k.keyframe == id)
            .map(|k| MapKeypoint { point: k.point.filter(|p| self.points.contains_key(p)), ..*k })
            .collect();
        for p in keypoints.iter().filter_map(|k| k.point) {
            self.observers.entry(p).or_default().insert(id);
        }
        let descriptors: Vec<Descriptor> = keypoints.iter().map(|k| k.descriptor).collect();
        let (bow, features) = self.transform(&descriptors);
        self.kfs.insert(
            id,
            PlaceKeyFrame { info, keypoints, bow: bow.clone(), features, parent: None, loops: BTreeSet::new() },
        );
        // Its points from local mapping (a single camera's triangulated ones).
        let own: Vec<MapObservation> = batch.observations.iter().filter(|o| o.keyframe == id).copied().collect();
        self.link_observations(&own);
        let parent = self.covisibility(id).into_iter().max_by_key(|&(k, w)| (w, std::cmp::Reverse(k))).map(|c| c.0);
        if let Some(kf) = self.kfs.get_mut(&id) {
            kf.parent = parent;
        }
        Some((id, bow))
    }

    /// Drop the key frames local mapping culled ([`SparseMap::culled`]), each as ORB-SLAM2's
    /// `KeyFrame::SetBadFlag`: out of the database (its words) and of its points' observers (a
    /// point no key frame observes any more goes too); its spanning-tree children take its
    /// parent (the key frame standing in for it when it had none), and its loop edges move to
    /// the key frame standing in for it, so the essential graph stays connected.
    pub fn cull_keyframes(&mut self, batch: &SparseMap) {
        for c in &batch.culled {
            let Some(kf) = self.kfs.remove(&c.id) else { continue };
            self.db.erase(c.id);
            for p in kf.keypoints.iter().filter_map(|k| k.point) {
                if let Some(set) = self.observers.get_mut(&p) {
                    set.remove(&c.id);
                    if set.is_empty() {
                        self.observers.remove(&p);
                        self.points.remove(&p);
                    }
                }
            }
            let anchor = Some(c.anchor).filter(|a| self.kfs.contains_key(a));
            let parent = kf.parent.filter(|p| self.kfs.contains_key(p)).or(anchor);
            for other in self.kfs.values_mut() {
                if other.parent == Some(c.id) {
                    other.parent = parent.filter(|&p| p != other.info.id);
                }
                if other.loops.remove(&c.id) && Some(other.info.id) != anchor {
                    other.loops.extend(anchor);
                }
            }
            if let Some(a) = anchor.and_then(|a| self.kfs.get_mut(&a)) {
                a.loops.extend(kf.loops.iter().filter(|&&l| l != c.anchor));
            }
        }
    }

    /// Drop a point and every keypoint's reference to it.
    pub fn remove_point(&mut self, id: u64) {
        self.points.remove(&id);
        if let Some(kfs) = self.observers.remove(&id) {
            for k in kfs {
                if let Some(kf) = self.kfs.get_mut(&k) {
                    for kp in &mut kf.keypoints {
                        if kp.point == Some(id) {
                            kp.point = None;
                        }
                    }
                }
            }
        }
    }

    /// Key frames sharing points with `kf`, with the number shared.
    pub fn covisibility(&self, kf: u64) -> Vec<(u64, usize)> {
        let mut count: BTreeMap<u64, usize> = BTreeMap::new();
        if let Some(k) = self.kfs.get(&kf) {
            for p in k.keypoints.iter().filter_map(|k| k.point) {
                for &o in self.observers.get(&p).into_iter().flatten() {
                    if o != kf {
                        *count.entry(o).or_default() += 1;
                    }
                }
            }
        }
        count.into_iter().collect()
    }

    /// ORB-SLAM2's covisible key frames (at least 15 shared points), most shared first.
    pub fn covisible(&self, kf: u64) -> Vec<u64> {
        let mut c: Vec<(u64, usize)> =
            self.covisibility(kf).into_iter().filter(|&(_, w)| w >= COVISIBILITY_MIN).collect();
        c.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        c.into_iter().map(|c| c.0).collect()
    }

    /// Every point seen by the key frames `kfs`, once.
    pub fn points_of(&self, kfs: &[u64]) -> Vec<u64> {
        let mut set = BTreeSet::new();
        for k in kfs {
            if let Some(kf) = self.kfs.get(k) {
                set.extend(kf.keypoints.iter().filter_map(|k| k.point));
            }
        }
        set.into_iter().filter(|p| self.points.contains_key(p)).collect()
    }

    /// ORB-SLAM2's `SearchByBoW` between key frames `a` and `b`: keypoint pairs (index in `a`,
    /// index in `b`) of the same vocabulary node, both with a point, Hamming <= 50, ratio 0.75,
    /// one-to-one.
    pub fn search_by_bow(&self, a: &PlaceKeyFrame, b: &PlaceKeyFrame) -> Vec<(usize, usize)> {
        let query: Vec<Option<(usize, &Descriptor)>> =
            a.keypoints.iter().enumerate().map(|(i, k)| k.point.map(|_| (i, &k.descriptor))).collect();
        let mut pairs = bow_pairs(&a.features, &query, b);
        pairs.sort_unstable();
        pairs
    }

    /// ORB-SLAM2's `SearchByBoW` between key frame `kf` and a frame (`features`, grouped by
    /// `frame_index`): (feature index, point id) pairs.
    pub fn search_frame_by_bow(
        &self,
        kf: &PlaceKeyFrame,
        features: &[Feature],
        frame_index: &FeatureVector,
        static_idx: &[usize],
    ) -> Vec<(usize, u64)> {
        // The frame's direct index holds positions in `static_idx`.
        let query: Vec<Option<(usize, &Descriptor)>> =
            static_idx.iter().map(|&i| Some((i, &features[i].descriptor))).collect();
        let mut pairs: Vec<(usize, u64)> = bow_pairs(frame_index, &query, kf)
            .into_iter()
            .filter_map(|(q, j)| kf.keypoints[j].point.map(|p| (q, p)))
            .collect();
        pairs.sort_unstable();
        pairs
    }

    /// Points projected into an image with keypoints `keypoints` at pose `world_from_cam`, each
    /// matched to the nearest-in-descriptor keypoint within `radius x scale^octave` pixels
    /// (Hamming <= 50), one point per keypoint (the closest descriptor wins).
    pub fn search_by_projection(
        &self,
        keypoints: &[MapKeypoint],
        world_from_cam: &Isometry3<f64>,
        points: &[u64],
        radius: f64,
    ) -> Vec<(usize, u64)> {
        let uv: Vec<[f32; 2]> = keypoints.iter().map(|k| [k.uv[0] as f32, k.uv[1] as f32]).collect();
        let grid = GridIndex::new(&uv, self.width.ceil() as usize, self.height.ceil() as usize, 32.0);
        let cam_from_world = world_from_cam.inverse();
        let mut best: BTreeMap<usize, (u32, u64)> = BTreeMap::new();
        for &id in points {
            let Some(p) = self.points.get(&id) else { continue };
            let Some(px) = self.cam.project(&(cam_from_world * p.position)) else { continue };
            if !(px[0] >= 0.0 && px[0] < self.width && px[1] >= 0.0 && px[1] < self.height) {
                continue;
            }
            let r = radius * self.scale_factor.powi(2);
            let near = grid.within([px[0] as f32, px[1] as f32], r as f32);
            let cands = near.iter().map(|&i| i as usize).filter(|&i| {
                let k = &keypoints[i];
                let s = radius * sigma(self.scale_factor, k.octave);
                (k.uv[0] - px[0]).powi(2) + (k.uv[1] - px[1]).powi(2) <= s * s
            });
            let Some((i, d)) =
                cands.map(|i| (i, hamming(&p.descriptor, &keypoints[i].descriptor))).min_by_key(|&(i, d)| (d, i))
            else {
                continue;
            };
            if d <= MAX_DISTANCE && best.get(&i).is_none_or(|b| d < b.0) {
                best.insert(i, (d, id));
            }
        }
        best.into_iter().map(|(i, (_, p))| (i, p)).collect()
    }

    /// A point's position in key frame `kf`'s camera.
    pub fn point_in(&self, kf: &PlaceKeyFrame, kp: &MapKeypoint) -> Option<Point3<f64>> {
        let p = self.points.get(&kp.point?)?;
        Some(kf.info.world_from_cam.inverse() * p.position)
    }
}

/// Pairs (query id, keypoint index in `b`) of descriptors in the same vocabulary node, with
/// Hamming <= 50 and ratio 0.75, one-to-one in `b`: `index` groups positions in `query` by
/// node; `query[pos]` is the (id, descriptor) there, `None` to skip it.
fn bow_pairs(index: &FeatureVector, query: &[Option<(usize, &Descriptor)>], b: &PlaceKeyFrame) -> Vec<(usize, usize)> {
    let mut used = BTreeSet::new();
    let mut out = Vec::new();
    for (node, members) in index {
        let Some(ib) = b.features.get(node) else { continue };
        for &m in members {
            let Some(&Some((qid, qd))) = query.get(m as usize) else { continue };
            let cands = ib
                .iter()
                .map(|&j| j as usize)
                .filter(|&j| b.keypoints[j].point.is_some() && !used.contains(&j))
                .map(|j| (j, &b.keypoints[j].descriptor));
            if let Some((j, best, second)) = nearest_two(qd, cands)
                && best <= MAX_DISTANCE
                && (best as f32) < BOW_RATIO * second as f32
            {
                used.insert(j);
                out.push((qid, j));
            }
        }
    }
    out
}
