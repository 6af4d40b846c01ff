//! Minimal and linear solvers for the fundamental matrix (Hartley & Zisserman, "Multiple View
//! Geometry", 2nd ed., sections 11.1-11.2), on Hartley-normalised coordinates.

use nalgebra::{Matrix3, SMatrix, SymmetricEigen, Vector3};

use super::Mat3;
use super::ransac::{Estimator, RansacConfig, Sampler, SplitMix64, ransac};

/// Similarity that moves the points' centroid to the origin and their mean distance from it
/// to sqrt(2). `None` when the points coincide (no scale to normalise).
pub(super) fn normaliser(points: &[[f64; 2]]) -> Option<Mat3> {
    let n = points.len() as f64;
    if points.is_empty() {
        return None;
    }
    let (cx, cy) = points.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0], y + p[1]));
    let (cx, cy) = (cx / n, cy / n);
    let mean = points.iter().map(|p| ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt()).sum::<f64>() / n;
    if !(mean > 1e-12 && mean.is_finite()) {
        return None;
    }
    let s = std::f64::consts::SQRT_2 / mean;
    Some(Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0))
}

fn apply(t: &Mat3, p: [f64; 2]) -> [f64; 2] {
    let v = t * Vector3::new(p[0], p[1], 1.0);
    [v.x / v.z, v.y / v.z]
}

/// The rows `x2^T F x1 = 0` as `A f = 0`, `f` the row-major entries of F; returns `A^T A`.
fn normal_matrix(p1: &[[f64; 2]], p2: &[[f64; 2]]) -> SMatrix<f64, 9, 9> {
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (a, b) in p1.iter().zip(p2) {
        let (x1, y1, x2, y2) = (a[0], a[1], b[0], b[1]);
        let row = SMatrix::<f64, 9, 1>::from_column_slice(&[x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, 1.0]);
        ata += row * row.transpose();
    }
    ata
}

/// Eigenvectors of a symmetric 9x9 matrix ordered by ascending eigenvalue.
fn smallest_eigenvectors(m: &SMatrix<f64, 9, 9>, count: usize) -> Vec<SMatrix<f64, 9, 1>> {
    let eig = SymmetricEigen::new(*m);
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    order.iter().take(count).map(|&i| eig.eigenvectors.column(i).into_owned()).collect()
}

fn to_mat(f: &SMatrix<f64, 9, 1>) -> Mat3 {
    Matrix3::new(f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8])
}

/// Scale to unit Frobenius norm with a positive last non-zero entry, so equal models compare
/// equal. `None` for a zero or non-finite matrix.
fn canonical(f: Mat3) -> Option<Mat3> {
    let n = f.norm();
    if !(n > 1e-300 && n.is_finite()) {
        return None;
    }
    let f = f / n;
    let sign = f.iter().rev().find(|v| v.abs() > 1e-12).map_or(1.0, |v| v.signum());
    Some(f * sign)
}

/// The normalised 8-point algorithm on `n >= 8` correspondences (least squares for more),
/// with rank 2 enforced. `None` for fewer than 8 points or degenerate configurations.
pub fn eight_point(p1: &[[f64; 2]], p2: &[[f64; 2]]) -> Option<Mat3> {
    if p1.len() < 8 || p1.len() != p2.len() {
        return None;
    }
    let (t1, t2) = (normaliser(p1)?, normaliser(p2)?);
    let n1: Vec<[f64; 2]> = p1.iter().map(|&p| apply(&t1, p)).collect();
    let n2: Vec<[f64; 2]> = p2.iter().map(|&p| apply(&t2, p)).collect();
    let f = smallest_eigenvectors(&normal_matrix(&n1, &n2), 1).first().map(to_mat)?;
    // Rank 2: zero the smallest singular value.
    let svd = f.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s = svd.singular_values;
    let (imin, _) = s.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    s[imin] = 0.0;
    let f = u * Matrix3::from_diagonal(&s) * v_t;
    canonical(t2.transpose() * f * t1)
}

