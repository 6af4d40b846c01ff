//! The occupancy octree: OctoMap 1.9's update rules on a compact arena.
//!
//! Every node is 16 bytes (log-odds, child block, colour, class, flags); the eight children
//! of a node live together in one block of an arena, so a node with children costs one index,
//! not eight pointers, and freed blocks are reused. Semantics are OctoMap's
//! (`OccupancyOcTreeBase`): a new node starts at log-odds 0; a hit adds `logit(prob_hit)`, a
//! miss `logit(prob_miss)`, clamped to `[logit(clamp_min), logit(clamp_max)]`; an update that
//! reaches a pruned node expands it into eight copies; on the way back up, a node whose eight
//! children are identical leaves is pruned into one, otherwise it takes its children's
//! maximum. A node at or above `logit(occupancy)` is occupied.
//!
//! The node layout and the arena live here, private to this module; its children see them
//! (child modules see their parent's private items) and hold the walks: [`update`] (a voxel's
//! hit or miss, pruning, maximum likelihood), [`scan`] (batch insertion with change tracking
//! and the memory budget), [`query`] (search, occupancy, leaves, ray casts).

use std::collections::HashSet;
use std::hash::{BuildHasherDefault, Hasher};

use crate::Error;
use crate::key::{DEPTH, Grid, Key};

mod query;
mod scan;
mod update;

use scan::Scratch;

/// `log(p / (1 - p))` in `f32`, as OctoMap's `logodds`.
pub fn logodds(p: f64) -> f32 {
    (p / (1.0 - p)).ln() as f32
}

/// Probability of a log-odds value.
pub fn probability(l: f32) -> f64 {
    1.0 - 1.0 / (1.0 + f64::from(l).exp())
}

/// Sensor model and tree parameters (OctoMap's defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Params {
    /// Edge of the finest voxel in metres (OctoMap's `res`; 0.05 in PSPNet-SLAM).
    pub resolution: f64,
    /// Probability a hit means occupied (0.7).
    pub prob_hit: f64,
    /// Probability a pass-through means occupied (0.4).
    pub prob_miss: f64,
    /// Lower clamp (0.1192).
    pub clamp_min: f64,
    /// Upper clamp (0.971).
    pub clamp_max: f64,
    /// Occupied at or above this probability (0.5).
    pub occupancy: f64,
    /// Memory budget in bytes for the tree's nodes plus one scan's scratch: a scan that would
    /// take them past it is refused before anything changes ([`Error`]), so no
    /// resolution or range reaches an allocation failure (default 4 GiB; a resource bound, not
    /// an OctoMap parameter).
    pub max_memory_bytes: u64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            resolution: 0.05,
            prob_hit: 0.7,
            prob_miss: 0.4,
            clamp_min: 0.1192,
            clamp_max: 0.971,
            occupancy: 0.5,
            max_memory_bytes: 4 << 30,
        }
    }
}

impl Params {
    /// Why these parameters cannot make a tree, if they cannot.
    pub fn check(&self) -> Result<(), Error> {
        self.problem().map_or(Ok(()), |m| Err(Error::Params(m)))
    }

    fn problem(&self) -> Option<String> {
        let p = |v: f64| v > 0.0 && v < 1.0;
        if !(self.resolution.is_finite() && self.resolution > 0.0) {
            return Some(format!("resolution {} must be a positive number of metres", self.resolution));
        }
        if !(p(self.prob_hit) && p(self.prob_miss) && p(self.clamp_min) && p(self.clamp_max) && p(self.occupancy)) {
            return Some("probabilities must lie strictly between 0 and 1".into());
        }
        if self.max_memory_bytes == 0 {
            return Some("the memory budget must be positive".into());
        }
        if self.prob_hit <= 0.5 || self.prob_miss >= 0.5 || self.clamp_min >= self.clamp_max {
            return Some(format!(
                "need prob_hit > 0.5 > prob_miss and clamp_min < clamp_max (got {}, {}, {}, {})",
                self.prob_hit, self.prob_miss, self.clamp_min, self.clamp_max
            ));
        }
        None
    }
}

