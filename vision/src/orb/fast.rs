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
    // Scores with a zero frame of one pixel (stride `pw`), so non-maximum suppression reads
    // every neighbour without a bounds test.
    let pw = rw + 2;
    scratch.scores.clear();
    scratch.scores.resize(pw * (rh + 2), 0);
    scratch.candidates.resize(rw, 0);
    let offsets: [isize; 16] = CIRCLE.map(|(dx, dy)| dy * width as isize + dx);
    for y in y0..y1 {
        let row = &data[y * width + x0 - 3..y * width + x1 + 3];
        let up = &data[(y - 3) * width + x0..(y - 3) * width + x1];
        let down = &data[(y + 3) * width + x0..(y + 3) * width + x1];
        // Quick test, vectorisable: any 9-arc holds two neighbouring compass pixels (top and
        // right, right and bottom, ...), so a corner has such a pair both brighter than c + t
        // or both darker than c - t.
        let cand = &mut scratch.candidates[..rw];
        let (left, centre, right) = (&row[..rw], &row[3..3 + rw], &row[6..6 + rw]);
        for (((((flag, &c), &u), &d), &l), &r) in cand.iter_mut().zip(centre).zip(up).zip(down).zip(left).zip(right) {
            let hi = c.saturating_add(t);
            let lo = c.saturating_sub(t);
            let (ub, rb, db, lb) = (u > hi, r > hi, d > hi, l > hi);
            let (ud, rd, dd, ld) = (u < lo, r < lo, d < lo, l < lo);
            let bright = (ub & rb) | (rb & db) | (db & lb) | (lb & ub);
            let dark = (ud & rd) | (rd & dd) | (dd & ld) | (ld & ud);
            *flag = u8::from(bright | dark);
        }
        // Full segment test, 16 pixels at a time where the quick test left any candidate.
        let mut i = 0;
        while i < rw {
            let n = (rw - i).min(LANES);
            if cand[i..i + n].iter().all(|&f| f == 0) {
                i += n;
                continue;
            }
            let first = y * width + x0 + i;
            let corners = if n == LANES {
                segment_test_block(data, first, &offsets, t)
            } else {
                (0..n).fold(0u32, |m, j| m | (u32::from(segment_test(data, first + j, &offsets, t)) << j))
            };
            for j in (0..n).filter(|&j| corners & (1 << j) != 0) {
                let center = first + j;
                let c = i16::from(data[center]);
                let d: [i16; 16] = offsets.map(|o| i16::from(data[(center as isize + o) as usize]) - c);
                scratch.scores[(y - y0 + 1) * pw + i + j + 1] = score(&d).clamp(1, 255) as u8;
            }
            i += n;
        }
    }
    // 3x3 non-maximum suppression, strict as OpenCV's: equal neighbours suppress each other.
    // Rows are scanned eight scores at a time; most words are all zero.
    let n = &scratch.scores;
    for ry in 1..=rh {
        let (above, row, below) =
            (&n[(ry - 1) * pw..ry * pw], &n[ry * pw..(ry + 1) * pw], &n[(ry + 1) * pw..(ry + 2) * pw]);
        let mut rx = 1;
        while rx <= rw {
            if rx + 8 <= rw + 1 {
                let mut word = [0u8; 8];
                word.copy_from_slice(&row[rx..rx + 8]);
                if u64::from_ne_bytes(word) == 0 {
                    rx += 8;
                    continue;
                }
            }
            let s = row[rx];
            if s != 0
                && above[rx - 1] < s
                && above[rx] < s
                && above[rx + 1] < s
                && row[rx - 1] < s
                && row[rx + 1] < s
                && below[rx - 1] < s
                && below[rx] < s
                && below[rx + 1] < s
            {
                out.push(Corner { x: (x0 + rx - 1) as u16, y: (y0 + ry - 1) as u16, score: s });
            }
            rx += 1;
        }
    }
}

/// Pixels per step of the vectorised segment test ([`segment_test_block`]).
const LANES: usize = 16;

/// The FAST-9 segment test of the pixel at index `center`: 9 contiguous circle pixels all
/// brighter than `c + t` or all darker than `c - t`.
fn segment_test(data: &[u8], center: usize, offsets: &[isize; 16], t: u8) -> bool {
    let c = data[center];
    let (hi, lo) = (c.saturating_add(t), c.saturating_sub(t));
    let (mut bright, mut dark) = (0u32, 0u32);
    for (k, o) in offsets.iter().enumerate() {
        let v = data[(center as isize + o) as usize];
        bright |= u32::from(v > hi) << k;
        dark |= u32::from(v < lo) << k;
    }
    has_arc9(bright) || has_arc9(dark)
}

/// [`segment_test`] of the 16 pixels from index `first` on, as a bit mask (bit `j`: pixel
/// `first + j`). Run lengths of brighter and darker circle pixels are counted in 16 lanes
/// over the circle and its first 8 pixels again (arcs that wrap), the way OpenCV's SIMD FAST
/// does; fixed-size arrays let the compiler keep each step in one vector register.
fn segment_test_block(data: &[u8], first: usize, offsets: &[isize; 16], t: u8) -> u32 {
    let lanes = |start: usize| -> [u8; LANES] {
        let mut v = [0u8; LANES];
        v.copy_from_slice(&data[start..start + LANES]);
        v
    };
    let c = lanes(first);
    let hi = c.map(|v| v.saturating_add(t));
    let lo = c.map(|v| v.saturating_sub(t));
    let (mut run_b, mut run_d, mut max_b, mut max_d) = ([0u8; LANES], [0u8; LANES], [0u8; LANES], [0u8; LANES]);
    for k in 0..24 {
        let p = lanes((first as isize + offsets[k % 16]) as usize);
        for j in 0..LANES {
            let b = 0u8.wrapping_sub(u8::from(p[j] > hi[j]));
            let d = 0u8.wrapping_sub(u8::from(p[j] < lo[j]));
            run_b[j] = run_b[j].wrapping_add(1) & b;
            run_d[j] = run_d[j].wrapping_add(1) & d;
            max_b[j] = max_b[j].max(run_b[j]);
            max_d[j] = max_d[j].max(run_d[j]);
        }
    }
    (0..LANES).fold(0u32, |m, j| m | (u32::from(max_b[j] >= 9 || max_d[j] >= 9) << j))
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
    fn the_vectorised_segment_test_agrees_with_the_scalar_one() {
        // Random-ish texture with flat patches and saturated pixels, every threshold band.
        let (w, h) = (64usize, 40usize);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let data: Vec<u8> = (0..w * h)
            .map(|i| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                match (i / 7) % 5 {
                    0 => 128,
                    1 => {
                        if state & 1 == 0 {
                            0
                        } else {
                            255
                        }
                    }
                    _ => (state >> 24) as u8,
                }
            })
            .collect();
        let offsets: [isize; 16] = CIRCLE.map(|(dx, dy)| dy * w as isize + dx);
        let mut corners = 0;
        for t in [1u8, 7, 20, 60, 120, 250] {
            for y in 3..h - 3 {
                for x in 3..w - 3 - LANES {
                    let block = segment_test_block(&data, y * w + x, &offsets, t);
                    for j in 0..LANES {
                        let one = segment_test(&data, y * w + x + j, &offsets, t);
                        assert_eq!(block & (1 << j) != 0, one, "t {t} at ({}, {y})", x + j);
                        corners += usize::from(one);
                    }
                }
            }
        }
        assert!(corners > 1000, "too few corners to compare: {corners}");
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
