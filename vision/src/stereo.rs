//! Sparse stereo matching of ORB keypoints on a rectified pair, as ORB-SLAM2's stereo frames
//! do it (`Frame::ComputeStereoMatches`; Mur-Artal & Tardós 2017, section III-A): each left
//! keypoint is matched by descriptor to the right keypoints on its row band, the match is
//! refined by a SAD patch search along the row at the keypoint's pyramid level with a
//! parabola through the best three costs, and matches whose SAD is far above the median are
//! dropped. The result is a depth and a right-image column per left keypoint, which the
//! back-end uses as it uses an RGB-D camera's (the "virtual right coordinate").
//!
//! Every constant is ORB-SLAM2's: the row band (2 x the octave's scale), octaves within one of
//! the left keypoint's, descriptor distance below `(TH_HIGH + TH_LOW) / 2 = 75`, an 11x11 SAD
//! window searched over +-5 columns, a sub-pixel step within +-1, disparities in
//! `[0, bf / b)` (a point no nearer than one baseline) and SAD above `1.5 x 1.4 x` the
//! median rejected (1.4826 x median is the robust sigma of the SAD costs).

use crate::image::GrayImage;
use crate::matching::hamming;
use crate::orb::Keypoint;

/// ORB-SLAM2's `ORBmatcher::TH_HIGH`.
pub const TH_HIGH: u32 = 100;
/// ORB-SLAM2's `ORBmatcher::TH_LOW`.
pub const TH_LOW: u32 = 50;
/// Half width of the SAD window (11x11).
const WINDOW: i64 = 5;
/// Columns searched either side of the descriptor match.
const SEARCH: i64 = 5;

/// One view of a rectified pair: its keypoints (positions at level 0, octaves), their ORB
/// descriptors and its image pyramid (level 0 first, each level the image scaled by
/// `scale_factor^-l`, as the ORB extractor builds it).
#[derive(Clone, Copy, Debug)]
pub struct StereoView<'a> {
    /// Keypoints.
    pub keypoints: &'a [Keypoint],
    /// One descriptor per keypoint.
    pub descriptors: &'a [[u8; 32]],
    /// Pyramid levels, level 0 the full image.
    pub levels: &'a [&'a GrayImage],
}

/// The rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoRig {
    /// Focal length times baseline, pixel metres (ORB-SLAM2's `Camera.bf`).
    pub bf: f64,
    /// Baseline, metres.
    pub baseline: f64,
    /// The pyramid's scale factor between levels (ORB-SLAM2: 1.2).
    pub scale_factor: f32,
}

/// A left keypoint's stereo match.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StereoMatch {
    /// Column of the point in the right image (sub-pixel), ORB-SLAM2's `mvuRight`.
    pub u_right: f32,
    /// Depth `bf / disparity`, metres.
    pub depth: f32,
    /// The SAD cost of the best column.
    pub cost: u32,
}

/// What a pair gave, with the counts of each rejection (for the benches and the docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StereoMatches {
    /// Per left keypoint: its match, or `None`.
    pub matches: Vec<Option<StereoMatch>>,
    /// Left keypoints with no right keypoint of a near octave on their row band and in the
    /// disparity range, or whose best descriptor distance was not under 75.
    pub no_candidate: usize,
    /// Whose SAD window or search left the pyramid level, or whose best cost was at the
    /// search's end, or whose parabola step was outside +-1.
    pub no_refinement: usize,
    /// Whose disparity fell outside `[0, bf / b)`.
    pub out_of_range: usize,
    /// Dropped by the SAD median test.
    pub high_cost: usize,
}

impl StereoMatches {
    /// Number of keypoints with a match.
    pub fn matched(&self) -> usize {
        self.matches.iter().filter(|m| m.is_some()).count()
    }
}

