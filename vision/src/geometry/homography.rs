//! The homography between two views by PROSAC (Chum & Matas, "Matching with PROSAC",
//! CVPR 2005): samples drawn from progressively larger sets of the best-ranked
//! correspondences, so good matches are tried first; the 4-point normalised DLT as solver.

use nalgebra::{Matrix3, SMatrix, SymmetricEigen, Vector3};

use super::Mat3;
use super::fundamental::normaliser;
use super::ransac::{Estimator, RansacConfig, Sampler, SplitMix64, ransac};

/// Where `h` maps `p` (infinite when it maps to the line at infinity).
pub fn transfer(h: &Mat3, p: [f64; 2]) -> [f64; 2] {
    let v = h * Vector3::new(p[0], p[1], 1.0);
    if v.z.abs() < 1e-15 { [f64::INFINITY, f64::INFINITY] } else { [v.x / v.z, v.y / v.z] }
}

/// Transfer error `|H p1 - p2|`, pixels.
pub fn transfer_error(h: &Mat3, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let q = transfer(h, p1);
    ((q[0] - p2[0]).powi(2) + (q[1] - p2[1]).powi(2)).sqrt()
}

/// The normalised DLT on `n >= 4` correspondences (least squares for more). `None` when
/// degenerate (coincident or collinear points give no finite, invertible model).
pub fn homography_dlt(p1: &[[f64; 2]], p2: &[[f64; 2]]) -> Option<Mat3> {
    if p1.len() < 4 || p1.len() != p2.len() {
        return None;
    }
    let (t1, t2) = (normaliser(p1)?, normaliser(p2)?);
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (a, b) in p1.iter().zip(p2) {
        let a = t1 * Vector3::new(a[0], a[1], 1.0);
        let b = t2 * Vector3::new(b[0], b[1], 1.0);
        let (x, y, u, v) = (a.x / a.z, a.y / a.z, b.x / b.z, b.y / b.z);
        for row in [[-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u], [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v]] {
            let r = SMatrix::<f64, 9, 1>::from_column_slice(&row);
            ata += r * r.transpose();
        }
    }
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    let h = eig.eigenvectors.column(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let h = t2.try_inverse()? * hn * t1;
    let scale = h.norm();
    let h = h / scale;
    (h.iter().all(|v| v.is_finite()) && h.determinant().abs() > 1e-12).then_some(h)
}

/// A robustly estimated homography.
#[derive(Clone, Debug, PartialEq)]
pub struct HomographyFit {
    /// `p2 ~ H p1`, unit Frobenius norm.
    pub h: Mat3,
    /// Per correspondence: transfer error within the threshold.
    pub inliers: Vec<bool>,
    /// Samples drawn.
    pub iterations: usize,
}

/// The homography as a RANSAC estimator: 4-point samples, the transfer error as residual,
/// the normalised DLT on all inliers as refit.
pub struct HomographyEstimator<'a> {
    /// Points in the first view.
    pub p1: &'a [[f64; 2]],
    /// Their correspondences in the second.
    pub p2: &'a [[f64; 2]],
}

impl Estimator for HomographyEstimator<'_> {
    type Model = Mat3;
    const SAMPLE_SIZE: usize = 4;
    fn len(&self) -> usize {
        self.p1.len()
    }
    fn fit(&self, sample: &[usize]) -> Vec<Mat3> {
        let (a, b): (Vec<[f64; 2]>, Vec<[f64; 2]>) = sample.iter().map(|&i| (self.p1[i], self.p2[i])).unzip();
        homography_dlt(&a, &b).into_iter().collect()
    }
    fn residual(&self, h: &Mat3, i: usize) -> f64 {
        transfer_error(h, self.p1[i], self.p2[i]).powi(2)
    }
    fn refit(&self, inliers: &[usize]) -> Option<Mat3> {
        let (a, b): (Vec<[f64; 2]>, Vec<[f64; 2]>) = inliers.iter().map(|&i| (self.p1[i], self.p2[i])).unzip();
        homography_dlt(&a, &b)
    }
}

/// PROSAC ([`ransac`] with [`Sampler::prosac`]): `quality[i]` ranks correspondence `i` (higher
/// is better; PSPNet-SLAM's `1 / (beta * d_min)`). Inliers have a transfer error within
/// `config.threshold` pixels. `None` with fewer than 4 correspondences or no usable sample.
pub fn fit_homography_prosac(
    p1: &[[f64; 2]],
    p2: &[[f64; 2]],
    quality: &[f64],
    config: &RansacConfig,
    rng: &mut SplitMix64,
) -> Option<HomographyFit> {
    if p2.len() != p1.len() || quality.len() != p1.len() {
        return None;
    }
    let c = ransac(&HomographyEstimator { p1, p2 }, config, Sampler::prosac(quality), rng)?;
    Some(HomographyFit { h: c.model, inliers: c.inliers, iterations: c.iterations })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth() -> Mat3 {
        Matrix3::new(1.02, 0.03, 5.0, -0.02, 0.98, -3.0, 1e-5, -2e-5, 1.0)
    }

    #[test]
    fn dlt_is_exact_and_prosac_rejects_outliers() {
        let h = truth();
        let mut rng = SplitMix64::new(3);
        let p1: Vec<[f64; 2]> = (0..100).map(|_| [rng.uniform() * 640.0, rng.uniform() * 480.0]).collect();
        let mut p2: Vec<[f64; 2]> = p1.iter().map(|&p| transfer(&h, p)).collect();
        let est = homography_dlt(&p1, &p2).unwrap();
        for (a, b) in p1.iter().zip(&p2) {
            assert!(transfer_error(&est, *a, *b) < 1e-6);
        }
        // 40 % outliers, ranked last by quality.
        for p in p2.iter_mut().skip(60) {
            *p = [rng.uniform() * 640.0, rng.uniform() * 480.0];
        }
        let quality: Vec<f64> = (0..100).map(|i| if i < 60 { 1.0 - i as f64 * 1e-3 } else { 0.1 }).collect();
        let fit = fit_homography_prosac(
            &p1,
            &p2,
            &quality,
            &RansacConfig { threshold: 1.0, max_iterations: 500, ..RansacConfig::default() },
            &mut SplitMix64::new(1),
        )
        .unwrap();
        assert_eq!(fit.inliers.iter().take(60).filter(|&&i| i).count(), 60);
        assert!(fit.inliers.iter().skip(60).filter(|&&i| i).count() <= 2);
        // Good ones ranked first: found within a few samples.
        assert!(fit.iterations <= 50, "{}", fit.iterations);
    }

    #[test]
    fn degenerate_input_gives_no_model() {
        let same = vec![[1.0, 1.0]; 10];
        assert!(homography_dlt(&same, &same).is_none());
        assert!(homography_dlt(&same[..3], &same[..3]).is_none());
        let line: Vec<[f64; 2]> = (0..10).map(|i| [f64::from(i), 2.0 * f64::from(i)]).collect();
        assert!(homography_dlt(&line, &line).is_none_or(|h| h.iter().all(|v| v.is_finite())));
        assert!(
            fit_homography_prosac(
                &same,
                &same,
                &[1.0; 10],
                &RansacConfig { threshold: 1.0, max_iterations: 50, ..RansacConfig::default() },
                &mut SplitMix64::new(0)
            )
            .is_none()
        );
    }
}
