//! Updates: a voxel's hit or miss on the way down, pruning and the parents' maximum on the way
//! back up, recolouring, maximum likelihood.

use super::*;

impl OcTree {
    /// [`OcTree::search`], for changing the node.
    pub(super) fn search_mut(&mut self, key: Key) -> Option<&mut Node> {
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
    pub(super) fn prune(&mut self, at: (u32, usize)) -> bool {
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

    pub(super) fn ml_recurs(&mut self, at: (u32, usize)) {
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

    pub(super) fn prune_recurs(&mut self, at: (u32, usize)) {
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
}
