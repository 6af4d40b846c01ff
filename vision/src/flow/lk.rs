//! The LK iteration for one point, coarse to fine (Bouguet, "Pyramidal implementation of the
//! Lucas Kanade feature tracker", 2000), with OpenCV's scalings so that its thresholds
//! (`minEigThreshold = 1e-4`, `epsilon = 0.01`) mean the same here.

use super::pyramid::{Level, Pyramid};

/// OpenCV's `FLT_SCALE`: the gradient sums are scaled by 2^-20.
const FLT_SCALE: f32 = 1.0 / (1u32 << 20) as f32;
/// OpenCV keeps intensities with 5 fractional bits; we scale by 32 likewise, so the
/// Scharr-unit gradients and the intensity differences combine as in OpenCV.
const INTENSITY_SCALE: f32 = 32.0;

/// Tracker settings; the defaults are `calcOpticalFlowPyrLK`'s as the seed papers use it
/// (window 21, `maxLevel` 3, 30 iterations or a step below 0.01 px).
#[derive(Clone, Debug, PartialEq)]
pub struct LkConfig {
    /// Window side, pixels (odd).
    pub window: usize,
    /// Coarsest level (OpenCV's `maxLevel`: `3` means four levels, 0..=3).
    pub max_level: usize,
    /// Iterations per level at most.
    pub max_iterations: usize,
    /// Stop when a step is shorter than this, pixels.
    pub epsilon: f32,
    /// Reject a point whose gradient matrix's smaller eigenvalue (normalised by the window
    /// area, OpenCV's scaling) is below this: no texture to track.
    pub min_eig_threshold: f32,
    /// Track back from the result and reject points that do not return within this many
    /// pixels (forward-backward check), if set.
    pub fb_threshold: Option<f32>,
}

impl Default for LkConfig {
    fn default() -> Self {
        Self {
            window: 21,
            max_level: 3,
            max_iterations: 30,
            epsilon: 0.01,
            min_eig_threshold: 1e-4,
            fb_threshold: None,
        }
    }
}

/// Where one point went.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackResult {
    /// Position in the next image.
    pub point: [f32; 2],
    /// Tracked (texture enough, inside the image, forward-backward consistent).
    pub found: bool,
    /// Mean absolute intensity difference over the window at the result (OpenCV's `err`).
    pub error: f32,
}

/// Pyramidal LK; keeps its window buffers between calls.
#[derive(Debug, Default)]
pub struct LkTracker {
    config: LkConfig,
    /// Window rows are stored `stride` apart (the window side rounded up to [`LANES`]); the
    /// pad columns have zero gradient, so they add nothing to any sum.
    stride: usize,
    patch: Vec<f32>,
    patch_dx: Vec<f32>,
    patch_dy: Vec<f32>,
    patch_j: Vec<f32>,
}

/// Sums run in this many independent lanes so the compiler vectorises them (a single float
/// accumulator is a serial dependency it may not reorder).
const LANES: usize = 8;

/// Bilinear weights for a fractional offset.
#[derive(Clone, Copy)]
struct Weights([f32; 4]);

impl Weights {
    fn new(ax: f32, ay: f32, scale: f32) -> Self {
        Self([(1.0 - ax) * (1.0 - ay), ax * (1.0 - ay), (1.0 - ax) * ay, ax * ay].map(|v| v * scale))
    }
}

/// A sampling window: top-left integer corner, rows, columns to fill and row stride.
#[derive(Clone, Copy)]
struct Window {
    x0: isize,
    y0: isize,
    rows: usize,
    cols: usize,
    stride: usize,
}

impl Window {
    /// Whether the window (plus the bilinear neighbour) lies inside a `w` x `h` image.
    fn inside(&self, w: usize, h: usize) -> bool {
        self.x0 >= 0 && self.y0 >= 0 && (self.x0 as usize) + self.cols < w && (self.y0 as usize) + self.rows < h
    }
}

