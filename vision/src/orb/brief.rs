//! Orientation by intensity centroid and the steered BRIEF descriptor (Rublee et al., "ORB:
//! an efficient alternative to SIFT or SURF", ICCV 2011).

use crate::image::GrayImage;

/// Radius of the orientation patch (half of the 31-pixel patch).
const HALF_PATCH: i32 = 15;

/// Half-widths of the circular patch, row by row, made symmetric as OpenCV does.
pub(crate) fn umax() -> Vec<i32> {
    let hp = HALF_PATCH;
    let mut umax = vec![0i32; hp as usize + 2];
    let vmax = (f64::from(hp) * std::f64::consts::SQRT_2 / 2.0 + 1.0).floor() as i32;
    let vmin = (f64::from(hp) * std::f64::consts::SQRT_2 / 2.0).ceil() as i32;
    let hp2 = f64::from(hp * hp);
    for v in 0..=vmax {
        umax[v as usize] = (hp2 - f64::from(v * v)).sqrt().round() as i32;
    }
    let mut v0 = 0usize;
    let mut v = hp;
    while v >= vmin {
        while umax[v0] == umax[v0 + 1] {
            v0 += 1;
        }
        umax[v as usize] = v0 as i32;
        v0 += 1;
        v -= 1;
    }
    umax
}

/// Orientation in degrees `[0, 360)` of the patch centred at `(x, y)`, which must be at least
/// 15 px from every border.
pub(crate) fn ic_angle(img: &GrayImage, x: usize, y: usize, umax: &[i32]) -> f32 {
    let w = img.width as isize;
    let c = (y * img.width + x) as isize;
    let px = |o: isize| i32::from(img.data[(c + o) as usize]);
    let (mut m01, mut m10) = (0i32, 0i32);
    for u in -HALF_PATCH..=HALF_PATCH {
        m10 += u * px(u as isize);
    }
    for v in 1..=HALF_PATCH {
        let d = umax[v as usize];
        let mut v_sum = 0;
        for u in -d..=d {
            let plus = px(u as isize + v as isize * w);
            let minus = px(u as isize - v as isize * w);
            v_sum += plus - minus;
            m10 += u * (plus + minus);
        }
        m01 += v * v_sum;
    }
    let a = (m01 as f32).atan2(m10 as f32).to_degrees();
    if a < 0.0 { a + 360.0 } else { a }
}

/// Harris response `det(M) - 0.04 trace(M)^2` of the 7x7 block around `(x, y)` (at least 4 px
/// from every border), with OpenCV's Sobel derivatives and scaling (so values compare with
/// `cv2.ORB`'s `response`).
pub(crate) fn harris(img: &GrayImage, x: usize, y: usize) -> f32 {
    const R: isize = 3;
    let w = img.width as isize;
    let c = (y * img.width + x) as isize;
    let px = |o: isize| i32::from(img.data[(c + o) as usize]);
    let (mut a, mut b, mut cc) = (0i64, 0i64, 0i64);
    for dy in -R..=R {
        for dx in -R..=R {
            let o = dy * w + dx;
            let ix = (px(o + 1) - px(o - 1)) * 2 + (px(o - w + 1) - px(o - w - 1)) + (px(o + w + 1) - px(o + w - 1));
            let iy = (px(o + w) - px(o - w)) * 2 + (px(o + w - 1) - px(o - w - 1)) + (px(o + w + 1) - px(o - w + 1));
            a += i64::from(ix * ix);
            b += i64::from(iy * iy);
            cc += i64::from(ix * iy);
        }
    }
    // OpenCV: scale_sq_sq = 1 / (7 * 4 * 255)^4.
    let scale = 1.0 / (7.0 * 4.0 * 255.0f64);
    let s2 = scale * scale;
    let (a, b, cc) = (a as f64 * s2, b as f64 * s2, cc as f64 * s2);
    (a * b - cc * cc - 0.04 * (a + b) * (a + b)) as f32
}

/// The learned pattern's 512 sample points as coordinates: `x`, then `y` (pair `i` compares
/// points `2i` and `2i + 1`).
fn pattern_points() -> &'static ([f32; 512], [f32; 512]) {
    static POINTS: std::sync::OnceLock<([f32; 512], [f32; 512])> = std::sync::OnceLock::new();
    POINTS.get_or_init(|| {
        let (mut xs, mut ys) = ([0f32; 512], [0f32; 512]);
        for (i, p) in super::pattern::learned().iter().enumerate() {
            (xs[2 * i], ys[2 * i], xs[2 * i + 1], ys[2 * i + 1]) =
                (f32::from(p[0]), f32::from(p[1]), f32::from(p[2]), f32::from(p[3]));
        }
        (xs, ys)
    })
}

