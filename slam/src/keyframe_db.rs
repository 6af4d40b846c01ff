//! ORB-SLAM2's key-frame database (Mur-Artal and Tardós, "ORB-SLAM2", T-RO 2017; ORB-SLAM's
//! `KeyFrameDatabase`, written from its description): an inverted index from each word to the
//! key frames that contain it, and the two queries place recognition asks of it.
//!
//! - [`KeyFrameDatabase::loop_candidates`]: key frames that share words with the query but are
//!   not among its covisible ones, at least 80 % as many shared words as the best, an L1 score
//!   at least the query's lowest score against its covisible key frames; then each candidate's
//!   score is accumulated over its covisible key frames that are candidates too, and the best
//!   key frame of every group scoring at least 75 % of the best group is returned.
//! - [`KeyFrameDatabase::relocalisation_candidates`]: the same over every key frame, without
//!   the covisibility exclusion or a minimum score.
//!
//! [`LoopConsistency`] keeps ORB-SLAM2's temporal check: a candidate is accepted once it (or a
//! key frame covisible with it) has been a candidate of 3 consecutive key frames.

use std::collections::{BTreeMap, BTreeSet};

use crate::bow::{BowVector, score};

/// Key frames sharing at least this share of the most shared words are scored (ORB-SLAM2: 0.8).
const MIN_COMMON_SHARE: f64 = 0.8;
/// Groups accumulating at least this share of the best group's score are kept (ORB-SLAM2: 0.75).
const MIN_GROUP_SHARE: f64 = 0.75;
/// Covisible key frames a candidate's group accumulates over (ORB-SLAM2: 10).
const GROUP_NEIGHBOURS: usize = 10;
/// Consecutive key frames a loop candidate must be seen by (ORB-SLAM2: 3).
pub const CONSISTENCY: usize = 3;

/// The inverted index.
#[derive(Clone, Debug, Default)]
pub struct KeyFrameDatabase {
    index: BTreeMap<u32, BTreeSet<u64>>,
    bows: BTreeMap<u64, BowVector>,
}

impl KeyFrameDatabase {
    /// An empty database.
    pub fn new() -> Self {
        Self::default()
    }

    /// Key frames held.
    pub fn len(&self) -> usize {
        self.bows.len()
    }

    /// Bytes of the inverted index and the stored bags of words ([`crate::memory`]).
    pub fn memory(&self) -> usize {
        use crate::memory::{map_bytes, set_bytes};
        map_bytes(&self.index)
            + self.index.values().map(set_bytes).sum::<usize>()
            + map_bytes(&self.bows)
            + self.bows.values().map(map_bytes).sum::<usize>()
    }

    /// Whether no key frame is held.
    pub fn is_empty(&self) -> bool {
        self.bows.is_empty()
    }

    /// Add (or replace) key frame `kf` with its bag of words.
    pub fn add(&mut self, kf: u64, bow: BowVector) {
        self.erase(kf);
        for w in bow.keys() {
            self.index.entry(*w).or_default().insert(kf);
        }
        self.bows.insert(kf, bow);
    }

    /// Remove key frame `kf`.
    pub fn erase(&mut self, kf: u64) {
        if let Some(bow) = self.bows.remove(&kf) {
            for w in bow.keys() {
                if let Some(s) = self.index.get_mut(w) {
                    s.remove(&kf);
                    if s.is_empty() {
                        self.index.remove(w);
                    }
                }
            }
        }
    }

    /// A key frame's bag of words.
    pub fn bow(&self, kf: u64) -> Option<&BowVector> {
        self.bows.get(&kf)
    }

    /// Words shared with `bow`, per key frame not in `exclude`.
    fn sharing(&self, bow: &BowVector, exclude: &BTreeSet<u64>) -> BTreeMap<u64, usize> {
        let mut common: BTreeMap<u64, usize> = BTreeMap::new();
        for w in bow.keys() {
            for &kf in self.index.get(w).into_iter().flatten() {
                if !exclude.contains(&kf) {
                    *common.entry(kf).or_default() += 1;
                }
            }
        }
        common
    }