/// Real roots of `a x^3 + b x^2 + c x + d` (degree drops when leading terms vanish).
pub(crate) fn real_roots_cubic(a: f64, b: f64, c: f64, d: f64) -> Vec<f64> {
    let scale = a.abs().max(b.abs()).max(c.abs()).max(d.abs());
    if scale == 0.0 || !scale.is_finite() {
        return Vec::new();
    }
    let (a, b, c, d) = (a / scale, b / scale, c / scale, d / scale);
    if a.abs() < 1e-12 {
        // Quadratic (or linear).
        if b.abs() < 1e-12 {
            return if c.abs() < 1e-12 { Vec::new() } else { vec![-d / c] };
        }
        let disc = c * c - 4.0 * b * d;
        if disc < 0.0 {
            return Vec::new();
        }
        let q = -0.5 * (c + c.signum() * disc.sqrt());
        let mut r = vec![q / b];
        if q.abs() > 1e-300 {
            r.push(d / q);
        }
        return r;
    }
    // Depressed cubic t^3 + p t + q with x = t - b / 3a.
    let (b, c, d) = (b / a, c / a, d / a);
    let p = c - b * b / 3.0;
    let q = 2.0 * b * b * b / 27.0 - b * c / 3.0 + d;
    let shift = -b / 3.0;
    let disc = q * q / 4.0 + p * p * p / 27.0;
    let mut roots = if disc > 0.0 {
        let s = disc.sqrt();
        vec![(-q / 2.0 + s).cbrt() + (-q / 2.0 - s).cbrt() + shift]
    } else if p.abs() < 1e-300 {
        vec![shift]
    } else {
        // Three real roots (trigonometric form).
        let r = (-p / 3.0).sqrt();
        let phi = (3.0 * q / (2.0 * p * r)).clamp(-1.0, 1.0).acos() / 3.0;
        (0..3).map(|k| 2.0 * r * (phi - 2.0 * std::f64::consts::PI * f64::from(k) / 3.0).cos() + shift).collect()
    };
    // One Newton step each: the closed forms lose digits near multiple roots.
    for x in &mut roots {
        let f = ((*x + b) * *x + c) * *x + d;
        let df = (3.0 * *x + 2.0 * b) * *x + c;
        if df.abs() > 1e-300 {
            *x -= f / df;
        }
    }
    roots
}

/// The 7-point algorithm: up to three fundamental matrices through exactly 7
/// correspondences (the real roots of `det(a F1 + (1 - a) F2) = 0`). Empty when degenerate.
pub fn seven_point(p1: &[[f64; 2]], p2: &[[f64; 2]]) -> Vec<Mat3> {
    if p1.len() != 7 || p2.len() != 7 {
        return Vec::new();
    }
    let (Some(t1), Some(t2)) = (normaliser(p1), normaliser(p2)) else { return Vec::new() };
    let n1: Vec<[f64; 2]> = p1.iter().map(|&p| apply(&t1, p)).collect();
    let n2: Vec<[f64; 2]> = p2.iter().map(|&p| apply(&t2, p)).collect();
    let null = smallest_eigenvectors(&normal_matrix(&n1, &n2), 2);
    let (Some(f1), Some(f2)) = (null.first().map(to_mat), null.get(1).map(to_mat)) else { return Vec::new() };
    // det(a F1 + (1 - a) F2) is a cubic in a: fit it from four samples.
    let det = |a: f64| (f1 * a + f2 * (1.0 - a)).determinant();
    let (d0, d1, dm, d2) = (det(0.0), det(1.0), det(-1.0), det(2.0));
    // p(a) = c3 a^3 + c2 a^2 + c1 a + c0.
    let c0 = d0;
    let c2 = (d1 + dm) / 2.0 - c0;
    let c3 = (d2 - 2.0 * d1 + d0 - 2.0 * c2) / 6.0;
    let c1 = d1 - c0 - c2 - c3;
    real_roots_cubic(c3, c2, c1, c0)
        .into_iter()
        .filter_map(|a| canonical(t2.transpose() * (f1 * a + f2 * (1.0 - a)) * t1))
        .collect()
}

/// Distance in pixels of `p2` from the epipolar line `F p1` (MG-SLAM's Eq. 4): how far a
/// point is from where a static point could be. Infinite for a degenerate line.
pub fn epipolar_distance(f: &Mat3, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let l = f * Vector3::new(p1[0], p1[1], 1.0);
    let n = (l.x * l.x + l.y * l.y).sqrt();
    if n > 0.0 { (l.x * p2[0] + l.y * p2[1] + l.z).abs() / n } else { f64::INFINITY }
}