/// The 256-bit steered BRIEF descriptor at `(x, y)` of the smoothed level, at least
/// [`super::EDGE`] px from every border.
pub(crate) fn describe(smoothed: &GrayImage, x: usize, y: usize, angle_deg: f32) -> [u8; 32] {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let w = smoothed.width as i32;
    let center = y * smoothed.width + x;
    // Round to nearest (ties to even, as OpenCV's cvRound) with the 1.5 * 2^23 trick: plain
    // adds instead of a libm call per coordinate. All 512 rotated offsets first, in a loop the
    // compiler vectorises, then the lookups.
    const MAGIC: f32 = 12_582_912.0;
    let (xs, ys) = pattern_points();
    let mut offsets = [0i32; 512];
    for ((o, &px), &py) in offsets.iter_mut().zip(xs).zip(ys) {
        let col = ((px * c - py * s) + MAGIC) - MAGIC;
        let row = ((px * s + py * c) + MAGIC) - MAGIC;
        *o = row as i32 * w + col as i32;
    }
    let at = |o: i32| smoothed.data[(center as isize + o as isize) as usize];
    let mut out = [0u8; 32];
    for (byte, pairs) in out.iter_mut().zip(offsets.chunks_exact(16)) {
        let mut v = 0u8;
        for (bit, pair) in pairs.chunks_exact(2).enumerate() {
            v |= u8::from(at(pair[0]) < at(pair[1])) << bit;
        }
        *byte = v;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The descriptor one sample at a time, rotating each point as it is read (the first
    /// implementation, kept as the reference for the batched one).
    fn describe_point_by_point(smoothed: &GrayImage, x: usize, y: usize, angle_deg: f32) -> [u8; 32] {
        let (s, c) = angle_deg.to_radians().sin_cos();
        let w = smoothed.width as isize;
        let center = (y * smoothed.width + x) as isize;
        let round = |v: f32| ((v + 12_582_912.0) - 12_582_912.0) as isize;
        let at = |px: i8, py: i8| {
            let (px, py) = (f32::from(px), f32::from(py));
            smoothed.data[(center + round(px * s + py * c) * w + round(px * c - py * s)) as usize]
        };
        let mut out = [0u8; 32];
        for (byte, pairs) in out.iter_mut().zip(crate::orb::pattern::learned().chunks_exact(8)) {
            for (bit, p) in pairs.iter().enumerate() {
                *byte |= u8::from(at(p[0], p[1]) < at(p[2], p[3])) << bit;
            }
        }
        out
    }

    #[test]
    fn batched_descriptor_has_the_same_bits_as_point_by_point() {
        let (w, h) = (96, 96);
        let mut img = GrayImage::new(w, h);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for v in &mut img.data {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            *v = (state >> 24) as u8;
        }
        // Every angle in tenths of a degree, including the ones whose rotated points land on .5.
        for i in 0..3600 {
            let angle = i as f32 * 0.1;
            let (x, y) = (30 + i % 37, 30 + (i / 37) % 37);
            assert_eq!(describe(&img, x, y, angle), describe_point_by_point(&img, x, y, angle), "angle {angle}");
        }
    }

    #[test]
    fn umax_is_a_symmetric_disc() {
        let u = umax();
        assert_eq!(u[0], 15);
        assert_eq!(u[15], 3);
        // The disc is symmetric about the diagonal: (u, v) inside iff (v, u) inside.
        for v in 0..=15i32 {
            for x in 0..=15i32 {
                assert_eq!(x <= u[v as usize], v <= u[x as usize], "({x}, {v}): {u:?}");
            }
        }
    }

    #[test]
    fn orientation_points_towards_the_bright_side() {
        let (w, h) = (41, 41);
        let mut img = GrayImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.data[y * w + x] = if x > 20 { 200 } else { 20 };
            }
        }
        let a = ic_angle(&img, 20, 20, &umax());
        assert!(!(1.0..=359.0).contains(&a), "{a}");
        for y in 0..h {
            for x in 0..w {
                img.data[y * w + x] = if y > 20 { 200 } else { 20 };
            }
        }
        // Image rows grow downwards, so "below" is +90 degrees.
        assert!((ic_angle(&img, 20, 20, &umax()) - 90.0).abs() < 1.0);
    }
}