/// Why [`stereo_match`] refused its input.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum StereoError {
    /// The two level-0 images differ in size.
    #[error("the right image is {right_w}x{right_h} but the left is {left_w}x{left_h}: a rectified pair has one size")]
    SizeMismatch {
        /// Left width.
        left_w: usize,
        /// Left height.
        left_h: usize,
        /// Right width.
        right_w: usize,
        /// Right height.
        right_h: usize,
    },
    /// `bf` or the baseline is not positive and finite.
    #[error("stereo baseline {baseline} m and bf {bf} must be positive and finite (a zero baseline has no disparity)")]
    Baseline {
        /// Baseline, metres.
        baseline: f64,
        /// fx times baseline.
        bf: f64,
    },
    /// Keypoints and descriptors differ in number, or a view has no level 0.
    #[error("{0}")]
    Inconsistent(String),
}

fn scale(factor: f32, level: u8) -> f32 {
    factor.powi(i32::from(level))
}

/// The SAD of the 11x11 windows centred on `(xl, y)` in `left` and `(xr, y)` in `right`, each
/// with its centre pixel's intensity subtracted (ORB-SLAM2's illumination normalisation).
/// The caller keeps both windows inside their images.
fn sad(left: &GrayImage, right: &GrayImage, xl: i64, xr: i64, y: i64) -> u32 {
    let (cl, cr) = (i32::from(left.row(y as usize)[xl as usize]), i32::from(right.row(y as usize)[xr as usize]));
    let mut sum = 0u32;
    for dy in -WINDOW..=WINDOW {
        let (rl, rr) = (left.row((y + dy) as usize), right.row((y + dy) as usize));
        let (l, r) = (
            &rl[(xl - WINDOW) as usize..=(xl + WINDOW) as usize],
            &rr[(xr - WINDOW) as usize..=(xr + WINDOW) as usize],
        );
        for (a, b) in l.iter().zip(r) {
            sum += ((i32::from(*a) - cl) - (i32::from(*b) - cr)).unsigned_abs();
        }
    }
    sum
}