/// Sample `win.cols` columns of each window row of `src` at fractional offset `wts` into
/// `out` (rows `win.stride` apart). Replicates the border outside the image.
fn sample(src: &[f32], w: usize, h: usize, win: Window, wts: Weights, out: &mut [f32]) {
    let [w00, w01, w10, w11] = wts.0;
    if win.inside(w, h) {
        let (x0, y0) = (win.x0 as usize, win.y0 as usize);
        for r in 0..win.rows {
            let a = &src[(y0 + r) * w + x0..(y0 + r) * w + x0 + win.cols + 1];
            let b = &src[(y0 + r + 1) * w + x0..(y0 + r + 1) * w + x0 + win.cols + 1];
            let o = &mut out[r * win.stride..r * win.stride + win.cols];
            for (c, o) in o.iter_mut().enumerate() {
                *o = w00 * a[c] + w01 * a[c + 1] + w10 * b[c] + w11 * b[c + 1];
            }
        }
        return;
    }
    let cx = |x: isize| x.clamp(0, w as isize - 1) as usize;
    let cy = |y: isize| y.clamp(0, h as isize - 1) as usize;
    for r in 0..win.rows {
        let (ya, yb) = (cy(win.y0 + r as isize), cy(win.y0 + r as isize + 1));
        for c in 0..win.cols {
            let (xa, xb) = (cx(win.x0 + c as isize), cx(win.x0 + c as isize + 1));
            out[r * win.stride + c] =
                w00 * src[ya * w + xa] + w01 * src[ya * w + xb] + w10 * src[yb * w + xa] + w11 * src[yb * w + xb];
        }
    }
}

/// [`sample`] of a level's intensities (weights `wimg`) and both gradients (weights `wg`) in
/// one pass, for a window inside the level: the same products and sums per value.
fn sample_three(
    level: &Level,
    win: Window,
    wimg: Weights,
    wg: Weights,
    img: &mut [f32],
    gx: &mut [f32],
    gy: &mut [f32],
) {
    let w = level.width;
    let (x0, y0) = (win.x0 as usize, win.y0 as usize);
    let [i00, i01, i10, i11] = wimg.0;
    let [g00, g01, g10, g11] = wg.0;
    for r in 0..win.rows {
        let (ra, rb) = ((y0 + r) * w + x0, (y0 + r + 1) * w + x0);
        let n = win.cols + 1;
        let (ia, ib) = (&level.img[ra..ra + n], &level.img[rb..rb + n]);
        let (xa, xb) = (&level.dx[ra..ra + n], &level.dx[rb..rb + n]);
        let (ya, yb) = (&level.dy[ra..ra + n], &level.dy[rb..rb + n]);
        let o = r * win.stride..r * win.stride + win.cols;
        for (c, ((oi, ox), oy)) in img[o.clone()].iter_mut().zip(&mut gx[o.clone()]).zip(&mut gy[o]).enumerate() {
            *oi = i00 * ia[c] + i01 * ia[c + 1] + i10 * ib[c] + i11 * ib[c + 1];
            *ox = g00 * xa[c] + g01 * xa[c + 1] + g10 * xb[c] + g11 * xb[c + 1];
            *oy = g00 * ya[c] + g01 * ya[c + 1] + g10 * yb[c] + g11 * yb[c + 1];
        }
    }
}

