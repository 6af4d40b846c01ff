//! One RANSAC driver for every robust fit in the workspace (the shape kornia-rs uses): an
//! [`Estimator`] says what a minimal sample is, how a model is fitted from one, how far a
//! correspondence is from a model, and how a model is refitted on many; a [`Sampler`] draws
//! the samples (uniform, or PROSAC's best-ranked-first); [`ransac`] runs the loop under one
//! [`RansacConfig`] and returns the [`Consensus`].
//!
//! The loop is MSAC-scored LO-RANSAC (Torr & Zisserman 2000; Chum, Matas & Kittler, DAGM
//! 2003): a model is better with more inliers, or as many with a smaller summed residual
//! (each truncated at the threshold); each new best model is refitted on its inliers while
//! that gains (`local_optimisation`); the iteration count adapts to the best inlier ratio
//! (the stopping rule for `confidence`); a final refit on all inliers is kept if it is at least
//! as good. Deterministic from the generator it is given; each call site derives its generator
//! by name ([`SplitMix64::named`]).

pub use dynaflow_base::rng::SplitMix64;

/// RANSAC settings, one type for every estimator; the defaults are OpenCV's
/// `findFundamentalMat(FM_RANSAC)` ones.
#[derive(Clone, Debug, PartialEq)]
pub struct RansacConfig {
    /// Inlier threshold, in the estimator's unit (pixels for every image-space residual).
    pub threshold: f64,
    /// Probability that at least one sample is all inliers when the loop stops early (the
    /// adaptive stopping rule; 1 runs every iteration).
    pub confidence: f64,
    /// Iterations at most.
    pub max_iterations: usize,
    /// Refit on the inliers of every new best model, while that gains (LO-RANSAC).
    pub local_optimisation: bool,
}

impl Default for RansacConfig {
    fn default() -> Self {
        Self { threshold: 1.0, confidence: 0.99, max_iterations: 1000, local_optimisation: true }
    }
}

/// A model family RANSAC can fit.
pub trait Estimator {
    /// The fitted model.
    type Model: Clone;
    /// Correspondences in a minimal sample.
    const SAMPLE_SIZE: usize;
    /// Correspondences in all.
    fn len(&self) -> usize;
    /// Whether there are none.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The models a minimal sample gives (none when degenerate; the 7-point solver gives up to
    /// three). `sample` holds [`Estimator::SAMPLE_SIZE`] distinct indices.
    fn fit(&self, sample: &[usize]) -> Vec<Self::Model>;
    /// Correspondence `i`'s squared residual under `model`, in the threshold's unit squared
    /// (an inlier has `residual <= threshold^2`).
    fn residual(&self, model: &Self::Model, i: usize) -> f64;
    /// A model fitted on many correspondences (least squares), for local optimisation and the
    /// final refit; `None` when the estimator has none or it fails.
    fn refit(&self, _inliers: &[usize]) -> Option<Self::Model> {
        None
    }
}

/// The robust fit: the model, which correspondences agree with it, and how long it took.
#[derive(Clone, Debug, PartialEq)]
pub struct Consensus<M> {
    /// The best model.
    pub model: M,
    /// Per correspondence: within the threshold.
    pub inliers: Vec<bool>,
    /// Number of inliers.
    pub count: usize,
    /// Samples drawn.
    pub iterations: usize,
}

/// How samples are drawn.
#[derive(Clone, Debug)]
pub enum Sampler {
    /// Uniformly, `SAMPLE_SIZE` distinct indices.
    Uniform,
    /// PROSAC (Chum & Matas, CVPR 2005): from progressively larger sets of the best-ranked
    /// correspondences, so good matches are tried first.
    Prosac(Prosac),
}

/// PROSAC's ranking and growth schedule.
#[derive(Clone, Debug)]
pub struct Prosac {
    /// Indices, best first.
    order: Vec<usize>,
    subset: usize,
    t_prime: usize,
    t_n: f64,
}

impl Sampler {
    /// PROSAC over `quality` (higher is better; ties keep index order).
    pub fn prosac(quality: &[f64]) -> Self {
        let mut order: Vec<usize> = (0..quality.len()).collect();
        order.sort_by(|&a, &b| quality[b].total_cmp(&quality[a]).then(a.cmp(&b)));
        Sampler::Prosac(Prosac { order, subset: 0, t_prime: 0, t_n: 0.0 })
    }