/// Bytes of one block of eight nodes.
const BLOCK_BYTES: u64 = std::mem::size_of::<[Node; 8]>() as u64;

/// No child block.
pub(crate) const NONE: u32 = u32::MAX;
/// The node exists (a child slot may be empty: unknown space).
pub(crate) const EXISTS: u8 = 1;

/// One node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// Occupancy log-odds.
    pub log_odds: f32,
    pub(crate) children: u32,
    /// RGB colour (white until observed, as OctoMap's ColorOcTree).
    pub color: [u8; 3],
    pub(crate) flags: u8,
    /// Semantic class (0: none).
    pub class: u16,
}

impl Node {
    pub(crate) const ABSENT: Node = Node { log_odds: 0.0, children: NONE, color: [255; 3], flags: 0, class: 0 };
    const NEW: Node = Node { log_odds: 0.0, children: NONE, color: [255; 3], flags: EXISTS, class: 0 };

    /// Whether it has children.
    pub fn has_children(&self) -> bool {
        self.children != NONE
    }

    /// Whether a colour was observed: OctoMap's `isColorSet`, any colour but white (a white
    /// pixel counts as unobserved there too).
    pub fn color_set(&self) -> bool {
        self.color != [255; 3]
    }

    pub(crate) fn exists(&self) -> bool {
        self.flags & EXISTS != 0
    }
}

/// A hasher for packed keys (multiply-shift; keys are not adversarial).
#[derive(Clone, Default)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ u64::from(b)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        self.0 ^= self.0 >> 32;
    }
}

pub(crate) type KeySet = HashSet<u64, BuildHasherDefault<KeyHasher>>;

/// What a scan point carries besides its position.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Label {
    /// RGB colour of the pixel.
    pub color: [u8; 3],
    /// Semantic class (0: none).
    pub class: u16,
}

/// A leaf of the tree (a voxel at some depth; pruned leaves are larger).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Leaf {
    /// Key of its first finest voxel (lowest corner).
    pub key: Key,
    /// Edge in finest voxels (1 at depth 16, 2 at depth 15...).
    pub size: u32,
    /// The node.
    pub node: Node,
}

/// What a ray cast found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RayHit {
    /// The centre of the first occupied voxel.
    Occupied([f64; 3]),
    /// The centre of the first unknown voxel.
    Unknown([f64; 3]),
    /// Free space all the way to the range limit (or the tree's edge).
    Free,
}

/// Labels pooled into one: colour sum, count, votes for the first `N` distinct classes seen
/// (a voxel's points in one scan: 4, more is noise; a pruned node's children: 8).
#[derive(Clone, Copy)]
struct Votes<const N: usize> {
    sum: [u32; 3],
    n: u32,
    classes: [(u16, u32); N],
}

impl<const N: usize> Default for Votes<N> {
    fn default() -> Self {
        Self { sum: [0; 3], n: 0, classes: [(0, 0); N] }
    }
}

impl<const N: usize> Votes<N> {
    fn add(&mut self, l: &Label) {
        for c in 0..3 {
            self.sum[c] += u32::from(l.color[c]);
        }
        self.n += 1;
        if let Some(v) = self.classes.iter_mut().find(|v| v.1 > 0 && v.0 == l.class) {
            v.1 += 1;
        } else if let Some(v) = self.classes.iter_mut().find(|v| v.1 == 0) {
            *v = (l.class, 1);
        }
    }

    /// Mean colour, most voted class (ties: the smaller id).
    fn label(&self) -> Label {
        let n = self.n.max(1);
        let class =
            self.classes.iter().filter(|v| v.1 > 0).max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0))).map_or(0, |v| v.0);
        Label { color: [(self.sum[0] / n) as u8, (self.sum[1] / n) as u8, (self.sum[2] / n) as u8], class }
    }
}

