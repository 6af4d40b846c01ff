//! ORB features as ORB-SLAM2/3 extract them.
//!
//! - `fast`: FAST-9 corners with OpenCV's score and non-maximum suppression.
//! - `distribute`: the quadtree that spreads features over the image.
//! - `brief`: intensity-centroid orientation and the rotated BRIEF descriptor.
//! - `pattern`: the learned 256-pair test pattern (vendored data).
//!
//! The steps are private: what a user needs is [`OrbExtractor::extract`]; the pyramid levels
//! and per-level corner lists are scratch that the extractor keeps across frames.

mod brief;
mod distribute;
pub mod fast;
mod pattern;

use crate::image::{BlurScratch, GrayImage, gaussian_blur, resize_bilinear};

/// Pixels kept free at each level's border: the rotated 31x31 BRIEF patch reaches 18.4 px
/// from its centre (ORB-SLAM's `EDGE_THRESHOLD` is 19).
pub const EDGE: usize = 19;
/// OpenCV's `edgeThreshold` default, used by [`Distribution::Harris`].
pub const EDGE_OPENCV: usize = 31;
/// BRIEF patch side.
pub const PATCH_SIZE: usize = 31;

/// How each level's keypoints are chosen among its FAST corners.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Distribution {
    /// ORB-SLAM2/3: FAST per 30-px cell at `ini_threshold`, or `min_threshold` where a cell
    /// has none, then a quadtree that spreads the level's share over the whole image, the
    /// strongest corner of each node. Features reach weakly textured areas too, which keeps
    /// tracking alive there; two-view repeatability is lower than `Harris`'s.
    #[default]
    Quadtree,
    /// OpenCV's `ORB`: FAST at `ini_threshold` at least 31 px from the borders, the 2N with
    /// the best FAST score, then the N with the best Harris response. Strong, repeatable
    /// corners where the texture is; no spreading.
    Harris,
}

/// Extraction settings; the defaults are ORB-SLAM2's for 640x480 (`ORBextractor.nFeatures:
/// 1000`, `scaleFactor: 1.2`, `nLevels: 8`, `iniThFAST: 20`, `minThFAST: 7`).
#[derive(Clone, Debug, PartialEq)]
pub struct OrbConfig {
    /// Features wanted over all levels.
    pub features: usize,
    /// Scale between levels.
    pub scale_factor: f32,
    /// Pyramid levels.
    pub levels: usize,
    /// FAST threshold tried first in each cell.
    pub ini_threshold: u8,
    /// Fallback threshold for cells where the first finds nothing (low contrast).
    pub min_threshold: u8,
    /// Side of the detection cells, pixels (ORB-SLAM's 30).
    pub cell: usize,
    /// How keypoints are chosen on each level.
    pub distribution: Distribution,
}

impl Default for OrbConfig {
    fn default() -> Self {
        Self {
            features: 1000,
            scale_factor: 1.2,
            levels: 8,
            ini_threshold: 20,
            min_threshold: 7,
            cell: 30,
            distribution: Distribution::Quadtree,
        }
    }
}

/// One ORB keypoint: the message type (OpenCV `KeyPoint` conventions; ORB's `size` is the
/// patch diameter at level 0, `31 * scale^octave`, its `response` the Harris score).
pub use dynaflow_msg::Keypoint;

/// Keypoints and their 256-bit descriptors, aligned.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct OrbFeatures {
    /// The keypoints.
    pub keypoints: Vec<Keypoint>,
    /// One 32-byte descriptor per keypoint.
    pub descriptors: Vec<[u8; 32]>,
}

/// Extracts ORB features; keeps its pyramid and scratch buffers between frames.
#[derive(Debug)]
pub struct OrbExtractor {
    config: OrbConfig,
    levels: Vec<GrayImage>,
    blurred: GrayImage,
    blur: BlurScratch,
    fast: fast::FastScratch,
    corners: Vec<fast::Corner>,
    umax: Vec<i32>,
}