/// `sum((J - I) * gx)` and `sum((J - I) * gy)` over the window, `J` the next image sampled at
/// `win`/`wts` (fused: no intermediate patch when the window is inside the image).
#[allow(clippy::too_many_arguments)]
fn mismatch(
    src: &[f32],
    w: usize,
    h: usize,
    win: Window,
    wts: Weights,
    i: &[f32],
    gx: &[f32],
    gy: &[f32],
    scratch: &mut [f32],
) -> (f32, f32) {
    let (mut s1, mut s2) = ([0.0f32; LANES], [0.0f32; LANES]);
    let [w00, w01, w10, w11] = wts.0;
    let stride = win.stride;
    let full = Window { cols: stride, ..win };
    if full.inside(w, h) {
        let (x0, y0) = (win.x0 as usize, win.y0 as usize);
        for r in 0..win.rows {
            let a = &src[(y0 + r) * w + x0..(y0 + r) * w + x0 + stride + 1];
            let b = &src[(y0 + r + 1) * w + x0..(y0 + r + 1) * w + x0 + stride + 1];
            let row = r * stride..(r + 1) * stride;
            for ((((ca, cb), ci), cx), cy) in a
                .windows(LANES + 1)
                .step_by(LANES)
                .zip(b.windows(LANES + 1).step_by(LANES))
                .zip(i[row.clone()].chunks_exact(LANES))
                .zip(gx[row.clone()].chunks_exact(LANES))
                .zip(gy[row].chunks_exact(LANES))
            {
                let (Some(ca), Some(cb)) = (ca.first_chunk::<{ LANES + 1 }>(), cb.first_chunk::<{ LANES + 1 }>())
                else {
                    continue;
                };
                let (Some(ci), Some(cx), Some(cy)) =
                    (ci.first_chunk::<LANES>(), cx.first_chunk::<LANES>(), cy.first_chunk::<LANES>())
                else {
                    continue;
                };
                for l in 0..LANES {
                    let j = w00 * ca[l] + w01 * ca[l + 1] + w10 * cb[l] + w11 * cb[l + 1];
                    let d = j - ci[l];
                    s1[l] += d * cx[l];
                    s2[l] += d * cy[l];
                }
            }
        }
    } else {
        sample(src, w, h, full, wts, scratch);
        for (((cj, ci), cx), cy) in scratch
            .chunks_exact(LANES)
            .zip(i.chunks_exact(LANES))
            .zip(gx.chunks_exact(LANES))
            .zip(gy.chunks_exact(LANES))
        {
            for l in 0..LANES {
                let d = cj[l] - ci[l];
                s1[l] += d * cx[l];
                s2[l] += d * cy[l];
            }
        }
    }
    (s1.iter().sum(), s2.iter().sum())
}

impl LkTracker {
    /// A tracker (an even window is made odd, at least 3).
    pub fn new(mut config: LkConfig) -> Self {
        config.window = (config.window.max(3)) | 1;
        let stride = config.window.div_ceil(LANES) * LANES;
        let n = config.window * stride;
        Self {
            config,
            stride,
            patch: vec![0.0; n],
            patch_dx: vec![0.0; n],
            patch_dy: vec![0.0; n],
            patch_j: vec![0.0; n],
        }
    }

    /// The settings.
    pub fn config(&self) -> &LkConfig {
        &self.config
    }

    /// Track `points` (level-0 pixels of `prev`) into `next`. Results align with `points`.
    /// `prev` needs gradients ([`Pyramid::build`]); `next` too only with the
    /// forward-backward check. A pyramid without them tracks nothing.
    pub fn track(&mut self, prev: &Pyramid, next: &Pyramid, points: &[[f32; 2]]) -> Vec<TrackResult> {
        let fb = self.config.fb_threshold;
        if !prev.has_gradients() || (fb.is_some() && !next.has_gradients()) {
            return points.iter().map(|&p| TrackResult { point: p, found: false, error: 0.0 }).collect();
        }
        let mut out: Vec<TrackResult> = points.iter().map(|&p| self.track_one(prev, next, p, p)).collect();
        if let Some(fb) = fb {
            for (r, &p) in out.iter_mut().zip(points) {
                if r.found {
                    let back = self.track_one(next, prev, r.point, p);
                    let d2 = (back.point[0] - p[0]).powi(2) + (back.point[1] - p[1]).powi(2);
                    r.found = back.found && d2 <= fb * fb;
                }
            }
        }
        out
    }

