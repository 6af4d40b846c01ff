//! LO-RANSAC for the fundamental matrix: 7-point minimal samples, an adaptive iteration
//! count, and a local optimisation (8-point refit on the inliers, repeated while it gains)
//! whenever a sample beats the best model so far (Chum, Matas & Kittler, DAGM 2003).

use super::Mat3;
use super::fundamental::{eight_point, epipolar_error, seven_point};

pub use dynaflow_msg::rng::SplitMix64;

/// RANSAC settings; the defaults are OpenCV's `findFundamentalMat(FM_RANSAC)` ones.
#[derive(Clone, Debug, PartialEq)]
pub struct RansacConfig {
    /// Inlier threshold on the distance to the epipolar lines, pixels.
    pub threshold: f64,
    /// Probability that at least one sample is all inliers when the loop stops.
    pub confidence: f64,
    /// Iterations at most.
    pub max_iterations: usize,
    /// Refit on the inliers of every new best model.
    pub local_optimisation: bool,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self { threshold: 1.0, confidence: 0.99, max_iterations: 1000, local_optimisation: true }
    }
}

/// A robustly estimated fundamental matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct FundamentalFit {
    /// F with `x2^T F x1 = 0`, unit Frobenius norm.
    pub f: Mat3,
    /// Per correspondence: within the threshold of both epipolar lines.
    pub inliers: Vec<bool>,
    /// Samples drawn.
    pub iterations: usize,
}

impl FundamentalFit {
    /// Number of inliers.
    pub fn inlier_count(&self) -> usize {
        self.inliers.iter().filter(|&&i| i).count()
    }
}

/// Inlier count and summed (truncated) error of `f`.
fn score(f: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]], thr2: f64) -> (usize, f64) {
    let mut n = 0;
    let mut cost = 0.0;
    for (a, b) in p1.iter().zip(p2) {
        let e = epipolar_error(f, *a, *b);
        if e <= thr2 {
            n += 1;
            cost += e;
        } else {
            cost += thr2;
        }
    }
    (n, cost)
}

fn inlier_points(f: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]], thr2: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
    p1.iter().zip(p2).filter(|(a, b)| epipolar_error(f, **a, **b) <= thr2).map(|(a, b)| (*a, *b)).unzip()
}

/// RANSAC's adaptive stopping rule: iterations needed so that, with inlier ratio `w`, an
/// all-inlier sample of `sample` points was drawn with probability `confidence` (at most
/// `cap`; 1 when every point is an inlier).
pub(super) fn needed(w: f64, sample: usize, confidence: f64, cap: usize) -> usize {
    let p_good = w.powi(i32::try_from(sample).unwrap_or(i32::MAX));
    if p_good <= 0.0 {
        return cap;
    }
    if p_good >= 1.0 {
        return 1;
    }
    let n = (1.0 - confidence).ln() / (1.0 - p_good).ln();
    if n.is_finite() { (n.ceil() as usize).clamp(1, cap) } else { cap }
}