/// The larger of the two point-to-epipolar-line distances (each point to the line of the
/// other), squared: OpenCV's residual for `findFundamalMat`'s RANSAC, so inlier sets agree.
pub fn epipolar_error(f: &Mat3, p1: [f64; 2], p2: [f64; 2]) -> f64 {
    let d2 = epipolar_distance(f, p1, p2);
    let d1 = epipolar_distance(&f.transpose(), p2, p1);
    d1.max(d2).powi(2)
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

/// F as a RANSAC estimator: 7-point minimal samples (up to three models each), the symmetric
/// epipolar distance as residual, the normalised 8-point solver as refit.
pub struct FundamentalEstimator<'a> {
    /// Points in the first view.
    pub p1: &'a [[f64; 2]],
    /// Their correspondences in the second.
    pub p2: &'a [[f64; 2]],
}

impl Estimator for FundamentalEstimator<'_> {
    type Model = Mat3;
    const SAMPLE_SIZE: usize = 7;
    fn len(&self) -> usize {
        self.p1.len()
    }
    fn fit(&self, sample: &[usize]) -> Vec<Mat3> {
        let (mut s1, mut s2) = ([[0.0; 2]; 7], [[0.0; 2]; 7]);
        for (k, &i) in sample.iter().enumerate().take(7) {
            (s1[k], s2[k]) = (self.p1[i], self.p2[i]);
        }
        seven_point(&s1, &s2)
    }
    fn residual(&self, f: &Mat3, i: usize) -> f64 {
        epipolar_error(f, self.p1[i], self.p2[i])
    }
    fn refit(&self, inliers: &[usize]) -> Option<Mat3> {
        let (a, b): (Vec<[f64; 2]>, Vec<[f64; 2]>) = inliers.iter().map(|&i| (self.p1[i], self.p2[i])).unzip();
        eight_point(&a, &b)
    }
}

