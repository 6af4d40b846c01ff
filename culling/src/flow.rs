//! Flow consistency: a track's residual against the frame's dominant homography.

use super::*;

/// The camera-induced motion as a homography by PROSAC, ranked by `quality` (PSPNet-SLAM's
/// `1 / (beta * d_min)`; here `1 / (1 + error)` of each track), and every point's transfer
/// error `|H p1 - p2|` in pixels.
pub fn homography_residuals(
    prev: &[[f32; 2]],
    cur: &[[f32; 2]],
    quality: &[f64],
    threshold: f64,
    seed: u64,
) -> Option<(HomographyFit, Vec<f32>)> {
    let (p1, p2) = (to64(prev), to64(cur));
    let config = RansacConfig { threshold, local_optimisation: false, ..RansacConfig::default() };
    let fit = fit_homography_prosac(&p1, &p2, quality, &config, &mut SplitMix64::new(seed))?;
    let r = p1.iter().zip(&p2).map(|(a, b)| transfer_error(&fit.h, *a, *b) as f32).collect();
    Some((fit, r))
}

/// PSPNet-SLAM's first screening: dynamic where the track disagrees with the camera-induced
/// motion (residual in pixels from the homography or the epipolar line) by more than
/// `threshold`.
pub fn flow_consistency(residuals: &[f32], threshold: f32) -> Vec<Decision> {
    residuals
        .iter()
        .map(|&r| {
            let dynamic = exceeds(r, threshold);
            Decision { dynamic, reason: if dynamic { LabelReason::Flow } else { LabelReason::Static }, score: r }
        })
        .collect()
}
