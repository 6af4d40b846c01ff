//! Descriptor matching: Hamming brute force with Lowe's ratio test, cross-check and
//! ORB-SLAM's rotation-consistency histogram, and a guided window search.

/// Hamming distance of two 256-bit descriptors.
#[inline]
pub fn hamming(a: &[u8; 32], b: &[u8; 32]) -> u32 {
    let mut d = 0;
    for (x, y) in a.chunks_exact(8).zip(b.chunks_exact(8)) {
        let x = u64::from_le_bytes(x.try_into().unwrap_or([0; 8]));
        let y = u64::from_le_bytes(y.try_into().unwrap_or([0; 8]));
        d += (x ^ y).count_ones();
    }
    d
}

/// Matching settings; defaults follow ORB-SLAM's frame-to-frame search for initialisation
/// (`TH_HIGH = 100`, `nnratio = 0.9`, 30 orientation bins keeping the three fullest).
#[derive(Clone, Debug, PartialEq)]
pub struct MatchConfig {
    /// Largest accepted Hamming distance (of 256 bits).
    pub max_distance: u32,
    /// Best must be below `ratio` times the second best (1.0 disables the test).
    pub ratio: f32,
    /// Keep a match only if it is also the best from the other side.
    pub cross_check: bool,
    /// Keep only matches whose keypoint rotation falls in the three fullest of 30 bins.
    pub check_orientation: bool,
}

impl Default for MatchConfig {
    fn default() -> Self {
        Self { max_distance: 100, ratio: 0.9, cross_check: true, check_orientation: true }
    }
}

/// One match: `query` indexes the current frame's features, `train` the previous ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Match {
    /// Index in the query set.
    pub query: u32,
    /// Index in the train set.
    pub train: u32,
    /// Hamming distance.
    pub distance: u32,
}

/// The candidate nearest to `q` in Hamming distance: `(index, best, second best)`, the second
/// `u32::MAX` with one candidate; `None` with none. Ties keep the first candidate.
pub fn nearest_two<'a>(
    q: &[u8; 32],
    candidates: impl IntoIterator<Item = (usize, &'a [u8; 32])>,
) -> Option<(usize, u32, u32)> {
    let (mut best, mut best_i, mut second) = (u32::MAX, None, u32::MAX);
    for (i, t) in candidates {
        let d = hamming(q, t);
        if d < best {
            second = best;
            best = d;
            best_i = Some(i);
        } else if d < second {
            second = d;
        }
    }
    best_i.map(|i| (i, best, second))
}

/// Best and second-best train index/distance for one query.
fn two_best(q: &[u8; 32], train: &[[u8; 32]]) -> (Option<(u32, u32)>, u32) {
    match nearest_two(q, train.iter().enumerate()) {
        Some((i, best, second)) => (Some((i as u32, best)), second),
        None => (None, u32::MAX),
    }
}

/// Brute-force matches of `query` against `train`. `angles` (degrees, per query and per
/// train keypoint) enable the rotation-consistency check.
pub fn match_brute_force(
    query: &[[u8; 32]],
    train: &[[u8; 32]],
    angles: Option<(&[f32], &[f32])>,
    config: &MatchConfig,
) -> Vec<Match> {
    let mut out = Vec::new();
    if query.is_empty() || train.is_empty() {
        return out;
    }
    // Best query per train descriptor, for the cross-check.
    let back: Vec<Option<u32>> = if config.cross_check {
        train.iter().map(|t| two_best(t, query).0.map(|(i, _)| i)).collect()
    } else {
        Vec::new()
    };
    for (qi, q) in query.iter().enumerate() {
        let (Some((ti, d)), second) = two_best(q, train) else { continue };
        if d > config.max_distance {
            continue;
        }
        if config.ratio < 1.0 && second != u32::MAX && d as f32 >= config.ratio * second as f32 {
            continue;
        }
        if config.cross_check && back.get(ti as usize).copied().flatten() != Some(qi as u32) {
            continue;
        }
        out.push(Match { query: qi as u32, train: ti, distance: d });
    }
    if config.check_orientation
        && let Some((qa, ta)) = angles
    {
        out = rotation_consistent(&out, qa, ta);
    }
    out
}

/// ORB-SLAM's rotation check: histogram the keypoint angle change over 30 bins and keep the
/// matches in the three fullest bins (a second or third bin only if it holds at least a
/// tenth of the first).
pub fn rotation_consistent(matches: &[Match], query_angles: &[f32], train_angles: &[f32]) -> Vec<Match> {
    const BINS: usize = 30;
    let bin_of = |m: &Match| {
        let a = query_angles.get(m.query as usize).copied().unwrap_or(0.0);
        let b = train_angles.get(m.train as usize).copied().unwrap_or(0.0);
        let rot = (a - b).rem_euclid(360.0);
        ((rot / (360.0 / BINS as f32)) as usize).min(BINS - 1)
    };
    let mut hist = [0usize; BINS];
    for m in matches {
        hist[bin_of(m)] += 1;
    }
    let mut order: Vec<usize> = (0..BINS).collect();
    order.sort_by_key(|&b| (std::cmp::Reverse(hist[b]), b));
    let top = hist[order[0]];
    let keep: Vec<usize> =
        order.iter().take(3).copied().filter(|&b| hist[b] > 0 && (b == order[0] || hist[b] * 10 >= top)).collect();
    matches.iter().copied().filter(|m| keep.contains(&bin_of(m))).collect()
}