    /// ORB-SLAM2's candidate search; `covisible(kf)` gives a key frame's best covisible key
    /// frames, best first.
    fn candidates(
        &self,
        bow: &BowVector,
        exclude: &BTreeSet<u64>,
        min_score: f64,
        covisible: &dyn Fn(u64) -> Vec<u64>,
    ) -> Vec<(u64, f64)> {
        let common = self.sharing(bow, exclude);
        let Some(&most) = common.values().max() else { return Vec::new() };
        let min_common = (MIN_COMMON_SHARE * most as f64).ceil() as usize;
        let scored: BTreeMap<u64, f64> = common
            .iter()
            .filter(|(_, c)| **c >= min_common)
            .filter_map(|(&kf, _)| {
                let s = score(bow, self.bows.get(&kf)?);
                (s >= min_score).then_some((kf, s))
            })
            .collect();
        if scored.is_empty() {
            return Vec::new();
        }
        // Accumulate over each candidate's covisible key frames that are candidates too.
        let mut groups: Vec<(u64, f64, f64)> = Vec::new(); // (best kf, accumulated, best score)
        for (&kf, &s) in &scored {
            let (mut acc, mut best) = (s, (kf, s));
            for n in covisible(kf).into_iter().take(GROUP_NEIGHBOURS) {
                if let Some(&sn) = scored.get(&n) {
                    acc += sn;
                    if sn > best.1 {
                        best = (n, sn);
                    }
                }
            }
            groups.push((best.0, acc, best.1));
        }
        let best_acc = groups.iter().map(|g| g.1).fold(0.0, f64::max);
        let mut out: Vec<(u64, f64)> = Vec::new();
        for (kf, acc, s) in groups {
            if acc >= MIN_GROUP_SHARE * best_acc && !out.iter().any(|o| o.0 == kf) {
                out.push((kf, s));
            }
        }
        out.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        out
    }

    /// Loop candidates for key frame `kf` (its bag of words `bow`), excluding `connected`
    /// (itself and its covisible key frames), scoring at least `min_score` (ORB-SLAM2: the
    /// lowest score of `kf` against its covisible key frames). Best first.
    pub fn loop_candidates(
        &self,
        kf: u64,
        bow: &BowVector,
        connected: &BTreeSet<u64>,
        min_score: f64,
        covisible: &dyn Fn(u64) -> Vec<u64>,
    ) -> Vec<(u64, f64)> {
        let mut exclude = connected.clone();
        exclude.insert(kf);
        self.candidates(bow, &exclude, min_score, covisible)
    }

    /// Relocalisation candidates for a frame's bag of words, best first.
    pub fn relocalisation_candidates(&self, bow: &BowVector, covisible: &dyn Fn(u64) -> Vec<u64>) -> Vec<(u64, f64)> {
        self.candidates(bow, &BTreeSet::new(), 0.0, covisible)
    }
}

/// ORB-SLAM2's loop consistency: groups (a candidate and its covisible key frames) carried from
/// key frame to key frame with a count of consecutive key frames that saw them.
#[derive(Clone, Debug, Default)]
pub struct LoopConsistency {
    groups: Vec<(BTreeSet<u64>, usize)>,
}

