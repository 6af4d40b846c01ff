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
//! Why one file of this size: the arena's block layout, the update and pruning walks, the
//! batch scan insertion with its change tracking and the memory budget all work on the same
//! private node representation and its invariants (a block is a node's eight children, freed
//! blocks are reused, a pruned node has none); split apart they would need that
//! representation public to each other. A third of the file is its unit tests.

use std::collections::HashSet;
use std::hash::{BuildHasherDefault, Hasher};

use crate::Error;
use crate::key::{DEPTH, Grid, Key};

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

/// Morton code of a key (x, y, z bits interleaved, z highest): sorting keys by it walks the
/// tree depth first, so consecutive updates share most of their path.
fn morton(k: Key) -> u64 {
    fn spread(v: u16) -> u64 {
        let mut x = u64::from(v);
        x = (x | (x << 16)) & 0x0000_FF00_00FF;
        x = (x | (x << 8)) & 0x00F0_0F00_F00F;
        x = (x | (x << 4)) & 0x0003_0C30_C30C_30C3;
        (x | (x << 2)) & 0x0009_2492_4924_9249
    }
    spread(k.0[0]) | (spread(k.0[1]) << 1) | (spread(k.0[2]) << 2)
}

/// Where the free-space ray of scan point `p` ends, and whether `p` is within `max_range`
/// (any when negative): the point itself, or the point at `max_range` along the ray, computed
/// as OctoMap's `computeUpdate` does (`f32` direction scaled by the range).
fn ray_end(origin: [f32; 3], p: [f32; 3], max_range: f64) -> ([f32; 3], bool) {
    let d = [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]];
    let norm = f64::from(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if max_range < 0.0 || norm <= max_range {
        return (p, true);
    }
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let dir = [d[0] / len, d[1] / len, d[2] / len];
    let r = max_range as f32;
    ([origin[0] + dir[0] * r, origin[1] + dir[1] * r, origin[2] + dir[2] * r], false)
}

/// The key [`Key::packed`] made.
fn unpack(p: u64) -> Key {
    Key([(p >> 32) as u16, (p >> 16) as u16, p as u16])
}

fn unmorton(m: u64) -> Key {
    fn squeeze(mut x: u64) -> u16 {
        x &= 0x0009_2492_4924_9249;
        x = (x | (x >> 2)) & 0x0003_0C30_C30C_30C3;
        x = (x | (x >> 4)) & 0x00F0_0F00_F00F;
        x = (x | (x >> 8)) & 0x0000_FF00_00FF;
        x = (x | (x >> 16)) & 0xFFFF;
        x as u16
    }
    Key([squeeze(m), squeeze(m >> 1), squeeze(m >> 2)])
}

/// A set of keys for one scan: a bitmap over the scan's bounding box (set and cleared in
/// O(1) per key), with a hash set for keys outside it; the distinct keys in `list`.
#[derive(Clone, Default)]
struct KeyDedup {
    lo: [i32; 3],
    dims: [usize; 3],
    bits: Vec<u64>,
    outside: KeySet,
    list: Vec<u64>,
}

impl KeyDedup {
    /// Empty, covering keys `lo..lo + dims` densely (when that fits in 16 MB of bits).
    fn reset(&mut self, lo: [i32; 3], dims: [usize; 3]) {
        for &m in &self.list {
            if let Some(i) = self.index(unmorton(m)) {
                self.bits[i / 64] &= !(1 << (i % 64));
            }
        }
        self.list.clear();
        self.outside.clear();
        match Self::dense_cells(dims) {
            Some(c) => {
                if self.bits.len() < c.div_ceil(64) {
                    self.bits.resize(c.div_ceil(64), 0);
                }
                self.lo = lo;
                self.dims = dims;
            }
            None => self.dims = [0; 3],
        }
    }

    /// The bitmap's cells for a box of `dims` keys, if it gets one (up to 2^27 bits, 16 MB).
    fn dense_cells(dims: [usize; 3]) -> Option<usize> {
        dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).filter(|&c| c <= 1 << 27)
    }

    #[inline]
    fn index(&self, k: Key) -> Option<usize> {
        // Wrapping subtraction: below `lo` becomes huge and fails the bound.
        let x = (i32::from(k.0[0]) - self.lo[0]) as u32 as usize;
        let y = (i32::from(k.0[1]) - self.lo[1]) as u32 as usize;
        let z = (i32::from(k.0[2]) - self.lo[2]) as u32 as usize;
        (x < self.dims[0] && y < self.dims[1] && z < self.dims[2]).then(|| (z * self.dims[1] + y) * self.dims[0] + x)
    }

    /// Add `k`; whether it was new.
    #[inline]
    fn insert(&mut self, k: Key) -> bool {
        let new = match self.index(k) {
            Some(i) => {
                let (w, b) = (i / 64, 1u64 << (i % 64));
                let new = self.bits[w] & b == 0;
                self.bits[w] |= b;
                new
            }
            None => self.outside.insert(k.packed()),
        };
        if new {
            self.list.push(morton(k));
        }
        new
    }

    fn contains(&self, k: Key) -> bool {
        match self.index(k) {
            Some(i) => self.bits[i / 64] & (1 << (i % 64)) != 0,
            None => self.outside.contains(&k.packed()),
        }
    }
}