/// Match every left keypoint into the right view (ORB-SLAM2's `ComputeStereoMatches`; see the
/// module documentation for each step and constant).
pub fn stereo_match(
    left: &StereoView<'_>,
    right: &StereoView<'_>,
    rig: &StereoRig,
) -> Result<StereoMatches, StereoError> {
    if !(rig.baseline > 0.0 && rig.baseline.is_finite() && rig.bf > 0.0 && rig.bf.is_finite()) {
        return Err(StereoError::Baseline { baseline: rig.baseline, bf: rig.bf });
    }
    for (name, v) in [("left", left), ("right", right)] {
        if v.keypoints.len() != v.descriptors.len() {
            return Err(StereoError::Inconsistent(format!(
                "the {name} view has {} keypoints but {} descriptors",
                v.keypoints.len(),
                v.descriptors.len()
            )));
        }
        if v.levels.is_empty() {
            return Err(StereoError::Inconsistent(format!("the {name} view has no image")));
        }
    }
    let (l0, r0) = (left.levels[0], right.levels[0]);
    if (l0.width, l0.height) != (r0.width, r0.height) {
        return Err(StereoError::SizeMismatch {
            left_w: l0.width,
            left_h: l0.height,
            right_w: r0.width,
            right_h: r0.height,
        });
    }
    let rows = l0.height;
    // Right keypoints by image row: each on every row within 2 x its octave's scale.
    let mut by_row: Vec<Vec<u32>> = vec![Vec::new(); rows];
    for (i, k) in right.keypoints.iter().enumerate() {
        let r = 2.0 * scale(rig.scale_factor, k.octave);
        let (lo, hi) =
            ((k.y - r).floor().max(0.0) as usize, ((k.y + r).ceil().max(0.0) as usize).min(rows.saturating_sub(1)));
        for row in by_row.iter_mut().take(hi + 1).skip(lo) {
            row.push(i as u32);
        }
    }
    let (min_d, max_d) = (0.0f64, rig.bf / rig.baseline);
    let th_orb = (TH_HIGH + TH_LOW) / 2;
    let mut out = StereoMatches { matches: vec![None; left.keypoints.len()], ..StereoMatches::default() };
    let mut costs: Vec<(u32, usize)> = Vec::new();
    for (il, kl) in left.keypoints.iter().enumerate() {
        let row = kl.y.round();
        let candidates = if row >= 0.0 && (row as usize) < rows { &by_row[row as usize][..] } else { &[][..] };
        let (u_min, u_max) = (f64::from(kl.x) - max_d, f64::from(kl.x) - min_d);
        // Best descriptor among the right keypoints of a near octave in the disparity range.
        let mut best: Option<(u32, usize)> = None;
        for &ir in candidates {
            let kr = &right.keypoints[ir as usize];
            if i32::from(kr.octave) < i32::from(kl.octave) - 1 || i32::from(kr.octave) > i32::from(kl.octave) + 1 {
                continue;
            }
            let ur = f64::from(kr.x);
            if ur < u_min || ur > u_max {
                continue;
            }
            let d = hamming(&left.descriptors[il], &right.descriptors[ir as usize]);
            if d < TH_HIGH && best.is_none_or(|(b, _)| d < b) {
                best = Some((d, ir as usize));
            }
        }
        let Some((_, ir)) = best.filter(|(d, _)| *d < th_orb) else {
            out.no_candidate += 1;
            continue;
        };
        // SAD search on the row at the left keypoint's level.
        let level = usize::from(kl.octave);
        let (Some(li), Some(ri)) = (left.levels.get(level), right.levels.get(level)) else {
            out.no_refinement += 1;
            continue;
        };
        let s = scale(rig.scale_factor, kl.octave);
        let (xl, y, xr0) =
            ((kl.x / s).round() as i64, (kl.y / s).round() as i64, (right.keypoints[ir].x / s).round() as i64);
        let (w, h) = (li.width as i64, li.height as i64);
        let inside = |x: i64| x - WINDOW >= 0 && x + WINDOW < w;
        if !(inside(xl) && y - WINDOW >= 0 && y + WINDOW < h && inside(xr0 - SEARCH) && inside(xr0 + SEARCH)) {
            out.no_refinement += 1;
            continue;
        }
        let sads: Vec<u32> = (-SEARCH..=SEARCH).map(|dx| sad(li, ri, xl, xr0 + dx, y)).collect();
        let (bi, &best_cost) = sads.iter().enumerate().min_by_key(|(i, c)| (**c, *i)).unwrap_or((0, &u32::MAX));
        if bi == 0 || bi == sads.len() - 1 {
            out.no_refinement += 1;
            continue;
        }
        let (c1, c2, c3) = (f64::from(sads[bi - 1]), f64::from(sads[bi]), f64::from(sads[bi + 1]));
        let denom = 2.0 * (c1 + c3 - 2.0 * c2);
        let delta = if denom != 0.0 { (c1 - c3) / denom } else { 0.0 };
        if !(-1.0..=1.0).contains(&delta) {
            out.no_refinement += 1;
            continue;
        }
        let u_right = f64::from(s) * ((xr0 + bi as i64 - SEARCH) as f64 + delta);
        let mut disparity = f64::from(kl.x) - u_right;
        if !(disparity >= min_d && disparity < max_d) {
            out.out_of_range += 1;
            continue;
        }
        // A zero disparity (a point at infinity) is kept as very far, as ORB-SLAM2 does.
        let u_right = if disparity <= 0.0 {
            disparity = 0.01;
            f64::from(kl.x) - 0.01
        } else {
            u_right
        };
        out.matches[il] =
            Some(StereoMatch { u_right: u_right as f32, depth: (rig.bf / disparity) as f32, cost: best_cost });
        costs.push((best_cost, il));
    }
    // Drop the matches whose SAD is far above the median's.
    if !costs.is_empty() {
        costs.sort_unstable();
        let threshold = 1.5 * 1.4 * f64::from(costs[costs.len() / 2].0);
        for &(c, il) in costs.iter().rev() {
            // (ORB-SLAM2 drops a cost equal to the bound too, which drops every match of a
            // noise-free pair, whose median SAD is 0; here the bound itself is kept.)
            if f64::from(c) <= threshold {
                break;
            }
            out.matches[il] = None;
            out.high_cost += 1;
        }
    }
    Ok(out)
}