impl LoopConsistency {
    /// A fresh state.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feed one key frame's candidates, each with its group (itself and its covisible key
    /// frames); returns the candidates that are now consistent over [`CONSISTENCY`] key frames.
    pub fn update(&mut self, candidates: &[(u64, BTreeSet<u64>)]) -> Vec<u64> {
        let mut next: Vec<(BTreeSet<u64>, usize)> = Vec::new();
        let mut accepted = Vec::new();
        for (kf, group) in candidates {
            let mut consistent_with_any = false;
            let mut accepted_here = false;
            for (previous, count) in &self.groups {
                if group.intersection(previous).next().is_some() {
                    consistent_with_any = true;
                    let c = count + 1;
                    if !next.iter().any(|(g, n)| g == group && *n == c) {
                        next.push((group.clone(), c));
                    }
                    if c >= CONSISTENCY && !accepted_here {
                        accepted.push(*kf);
                        accepted_here = true;
                    }
                }
            }
            if !consistent_with_any {
                next.push((group.clone(), 1));
            }
        }
        self.groups = next;
        accepted
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bow(words: &[u32]) -> BowVector {
        let w = 1.0 / words.len() as f64;
        words.iter().map(|&x| (x, w)).collect()
    }

    #[test]
    fn the_inverted_index_finds_the_revisited_place_and_skips_the_connected_ones() {
        let mut db = KeyFrameDatabase::new();
        // A path through places A (words 0-19), B (100-119), C (200-219); key frames 0-2 at A,
        // 3-5 at B, 6-8 at C, 9 back at A (the loop) with some new words.
        let place = |base: u32, shift: u32| bow(&(base + shift..base + shift + 20).collect::<Vec<_>>());
        for (kf, (base, shift)) in
            [(0, 0), (0, 1), (0, 2), (100, 0), (100, 1), (100, 2), (200, 0), (200, 1), (200, 2)].into_iter().enumerate()
        {
            db.add(kf as u64, place(base, shift));
        }
        let covisible = |kf: u64| -> Vec<u64> {
            let start = kf / 3 * 3;
            (start..start + 3).filter(|&k| k != kf).collect()
        };
        let query = place(0, 1);
        // Connected: the last key frames of C.
        let connected: BTreeSet<u64> = [7, 8].into_iter().collect();
        let c = db.loop_candidates(9, &query, &connected, 0.3, &covisible);
        assert_eq!(c.first().map(|x| x.0), Some(1), "{c:?}");
        assert!(c.iter().all(|(k, _)| *k < 3), "only place A: {c:?}");
        // The same place in the connected set only: no candidate.
        let c = db.loop_candidates(9, &place(200, 1), &[6, 7, 8].into_iter().collect(), 0.0, &covisible);
        assert!(c.is_empty(), "{c:?}");
        // Relocalisation: everything is eligible.
        let c = db.relocalisation_candidates(&place(100, 2), &covisible);
        assert_eq!(c.first().map(|x| x.0), Some(5), "{c:?}");
        db.erase(5);
        let c = db.relocalisation_candidates(&place(100, 2), &covisible);
        assert_eq!(c.first().map(|x| x.0), Some(4), "{c:?}");
        assert_eq!(db.len(), 8);
    }

    #[test]
    fn a_loop_is_accepted_after_three_consistent_key_frames() {
        let mut c = LoopConsistency::new();
        let g = |v: &[u64]| v.iter().copied().collect::<BTreeSet<u64>>();
        assert!(c.update(&[(1, g(&[0, 1, 2]))]).is_empty());
        // The next key frame's candidate overlaps the group: consistent twice.
        assert!(c.update(&[(2, g(&[1, 2, 3]))]).is_empty());
        // A third time: accepted.
        assert_eq!(c.update(&[(3, g(&[2, 3, 4]))]), vec![3]);
        // A key frame with an unrelated candidate starts over.
        let mut c = LoopConsistency::new();
        c.update(&[(1, g(&[0, 1]))]);
        c.update(&[(50, g(&[50, 51]))]);
        assert!(c.update(&[(51, g(&[51, 52]))]).is_empty());
        assert_eq!(c.update(&[(52, g(&[52, 53]))]), vec![52]);
        // No candidate: the groups are forgotten.
        c.update(&[]);
        assert!(c.update(&[(53, g(&[52, 53]))]).is_empty());
    }
}