/// Estimate F from correspondences `p1[i] <-> p2[i]`. `None` with fewer than 8 points or when
/// no sample gives a model.
pub fn fit_fundamental(
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    config: &RansacConfig,
    rng: &mut SplitMix64,
) -> Option<FundamentalFit> {
    let n = p1.len();
    if n < 8 || p2.len() != n || p1.iter().chain(p2).any(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return None;
    }
    let thr2 = config.threshold * config.threshold;
    let mut best: Option<(Mat3, usize, f64)> = None;
    let mut limit = config.max_iterations.max(1);
    let mut iterations = 0;
    let (mut s1, mut s2) = ([[0.0; 2]; 7], [[0.0; 2]; 7]);
    let mut idx = [0usize; 7];
    while iterations < limit {
        iterations += 1;
        // Seven distinct indices.
        for k in 0..7 {
            loop {
                let i = rng.below(n);
                if !idx[..k].contains(&i) {
                    idx[k] = i;
                    break;
                }
            }
            s1[k] = p1[idx[k]];
            s2[k] = p2[idx[k]];
        }
        for f in seven_point(&s1, &s2) {
            let (count, cost) = score(&f, p1, p2, thr2);
            let better = best.as_ref().is_none_or(|b| count > b.1 || (count == b.1 && cost < b.2));
            if !better {
                continue;
            }
            let mut cand = (f, count, cost);
            if config.local_optimisation {
                // Refit on the inliers while that gains inliers (at most 4 rounds).
                for _ in 0..4 {
                    let (i1, i2) = inlier_points(&cand.0, p1, p2, thr2);
                    let Some(g) = eight_point(&i1, &i2) else { break };
                    let (c, e) = score(&g, p1, p2, thr2);
                    if c > cand.1 || (c == cand.1 && e < cand.2) {
                        cand = (g, c, e);
                    } else {
                        break;
                    }
                }
            }
            limit = needed(cand.1 as f64 / n as f64, 7, config.confidence, config.max_iterations.max(1));
            best = Some(cand);
        }
    }
    let (mut f, mut count, _) = best?;
    // Final least-squares refit on all inliers, kept if it is at least as good.
    let (i1, i2) = inlier_points(&f, p1, p2, thr2);
    if let Some(g) = eight_point(&i1, &i2) {
        let (c, _) = score(&g, p1, p2, thr2);
        if c >= count {
            f = g;
            count = c;
        }
    }
    let inliers: Vec<bool> = p1.iter().zip(p2).map(|(a, b)| epipolar_error(&f, *a, *b) <= thr2).collect();
    debug_assert_eq!(inliers.iter().filter(|&&i| i).count(), count);
    Some(FundamentalFit { f, inliers, iterations })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::fundamental::tests::scene;

    #[test]
    fn finds_the_inliers_among_outliers_and_is_reproducible() {
        let (mut p1, mut p2, _) = scene(200, 9);
        let mut rng = SplitMix64::new(77);
        // 30 % gross outliers.
        for p in p2.iter_mut().take(60) {
            *p = [rng.uniform() * 640.0, rng.uniform() * 480.0];
        }
        // Half a pixel of noise on the rest.
        for p in p1.iter_mut().chain(p2.iter_mut().skip(60)) {
            p[0] += rng.uniform() - 0.5;
            p[1] += rng.uniform() - 0.5;
        }
        let config = RansacConfig { threshold: 2.0, ..RansacConfig::default() };
        let fit = fit_fundamental(&p1, &p2, &config, &mut SplitMix64::new(1)).unwrap();
        let found_good = fit.inliers.iter().skip(60).filter(|&&i| i).count();
        let found_bad = fit.inliers.iter().take(60).filter(|&&i| i).count();
        assert!(found_good >= 135, "{found_good} of 140 inliers");
        assert!(found_bad <= 6, "{found_bad} outliers accepted");
        assert!(fit.iterations < config.max_iterations, "adaptive stop: {}", fit.iterations);
        let again = fit_fundamental(&p1, &p2, &config, &mut SplitMix64::new(1)).unwrap();
        assert_eq!(fit, again);
    }

    #[test]
    fn too_few_or_bad_points_give_no_model() {
        let (p1, p2, _) = scene(7, 2);
        assert!(fit_fundamental(&p1, &p2, &RansacConfig::default(), &mut SplitMix64::new(0)).is_none());
        let same = vec![[5.0, 5.0]; 30];
        assert!(fit_fundamental(&same, &same, &RansacConfig::default(), &mut SplitMix64::new(0)).is_none());
        let mut bad = scene(20, 2).0;
        bad[3] = [f64::NAN, 0.0];
        assert!(fit_fundamental(&bad, &bad, &RansacConfig::default(), &mut SplitMix64::new(0)).is_none());
    }
}
