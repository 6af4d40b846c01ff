//! Voxel keys and ray traversal, as OctoMap addresses its tree: a point maps to three 16-bit
//! keys `floor(x / resolution) + 32768`, and free space along a ray is the voxels a 3-D DDA
//! (Amanatides & Woo) walks from the sensor's voxel up to, but not including, the end
//! point's. The arithmetic follows OctoMap 1.9 precision for precision (`f32` points and
//! direction, `f64` voxel borders and crossing distances), so the same scan marks the same
//! voxels free.

/// Tree depth (OctoMap's default, the only one its files carry).
pub const DEPTH: u32 = 16;
/// Half the key range: the key of coordinate 0.
pub const MAX_VAL: i32 = 32_768;

/// The address of a voxel at the finest level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Key(pub [u16; 3]);

impl Key {
    /// The three keys packed in one integer (for hashing and ordering).
    pub fn packed(self) -> u64 {
        (u64::from(self.0[0]) << 32) | (u64::from(self.0[1]) << 16) | u64::from(self.0[2])
    }

    /// Which of a node's eight children at `level` (0 = the finest) holds this key: bit 0 from
    /// x, bit 1 from y, bit 2 from z, as OctoMap's `computeChildIdx`.
    pub fn child_index(self, level: u32) -> usize {
        let bit = 1u16 << level;
        usize::from(self.0[0] & bit != 0)
            | (usize::from(self.0[1] & bit != 0) << 1)
            | (usize::from(self.0[2] & bit != 0) << 2)
    }
}

/// Conversions between coordinates and keys for one resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    /// Edge of the finest voxel in metres.
    pub resolution: f64,
    factor: f64,
}

impl Grid {
    /// A grid of `resolution` metres (positive and finite; callers check).
    pub fn new(resolution: f64) -> Self {
        Self { resolution, factor: 1.0 / resolution }
    }

    /// The key of one coordinate, if inside the tree's range.
    pub fn coord_key(&self, c: f64) -> Option<u16> {
        let k = (self.factor * c).floor();
        if !k.is_finite() {
            return None;
        }
        let k = k as i64 + i64::from(MAX_VAL);
        u16::try_from(k).ok()
    }

    /// The key of a point, if inside the tree's range.
    pub fn key(&self, p: [f32; 3]) -> Option<Key> {
        Some(Key([
            self.coord_key(f64::from(p[0]))?,
            self.coord_key(f64::from(p[1]))?,
            self.coord_key(f64::from(p[2]))?,
        ]))
    }

    /// Centre of the voxel with key `k` (finest level) along one axis.
    pub fn key_coord(&self, k: u16) -> f64 {
        (f64::from(i32::from(k) - MAX_VAL) + 0.5) * self.resolution
    }

    /// Centre of a voxel at the finest level.
    pub fn centre(&self, k: Key) -> [f64; 3] {
        [self.key_coord(k.0[0]), self.key_coord(k.0[1]), self.key_coord(k.0[2])]
    }

    /// Centre of the node of `size` finest voxels per edge (a power of two) holding `k`.
    pub fn node_centre(&self, k: Key, size: u32) -> [f64; 3] {
        if size <= 1 {
            return self.centre(k);
        }
        let s = size as i32;
        let c = |v: u16| {
            let base = (i32::from(v) - MAX_VAL).div_euclid(s) * s;
            (f64::from(base) + f64::from(s) / 2.0) * self.resolution
        };
        [c(k.0[0]), c(k.0[1]), c(k.0[2])]
    }

    /// The voxels a ray from `origin` to `end` crosses, the end point's excluded, into `out`
    /// (cleared first); `false` when either point is outside the tree's range.
    pub fn ray_keys(&self, origin: [f32; 3], end: [f32; 3], out: &mut Vec<Key>) -> bool {
        out.clear();
        self.ray_walk(origin, end, |k| out.push(k))
    }