    /// Set up for `n` correspondences, samples of `m`, at most `max_iterations`.
    fn start(&mut self, n: usize, m: usize, max_iterations: usize) {
        if let Sampler::Prosac(p) = self {
            // T_n: the expected number of samples drawn from the top n.
            let mut t_n = max_iterations.max(1) as f64;
            for i in 0..m {
                t_n *= (m - i) as f64 / (n - i) as f64;
            }
            (p.subset, p.t_prime, p.t_n) = (m, 1, t_n);
        }
    }

    /// Draw sample number `iteration` (from 1) into `out` (`m = out.len()` distinct indices).
    fn draw(&mut self, iteration: usize, n: usize, rng: &mut SplitMix64, out: &mut [usize]) {
        let m = out.len();
        match self {
            Sampler::Uniform => {
                for k in 0..m {
                    loop {
                        let i = rng.below(n);
                        if !out[..k].contains(&i) {
                            out[k] = i;
                            break;
                        }
                    }
                }
            }
            Sampler::Prosac(p) => {
                if iteration == p.t_prime && p.subset < n {
                    // Grow the pool by the next-best correspondence.
                    let t_next = p.t_n * (p.subset + 1) as f64 / (p.subset + 1 - m) as f64;
                    p.t_prime += (t_next - p.t_n).ceil().max(1.0) as usize;
                    p.t_n = t_next;
                    p.subset += 1;
                }
                // m - 1 points from the top `subset - 1`, plus the `subset`-th.
                out[m - 1] = p.order[p.subset - 1];
                for k in 0..m - 1 {
                    loop {
                        let i = p.order[rng.below(p.subset.saturating_sub(1).max(1))];
                        if !out[..k].contains(&i) && i != out[m - 1] {
                            out[k] = i;
                            break;
                        }
                        if p.subset <= m {
                            // Only the top m exist: take them in order.
                            out[k] = p.order[k];
                            break;
                        }
                    }
                }
            }
        }
    }
}