/// Keypoints bucketed on a grid, for window searches around a predicted position (the
/// tracker's projection search).
#[derive(Clone, Debug)]
pub struct GridIndex {
    cell: f32,
    cols: usize,
    rows: usize,
    cells: Vec<Vec<u32>>,
    points: Vec<[f32; 2]>,
}

impl GridIndex {
    /// Index `points` (level-0 pixels) of an image `width` x `height`.
    pub fn new(points: &[[f32; 2]], width: usize, height: usize, cell: f32) -> Self {
        let cell = if cell > 0.0 { cell } else { 32.0 };
        let cols = ((width as f32 / cell).ceil() as usize).max(1);
        let rows = ((height as f32 / cell).ceil() as usize).max(1);
        let mut cells = vec![Vec::new(); cols * rows];
        for (i, p) in points.iter().enumerate() {
            if p[0].is_finite() && p[1].is_finite() {
                let cx = ((p[0] / cell).max(0.0) as usize).min(cols - 1);
                let cy = ((p[1] / cell).max(0.0) as usize).min(rows - 1);
                cells[cy * cols + cx].push(i as u32);
            }
        }
        Self { cell, cols, rows, cells, points: points.to_vec() }
    }

    /// Indices of the points within `radius` of `center`.
    pub fn within(&self, center: [f32; 2], radius: f32) -> Vec<u32> {
        let mut out = Vec::new();
        if !(center[0].is_finite() && center[1].is_finite() && radius >= 0.0) {
            return out;
        }
        let lo = |v: f32| ((v - radius) / self.cell).floor().max(0.0) as usize;
        let hi = |v: f32, n: usize| (((v + radius) / self.cell).floor().max(0.0) as usize).min(n - 1);
        for cy in lo(center[1]).min(self.rows - 1)..=hi(center[1], self.rows) {
            for cx in lo(center[0]).min(self.cols - 1)..=hi(center[0], self.cols) {
                for &i in &self.cells[cy * self.cols + cx] {
                    let p = self.points[i as usize];
                    if (p[0] - center[0]).powi(2) + (p[1] - center[1]).powi(2) <= radius * radius {
                        out.push(i);
                    }
                }
            }
        }
        out
    }
}

/// Guided search: for each query descriptor with a predicted position, the best train
/// feature within `radius` of it (below `max_distance`, passing the ratio test among the
/// candidates). Returns one match per query at most.
pub fn match_in_windows(
    query: &[[u8; 32]],
    predicted: &[[f32; 2]],
    train: &[[u8; 32]],
    index: &GridIndex,
    radius: f32,
    config: &MatchConfig,
) -> Vec<Match> {
    let mut out = Vec::new();
    for (qi, (q, p)) in query.iter().zip(predicted).enumerate() {
        let near = index.within(*p, radius);
        let candidates = near.iter().filter_map(|&ti| train.get(ti as usize).map(|t| (ti as usize, t)));
        let Some((ti, best, second)) = nearest_two(q, candidates) else { continue };
        let ti = ti as u32;
        if best > config.max_distance || (second != u32::MAX && best as f32 >= config.ratio * second as f32) {
            continue;
        }
        out.push(Match { query: qi as u32, train: ti, distance: best });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn desc(seed: u64) -> [u8; 32] {
        let mut s = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
        let mut d = [0u8; 32];
        for b in &mut d {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            *b = s as u8;
        }
        d
    }

    #[test]
    fn hamming_counts_bits() {
        let a = [0u8; 32];
        let mut b = [0u8; 32];
        b[0] = 0b1011;
        b[31] = 0x80;
        assert_eq!(hamming(&a, &b), 4);
    }

    #[test]
    fn brute_force_finds_permuted_copies_and_cross_check_rejects_duplicates() {
        let train: Vec<[u8; 32]> = (0..50).map(desc).collect();
        let query: Vec<[u8; 32]> = (0..50).rev().map(desc).collect();
        let m = match_brute_force(&query, &train, None, &MatchConfig::default());
        assert_eq!(m.len(), 50);
        assert!(m.iter().all(|m| m.train == 49 - m.query && m.distance == 0));
        assert!(match_brute_force(&[], &train, None, &MatchConfig::default()).is_empty());
        // Two identical queries: only one survives the cross-check (and the ratio test).
        let dup = vec![desc(3), desc(3)];
        assert!(match_brute_force(&dup, &train, None, &MatchConfig::default()).len() <= 1);
    }

    #[test]
    fn rotation_check_drops_matches_with_an_odd_rotation() {
        let matches: Vec<Match> = (0..20).map(|i| Match { query: i, train: i, distance: 0 }).collect();
        let q: Vec<f32> = (0..20).map(|i| if i == 7 { 200.0 } else { 40.0 }).collect();
        let t = vec![10.0; 20];
        let kept = rotation_consistent(&matches, &q, &t);
        assert_eq!(kept.len(), 19);
        assert!(kept.iter().all(|m| m.query != 7));
    }

    #[test]
    fn window_search_only_looks_near_the_prediction() {
        let points = vec![[10.0, 10.0], [100.0, 100.0]];
        let train = vec![desc(1), desc(2)];
        let index = GridIndex::new(&points, 200, 200, 16.0);
        assert_eq!(index.within([12.0, 9.0], 5.0), vec![0]);
        let m = match_in_windows(&[desc(2)], &[[95.0, 98.0]], &train, &index, 10.0, &MatchConfig::default());
        assert_eq!(m, vec![Match { query: 0, train: 1, distance: 0 }]);
        assert!(
            match_in_windows(&[desc(2)], &[[10.0, 10.0]], &train, &index, 10.0, &MatchConfig::default()).is_empty()
        );
    }
}