/// Scratch buffers reused between scans.
#[derive(Clone, Default)]
struct Scratch {
    free: KeyDedup,
    occupied: KeyDedup,
    labels: std::collections::HashMap<u64, Votes<4>, BuildHasherDefault<KeyHasher>>,
    /// Each in-range end point's voxel and colour, in scan order (a semantic tree colours
    /// them after the occupancy updates).
    colours: Vec<(Key, [u8; 3])>,
    changes: Vec<(Key, bool)>,
}

impl Scratch {
    /// Room (after the resets) for a scan of `visits` voxel visits and `points` end points, so that nothing
    /// grows while it runs: an allocation failure is an error, not an abort.
    fn reserve(&mut self, visits: u64, points: usize, dense: bool) -> Result<(), Error> {
        let visits = usize::try_from(visits).unwrap_or(usize::MAX);
        let fail = |n: usize, each: usize| Error::Alloc { bytes: (n as u64).saturating_mul(each as u64) };
        self.free.list.try_reserve(visits).map_err(|_| fail(visits, 8))?;
        self.occupied.list.try_reserve(points).map_err(|_| fail(points, 8))?;
        if !dense {
            self.free.outside.try_reserve(visits).map_err(|_| fail(visits, 16))?;
            self.occupied.outside.try_reserve(points).map_err(|_| fail(points, 16))?;
        }
        // (The label table is left to size itself: it is per point, so bounded by the image,
        // and sized ahead it would spread over more memory than the scan's distinct voxels.)
        self.colours.try_reserve(points).map_err(|_| fail(points, 8))?;
        self.changes.try_reserve(visits.saturating_add(points)).map_err(|_| fail(visits, 8))?;
        Ok(())
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

    /// [`OcTree::search`], for changing the node.
    fn search_mut(&mut self, key: Key) -> Option<&mut Node> {
        if !self.root.exists() {
            return None;
        }
        let mut at = (NONE, 0usize);
        for level in (0..DEPTH).rev() {
            let n = *self.node_mut(at);
            if !n.has_children() {
                break;
            }
            let pos = key.child_index(level);
            if !self.blocks[n.children as usize][pos].exists() {
                return None;
            }
            at = (n.children, pos);
        }
        Some(self.node_mut(at))
    }

    /// OctoMap's `ColorOcTree::averageNodeColor`: the node holding `key` (the voxel, or the
    /// pruned node it lies in) takes the mean of its colour and `color` (each channel
    /// `(old + new) / 2`, rounded down), or `color` if it had none; nothing in unknown space.
    pub fn average_node_color(&mut self, key: Key, color: [u8; 3]) {
        if let Some(n) = self.search_mut(key) {
            if n.color_set() {
                for (c, new) in n.color.iter_mut().zip(color) {
                    *c = ((u16::from(*c) + u16::from(new)) / 2) as u8;
                }
            } else {
                n.color = color;
            }
        }
    }

    /// The deepest node on `key`'s path: the voxel, or the pruned node holding it; `None`
    /// for unknown space.
    pub fn search(&self, key: Key) -> Option<&Node> {
        let mut n = self.root()?;
        for level in (0..DEPTH).rev() {
            if !n.has_children() {
                return Some(n);
            }
            n = self.child(n, key.child_index(level))?;
        }
        Some(n)
    }

    /// Occupancy probability at a point; `None` for unknown space or outside the tree.
    pub fn occupancy_at(&self, p: [f32; 3]) -> Option<f64> {
        let k = self.grid.key(p)?;
        self.search(k).map(|n| probability(n.log_odds))
    }

    /// Update one voxel with a hit or a miss (and, for hits in a semantic tree, its label),
    /// as OctoMap's `updateNode(key, occupied, lazy_eval = false)`. Returns the voxel's new
    /// state (occupied or not) when its occupancy decision changed (unknown counts as a
    /// state), as OctoMap's change detection.
    pub fn update(&mut self, key: Key, hit: bool, label: Option<Label>) -> Option<bool> {
        let delta = if hit { self.hit } else { self.miss };
        // OctoMap's early abort: the voxel (or the pruned node holding it) is already clamped
        // in this direction. Checked on the way down, where that node is met, before anything
        // is modified.
        let keep_label = label.is_some() && self.semantic;
        let (lo_clamp, hi_clamp) = (self.clamp_min, self.clamp_max);
        let clamped = |l: f32| !keep_label && ((delta >= 0.0 && l >= hi_clamp) || (delta <= 0.0 && l <= lo_clamp));
        // The state before: the node met (`None`: unknown space).
        let mut before: Option<bool> = None;
        let mut just_created = false;
        if !self.root.exists() {
            self.root = Node::NEW;
            just_created = true;
        }
        // Down: (block, slot) of each node on the path; the root is (NONE, 0).
        let mut path = [(NONE, 0usize); DEPTH as usize + 1];
        // Each node's state before this update (existed, log-odds, had children): once a node
        // comes out unchanged, nothing above it can change and the walk up stops.
        let mut was = [(false, 0.0f32, false); DEPTH as usize + 1];
        let mut at = (NONE, 0usize);
        for (depth, level) in (0..DEPTH).rev().enumerate() {
            path[depth] = at;
            let pos = key.child_index(level);
            let node = *self.node_mut(at);
            was[depth] = (!just_created, node.log_odds, node.has_children());
            let mut created = false;
            let exists = node.children != NONE && self.blocks[node.children as usize][pos].exists();
            if !exists {
                if node.children == NONE && !just_created {
                    // A pruned node: expand it into eight copies of itself.
                    if clamped(node.log_odds) {
                        return None;
                    }
                    before = Some(self.is_occupied(&node));
                    let b = self.alloc();
                    let mut copy = node;
                    copy.children = NONE;
                    copy.flags |= EXISTS;
                    self.blocks[b as usize] = [copy; 8];
                    self.node_mut(at).children = b;
                } else {
                    let b = if node.children == NONE {
                        let b = self.alloc();
                        self.node_mut(at).children = b;
                        b
                    } else {
                        node.children
                    };
                    self.blocks[b as usize][pos] = Node::NEW;
                    created = true;
                }
            }
            just_created = created;
            at = (self.node_mut(at).children, pos);
        }
        path[DEPTH as usize] = at;
        if !just_created && before.is_none() {
            // An existing voxel at the finest level.
            let l = self.node_mut(at).log_odds;
            if clamped(l) {
                return None;
            }
            before = Some(l >= self.occupied_at);
        }
        let (lo, hi, at_least) = (self.clamp_min, self.clamp_max, self.occupied_at);
        let semantic = self.semantic;
        let leaf = self.node_mut(at);
        leaf.log_odds = (leaf.log_odds + delta).clamp(lo, hi);
        let now = leaf.log_odds >= at_least;
        if semantic && let Some(l) = label {
            leaf.color = l.color;
            leaf.class = l.class;
        }
        // Up: prune, or take the children's maximum, until a node comes out as it was.
        for depth in (0..DEPTH as usize).rev() {
            let at = path[depth];
            if !self.prune(at) {
                let b = self.node_mut(at).children;
                let max = self.blocks[b as usize]
                    .iter()
                    .filter(|c| c.exists())
                    .map(|c| c.log_odds)
                    .fold(f32::NEG_INFINITY, f32::max);
                self.node_mut(at).log_odds = max;
            }
            let n = self.node_mut(at);
            if was[depth] == (true, n.log_odds, n.has_children()) {
                break;
            }
        }
        (before != Some(now)).then_some(now)
    }

    /// Prune the node at `at` if its eight children are leaves of equal occupancy; whether
    /// it did. As OctoMap's ColorOcTree, colours do not prevent pruning: the merged node takes
    /// the average colour of its children (and here the most frequent class).
    fn prune(&mut self, at: (u32, usize)) -> bool {
        let b = self.node_mut(at).children;
        if b == NONE {
            return false;
        }
        let kids = self.blocks[b as usize];
        let first = kids[0];
        if !kids.iter().all(|c| c.exists() && !c.has_children() && c.log_odds == first.log_odds) {
            return false;
        }
        let mut merged = first;
        merged.children = NONE;
        merged.flags |= EXISTS;
        if self.semantic && first.color_set() {
            let mut votes = Votes::<8>::default();
            for c in kids.iter().filter(|c| c.color_set()) {
                votes.add(&Label { color: c.color, class: c.class });
            }
            let Label { color, class } = votes.label();
            (merged.color, merged.class) = (color, class);
        }
        *self.node_mut(at) = merged;
        self.free_blocks.push(b);
        self.released += 1;
        true
    }

    /// Insert one scan as OctoMap's `insertPointCloud(cloud, origin, max_range)`: the voxels on
    /// each ray from `origin` up to its end point are updated free once, each end point's
    /// voxel occupied once (a voxel that is both counts as occupied); a point beyond
    /// `max_range` (when positive) clears the ray up to `max_range` and marks nothing. With
    /// `labels` (one per point) a semantic tree then colours, point by point in scan order,
    /// the node holding each end point as OctoMap's ColorOcTree does after an insertion
    /// (`averageNodeColor`, what octomap_server calls), and gives it the most frequent class
    /// of the scan's points in it. Points are world coordinates.
    ///
    /// The scan is refused, the tree untouched, when it would take the tree's nodes plus its
    /// own scratch past [`Params::max_memory_bytes`]: first on a bound of the voxels its rays
    /// cross (the key distance of each ray, before any work), then on the blocks of nodes its
    /// distinct voxels would add, counted exactly on the tree before it changes.
    pub fn insert_scan(
        &mut self,
        points: &[[f32; 3]],
        labels: Option<&[Label]>,
        origin: [f32; 3],
        max_range: f64,
    ) -> Result<(), Error> {
        let budget = self.params.max_memory_bytes;
        let tree_bytes = self.memory_bytes() as u64;
        let voxels = self.scan_voxels(points, origin, max_range);
        let mut s = std::mem::take(&mut self.scratch);
        s.changes.clear();
        // The scan's bounding box in keys: the sensor's range around it, or the points'.
        let (lo, dims) = self.scan_box(points, origin, max_range);
        // Scratch, per voxel visit at most: a key in the list and a change (16 bytes), a hash
        // entry with the table's slack (24 more) when the box is too large for the bitmap; per
        // point: its key, hash entry, label votes with slack and colour (168); both bitmaps.
        let dense_cells = KeyDedup::dense_cells(dims);
        let dense = dense_cells.is_some();
        let per_visit = if dense { 16 } else { 40 };
        let scratch = voxels.saturating_mul(per_visit)
            + (points.len() as u64).saturating_mul(168)
            + 2 * dense_cells.map_or(0, |c| c.div_ceil(8) as u64);
        let over = |scan_bytes: u64| Error::OverBudget { voxels, tree_bytes, scan_bytes, budget };
        if tree_bytes.saturating_add(scratch) > budget {
            self.scratch = s;
            return Err(over(scratch));
        }
        s.free.reset(lo, dims);
        s.occupied.reset(lo, dims);
        s.labels.clear();
        s.colours.clear();
        if let Err(e) = s.reserve(voxels, points.len(), dense) {
            self.scratch = s;
            return Err(e);
        }
        for (i, p) in points.iter().enumerate() {
            let (end, in_range) = ray_end(origin, *p, max_range);
            let free = &mut s.free;
            self.grid.ray_walk(origin, end, |k| {
                free.insert(k);
            });
            if in_range && let Some(k) = self.grid.key(*p) {
                s.occupied.insert(k);
                if let Some(l) = labels.and_then(|l| l.get(i)) {
                    s.labels.entry(k.packed()).or_default().add(l);
                    if self.semantic {
                        s.colours.push((k, l.color));
                    }
                }
            }
        }
        // Depth-first order: consecutive updates share their path down the tree.
        s.free.list.sort_unstable();
        s.occupied.list.sort_unstable();
        // The nodes the scan adds. Quick: the distinct nodes of its paths, as if the tree were
        // empty, the arena left to grow as a vector does (doubling, so at most twice what it
        // holds). Else the exact count on the tree as it is, and the arena grown to fit it
        // before any update.
        let (len, capacity) = (self.blocks.len() as u64, self.blocks.capacity() as u64);
        let quick = self.new_blocks(&s.free.list, &s.occupied.list, false);
        let doubled = capacity.max(len.saturating_add(quick).saturating_mul(2));
        if doubled.saturating_mul(BLOCK_BYTES).saturating_add(scratch) > budget {
            let blocks = self.new_blocks(&s.free.list, &s.occupied.list, true);
            let need = blocks.saturating_sub(self.free_blocks.len() as u64);
            // (The arena's capacity already fits: the first check counted it.)
            if (len + need) * BLOCK_BYTES + scratch > budget {
                self.scratch = s;
                return Err(over(scratch + blocks * BLOCK_BYTES));
            }
            if len + need > capacity {
                // Grow as a vector would (doubling), but never past the budget.
                let cap_max = (budget.saturating_sub(scratch) / BLOCK_BYTES).max(len + need);
                let target = (capacity * 2).clamp(len + need, cap_max);
                if self.blocks.try_reserve_exact((target - len) as usize).is_err() {
                    self.scratch = s;
                    return Err(Error::Alloc { bytes: (target - len) * BLOCK_BYTES });
                }
            }
        }
        for &m in &s.free.list {
            let k = unmorton(m);
            if !s.occupied.contains(k)
                && let Some(now) = self.update(k, false, None)
            {
                s.changes.push((k, now));
            }
        }
        for &m in &s.occupied.list {
            let k = unmorton(m);
            if let Some(now) = self.update(k, true, None) {
                s.changes.push((k, now));
            }
        }
        if self.semantic {
            for &(k, color) in &s.colours {
                self.average_node_color(k, color);
            }
            for (&packed, votes) in &s.labels {
                if let Some(n) = self.search_mut(unpack(packed)) {
                    n.class = votes.label().class;
                }
            }
        }
        self.scratch = s;
        Ok(())
    }

    /// An upper bound on the voxel visits of a scan's rays: a 3-D DDA steps one key along one
    /// axis at a time, so a ray visits at most its key distance plus one.
    fn scan_voxels(&self, points: &[[f32; 3]], origin: [f32; 3], max_range: f64) -> u64 {
        let Some(o) = self.grid.key(origin) else { return 0 };
        let mut total = 0u64;
        for p in points {
            if let Some(e) = self.grid.key(ray_end(origin, *p, max_range).0) {
                let dist: u64 = (0..3).map(|a| u64::from(o.0[a].abs_diff(e.0[a]))).sum();
                total = total.saturating_add(dist + 1);
            }
        }
        total
    }

    /// The blocks of eight nodes that updating these voxels (two lists in Morton order, free
    /// and occupied) adds to the tree as it is: each voxel, in Morton order over both lists,
    /// needs a block under every node of its path from the first one without children
    /// (unknown space, or a pruned node that expands) down, less those the voxel before it
    /// already added on their shared path. Exact as a bound on the live blocks: a block more
    /// is only ever taken under a node this scan pruned, which gave one back.
    ///
    /// With `on_tree` false, the tree is not read and every path counts from the root: the
    /// distinct nodes of the scan's paths, a bound that costs no search.
    fn new_blocks(&self, free: &[u64], occupied: &[u64], on_tree: bool) -> u64 {
        let (mut i, mut j) = (0, 0);
        let mut total = 0u64;
        let mut prev: Option<(u64, u32)> = None;
        loop {
            let m = match (free.get(i), occupied.get(j)) {
                (Some(&a), Some(&b)) if a == b => {
                    i += 1;
                    j += 1;
                    a
                }
                (Some(&a), Some(&b)) if a < b => {
                    i += 1;
                    a
                }
                (_, Some(&b)) => {
                    j += 1;
                    b
                }
                (Some(&a), None) => {
                    i += 1;
                    a
                }
                (None, None) => break,
            };
            let first = if on_tree { self.first_childless(unmorton(m)) } else { 0 };
            let mut n = DEPTH - first;
            if let Some((pm, pfirst)) = prev {
                // Nodes at depths 0..=shared lie on both paths.
                let shared = ((m ^ pm).leading_zeros() - 16) / 3;
                let lo = first.max(pfirst);
                let hi = shared.min(DEPTH - 1);
                if hi >= lo {
                    n -= hi - lo + 1;
                }
            }
            total += u64::from(n);
            prev = Some((m, first));
        }
        total
    }

    /// The depth of the first node on `key`'s path that would need a block of children (the
    /// root is depth 0; `DEPTH`: none, the voxel exists).
    fn first_childless(&self, key: Key) -> u32 {
        if !self.root.exists() {
            return 0;
        }
        let mut n = &self.root;
        for (depth, level) in (0..DEPTH).rev().enumerate() {
            if !n.has_children() {
                return depth as u32;
            }
            match self.child(n, key.child_index(level)) {
                Some(c) => n = c,
                None => return depth as u32 + 1,
            }
        }
        DEPTH
    }

    /// Keys `lo .. lo + dims` covering a scan: its range around the origin, or its points.
    fn scan_box(&self, points: &[[f32; 3]], origin: [f32; 3], max_range: f64) -> ([i32; 3], [usize; 3]) {
        let key = |v: f64| (v / self.params.resolution).floor() as i64 + i64::from(crate::key::MAX_VAL);
        let (mut lo, mut hi) = ([0i64; 3], [0i64; 3]);
        if max_range > 0.0 {
            for a in 0..3 {
                lo[a] = key(f64::from(origin[a]) - max_range) - 1;
                hi[a] = key(f64::from(origin[a]) + max_range) + 1;
            }
        } else {
            for a in 0..3 {
                let o = f64::from(origin[a]);
                let (mn, mx) =
                    points.iter().fold((o, o), |(a0, b0), p| (a0.min(f64::from(p[a])), b0.max(f64::from(p[a]))));
                lo[a] = key(mn) - 1;
                hi[a] = key(mx) + 1;
            }
        }
        let lo = lo.map(|v| v.clamp(0, 65_535) as i32);
        let hi = hi.map(|v| v.clamp(0, 65_535) as i32);
        (lo, [0, 1, 2].map(|a| (hi[a] - lo[a] + 1).max(0) as usize))
    }

    /// The voxels whose occupancy decision the last [`OcTree::insert_scan`] changed, with
    /// their new state (`true`: occupied).
    pub fn last_changes(&self) -> &[(Key, bool)] {
        &self.scratch.changes
    }

    /// Every leaf (voxels at the finest level and pruned nodes), depth first.
    pub fn leaves(&self) -> Vec<Leaf> {
        let mut out = Vec::new();
        if let Some(r) = self.root() {
            self.collect(r, Key([0; 3]), 1 << DEPTH, &mut out);
        }
        out
    }

    fn collect(&self, n: &Node, corner: Key, size: u32, out: &mut Vec<Leaf>) {
        if !n.has_children() {
            out.push(Leaf { key: corner, size, node: *n });
            return;
        }
        let half = (size / 2) as u16;
        for i in 0..8 {
            if let Some(c) = self.child(n, i) {
                let k = Key([
                    corner.0[0] + if i & 1 != 0 { half } else { 0 },
                    corner.0[1] + if i & 2 != 0 { half } else { 0 },
                    corner.0[2] + if i & 4 != 0 { half } else { 0 },
                ]);
                self.collect(c, k, size / 2, out);
            }
        }
    }

    /// Occupied leaves.
    pub fn occupied_leaves(&self) -> Vec<Leaf> {
        self.leaves().into_iter().filter(|l| self.is_occupied(&l.node)).collect()
    }

    /// Walk from `origin` along `direction` (voxel by voxel) to the first occupied voxel, as
    /// OctoMap's `castRay` with `ignoreUnknown = false`; `max_range` <= 0: to the tree's edge.
    pub fn cast_ray(&self, origin: [f32; 3], direction: [f32; 3], max_range: f64) -> RayHit {
        let norm = (direction.iter().map(|d| f64::from(*d).powi(2)).sum::<f64>()).sqrt();
        let Some(start) = self.grid.key(origin) else { return RayHit::Free };
        if norm == 0.0 {
            return RayHit::Free;
        }
        let dir = [f64::from(direction[0]) / norm, f64::from(direction[1]) / norm, f64::from(direction[2]) / norm];
        let res = self.params.resolution;
        let mut cur = [i32::from(start.0[0]), i32::from(start.0[1]), i32::from(start.0[2])];
        let mut step = [0i32; 3];
        let mut t_max = [f64::MAX; 3];
        let mut t_delta = [f64::MAX; 3];
        for i in 0..3 {
            if dir[i] != 0.0 {
                step[i] = if dir[i] > 0.0 { 1 } else { -1 };
                let border = self.grid.key_coord(start.0[i]) + f64::from(step[i]) * res * 0.5;
                t_max[i] = (border - f64::from(origin[i])) / dir[i];
                t_delta[i] = res / dir[i].abs();
            }
        }
        loop {
            let key = Key([cur[0] as u16, cur[1] as u16, cur[2] as u16]);
            match self.search(key) {
                Some(n) if self.is_occupied(n) => return RayHit::Occupied(self.grid.centre(key)),
                Some(_) => {}
                None => return RayHit::Unknown(self.grid.centre(key)),
            }
            let dim = (0..3).min_by(|&a, &b| t_max[a].total_cmp(&t_max[b])).unwrap_or(0);
            if max_range > 0.0 && t_max[dim] > max_range {
                return RayHit::Free;
            }
            cur[dim] += step[dim];
            t_max[dim] += t_delta[dim];
            if !(0..=65_535).contains(&cur[dim]) {
                return RayHit::Free;
            }
        }
    }

    /// Colour every observed voxel by its class (a semantic map's colours).
    pub fn recolor(&mut self, color: impl Fn(u16) -> [u8; 3]) {
        for n in self.blocks.iter_mut().flatten().chain(std::iter::once(&mut self.root)) {
            if n.exists() && n.color_set() {
                n.color = color(n.class);
            }
        }
    }

    /// Every node to its maximum-likelihood value (clamp bound), then pruned again, as
    /// OctoMap's `toMaxLikelihood` + `prune` (what `writeBinary` stores).
    pub fn to_max_likelihood(&mut self) {
        if !self.root.exists() {
            return;
        }
        self.ml_recurs((NONE, 0));
    }

    fn ml_recurs(&mut self, at: (u32, usize)) {
        let n = *self.node_mut(at);
        let v = if self.is_occupied(&n) { self.clamp_max } else { self.clamp_min };
        self.node_mut(at).log_odds = v;
        if n.children != NONE {
            for i in 0..8 {
                if self.blocks[n.children as usize][i].exists() {
                    self.ml_recurs((n.children, i));
                }
            }
            self.prune(at);
        }
    }

    /// Prune every collapsible node, bottom up (OctoMap's `prune`).
    pub fn prune_all(&mut self) {
        if self.root.exists() {
            self.prune_recurs((NONE, 0));
        }
    }

    fn prune_recurs(&mut self, at: (u32, usize)) {
        let b = self.node_mut(at).children;
        if b == NONE {
            return;
        }
        for i in 0..8 {
            if self.blocks[b as usize][i].exists() {
                self.prune_recurs((b, i));
            }
        }
        self.prune(at);
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
mod tests {
    use super::*;

    fn tree() -> OcTree {
        OcTree::new(Params::default(), false).unwrap()
    }

    #[test]
    fn hits_and_misses_follow_octomaps_log_odds_and_clamp() {
        let mut t = tree();
        let k = t.grid().key([0.3, 0.2, 0.1]).unwrap();
        t.update(k, true, None);
        assert!((t.search(k).unwrap().log_odds - logodds(0.7)).abs() < 1e-7);
        for _ in 0..20 {
            t.update(k, true, None);
        }
        assert_eq!(t.search(k).unwrap().log_odds, logodds(0.971));
        for _ in 0..40 {
            t.update(k, false, None);
        }
        assert_eq!(t.search(k).unwrap().log_odds, logodds(0.1192));
        // One voxel: 16 levels of single children plus the root.
        assert_eq!(t.size(), 17);
        assert!(t.search(Key([1, 2, 3])).is_none());
    }

    #[test]
    fn eight_equal_siblings_are_pruned_and_expand_again() {
        let mut t = tree();
        let base = t.grid().key([0.0, 0.0, 0.0]).unwrap();
        let sib = |i: u16| Key([base.0[0] + (i & 1), base.0[1] + ((i >> 1) & 1), base.0[2] + ((i >> 2) & 1)]);
        for i in 0..8 {
            t.update(sib(i), true, None);
        }
        assert_eq!(t.size(), 16, "the eight leaves merged into their parent");
        assert_eq!(t.leaves().len(), 1);
        assert_eq!(t.leaves()[0].size, 2);
        t.update(sib(3), true, None);
        assert_eq!(t.size(), 24, "expanded back into eight");
        assert!(t.search(sib(3)).unwrap().log_odds > t.search(sib(2)).unwrap().log_odds);
    }

    #[test]
    fn a_scan_clears_its_rays_and_marks_its_end_points() {
        let mut t = tree();
        let wall: Vec<[f32; 3]> =
            (0..20).flat_map(|i| (0..20).map(move |j| [2.0, -0.5 + i as f32 * 0.05, -0.5 + j as f32 * 0.05])).collect();
        t.insert_scan(&wall, None, [0.01, 0.01, 0.01], -1.0).unwrap();
        assert!(t.occupancy_at([2.0, 0.0, 0.0]).unwrap() > 0.5);
        assert!(t.occupancy_at([1.0, 0.0, 0.0]).unwrap() < 0.5);
        assert!(t.occupancy_at([3.0, 0.0, 0.0]).is_none(), "behind the wall is unknown");
        match t.cast_ray([0.01, 0.01, 0.01], [1.0, 0.0, 0.0], -1.0) {
            RayHit::Occupied(p) => assert!((p[0] - 2.025).abs() < 1e-9, "{p:?}"),
            other => panic!("{other:?}"),
        }
        assert_eq!(t.cast_ray([0.01, 0.01, 0.01], [1.0, 0.0, 0.0], 1.0), RayHit::Free);
        let occupied_now = t.last_changes().iter().filter(|c| c.1).count();
        assert_eq!(occupied_now, t.occupied_leaves().iter().map(|l| (l.size as usize).pow(3)).sum::<usize>());
        // The same scan again changes nothing.
        t.insert_scan(&wall, None, [0.01, 0.01, 0.01], -1.0).unwrap();
        assert!(t.last_changes().is_empty());
        assert!(matches!(t.cast_ray([0.01, 0.01, 0.01], [0.0, 0.0, -1.0], -1.0), RayHit::Unknown(_)));
        // Beyond max range: the ray is cleared to the range, nothing is marked.
        let mut u = tree();
        u.insert_scan(&wall, None, [0.01, 0.01, 0.01], 1.0).unwrap();
        assert!(u.occupancy_at([2.0, 0.0, 0.0]).is_none());
        assert!(u.occupancy_at([0.9, 0.0, 0.0]).unwrap() < 0.5);
    }

    #[test]
    fn a_semantic_tree_keeps_colour_and_class() {
        let mut t = OcTree::new(Params::default(), true).unwrap();
        let pts = [[1.0f32, 0.0, 0.0], [1.01, 0.01, 0.0], [2.0, 0.0, 0.0]];
        let labels = [
            Label { color: [10, 20, 30], class: 5 },
            Label { color: [30, 40, 50], class: 5 },
            Label { color: [200, 0, 0], class: 1 },
        ];
        t.insert_scan(&pts, Some(&labels), [0.0, 0.0, 0.0], -1.0).unwrap();
        let k = t.grid().key([1.0, 0.0, 0.0]).unwrap();
        let n = t.search(k).unwrap();
        assert_eq!((n.color, n.class, n.color_set()), ([20, 30, 40], 5, true));
        assert_eq!(t.search(t.grid().key([2.0, 0.0, 0.0]).unwrap()).unwrap().class, 1);
    }

    #[test]
    fn morton_codes_round_trip_and_order_depth_first() {
        for k in [Key([0, 0, 0]), Key([65_535, 1, 32_768]), Key([12_345, 54_321, 777])] {
            assert_eq!(unmorton(morton(k)), k);
        }
        // The eight children of one node are consecutive.
        assert_eq!(morton(Key([1, 1, 1])), 7);
        assert!(morton(Key([1, 1, 1])) < morton(Key([2, 0, 0])));
    }

    /// A fan of rays from the origin to a wall `at` metres away.
    fn fan(at: f32, n: usize) -> Vec<[f32; 3]> {
        (0..n).flat_map(|i| (0..n).map(move |j| [at, -0.5 + i as f32 / n as f32, -0.4 + j as f32 / n as f32])).collect()
    }

    #[test]
    fn the_blocks_a_scan_adds_are_counted_exactly_before_it_runs() {
        let mut t = tree();
        for (scan, origin) in [(fan(2.0, 30), [0.01f32, 0.02, 0.03]), (fan(3.0, 25), [0.3, -0.2, 0.1])] {
            // The count the budget uses, on the tree as it is (the scan's sorted key lists).
            let mut probe = t.clone();
            probe.insert_scan(&scan, None, origin, -1.0).unwrap();
            let (free, occupied) = (probe.scratch.free.list.clone(), probe.scratch.occupied.list.clone());
            let predicted = t.new_blocks(&free, &occupied, true);
            assert!(predicted <= t.new_blocks(&free, &occupied, false), "the quick bound bounds");
            let (allocated, released) = (t.allocated, t.released);
            t.insert_scan(&scan, None, origin, -1.0).unwrap();
            let (used, pruned) = (t.allocated - allocated, t.released - released);
            // Every predicted block is taken; more only under nodes the scan pruned.
            assert!(
                predicted <= used && used <= predicted + pruned,
                "used {used}, pruned {pruned}, predicted {predicted}"
            );
        }
    }

    #[test]
    fn a_scan_over_the_memory_budget_is_refused_and_changes_nothing() {
        let params = Params { max_memory_bytes: 1 << 20, ..Params::default() };
        let mut t = OcTree::new(params, false).unwrap();
        t.insert_scan(&fan(2.0, 10), None, [0.0, 0.0, 0.0], -1.0).unwrap();
        let (leaves, size, bytes) = (t.leaves(), t.size(), t.memory_bytes());
        assert!(!t.last_changes().is_empty());
        // 1 mm voxels over 2 m rays: far past 1 MiB, refused before any work (the visit bound).
        let mut fine = OcTree::new(Params { resolution: 0.001, ..params }, false).unwrap();
        let err = fine.insert_scan(&fan(2.0, 40), None, [0.0, 0.0, 0.0], -1.0).unwrap_err();
        let Error::OverBudget { voxels, scan_bytes, budget, .. } = err.clone() else { panic!("{err}") };
        assert!(voxels >= 1600 * 2000 && scan_bytes > budget, "{err}");
        assert!(err.to_string().contains("over the 1 MiB memory budget"), "{err}");
        assert_eq!(fine.size(), 0);
        // Within the visit bound but not the nodes: refused after the walk, the tree as it was.
        let err = t.insert_scan(&fan(4.0, 60), None, [0.0, 0.0, 0.0], -1.0).unwrap_err();
        assert!(matches!(err, Error::OverBudget { .. }), "{err}");
        assert_eq!((t.leaves(), t.size(), t.memory_bytes()), (leaves, size, bytes));
        assert!(t.last_changes().is_empty(), "a refused scan changed nothing");
        // The arena never grows past the budget while scans fit.
        let mut u = OcTree::new(Params { max_memory_bytes: 8 << 20, ..Params::default() }, false).unwrap();
        for i in 0..40 {
            let _ = u.insert_scan(&fan(1.0 + 0.1 * i as f32, 40), None, [0.1 * i as f32, 0.0, 0.0], -1.0);
            assert!(u.memory_bytes() as u64 <= 8 << 20);
        }
    }

    #[test]
    fn bad_parameters_are_refused() {
        assert!(OcTree::new(Params { resolution: 0.0, ..Params::default() }, false).is_err());
        assert!(OcTree::new(Params { prob_hit: 0.4, ..Params::default() }, false).is_err());
        assert!(OcTree::new(Params { clamp_min: 0.99, ..Params::default() }, false).is_err());
    }
}
