//! FAST-9 corners (16-pixel Bresenham circle of radius 3) with OpenCV's corner score and
//! 3x3 non-maximum suppression.
//!
//! One pass per image at the lowest threshold in use: the score of a pixel is the largest
//! threshold at which it is still a corner, so "corners at threshold t" are exactly the
//! candidates with `score >= t`, and a later per-cell threshold is a filter, not a rerun.

/// Circle offsets `(dx, dy)`, clockwise from the top.
const CIRCLE: [(isize, isize); 16] = [
    (0, -3),
    (1, -3),
    (2, -2),
    (3, -1),
    (3, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 3),
    (-1, 3),
    (-2, 2),
    (-3, 1),
    (-3, 0),
    (-3, -1),
    (-2, -2),
    (-1, -3),
];

/// A corner at integer position with its score.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Corner {
    /// Column.
    pub x: u16,
    /// Row.
    pub y: u16,
    /// Largest threshold at which it is a FAST-9 corner.
    pub score: u8,
}

/// Reusable buffers for [`detect`].
#[derive(Debug, Default)]
pub struct FastScratch {
    scores: Vec<u8>,
    candidates: Vec<u8>,
}

/// A rectangle of pixel positions, `[x0, x1) x [y0, y1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// First column.
    pub x0: usize,
    /// First row.
    pub y0: usize,
    /// Column past the end.
    pub x1: usize,
    /// Row past the end.
    pub y1: usize,
}

/// FAST-9 corners of `img` (row-major, `width` columns) with `score >= threshold`, at least
/// `border` pixels (>= 3) from the edges, non-maximum suppressed over 3x3, appended to `out`
/// in row-major order.
pub fn detect(
    data: &[u8],
    width: usize,
    height: usize,
    threshold: u8,
    border: usize,
    scratch: &mut FastScratch,
    out: &mut Vec<Corner>,
) {
    let b = border.max(3);
    if width < 2 * b + 1 || height < 2 * b + 1 {
        return;
    }
    let region = Region { x0: b, y0: b, x1: width - b, y1: height - b };
    detect_in(data, width, height, region, threshold, scratch, out);
}

/// [`detect`] for corners inside `region` only (clipped to 3 px from the edges); the circle
/// may reach outside it. Non-maximum suppression compares within the region.
pub fn detect_in(
    data: &[u8],
    width: usize,
    height: usize,
    region: Region,
    threshold: u8,
    scratch: &mut FastScratch,
    out: &mut Vec<Corner>,
) {
    let (x0, y0) = (region.x0.max(3), region.y0.max(3));
    let (x1, y1) = (region.x1.min(width.saturating_sub(3)), region.y1.min(height.saturating_sub(3)));
    if x1 <= x0 || y1 <= y0 || data.len() < width * height {
        return;
    }
    let t = threshold.max(1);
    let (rw, rh) = (x1 - x0, y1 - y0);
    scratch.scores.clear();
    scratch.scores.resize(rw * rh, 0);
    scratch.candidates.resize(rw, 0);
    let offsets: [isize; 16] = CIRCLE.map(|(dx, dy)| dy * width as isize + dx);
    for y in y0..y1 {
        let row = &data[y * width + x0 - 3..y * width + x1 + 3];
        let up = &data[(y - 3) * width + x0..(y - 3) * width + x1];
        let down = &data[(y + 3) * width + x0..(y + 3) * width + x1];
        // Quick test, vectorisable: any 9-arc holds two of the four compass pixels, so a
        // corner has two of them brighter than c + t or two darker than c - t.
        let cand = &mut scratch.candidates[..rw];
        let (left, centre, right) = (&row[..rw], &row[3..3 + rw], &row[6..6 + rw]);
        for (((((flag, &c), &u), &d), &l), &r) in cand.iter_mut().zip(centre).zip(up).zip(down).zip(left).zip(right) {
            let hi = c.saturating_add(t);
            let lo = c.saturating_sub(t);
            let bright = u8::from(u > hi) + u8::from(d > hi) + u8::from(l > hi) + u8::from(r > hi);
            let dark = u8::from(u < lo) + u8::from(d < lo) + u8::from(l < lo) + u8::from(r < lo);
            *flag = u8::from(bright >= 2) | u8::from(dark >= 2);
        }
        for (i, _) in cand.iter().enumerate().filter(|(_, c)| **c != 0) {
            let center = y * width + x0 + i;
            let c = data[center];
            let (hi, lo) = (c.saturating_add(t), c.saturating_sub(t));
            let mut d = [0i16; 16];
            let (mut bright, mut dark) = (0u32, 0u32);
            for (k, o) in offsets.iter().enumerate() {
                let v = data[(center as isize + o) as usize];
                d[k] = i16::from(v) - i16::from(c);
                bright |= u32::from(v > hi) << k;
                dark |= u32::from(v < lo) << k;
            }
            if !(has_arc9(bright) || has_arc9(dark)) {
                continue;
            }
            scratch.scores[(y - y0) * rw + i] = score(&d).clamp(1, 255) as u8;
        }
    }
    // 3x3 non-maximum suppression, strict as OpenCV's: equal neighbours suppress each other.
    let n = &scratch.scores;
    for ry in 0..rh {
        for rx in 0..rw {
            let s = n[ry * rw + rx];
            if s == 0 {
                continue;
            }
            let at = |dx: isize, dy: isize| {
                let (x, y) = (rx as isize + dx, ry as isize + dy);
                if x < 0 || y < 0 || x >= rw as isize || y >= rh as isize { 0 } else { n[y as usize * rw + x as usize] }
            };
            let before = at(-1, -1) < s && at(0, -1) < s && at(1, -1) < s && at(-1, 0) < s;
            let after = at(1, 0) < s && at(-1, 1) < s && at(0, 1) < s && at(1, 1) < s;
            if before && after {
                out.push(Corner { x: (x0 + rx) as u16, y: (y0 + ry) as u16, score: s });
            }
        }
    }
}