impl OrbExtractor {
    /// A new extractor (invalid settings are clamped to usable ones).
    pub fn new(mut config: OrbConfig) -> Self {
        config.levels = config.levels.clamp(1, 32);
        if !(config.scale_factor > 1.0 && config.scale_factor.is_finite()) {
            config.scale_factor = 1.2;
        }
        config.cell = config.cell.max(8);
        config.min_threshold = config.min_threshold.clamp(1, config.ini_threshold.max(1));
        Self {
            config,
            levels: Vec::new(),
            blurred: GrayImage::default(),
            blur: BlurScratch::default(),
            fast: fast::FastScratch::default(),
            corners: Vec::new(),
            umax: brief::umax(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &OrbConfig {
        &self.config
    }

    /// The pyramid of the last [`extract`](Self::extract) or [`describe`](Self::describe):
    /// `image` (the one it was given, level 0) and the levels resized from it, as the
    /// stereo matcher's SAD search reads them.
    pub fn pyramid<'a>(&'a self, image: &'a GrayImage) -> Vec<&'a GrayImage> {
        std::iter::once(image).chain(self.levels.iter().skip(1).take_while(|l| !l.is_empty())).collect()
    }

    /// Build the pyramid of `image` as [`extract`](Self::extract) would, without extracting,
    /// and return it as [`pyramid`](Self::pyramid) does (the stereo matcher's left view when
    /// the keypoints came from another extractor with the same settings).
    pub fn build_pyramid<'a>(&'a mut self, image: &'a GrayImage) -> Vec<&'a GrayImage> {
        self.levels.resize_with(self.config.levels, GrayImage::default);
        let mut built = 1;
        for level in 1..self.config.levels {
            if !self.build_level(image, level) {
                break;
            }
            built += 1;
        }
        std::iter::once(image).chain(self.levels.iter().skip(1).take(built - 1)).collect()
    }

    /// Scale of `level` relative to level 0.
    pub fn scale(&self, level: usize) -> f32 {
        self.config.scale_factor.powi(level as i32)
    }

    /// Make pyramid level `level` (level 0 is `image` itself; level l is resized from level
    /// l - 1, as ORB-SLAM and OpenCV do). False when the level is too small for a patch.
    fn build_level(&mut self, image: &GrayImage, level: usize) -> bool {
        let scale = self.scale(level);
        let (w, h) = ((image.width as f32 / scale).round() as usize, (image.height as f32 / scale).round() as usize);
        if w < 2 * EDGE + 1 || h < 2 * EDGE + 1 {
            return false;
        }
        if level > 0 {
            let (prev, rest) = self.levels.split_at_mut(level);
            let src = if level == 1 { image } else { &prev[level - 1] };
            resize_bilinear(src, w, h, &mut rest[0]);
        }
        true
    }

    /// Features wanted on each level: a geometric series over the levels' areas' square
    /// roots, as ORB-SLAM does.
    fn per_level(&self) -> Vec<usize> {
        let (n, l) = (self.config.features, self.config.levels);
        let f = 1.0 / f64::from(self.config.scale_factor);
        let first = n as f64 * (1.0 - f) / (1.0 - f.powi(l as i32));
        let mut out: Vec<usize> = (0..l).map(|i| (first * f.powi(i as i32)).round() as usize).collect();
        let assigned: usize = out.iter().take(l - 1).sum();
        if let Some(last) = out.last_mut() {
            *last = n.saturating_sub(assigned);
        }
        out
    }

    /// Extract features from `image`. With a `mask` (same size, non-zero = excluded, e.g.
    /// people), no keypoint lies on a masked pixel. An image too small for the 31x31 patch
    /// gives no features.
    pub fn extract(&mut self, image: &GrayImage, mask: Option<&GrayImage>) -> OrbFeatures {
        let mut out = OrbFeatures::default();
        if image.width < 2 * EDGE + 1 || image.height < 2 * EDGE + 1 || image.data.len() < image.width * image.height {
            return out;
        }
        let mask = mask.filter(|m| m.width == image.width && m.height == image.height && !m.is_empty());
        let wanted = self.per_level();
        self.levels.resize_with(self.config.levels, GrayImage::default);
        let mut carry = 0usize;
        for (level, &share) in wanted.iter().enumerate() {
            let scale = self.scale(level);
            if !self.build_level(image, level) {
                break;
            }
            // Borrow the level out of `self` while the scratch buffers are in use.
            let taken = (level > 0).then(|| std::mem::take(&mut self.levels[level]));
            let img: &GrayImage = taken.as_ref().unwrap_or(image);
            let target = share + carry;
            let kept = self.level_corners(img, scale, target, mask);
            carry = target.saturating_sub(kept.len());
            if !kept.is_empty() {
                gaussian_blur(img, 3, 2.0, &mut self.blur, &mut self.blurred);
            }
            for (c, response) in kept {
                let (x, y) = (usize::from(c.x), usize::from(c.y));
                let angle = brief::ic_angle(img, x, y, &self.umax);
                out.descriptors.push(brief::describe(&self.blurred, x, y, angle));
                out.keypoints.push(Keypoint {
                    x: f32::from(c.x) * scale,
                    y: f32::from(c.y) * scale,
                    size: PATCH_SIZE as f32 * scale,
                    angle,
                    response,
                    octave: level as u8,
                });
            }
            if let Some(t) = taken {
                self.levels[level] = t;
            }
        }
        out
    }

    /// Orientation and descriptor for keypoints found elsewhere (e.g. by another detector;
    /// OpenCV's `compute`). Keypoints whose patch would leave their level are dropped; the
    /// result holds the kept ones with their angle filled in.
    pub fn describe(&mut self, image: &GrayImage, keypoints: &[Keypoint]) -> OrbFeatures {
        let mut out = OrbFeatures::default();
        if image.is_empty() || image.data.len() < image.width * image.height {
            return out;
        }
        self.levels.resize_with(self.config.levels, GrayImage::default);
        for level in 0..self.config.levels {
            let scale = self.scale(level);
            if !self.build_level(image, level) {
                break;
            }
            let (w, h) = if level == 0 {
                (image.width, image.height)
            } else {
                (self.levels[level].width, self.levels[level].height)
            };
            let on_level: Vec<&Keypoint> = keypoints.iter().filter(|k| usize::from(k.octave) == level).collect();
            if on_level.is_empty() {
                continue;
            }
            let img: &GrayImage = if level == 0 { image } else { &self.levels[level] };
            gaussian_blur(img, 3, 2.0, &mut self.blur, &mut self.blurred);
            for k in on_level {
                let (x, y) = ((k.x / scale).round(), (k.y / scale).round());
                if !(x >= EDGE as f32 && y >= EDGE as f32 && x < (w - EDGE) as f32 && y < (h - EDGE) as f32) {
                    continue;
                }
                let (x, y) = (x as usize, y as usize);
                let angle = brief::ic_angle(img, x, y, &self.umax);
                out.descriptors.push(brief::describe(&self.blurred, x, y, angle));
                out.keypoints.push(Keypoint { angle, ..*k });
            }
        }
        out
    }

    /// FAST corners of one level: per cell the initial threshold, or the fallback where a
    /// cell has none; masked ones dropped; spread by the quadtree; at most `target`.
    fn level_corners(
        &mut self,
        img: &GrayImage,
        scale: f32,
        target: usize,
        mask: Option<&GrayImage>,
    ) -> Vec<(fast::Corner, f32)> {
        let (w, h) = (img.width, img.height);
        self.corners.clear();
        let harris_mode = self.config.distribution == Distribution::Harris;
        let edge = if harris_mode { EDGE_OPENCV } else { EDGE };
        if w < 2 * edge + 1 || h < 2 * edge + 1 {
            return Vec::new();
        }
        // Pass 1 over the whole detection area at the initial threshold.
        let area = fast::Region { x0: edge, y0: edge, x1: w - edge, y1: h - edge };
        fast::detect_in(&img.data, w, h, area, self.config.ini_threshold, &mut self.fast, &mut self.corners);
        if !harris_mode && self.config.min_threshold < self.config.ini_threshold {
            // Pass 2, ORB-SLAM's per-cell retry: the fallback threshold only in the cells
            // that got nothing.
            let cell = self.config.cell;
            let (cols, rows) = ((w - 2 * edge).div_ceil(cell).max(1), (h - 2 * edge).div_ceil(cell).max(1));
            let mut filled = vec![false; cols * rows];
            for c in &self.corners {
                let cx = ((usize::from(c.x) - edge) / cell).min(cols - 1);
                let cy = ((usize::from(c.y) - edge) / cell).min(rows - 1);
                filled[cy * cols + cx] = true;
            }
            for cy in 0..rows {
                for cx in 0..cols {
                    if filled[cy * cols + cx] {
                        continue;
                    }
                    let region = fast::Region {
                        x0: edge + cx * cell,
                        y0: edge + cy * cell,
                        x1: (edge + (cx + 1) * cell).min(w - edge),
                        y1: (edge + (cy + 1) * cell).min(h - edge),
                    };
                    let t = self.config.min_threshold;
                    fast::detect_in(&img.data, w, h, region, t, &mut self.fast, &mut self.corners);
                }
            }
        }
        if let Some(m) = mask {
            self.corners.retain(|c| {
                let x = ((f32::from(c.x) * scale).round() as usize).min(m.width - 1);
                let y = ((f32::from(c.y) * scale).round() as usize).min(m.height - 1);
                m.data[y * m.width + x] == 0
            });
        }
        if harris_mode && self.corners.len() > 2 * target {
            // OpenCV keeps the 2N best FAST scores before computing Harris responses.
            self.corners.sort_by_key(|c| (std::cmp::Reverse(c.score), c.y, c.x));
            self.corners.truncate(2 * target);
        }
        // Ranking: OpenCV ranks by Harris response (7x7 block, k = 0.04), ORB-SLAM's quadtree
        // by FAST score (cheap: the quadtree sees every corner, weak ones included). The
        // reported response is Harris's either way.
        let response: Vec<f32> = if harris_mode {
            self.corners.iter().map(|c| brief::harris(img, usize::from(c.x), usize::from(c.y))).collect()
        } else {
            self.corners.iter().map(|c| f32::from(c.score)).collect()
        };
        let mut chosen: Vec<u32> = if harris_mode {
            (0..self.corners.len() as u32).collect()
        } else {
            let bounds = [edge as f32, edge as f32, (w - edge) as f32, (h - edge) as f32];
            distribute::distribute(&self.corners, &response, target, bounds)
        };
        if chosen.len() > target {
            // Strongest first; ties by position, so results never depend on sort stability.
            chosen.sort_by(|&a, &b| {
                let (ca, cb) = (self.corners[a as usize], self.corners[b as usize]);
                response[b as usize].total_cmp(&response[a as usize]).then((ca.y, ca.x).cmp(&(cb.y, cb.x)))
            });
            chosen.truncate(target);
        }
        chosen
            .iter()
            .map(|&i| {
                let c = self.corners[i as usize];
                let r = if harris_mode {
                    response[i as usize]
                } else {
                    brief::harris(img, usize::from(c.x), usize::from(c.y))
                };
                (c, r)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_level_counts_sum_to_the_request() {
        let e = OrbExtractor::new(OrbConfig::default());
        let n = e.per_level();
        assert_eq!(n.len(), 8);
        assert_eq!(n.iter().sum::<usize>(), 1000);
        assert!(n.windows(2).all(|w| w[0] >= w[1]));
    }

    #[test]
    fn degenerate_images_give_no_features() {
        let mut e = OrbExtractor::new(OrbConfig::default());
        for (w, h, v) in [(0, 0, 0u8), (8, 8, 128), (1, 480, 30), (640, 1, 30), (640, 480, 0), (640, 480, 255)] {
            let img = GrayImage::from_vec(w, h, vec![v; w * h]).unwrap();
            assert!(e.extract(&img, None).keypoints.is_empty(), "{w}x{h}");
        }
    }
}
