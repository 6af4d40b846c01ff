//! Image pyramids for LK: each level is the previous one smoothed with the 5x5 binomial
//! kernel and halved (OpenCV's `pyrDown`, BORDER_REFLECT_101), stored as `f32` with Scharr
//! gradients so the tracker's inner loops are plain multiply-adds.

use crate::image::{GrayImage, reflect101 as reflect};

/// One level: intensities and their Scharr derivatives, row-major.
#[derive(Clone, Debug, Default)]
pub struct Level {
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Intensities (0..=255).
    pub img: Vec<f32>,
    /// d/dx (Scharr, unnormalised: 32 x the central difference on a ramp).
    pub dx: Vec<f32>,
    /// d/dy.
    pub dy: Vec<f32>,
}

/// A pyramid of [`Level`]s, finest first. Reused across frames (no allocation once warm).
#[derive(Clone, Debug, Default)]
pub struct Pyramid {
    /// Levels, level 0 = full resolution.
    pub levels: Vec<Level>,
    tmp: Vec<f32>,
}

impl Pyramid {
    /// Build `max_level + 1` levels from `image` (fewer if the image gets too small), with
    /// gradients (what the previous frame of a track needs).
    pub fn build(&mut self, image: &GrayImage, max_level: usize) {
        self.build_levels(image, max_level);
        self.ensure_gradients();
    }

    /// Build the levels only: the frame tracked *into* needs no gradients (unless it is
    /// tracked back from, or becomes the next call's previous frame: [`Self::ensure_gradients`]).
    pub fn build_levels(&mut self, image: &GrayImage, max_level: usize) {
        let count = max_level + 1;
        self.levels.resize_with(count, Level::default);
        let mut built = 0;
        if !image.is_empty() && image.data.len() >= image.width * image.height {
            let l0 = &mut self.levels[0];
            l0.width = image.width;
            l0.height = image.height;
            l0.img.clear();
            l0.img.extend(image.data[..image.width * image.height].iter().map(|&v| f32::from(v)));
            built = 1;
            for l in 1..count {
                let (prev, rest) = self.levels.split_at_mut(l);
                let src = &prev[l - 1];
                let (w, h) = (src.width.div_ceil(2), src.height.div_ceil(2));
                if src.width < 8 || src.height < 8 {
                    break;
                }
                pyr_down(src, w, h, &mut self.tmp, &mut rest[0]);
                built = l + 1;
            }
        }
        self.levels.truncate(built);
        for level in &mut self.levels {
            level.dx.clear();
            level.dy.clear();
        }
    }

    /// Compute the Scharr gradients of every level, if not done yet.
    pub fn ensure_gradients(&mut self) {
        for level in &mut self.levels {
            if level.dx.len() != level.img.len() {
                scharr(level);
            }
        }
    }

    /// Whether every level has its gradients.
    pub fn has_gradients(&self) -> bool {
        self.levels.iter().all(|l| l.dx.len() == l.img.len() && l.dy.len() == l.img.len())
    }
}

fn pyr_down(src: &Level, w: usize, h: usize, tmp: &mut Vec<f32>, dst: &mut Level) {
    const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    let (sw, sh) = (src.width, src.height);
    // Horizontal pass at the kept columns, all rows.
    tmp.clear();
    tmp.resize(w * sh, 0.0);
    for y in 0..sh {
        let row = &src.img[y * sw..(y + 1) * sw];
        let out = &mut tmp[y * w..(y + 1) * w];
        for (x, o) in out.iter_mut().enumerate() {
            let cx = 2 * x;
            *o = if cx >= 2 && cx + 2 < sw {
                let r = &row[cx - 2..cx + 3];
                K[0] * r[0] + K[1] * r[1] + K[2] * r[2] + K[3] * r[3] + K[4] * r[4]
            } else {
                K.iter().enumerate().map(|(k, &kv)| kv * row[reflect(cx as isize + k as isize - 2, sw)]).sum()
            };
        }
    }
    dst.width = w;
    dst.height = h;
    dst.img.clear();
    dst.img.resize(w * h, 0.0);
    for y in 0..h {
        let cy = 2 * y as isize;
        let rows = [0isize, 1, 2, 3, 4].map(|k| reflect(cy + k - 2, sh));
        let r: [&[f32]; 5] = rows.map(|i| &tmp[i * w..(i + 1) * w]);
        let out = &mut dst.img[y * w..(y + 1) * w];
        for (x, o) in out.iter_mut().enumerate() {
            *o = K[0] * r[0][x] + K[1] * r[1][x] + K[2] * r[2][x] + K[3] * r[3][x] + K[4] * r[4][x];
        }
    }
}

/// Scharr derivatives with replicated borders (OpenCV's `calcSharrDeriv` kernel:
/// `[-3 0 3; -10 0 10; -3 0 3]`).
fn scharr(level: &mut Level) {
    let (w, h) = (level.width, level.height);
    level.dx.clear();
    level.dx.resize(w * h, 0.0);
    level.dy.clear();
    level.dy.resize(w * h, 0.0);
    if w == 0 || h == 0 {
        return;
    }
    let img = &level.img;
    for y in 0..h {
        let (ym, yp) = (y.saturating_sub(1), (y + 1).min(h - 1));
        let (r0, r1, r2) = (&img[ym * w..ym * w + w], &img[y * w..y * w + w], &img[yp * w..yp * w + w]);
        let dx = &mut level.dx[y * w..y * w + w];
        let dy = &mut level.dy[y * w..y * w + w];
        for x in 0..w {
            let (xm, xp) = (x.saturating_sub(1), (x + 1).min(w - 1));
            dx[x] = 3.0 * (r0[xp] + r2[xp] - r0[xm] - r2[xm]) + 10.0 * (r1[xp] - r1[xm]);
            dy[x] = 3.0 * (r2[xm] + r2[xp] - r0[xm] - r0[xp]) + 10.0 * (r2[x] - r0[x]);
        }
    }
}