/// Whether a point of depth `z` is "close" in ORB-SLAM2's sense: nearer than `th_depth`
/// baselines (`ThDepth`, 40 in its stereo configurations), so its stereo depth is trusted for
/// creating map points from a single frame; far points are triangulated from two views.
pub fn is_close(z: f64, rig: &StereoRig, th_depth_baselines: f64) -> bool {
    z > 0.0 && z < th_depth_baselines * rig.baseline
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::orb::{OrbConfig, OrbExtractor};

    /// A textured image and the same image shifted left by `d` px (a fronto-parallel plane
    /// at disparity `d`), as the right camera sees it.
    fn pair(d: usize) -> (GrayImage, GrayImage) {
        let (w, h) = (320usize, 240usize);
        let tex = |x: usize, y: usize| {
            let v = (x * 7919 + y * 104_729) ^ (x * y * 31);
            (((v >> 3) & 0xFF) as u8 / 2) + (((x / 9 + y / 7) % 2) as u8 * 100)
        };
        // The right camera sees the left's column u at u - d.
        let left = GrayImage::from_vec(w, h, (0..w * h).map(|i| tex(i % w, i / w)).collect()).unwrap();
        let right = GrayImage::from_vec(w, h, (0..w * h).map(|i| tex(i % w + d, i / w)).collect()).unwrap();
        (left, right)
    }

    #[test]
    fn a_plane_at_one_disparity_gives_that_disparity_and_refuses_bad_rigs() {
        let (l, r) = pair(12);
        let mut orb = OrbExtractor::new(OrbConfig { features: 500, levels: 1, ..OrbConfig::default() });
        let fl = orb.extract(&l, None);
        let fr = orb.extract(&r, None);
        let (ll, rl) = ([&l], [&r]);
        let lv = StereoView { keypoints: &fl.keypoints, descriptors: &fl.descriptors, levels: &ll };
        let rv = StereoView { keypoints: &fr.keypoints, descriptors: &fr.descriptors, levels: &rl };
        let rig = StereoRig { bf: 40.0, baseline: 0.1, scale_factor: 1.2 };
        let m = stereo_match(&lv, &rv, &rig).unwrap();
        assert!(m.matched() > fl.keypoints.len() / 2, "{} of {}: {m:?}", m.matched(), fl.keypoints.len());
        for (k, s) in fl.keypoints.iter().zip(&m.matches) {
            if let Some(s) = s {
                assert!((k.x - s.u_right - 12.0).abs() < 0.5, "disparity {}", k.x - s.u_right);
                assert!((s.depth - 40.0 / 12.0).abs() < 0.2);
            }
        }
        let zero = StereoRig { baseline: 0.0, ..rig };
        assert!(matches!(stereo_match(&lv, &rv, &zero), Err(StereoError::Baseline { .. })));
        let small = GrayImage::new(100, 100);
        let sl = [&small];
        let rv = StereoView { levels: &sl, ..rv };
        assert!(matches!(stereo_match(&lv, &rv, &rig), Err(StereoError::SizeMismatch { .. })));
    }

    #[test]
    fn a_textureless_pair_matches_nothing() {
        let flat = GrayImage::from_vec(160, 120, vec![128; 160 * 120]).unwrap();
        let mut orb = OrbExtractor::new(OrbConfig::default());
        let f = orb.extract(&flat, None);
        let levels = [&flat];
        let v = StereoView { keypoints: &f.keypoints, descriptors: &f.descriptors, levels: &levels };
        let m = stereo_match(&v, &v, &StereoRig { bf: 40.0, baseline: 0.1, scale_factor: 1.2 }).unwrap();
        assert_eq!(m.matched(), 0);
    }
}
