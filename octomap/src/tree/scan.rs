//! Batch scan insertion (OctoMap's `insertPointCloud`): each voxel updated once per scan, end
//! points win over free space, the blocks a scan adds counted before it runs.

use super::*;

/// Morton code of a key (x, y, z bits interleaved, z highest): sorting keys by it walks the
/// tree depth first, so consecutive updates share most of their path.
pub(super) fn morton(k: Key) -> u64 {
    pub(super) fn spread(v: u16) -> u64 {
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
pub(super) fn ray_end(origin: [f32; 3], p: [f32; 3], max_range: f64) -> ([f32; 3], bool) {
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
pub(super) fn unpack(p: u64) -> Key {
    Key([(p >> 32) as u16, (p >> 16) as u16, p as u16])
}

pub(super) fn unmorton(m: u64) -> Key {
    pub(super) fn squeeze(mut x: u64) -> u16 {
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
pub(super) struct KeyDedup {
    pub(super) lo: [i32; 3],
    pub(super) dims: [usize; 3],
    pub(super) bits: Vec<u64>,
    pub(super) outside: KeySet,
    pub(super) list: Vec<u64>,
}

impl KeyDedup {
    /// Empty, covering keys `lo..lo + dims` densely (when that fits in 16 MB of bits).
    pub(super) fn reset(&mut self, lo: [i32; 3], dims: [usize; 3]) {
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
    pub(super) fn dense_cells(dims: [usize; 3]) -> Option<usize> {
        dims.iter().try_fold(1usize, |a, &d| a.checked_mul(d)).filter(|&c| c <= 1 << 27)
    }

    #[inline]
    pub(super) fn index(&self, k: Key) -> Option<usize> {
        // Wrapping subtraction: below `lo` becomes huge and fails the bound.
        let x = (i32::from(k.0[0]) - self.lo[0]) as u32 as usize;
        let y = (i32::from(k.0[1]) - self.lo[1]) as u32 as usize;
        let z = (i32::from(k.0[2]) - self.lo[2]) as u32 as usize;
        (x < self.dims[0] && y < self.dims[1] && z < self.dims[2]).then(|| (z * self.dims[1] + y) * self.dims[0] + x)
    }

    /// Add `k`; whether it was new.
    #[inline]
    pub(super) fn insert(&mut self, k: Key) -> bool {
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

    pub(super) fn contains(&self, k: Key) -> bool {
        match self.index(k) {
            Some(i) => self.bits[i / 64] & (1 << (i % 64)) != 0,
            None => self.outside.contains(&k.packed()),
        }
    }
}

/// Scratch buffers reused between scans.
#[derive(Clone, Default)]
pub(super) struct Scratch {
    pub(super) free: KeyDedup,
    pub(super) occupied: KeyDedup,
    pub(super) labels: std::collections::HashMap<u64, Votes<4>, BuildHasherDefault<KeyHasher>>,
    /// Each in-range end point's voxel and colour, in scan order (a semantic tree colours
    /// them after the occupancy updates).
    pub(super) colours: Vec<(Key, [u8; 3])>,
    pub(super) changes: Vec<(Key, bool)>,
}

impl Scratch {
    /// Room (after the resets) for a scan of `visits` voxel visits and `points` end points, so that nothing
    /// grows while it runs: an allocation failure is an error, not an abort.
    pub(super) fn reserve(&mut self, visits: u64, points: usize, dense: bool) -> Result<(), Error> {
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

impl OcTree {
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
    pub(super) fn scan_voxels(&self, points: &[[f32; 3]], origin: [f32; 3], max_range: f64) -> u64 {
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
    pub(super) fn new_blocks(&self, free: &[u64], occupied: &[u64], on_tree: bool) -> u64 {
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
    pub(super) fn first_childless(&self, key: Key) -> u32 {
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
    pub(super) fn scan_box(&self, points: &[[f32; 3]], origin: [f32; 3], max_range: f64) -> ([i32; 3], [usize; 3]) {
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
}