/// Estimate F from correspondences `p1[i] <-> p2[i]` by LO-RANSAC ([`ransac`], uniform
/// samples; `config.threshold` in pixels from both epipolar lines). `None` with fewer than 8
/// points, a non-finite one, or when no sample gives a model.
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
    let c = ransac(&FundamentalEstimator { p1, p2 }, config, Sampler::Uniform, rng)?;
    Some(FundamentalFit { f: c.model, inliers: c.inliers, iterations: c.iterations })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    /// Exact correspondences of random 3-D points seen by two cameras (fx 500, 640x480).
    pub(crate) fn scene(n: usize, seed: u64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>, Mat3) {
        let mut rng = crate::geometry::SplitMix64::new(seed);
        let k = Matrix3::new(500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0);
        let r = Rotation3::from_euler_angles(0.05, -0.1, 0.03).into_inner();
        let t = Vector3::new(0.3, 0.05, 0.1);
        let (mut p1, mut p2) = (Vec::new(), Vec::new());
        while p1.len() < n {
            let x = Vector3::new(rng.uniform() * 4.0 - 2.0, rng.uniform() * 3.0 - 1.5, 3.0 + rng.uniform() * 5.0);
            let y = r * x + t;
            let (a, b) = (k * x, k * y);
            p1.push([a.x / a.z, a.y / a.z]);
            p2.push([b.x / b.z, b.y / b.z]);
        }
        let tx = Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0);
        let kinv = k.try_inverse().unwrap_or_else(Matrix3::identity);
        let f = canonical(kinv.transpose() * tx * r * kinv).unwrap_or_else(Matrix3::zeros);
        (p1, p2, f)
    }

    /// `max |x2^T F x1|` on Hartley-normalised coordinates, F scaled to unit norm there.
    fn normalised_residual(f: &Mat3, p1: &[[f64; 2]], p2: &[[f64; 2]]) -> f64 {
        let (t1, t2) = (normaliser(p1).unwrap(), normaliser(p2).unwrap());
        let fn_ = t2.try_inverse().unwrap().transpose() * f * t1.try_inverse().unwrap();
        let fn_ = fn_ / fn_.norm();
        p1.iter()
            .zip(p2)
            .map(|(a, b)| {
                let (a, b) = (apply(&t1, *a), apply(&t2, *b));
                (Vector3::new(b[0], b[1], 1.0).transpose() * fn_ * Vector3::new(a[0], a[1], 1.0))[0].abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn eight_point_is_exact_on_exact_correspondences() {
        let (p1, p2, truth) = scene(50, 1);
        let f = eight_point(&p1, &p2).unwrap();
        assert!(normalised_residual(&f, &p1, &p2) <= 1e-9, "{}", normalised_residual(&f, &p1, &p2));
        assert!((f - truth).norm() < 1e-6 || (f + truth).norm() < 1e-6, "{f}\n{truth}");
        assert!(f.determinant().abs() < 1e-12);
    }

    #[test]
    fn seven_point_finds_the_true_model_among_its_roots() {
        for seed in 0..20 {
            let (p1, p2, truth) = scene(7, seed);
            let fs = seven_point(&p1, &p2);
            assert!((1..=3).contains(&fs.len()), "seed {seed}: {} roots", fs.len());
            for f in &fs {
                assert!(normalised_residual(f, &p1, &p2) <= 1e-9, "seed {seed}");
                assert!(f.determinant().abs() < 1e-9 * f.norm().powi(3), "seed {seed}: rank 3");
            }
            assert!(fs.iter().any(|f| (f - truth).norm() < 1e-6), "seed {seed}");
        }
    }

    #[test]
    fn degenerate_input_gives_no_model_and_no_panic() {
        let (p1, p2, _) = scene(20, 3);
        // Fewer than the minimum.
        assert!(eight_point(&p1[..7], &p2[..7]).is_none());
        assert!(seven_point(&p1[..6], &p2[..6]).is_empty());
        // All points identical.
        let same = vec![[10.0, 20.0]; 12];
        assert!(eight_point(&same, &same).is_none());
        assert!(seven_point(&same[..7], &same[..7]).is_empty());
        // Collinear points and duplicates: whatever comes out is finite.
        let line: Vec<[f64; 2]> = (0..12).map(|i| [f64::from(i) * 10.0, f64::from(i) * 5.0 + 3.0]).collect();
        for f in eight_point(&line, &line).into_iter().chain(seven_point(&line[..7], &line[..7])) {
            assert!(f.iter().all(|v| v.is_finite()));
        }
        let dup: Vec<[f64; 2]> = p1.iter().take(4).chain(p1.iter().take(4)).copied().collect();
        let dup2: Vec<[f64; 2]> = p2.iter().take(4).chain(p2.iter().take(4)).copied().collect();
        if let Some(f) = eight_point(&dup, &dup2) {
            assert!(f.iter().all(|v| v.is_finite()));
        }
        // Mismatched lengths, NaN.
        assert!(eight_point(&p1, &p2[..10]).is_none());
        let nan = vec![[f64::NAN, 1.0]; 8];
        assert!(eight_point(&nan, &nan).is_none());
    }

    #[test]
    fn epipolar_distance_is_zero_on_the_line_and_grows_off_it() {
        let (p1, p2, f) = scene(10, 5);
        assert!(epipolar_distance(&f, p1[0], p2[0]) < 1e-6);
        let off = [p2[0][0] + 5.0, p2[0][1]];
        let d = epipolar_distance(&f, p1[0], off);
        assert!(d > 0.5 && d <= 5.0 + 1e-9, "{d}");
        assert!(epipolar_error(&f, p1[0], off) >= d * d - 1e-9);
    }

    #[test]
    fn cubic_roots() {
        // (x - 1)(x + 2)(x - 3) = x^3 - 2x^2 - 5x + 6.
        let mut r = real_roots_cubic(1.0, -2.0, -5.0, 6.0);
        r.sort_by(f64::total_cmp);
        assert_eq!(r.len(), 3);
        for (got, want) in r.iter().zip([-2.0, 1.0, 3.0]) {
            assert!((got - want).abs() < 1e-9, "{r:?}");
        }
        assert_eq!(real_roots_cubic(0.0, 0.0, 0.0, 1.0), Vec::<f64>::new());
        assert_eq!(real_roots_cubic(1.0, 0.0, 1.0, 0.0).len(), 1);
    }

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