    fn track_one(&mut self, prev: &Pyramid, next: &Pyramid, p: [f32; 2], guess: [f32; 2]) -> TrackResult {
        let lost = TrackResult { point: p, found: false, error: 0.0 };
        let levels = prev.levels.len().min(next.levels.len()).min(self.config.max_level + 1);
        if levels == 0 || !(p[0].is_finite() && p[1].is_finite() && guess[0].is_finite() && guess[1].is_finite()) {
            return lost;
        }
        let win = self.config.window;
        let stride = self.stride;
        let half = ((win - 1) / 2) as f32;
        let area = (win * win) as f32;
        let top = levels - 1;
        let top_scale = 1.0 / (1u32 << top) as f32;
        let mut next_pt = [guess[0] * top_scale, guess[1] * top_scale];
        let mut found = true;
        let mut error = 0.0;
        let outside = |x: f32, y: f32, w: usize, h: usize| {
            x < -(win as f32) || x >= w as f32 || y < -(win as f32) || y >= h as f32
        };
        for l in (0..levels).rev() {
            let s = 1.0 / (1u32 << l) as f32;
            if l != top {
                next_pt = [next_pt[0] * 2.0, next_pt[1] * 2.0];
            }
            let (lp, ln): (&Level, &Level) = (&prev.levels[l], &next.levels[l]);
            let (w, h) = (lp.width, lp.height);
            let ip = [p[0] * s - half, p[1] * s - half];
            let (ix, iy) = (ip[0].floor(), ip[1].floor());
            if outside(ix, iy, w, h) {
                if l == 0 {
                    found = false;
                }
                continue;
            }
            let window = Window { x0: ix as isize, y0: iy as isize, rows: win, cols: win, stride };
            let wimg = Weights::new(ip[0] - ix, ip[1] - iy, INTENSITY_SCALE);
            let wi = Weights::new(ip[0] - ix, ip[1] - iy, 1.0);
            if window.inside(w, h) {
                sample_three(lp, window, wimg, wi, &mut self.patch, &mut self.patch_dx, &mut self.patch_dy);
            } else {
                sample(&lp.img, w, h, window, wimg, &mut self.patch);
                sample(&lp.dx, w, h, window, wi, &mut self.patch_dx);
                sample(&lp.dy, w, h, window, wi, &mut self.patch_dy);
            }
            let (mut s11, mut s12, mut s22) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
            for (gx, gy) in self.patch_dx.chunks_exact(LANES).zip(self.patch_dy.chunks_exact(LANES)) {
                for l in 0..LANES {
                    s11[l] += gx[l] * gx[l];
                    s12[l] += gx[l] * gy[l];
                    s22[l] += gy[l] * gy[l];
                }
            }
            let sum = |v: [f32; LANES]| v.iter().sum::<f32>() * FLT_SCALE;
            let (a11, a12, a22) = (sum(s11), sum(s12), sum(s22));
            let det = a11 * a22 - a12 * a12;
            let min_eig = (a22 + a11 - ((a11 - a22).powi(2) + 4.0 * a12 * a12).sqrt()) / (2.0 * area);
            if min_eig < self.config.min_eig_threshold || det < f32::EPSILON {
                if l == 0 {
                    found = false;
                }
                continue;
            }
            let inv_det = 1.0 / det;
            let mut prev_delta = [0.0f32; 2];
            for iter in 0..self.config.max_iterations {
                let jp = [next_pt[0] - half, next_pt[1] - half];
                let (jx, jy) = (jp[0].floor(), jp[1].floor());
                if outside(jx, jy, ln.width, ln.height) {
                    if l == 0 {
                        found = false;
                    }
                    break;
                }
                let wj = Weights::new(jp[0] - jx, jp[1] - jy, INTENSITY_SCALE);
                let jw = Window { x0: jx as isize, y0: jy as isize, ..window };
                let (b1, b2) = mismatch(
                    &ln.img,
                    ln.width,
                    ln.height,
                    jw,
                    wj,
                    &self.patch,
                    &self.patch_dx,
                    &self.patch_dy,
                    &mut self.patch_j,
                );
                let (b1, b2) = (b1 * FLT_SCALE, b2 * FLT_SCALE);
                let delta = [(a12 * b2 - a22 * b1) * inv_det, (a12 * b1 - a11 * b2) * inv_det];
                next_pt = [next_pt[0] + delta[0], next_pt[1] + delta[1]];
                if delta[0] * delta[0] + delta[1] * delta[1] <= self.config.epsilon * self.config.epsilon {
                    break;
                }
                // Oscillating between two positions: settle in the middle.
                if iter > 0 && (delta[0] + prev_delta[0]).abs() < 0.01 && (delta[1] + prev_delta[1]).abs() < 0.01 {
                    next_pt = [next_pt[0] - delta[0] * 0.5, next_pt[1] - delta[1] * 0.5];
                    break;
                }
                prev_delta = delta;
            }
            if l == 0 && found {
                let jp = [next_pt[0] - half, next_pt[1] - half];
                let (jx, jy) = (jp[0].floor(), jp[1].floor());
                if outside(jx, jy, ln.width, ln.height) {
                    found = false;
                } else {
                    let jw = Window { x0: jx as isize, y0: jy as isize, ..window };
                    let wj = Weights::new(jp[0] - jx, jp[1] - jy, INTENSITY_SCALE);
                    sample(&ln.img, ln.width, ln.height, jw, wj, &mut self.patch_j);
                    let mut sum = 0.0;
                    for r in 0..win {
                        for c in 0..win {
                            sum += (self.patch_j[r * stride + c] - self.patch[r * stride + c]).abs();
                        }
                    }
                    error = sum / (area * INTENSITY_SCALE);
                }
            }
        }
        // A point that left the image is lost even if the iteration ended.
        let (w0, h0) = prev.levels.first().map_or((0, 0), |l| (l.width, l.height));
        if !(next_pt[0] >= 0.0 && next_pt[1] >= 0.0 && next_pt[0] < w0 as f32 && next_pt[1] < h0 as f32) {
            found = false;
        }
        TrackResult { point: next_pt, found, error }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::GrayImage;

    /// A smooth, textured test image shifted by `(sx, sy)`.
    fn texture(w: usize, h: usize, sx: f32, sy: f32) -> GrayImage {
        let mut img = GrayImage::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (x as f32 - sx, y as f32 - sy);
                let val = 128.0 + 50.0 * (u * 0.21).sin() * (v * 0.17).cos() + 40.0 * ((u + v) * 0.11).sin();
                img.data[y * w + x] = val.round().clamp(0.0, 255.0) as u8;
            }
        }
        img
    }

    #[test]
    fn recovers_a_subpixel_shift() {
        let (a, b) = (texture(160, 120, 0.0, 0.0), texture(160, 120, 3.4, -2.3));
        let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
        pa.build(&a, 3);
        pb.build(&b, 3);
        let mut lk = LkTracker::new(LkConfig { fb_threshold: Some(0.5), ..LkConfig::default() });
        let pts = [[60.0, 50.0], [100.0, 70.0], [80.0, 40.0]];
        for r in lk.track(&pa, &pb, &pts).iter().zip(&pts) {
            let (res, p) = r;
            assert!(res.found, "{res:?}");
            assert!((res.point[0] - p[0] - 3.4).abs() < 0.1 && (res.point[1] - p[1] + 2.3).abs() < 0.1, "{res:?}");
        }
    }

    #[test]
    fn flat_and_degenerate_inputs_are_lost_not_panics() {
        let flat = GrayImage::from_vec(64, 48, vec![90; 64 * 48]).unwrap();
        let (mut pa, mut pb) = (Pyramid::default(), Pyramid::default());
        pa.build(&flat, 3);
        pb.build(&flat, 3);
        let mut lk = LkTracker::new(LkConfig::default());
        let r = lk.track(&pa, &pb, &[[30.0, 20.0], [f32::NAN, 1.0], [-500.0, 3.0]]);
        assert!(r.iter().all(|r| !r.found));
        let empty = Pyramid::default();
        assert!(lk.track(&empty, &pb, &[[1.0, 1.0]]).iter().all(|r| !r.found));
        for (w, h) in [(1, 1), (8, 8), (1, 100), (100, 1)] {
            let img = GrayImage::from_vec(w, h, vec![7; w * h]).unwrap();
            let mut p = Pyramid::default();
            p.build(&img, 3);
            assert!(lk.track(&p, &p, &[[0.0, 0.0]]).iter().all(|r| !r.found));
        }
    }
}