/// RANSAC's adaptive stopping rule: iterations needed so that, with inlier ratio `w`, an
/// all-inlier sample of `sample` points was drawn with probability `confidence` (at most
/// `cap`; 1 when every point is an inlier).
pub fn needed(w: f64, sample: usize, confidence: f64, cap: usize) -> usize {
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

/// Inlier count and summed truncated residual (MSAC's score) of `model`.
fn score<E: Estimator>(est: &E, model: &E::Model, thr2: f64) -> (usize, f64) {
    let mut n = 0;
    let mut cost = 0.0;
    for i in 0..est.len() {
        let e = est.residual(model, i);
        if e <= thr2 {
            n += 1;
            cost += e;
        } else {
            cost += thr2;
        }
    }
    (n, cost)
}

fn inlier_indices<E: Estimator>(est: &E, model: &E::Model, thr2: f64) -> Vec<usize> {
    (0..est.len()).filter(|&i| est.residual(model, i) <= thr2).collect()
}

/// The consensus of `est`'s correspondences, or `None` with fewer than a minimal sample or
/// when no sample gives a model.
pub fn ransac<E: Estimator>(
    est: &E,
    config: &RansacConfig,
    mut sampler: Sampler,
    rng: &mut SplitMix64,
) -> Option<Consensus<E::Model>> {
    let n = est.len();
    let m = E::SAMPLE_SIZE;
    if n < m || m == 0 {
        return None;
    }
    let thr2 = config.threshold * config.threshold;
    let cap = config.max_iterations.max(1);
    sampler.start(n, m, cap);
    let mut best: Option<(E::Model, usize, f64)> = None;
    let mut limit = cap;
    let mut iterations = 0;
    let mut sample = vec![0usize; m];
    while iterations < limit {
        iterations += 1;
        sampler.draw(iterations, n, rng, &mut sample);
        for model in est.fit(&sample) {
            let (count, cost) = score(est, &model, thr2);
            if !best.as_ref().is_none_or(|b| count > b.1 || (count == b.1 && cost < b.2)) {
                continue;
            }
            let mut cand = (model, count, cost);
            if config.local_optimisation {
                // Refit on the inliers while that gains (at most 4 rounds).
                for _ in 0..4 {
                    let Some(g) = est.refit(&inlier_indices(est, &cand.0, thr2)) else { break };
                    let (c, e) = score(est, &g, thr2);
                    if c > cand.1 || (c == cand.1 && e < cand.2) {
                        cand = (g, c, e);
                    } else {
                        break;
                    }
                }
            }
            limit = limit.min(needed(cand.1 as f64 / n as f64, m, config.confidence, cap));
            best = Some(cand);
        }
    }
    let (mut model, count, _) = best?;
    // A final least-squares refit on all inliers, kept if it is at least as good.
    if let Some(g) = est.refit(&inlier_indices(est, &model, thr2))
        && score(est, &g, thr2).0 >= count
    {
        model = g;
    }
    let inliers: Vec<bool> = (0..n).map(|i| est.residual(&model, i) <= thr2).collect();
    let count = inliers.iter().filter(|&&i| i).count();
    Some(Consensus { model, inliers, count, iterations })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line `y = a x + b` through 2-point samples: the smallest estimator there is.
    struct Line<'a>(&'a [[f64; 2]]);

    impl Estimator for Line<'_> {
        type Model = (f64, f64);
        const SAMPLE_SIZE: usize = 2;
        fn len(&self) -> usize {
            self.0.len()
        }
        fn fit(&self, s: &[usize]) -> Vec<(f64, f64)> {
            let (p, q) = (self.0[s[0]], self.0[s[1]]);
            if (q[0] - p[0]).abs() < 1e-12 {
                return Vec::new();
            }
            let a = (q[1] - p[1]) / (q[0] - p[0]);
            vec![(a, p[1] - a * p[0])]
        }
        fn residual(&self, (a, b): &(f64, f64), i: usize) -> f64 {
            (self.0[i][1] - a * self.0[i][0] - b).powi(2)
        }
    }

    fn points() -> Vec<[f64; 2]> {
        let mut rng = SplitMix64::new(3);
        (0..100)
            .map(|i| {
                let x = i as f64;
                // Every fourth point an outlier.
                if i % 4 == 0 { [x, rng.uniform() * 500.0] } else { [x, 2.0 * x + 1.0 + 0.1 * (rng.uniform() - 0.5)] }
            })
            .collect()
    }

    #[test]
    fn the_driver_finds_the_line_and_stops_early() {
        let p = points();
        let config = RansacConfig { threshold: 0.5, ..RansacConfig::default() };
        let fit = ransac(&Line(&p), &config, Sampler::Uniform, &mut SplitMix64::named(1, "test")).unwrap();
        assert!((fit.model.0 - 2.0).abs() < 0.01 && (fit.model.1 - 1.0).abs() < 0.5, "{:?}", fit.model);
        assert_eq!(fit.count, 75, "the 75 points on the line");
        assert_eq!(fit.count, fit.inliers.iter().filter(|&&i| i).count());
        assert!(fit.iterations < 30, "adaptive stop at 75 % inliers: {} iterations", fit.iterations);
        // PROSAC with the inliers ranked first needs fewer samples still.
        let quality: Vec<f64> = (0..100).map(|i| if i % 4 == 0 { 0.0 } else { 1.0 }).collect();
        let pro = ransac(&Line(&p), &config, Sampler::prosac(&quality), &mut SplitMix64::named(1, "test")).unwrap();
        assert_eq!(pro.count, 75);
        assert!(pro.iterations <= fit.iterations, "{} vs {}", pro.iterations, fit.iterations);
    }

    #[test]
    fn too_few_points_give_no_consensus() {
        let p = [[0.0, 1.0]];
        assert!(ransac(&Line(&p), &RansacConfig::default(), Sampler::Uniform, &mut SplitMix64::new(0)).is_none());
    }

    #[test]
    fn the_stopping_rule_follows_the_inlier_ratio() {
        // 50 % inliers, 7-point samples, 99 %: log(0.01) / log(1 - 0.5^7) = 587.2.
        assert_eq!(needed(0.5, 7, 0.99, 10_000), 588);
        assert_eq!(needed(1.0, 7, 0.99, 10_000), 1);
        assert_eq!(needed(0.0, 7, 0.99, 500), 500);
    }
}
