//! What the maps hold, in bytes: the memory of each component as the summary reports it.
//!
//! An estimate from the containers' contents (element sizes times capacity for vectors,
//! key and value sizes per entry for B-trees, their node overhead left out), so it can be told
//! apart per component, where the process's RSS cannot; it is not the allocator's figure.

use std::collections::{BTreeMap, BTreeSet};
use std::mem::size_of;

/// Bytes per component of a map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct MapMemory {
    /// Key frames: their poses, keypoints (descriptors, depths, point ids) and observations.
    pub keyframes: usize,
    /// Map points and who observes them.
    pub points: usize,
    /// The place-recognition index: each key frame's bag of words and direct index, and the
    /// key-frame database's inverted index.
    pub bow_index: usize,
}

impl std::ops::Add for MapMemory {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            keyframes: self.keyframes + o.keyframes,
            points: self.points + o.points,
            bow_index: self.bow_index + o.bow_index,
        }
    }
}

/// Bytes of a vector's elements (its capacity).
pub(crate) fn vec_bytes<T>(v: &Vec<T>) -> usize {
    v.capacity() * size_of::<T>()
}

/// Bytes of a B-tree map's entries.
pub(crate) fn map_bytes<K, V>(m: &BTreeMap<K, V>) -> usize {
    m.len() * (size_of::<K>() + size_of::<V>())
}

/// Bytes of a B-tree set's entries.
pub(crate) fn set_bytes<K>(s: &BTreeSet<K>) -> usize {
    s.len() * size_of::<K>()
}