/// A probabilistic occupancy octree with OctoMap's semantics.
#[derive(Clone)]
pub struct OcTree {
    params: Params,
    grid: Grid,
    hit: f32,
    miss: f32,
    clamp_min: f32,
    clamp_max: f32,
    occupied_at: f32,
    /// Keep colours and classes (OctoMap's ColorOcTree, plus a class).
    semantic: bool,
    root: Node,
    blocks: Vec<[Node; 8]>,
    free_blocks: Vec<u32>,
    /// Blocks handed out so far (new or reused), and given back by pruning: what
    /// [`OcTree::new_blocks`] predicts, checked in the tests.
    allocated: u64,
    released: u64,
    scratch: Scratch,
}

impl std::fmt::Debug for OcTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OcTree").field("params", &self.params).field("nodes", &self.size()).finish()
    }
}

impl OcTree {
    /// An empty tree (checked parameters). `semantic`: keep colour and class per voxel.
    pub fn new(params: Params, semantic: bool) -> Result<Self, Error> {
        params.check()?;
        Ok(Self {
            grid: Grid::new(params.resolution),
            hit: logodds(params.prob_hit),
            miss: logodds(params.prob_miss),
            clamp_min: logodds(params.clamp_min),
            clamp_max: logodds(params.clamp_max),
            occupied_at: logodds(params.occupancy),
            params,
            semantic,
            root: Node::ABSENT,
            blocks: Vec::new(),
            free_blocks: Vec::new(),
            allocated: 0,
            released: 0,
            scratch: Scratch::default(),
        })
    }

    /// Parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Key and coordinate conversions.
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// Whether colours and classes are kept.
    pub fn semantic(&self) -> bool {
        self.semantic
    }

    /// Clamping bounds in log-odds.
    pub fn clamping(&self) -> (f32, f32) {
        (self.clamp_min, self.clamp_max)
    }

    /// Whether a node counts as occupied.
    pub fn is_occupied(&self, n: &Node) -> bool {
        n.log_odds >= self.occupied_at
    }

    /// The root, if the tree is not empty.
    pub fn root(&self) -> Option<&Node> {
        self.root.exists().then_some(&self.root)
    }

    /// Child `i` of `n`, if it exists.
    pub fn child(&self, n: &Node, i: usize) -> Option<&Node> {
        if n.children == NONE {
            return None;
        }
        let c = &self.blocks[n.children as usize][i];
        c.exists().then_some(c)
    }

    /// Number of nodes (OctoMap's `size()`).
    pub fn size(&self) -> usize {
        fn count(t: &OcTree, n: &Node) -> usize {
            1 + (0..8).filter_map(|i| t.child(n, i)).map(|c| count(t, c)).sum::<usize>()
        }
        self.root().map_or(0, |r| count(self, r))
    }

    /// Bytes held by the tree's nodes (the arena, free blocks included).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.blocks.capacity() * std::mem::size_of::<[Node; 8]>()
    }

    fn alloc(&mut self) -> u32 {
        self.allocated += 1;
        if let Some(b) = self.free_blocks.pop() {
            self.blocks[b as usize] = [Node::ABSENT; 8];
            return b;
        }
        self.blocks.push([Node::ABSENT; 8]);
        (self.blocks.len() - 1) as u32
    }

    /// The node at `path` (child indices from the root).
    fn node_mut(&mut self, at: (u32, usize)) -> &mut Node {
        if at.0 == NONE { &mut self.root } else { &mut self.blocks[at.0 as usize][at.1] }
    }

    /// A tree from nodes read from a file (`io`).
    pub(crate) fn from_parts(
        params: Params,
        semantic: bool,
        root: Node,
        blocks: Vec<[Node; 8]>,
    ) -> Result<Self, Error> {
        let mut t = Self::new(params, semantic)?;
        t.root = root;
        t.blocks = blocks;
        Ok(t)
    }
}

#[cfg(test)]
mod tests;
