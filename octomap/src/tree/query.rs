//! Queries: a voxel by key, occupancy at a point, leaves, ray casts.

use super::*;

impl OcTree {
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

    /// Every leaf (voxels at the finest level and pruned nodes), depth first.
    pub fn leaves(&self) -> Vec<Leaf> {
        let mut out = Vec::new();
        if let Some(r) = self.root() {
            self.collect(r, Key([0; 3]), 1 << DEPTH, &mut out);
        }
        out
    }

    pub(super) fn collect(&self, n: &Node, corner: Key, size: u32, out: &mut Vec<Leaf>) {
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
}