    /// [`Grid::ray_keys`] without a buffer: `visit` sees each voxel in order.
    pub fn ray_walk(&self, origin: [f32; 3], end: [f32; 3], mut visit: impl FnMut(Key)) -> bool {
        let (Some(start), Some(stop)) = (self.key(origin), self.key(end)) else { return false };
        if start == stop {
            return true;
        }
        visit(start);
        let mut dir = [end[0] - origin[0], end[1] - origin[1], end[2] - origin[2]];
        let length = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
        for d in &mut dir {
            *d /= length;
        }
        let mut step = [0i32; 3];
        let mut t_max = [f64::MAX; 3];
        let mut t_delta = [f64::MAX; 3];
        for i in 0..3 {
            step[i] = if dir[i] > 0.0 {
                1
            } else if dir[i] < 0.0 {
                -1
            } else {
                0
            };
            if step[i] != 0 {
                let mut border = self.key_coord(start.0[i]);
                border += f64::from((f64::from(step[i]) * self.resolution * 0.5) as f32);
                t_max[i] = (border - f64::from(origin[i])) / f64::from(dir[i]);
                t_delta[i] = self.resolution / f64::from(dir[i]).abs();
            }
        }
        let [mut tx, mut ty, mut tz] = t_max;
        let [dx, dy, dz] = t_delta;
        let [sx, sy, sz] = step;
        let [mut x, mut y, mut z] = [i32::from(start.0[0]), i32::from(start.0[1]), i32::from(start.0[2])];
        let stop = [i32::from(stop.0[0]), i32::from(stop.0[1]), i32::from(stop.0[2])];
        let length = f64::from(length);
        loop {
            // The smallest crossing distance; ties go to the later axis, as OctoMap's.
            if tx < ty {
                if tx < tz {
                    x += sx;
                    tx += dx;
                } else {
                    z += sz;
                    tz += dz;
                }
            } else if ty < tz {
                y += sy;
                ty += dy;
            } else {
                z += sz;
                tz += dz;
            }
            if [x, y, z] == stop {
                return true;
            }
            // Past the end point's distance without meeting its voxel (rounding): stop.
            if tx.min(ty).min(tz) > length {
                return true;
            }
            if !((0..=65_535).contains(&x) && (0..=65_535).contains(&y) && (0..=65_535).contains(&z)) {
                return true;
            }
            visit(Key([x as u16, y as u16, z as u16]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_match_octomaps_addressing() {
        let g = Grid::new(0.05);
        assert_eq!(g.coord_key(0.0), Some(32_768));
        assert_eq!(g.coord_key(-0.01), Some(32_767));
        assert_eq!(g.coord_key(0.049), Some(32_768));
        assert_eq!(g.coord_key(0.05), Some(32_769));
        assert_eq!(g.coord_key(1e9), None);
        assert!((g.key_coord(32_768) - 0.025).abs() < 1e-12);
        let k = Key([0b101, 0b110, 0b011]);
        assert_eq!(k.child_index(0), 0b101);
        assert_eq!(k.child_index(1), 0b110);
        assert_eq!(k.child_index(2), 0b011);
    }

    #[test]
    fn a_ray_walks_face_adjacent_voxels_to_the_end() {
        let g = Grid::new(0.1);
        let mut keys = Vec::new();
        let (o, e) = ([0.05, 0.05, 0.05], [1.03, 0.47, -0.31]);
        assert!(g.ray_keys(o, e, &mut keys));
        assert_eq!(keys[0], g.key(o).unwrap());
        for w in keys.windows(2) {
            let d: i32 = (0..3).map(|i| (i32::from(w[0].0[i]) - i32::from(w[1].0[i])).abs()).sum();
            assert_eq!(d, 1, "{w:?}");
        }
        let last = keys.last().unwrap();
        let end = g.key(e).unwrap();
        let d: i32 = (0..3).map(|i| (i32::from(last.0[i]) - i32::from(end.0[i])).abs()).sum();
        assert_eq!(d, 1, "the last free voxel touches the end point's");
        assert!(!keys.contains(&end));
        // Same voxel: nothing free; outside the range: refused.
        assert!(g.ray_keys(o, [0.06, 0.06, 0.06], &mut keys) && keys.is_empty());
        assert!(!g.ray_keys(o, [1e9, 0.0, 0.0], &mut keys));
    }
}