/// Whether the 16-bit circle mask has 9 contiguous set bits (wrapping).
#[inline]
fn has_arc9(m: u32) -> bool {
    if m.count_ones() < 9 {
        return false;
    }
    let m = m | (m << 16);
    let m2 = m & (m >> 1);
    let m4 = m2 & (m2 >> 2);
    let m8 = m4 & (m4 >> 4);
    (m8 & (m >> 8)) & 0xffff != 0
}

/// OpenCV's FAST-9 score: the largest `t` such that 9 contiguous circle pixels are all
/// brighter than `c + t` or all darker than `c - t`, i.e. the best arc's smallest margin,
/// minus one (the test is strict). Sliding minima over the doubled circle.
#[inline]
fn score(d: &[i16; 16]) -> i16 {
    let mut e = [0i16; 32];
    e[..16].copy_from_slice(d);
    e[16..].copy_from_slice(d);
    let mut best = i16::MIN;
    for sign in [1i16, -1] {
        let mut m2 = [0i16; 31];
        for k in 0..31 {
            m2[k] = (sign * e[k]).min(sign * e[k + 1]);
        }
        let mut m4 = [0i16; 29];
        for k in 0..29 {
            m4[k] = m2[k].min(m2[k + 2]);
        }
        for k in 0..16 {
            // Nine pixels k..=k+8: four pairs then the ninth.
            let m8 = m4[k].min(m4[k + 4]);
            best = best.max(m8.min(sign * e[k + 8]));
        }
    }
    best - 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bright_square_corner_is_found_and_flat_image_has_none() {
        let (w, h) = (32, 32);
        let mut img = vec![20u8; w * h];
        // A bright square with a slight ramp (an ideal square has tied scores, which
        // OpenCV's strict suppression removes together).
        for y in 16..32 {
            for x in 16..32 {
                img[y * w + x] = 200 + (x + 2 * y - 48) as u8;
            }
        }
        let mut out = Vec::new();
        detect(&img, w, h, 20, 3, &mut FastScratch::default(), &mut out);
        assert!(out.iter().any(|c| (15..=18).contains(&c.x) && (15..=18).contains(&c.y)), "{out:?}");
        out.clear();
        detect(&vec![7u8; w * h], w, h, 1, 3, &mut FastScratch::default(), &mut out);
        assert!(out.is_empty());
        // Too small for the circle: nothing, no panic.
        detect(&[1, 2, 3], 3, 1, 5, 3, &mut FastScratch::default(), &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn score_is_the_largest_threshold_that_still_detects() {
        let mut d = [0i16; 16];
        for v in d.iter_mut().take(9) {
            *v = 50;
        }
        d[4] = 30;
        // Brighter by at least 30 on a 9-arc: a corner for t < 30.
        assert_eq!(score(&d), 29);
    }
}
