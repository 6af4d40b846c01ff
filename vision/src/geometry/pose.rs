//! Pinhole pose from 3-D points and their images (PnP), as ORB-SLAM's tracking needs it:
//! a linear DLT for initial poses inside RANSAC, then motion-only bundle adjustment
//! (Levenberg-Marquardt on SE(3), Huber kernel, analytic Jacobians, inliers re-classified
//! over four rounds as ORB-SLAM's `PoseOptimization` does).

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, SMatrix, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};

use super::p3p::p3p;
use super::ransac::{Estimator, RansacConfig, Sampler, SplitMix64, ransac};
use crate::camera::Pinhole;

/// Levenberg-Marquardt's damping as the pose optimisers here use it (Marquardt's: `λ` times
/// the normal matrix's diagonal, floored at 1e-9): `λ` starts at 1e-3, falls by 0.3 after an
/// accepted step and rises tenfold after a rejected one; the iteration ends when an accepted
/// step is shorter than the caller's tolerance or `λ` passes 1e8.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmDamping {
    lambda: f64,
}

impl Default for LmDamping {
    fn default() -> Self {
        Self { lambda: 1e-3 }
    }
}

impl LmDamping {
    /// `h` with `λ · max(h_kk, 1e-9)` added to each diagonal element.
    pub fn damped<D: nalgebra::Dim, S: nalgebra::Storage<f64, D, D>>(
        &self,
        h: &nalgebra::Matrix<f64, D, D, S>,
    ) -> nalgebra::OMatrix<f64, D, D>
    where
        nalgebra::DefaultAllocator: nalgebra::allocator::Allocator<D, D>,
    {
        let mut damped = h.clone_owned();
        for k in 0..h.nrows() {
            damped[(k, k)] += self.lambda * h[(k, k)].max(1e-9);
        }
        damped
    }

    /// After a trial step of length `step_norm`, accepted (its cost fell) or not: whether to
    /// go on iterating.
    pub fn next(&mut self, accepted: bool, step_norm: f64, tolerance: f64) -> bool {
        if accepted {
            self.lambda = (self.lambda * 0.3).max(1e-9);
            step_norm >= tolerance
        } else {
            self.lambda *= 10.0;
            self.lambda <= 1e8
        }
    }
}

/// Chi-square 95 % quantile for 2 degrees of freedom: ORB-SLAM's inlier test on squared
/// reprojection errors in units of the measurement's sigma.
pub const CHI2_2DOF_95: f64 = 5.991;

/// `cam_from_world` by the direct linear transform on `n >= 6` correspondences, the rotation
/// projected onto SO(3). `None` when degenerate (coplanar or collinear points can defeat it).
pub fn pnp_dlt(world: &[Point3<f64>], pixels: &[[f64; 2]], cam: &Pinhole) -> Option<Isometry3<f64>> {
    if world.len() < 6 || world.len() != pixels.len() {
        return None;
    }
    // Normalise the 3-D points (centroid, mean distance sqrt(3)) for conditioning.
    let n = world.len() as f64;
    let c = world.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    let s = world.iter().map(|p| (p.coords - c).norm()).sum::<f64>() / n;
    if !(s > 1e-12 && s.is_finite()) {
        return None;
    }
    let k = 3f64.sqrt() / s;
    let mut ata = SMatrix::<f64, 12, 12>::zeros();
    for (p, uv) in world.iter().zip(pixels) {
        let q = (p.coords - c) * k;
        let [x, y] = cam.normalised(*uv);
        let r1 = SMatrix::<f64, 12, 1>::from_column_slice(&[
            q.x,
            q.y,
            q.z,
            1.0,
            0.0,
            0.0,
            0.0,
            0.0,
            -x * q.x,
            -x * q.y,
            -x * q.z,
            -x,
        ]);
        let r2 = SMatrix::<f64, 12, 1>::from_column_slice(&[
            0.0,
            0.0,
            0.0,
            0.0,
            q.x,
            q.y,
            q.z,
            1.0,
            -y * q.x,
            -y * q.y,
            -y * q.z,
            -y,
        ]);
        ata += r1 * r1.transpose() + r2 * r2.transpose();
    }
    let eig = SymmetricEigen::new(ata);
    let (imin, _) = eig.eigenvalues.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    let v = eig.eigenvectors.column(imin);
    let m = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
    let mut t = Vector3::new(v[3], v[7], v[11]);
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let scale = svd.singular_values.mean();
    if scale.is_nan() || scale <= 1e-12 {
        return None;
    }
    let mut r = u * vt;
    t /= scale;
    if r.determinant() < 0.0 {
        r = -r;
        t = -t;
    }
    // Points in front of the camera: flip the solution's sign if most are behind.
    let in_front = world.iter().filter(|p| (r * ((p.coords - c) * k) + t).z > 0.0).count();
    if in_front * 2 < world.len() {
        return None;
    }
    // Undo the normalisation: the DLT saw q = k (X - c), so k X_cam = R q + t and
    // X_cam = R X + (t / k - R c).
    let rot = Rotation3::from_matrix_unchecked(r);
    let trans = t / k - r * c;
    Some(Isometry3::from_parts(Translation3::from(trans), UnitQuaternion::from_rotation_matrix(&rot)))
}

/// SE(3) exponential of `xi = (rho, phi)` (translation first), as a pose increment.
pub fn exp_se3(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rho = Vector3::new(xi[0], xi[1], xi[2]);
    let phi = Vector3::new(xi[3], xi[4], xi[5]);
    let theta = phi.norm();
    let rot = UnitQuaternion::from_scaled_axis(phi);
    let v = if theta < 1e-10 {
        Matrix3::identity() + 0.5 * phi.cross_matrix()
    } else {
        let a = phi.cross_matrix();
        Matrix3::identity()
            + (1.0 - theta.cos()) / (theta * theta) * a
            + (theta - theta.sin()) / (theta.powi(3)) * a * a
    };
    Isometry3::from_parts(Translation3::from(v * rho), rot)
}

/// `exp(xi) * pose` with the rotation renormalised: products of unit quaternions drift off
/// the unit sphere, and composed frame after frame the drift grows geometrically.
pub fn compose(xi: &Vector6<f64>, pose: &Isometry3<f64>) -> Isometry3<f64> {
    renormalised(&(exp_se3(xi) * pose))
}

/// `pose` with its quaternion scaled back to unit length.
pub fn renormalised(pose: &Isometry3<f64>) -> Isometry3<f64> {
    let mut p = *pose;
    p.rotation.renormalize();
    p
}

/// Motion-only bundle adjustment result.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFit {
    /// The camera's pose, `cam_from_world`.
    pub cam_from_world: Isometry3<f64>,
    /// Per correspondence: reprojection error within the chi-square bound at the end.
    pub inliers: Vec<bool>,
    /// Reprojection error per correspondence, pixels.
    pub errors: Vec<f64>,
}

/// Chi-square 95 % quantile for 3 degrees of freedom: the bound for an RGB-D observation
/// (pixel plus virtual right-image coordinate), as ORB-SLAM2 uses it.
pub const CHI2_3DOF_95: f64 = 7.815;

/// One 3-D point and where it was seen, for [`optimize_pose`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseObservation {
    /// World point.
    pub point: Point3<f64>,
    /// Observed pixel.
    pub uv: [f64; 2],
    /// Standard deviation of the observation, pixels (ORB-SLAM: 1.2^octave).
    pub sigma: f64,
    /// Measured depth (metres) of the observation, when the sensor gives one: it becomes
    /// ORB-SLAM2's RGB-D virtual right coordinate `u - bf / depth`.
    pub depth: Option<f64>,
}

/// Residual and Jacobian (left SE(3) perturbation, translation first) of one observation:
/// rows 0-1 for the pixel, row 2 for the virtual right coordinate `u - bf / z` when the
/// observation has a depth and `bf > 0` (zero otherwise). `None` behind the camera.
pub fn observation_jacobian(
    cam: &Pinhole,
    bf: f64,
    pc: &Point3<f64>,
    obs: &PoseObservation,
) -> Option<(Vector3<f64>, SMatrix<f64, 3, 6>)> {
    let uv = cam.project(pc)?;
    let (x, y, z) = (pc.x, pc.y, pc.z);
    let (iz, iz2) = (1.0 / z, 1.0 / (z * z));
    let mut r = Vector3::new(uv[0] - obs.uv[0], uv[1] - obs.uv[1], 0.0);
    let mut dp = Matrix3::zeros();
    dp[(0, 0)] = cam.fx * iz;
    dp[(0, 2)] = -cam.fx * x * iz2;
    dp[(1, 1)] = cam.fy * iz;
    dp[(1, 2)] = -cam.fy * y * iz2;
    if let Some(d) = obs.depth.filter(|_| bf > 0.0) {
        r[2] = (uv[0] - bf * iz) - (obs.uv[0] - bf / d);
        dp[(2, 0)] = cam.fx * iz;
        dp[(2, 2)] = -cam.fx * x * iz2 + bf * iz2;
    }
    let mut j = SMatrix::<f64, 3, 6>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&dp);
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&(dp * -pc.coords.cross_matrix()));
    Some((r, j))
}

/// Huber's kernel of a squared error `e2` with threshold `delta`: the robust cost and the
/// weight of the squared error (1 inside the threshold), as g2o's `RobustKernelHuber`.
pub fn huber(e2: f64, delta: f64) -> (f64, f64) {
    let e = e2.sqrt();
    if e <= delta { (e2, 1.0) } else { (2.0 * delta * e - delta * delta, delta / e) }
}

/// Motion-only bundle adjustment (ORB-SLAM's `PoseOptimization`): Levenberg-Marquardt on
/// SE(3) over the reprojection errors (and depth, with `bf > 0`: focal length times a virtual
/// baseline, ORB-SLAM2's RGB-D model) whitened by each observation's sigma, Huber kernel at
/// the chi-square 95 % bound, four rounds of ten iterations with every observation
/// re-classified after each round (outliers may come back). `inliers` is the starting
/// classification (all observations when `None`).
pub fn optimize_pose(
    obs: &[PoseObservation],
    cam: &Pinhole,
    bf: f64,
    initial: &Isometry3<f64>,
    inliers: Option<Vec<bool>>,
) -> PoseFit {
    let n = obs.len();
    let mut pose = *initial;
    let mut inlier = inliers.filter(|v| v.len() == n).unwrap_or_else(|| vec![true; n]);
    let bound = |o: &PoseObservation| if o.depth.is_some() && bf > 0.0 { CHI2_3DOF_95 } else { CHI2_2DOF_95 };
    let chi2 = |pose: &Isometry3<f64>, i: usize| -> Option<f64> {
        let o = &obs[i];
        let (r, _) = observation_jacobian(cam, bf, &(pose * o.point), o)?;
        Some(r.norm_squared() / (o.sigma * o.sigma))
    };
    let cost_of = |pose: &Isometry3<f64>, mask: &[bool]| -> f64 {
        (0..n).filter(|&i| mask[i]).map(|i| chi2(pose, i).map_or(0.0, |c| huber(c, bound(&obs[i]).sqrt()).0)).sum()
    };
    for _round in 0..4 {
        let mut lm = LmDamping::default();
        let mut cost = cost_of(&pose, &inlier);
        for _ in 0..10 {
            let mut h = Matrix6::<f64>::zeros();
            let mut g = Vector6::<f64>::zeros();
            for i in (0..n).filter(|&i| inlier[i]) {
                let o = &obs[i];
                let Some((r, j)) = observation_jacobian(cam, bf, &(pose * o.point), o) else { continue };
                let info = 1.0 / (o.sigma * o.sigma);
                let (_, w) = huber(r.norm_squared() * info, bound(o).sqrt());
                let jt = j.transpose();
                h += (w * info) * (jt * j);
                g += (w * info) * (jt * r);
            }
            let Some(step) = lm.damped(&h).cholesky().map(|c| c.solve(&(-g))) else { break };
            let candidate = compose(&step, &pose);
            let new_cost = cost_of(&candidate, &inlier);
            let accepted = new_cost < cost;
            if accepted {
                pose = candidate;
                cost = new_cost;
            }
            if !lm.next(accepted, step.norm(), 1e-10) {
                break;
            }
        }
        for (i, flag) in inlier.iter_mut().enumerate() {
            *flag = chi2(&pose, i).is_some_and(|c| c <= bound(&obs[i]));
        }
    }
    let errors = obs
        .iter()
        .map(|o| cam.project(&(pose * o.point)).map_or(f64::INFINITY, |uv| (uv[0] - o.uv[0]).hypot(uv[1] - o.uv[1])))
        .collect();
    PoseFit { cam_from_world: pose, inliers: inlier, errors }
}

/// Pixel-only observations with one sigma.
fn pixel_observations(world: &[Point3<f64>], pixels: &[[f64; 2]], sigma: f64) -> Vec<PoseObservation> {
    world.iter().zip(pixels).map(|(p, uv)| PoseObservation { point: *p, uv: *uv, sigma, depth: None }).collect()
}

/// [`optimize_pose`] on pixels alone with one sigma for all (pixels, sigma `sigma`).
pub fn refine_pose(
    world: &[Point3<f64>],
    pixels: &[[f64; 2]],
    cam: &Pinhole,
    initial: &Isometry3<f64>,
    sigma: f64,
) -> PoseFit {
    optimize_pose(&pixel_observations(world, pixels, sigma), cam, 0.0, initial, None)
}

/// The unit bearing of a pixel.
pub fn bearing(cam: &Pinhole, uv: [f64; 2]) -> Vector3<f64> {
    let [x, y] = cam.normalised(uv);
    Vector3::new(x, y, 1.0).normalize()
}

/// P3P as a RANSAC estimator: 4-point samples (three solve, the fourth picks among P3P's up
/// to four poses and must reproject within the threshold), the squared reprojection error as
/// residual; no refit (motion-only BA follows in [`pnp_ransac`]).
pub struct P3pEstimator<'a> {
    /// The points, world frame.
    pub world: &'a [Point3<f64>],
    /// Their pixels.
    pub pixels: &'a [[f64; 2]],
    /// The camera.
    pub cam: &'a Pinhole,
    /// Unit bearings of the pixels.
    bearings: Vec<Vector3<f64>>,
    /// The fourth point's test, squared pixels.
    t2: f64,
}

impl<'a> P3pEstimator<'a> {
    /// The estimator for `world[i] <-> pixels[i]`, its fourth-point test at `threshold` pixels.
    pub fn new(world: &'a [Point3<f64>], pixels: &'a [[f64; 2]], cam: &'a Pinhole, threshold: f64) -> Self {
        let bearings = pixels.iter().map(|uv| bearing(cam, *uv)).collect();
        Self { world, pixels, cam, bearings, t2: threshold * threshold }
    }
}

impl Estimator for P3pEstimator<'_> {
    type Model = Isometry3<f64>;
    const SAMPLE_SIZE: usize = 4;
    fn len(&self) -> usize {
        self.world.len()
    }
    fn fit(&self, idx: &[usize]) -> Vec<Isometry3<f64>> {
        let sols = p3p(
            &[self.world[idx[0]], self.world[idx[1]], self.world[idx[2]]],
            &[self.bearings[idx[0]], self.bearings[idx[1]], self.bearings[idx[2]]],
        );
        let Some(pose) = sols.into_iter().min_by(|a, b| self.residual(a, idx[3]).total_cmp(&self.residual(b, idx[3])))
        else {
            return Vec::new();
        };
        let e4 = self.residual(&pose, idx[3]);
        if e4 > self.t2 || e4.is_nan() { Vec::new() } else { vec![pose] }
    }
    fn residual(&self, pose: &Isometry3<f64>, i: usize) -> f64 {
        self.cam.project(&(pose * self.world[i])).map_or(f64::INFINITY, |uv| {
            let (du, dv) = (uv[0] - self.pixels[i][0], uv[1] - self.pixels[i][1]);
            du * du + dv * dv
        })
    }
}

/// P3P inside RANSAC ([`ransac`], uniform samples): `cam_from_world` and the inlier mask
/// (reprojection within `config.threshold` pixels). `None` with fewer than 4 correspondences
/// or no usable sample.
pub fn p3p_ransac(
    world: &[Point3<f64>],
    pixels: &[[f64; 2]],
    cam: &Pinhole,
    config: &RansacConfig,
    rng: &mut SplitMix64,
) -> Option<(Isometry3<f64>, Vec<bool>)> {
    if pixels.len() != world.len() {
        return None;
    }
    let c = ransac(&P3pEstimator::new(world, pixels, cam, config.threshold), config, Sampler::Uniform, rng)?;
    Some((c.model, c.inliers))
}

/// PnP: [`p3p_ransac`] (reprojection threshold `config.threshold` pixels), then motion-only BA
/// started from its consensus. `None` with fewer than 4 correspondences or no usable sample.
pub fn pnp_ransac(
    world: &[Point3<f64>],
    pixels: &[[f64; 2]],
    cam: &Pinhole,
    config: &RansacConfig,
    rng: &mut SplitMix64,
) -> Option<PoseFit> {
    let (pose, mask) = p3p_ransac(world, pixels, cam, config, rng)?;
    let sigma = config.threshold / CHI2_2DOF_95.sqrt();
    Some(optimize_pose(&pixel_observations(world, pixels, sigma), cam, 0.0, &pose, Some(mask)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pnp_config(threshold: f64, max_iterations: usize) -> RansacConfig {
        RansacConfig { threshold, max_iterations, ..RansacConfig::default() }
    }

    /// Points, their pixels, the camera and the true `cam_from_world`.
    type Scene = (Vec<Point3<f64>>, Vec<[f64; 2]>, Pinhole, Isometry3<f64>);

    fn scene(n: usize, seed: u64) -> Scene {
        let cam = Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };
        let truth = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.05, -0.1, 0.2),
        );
        let mut rng = SplitMix64::new(seed);
        let mut world = Vec::new();
        let mut pixels = Vec::new();
        while world.len() < n {
            let pw = Point3::new(rng.uniform() * 4.0 - 2.0, rng.uniform() * 3.0 - 1.5, 2.0 + rng.uniform() * 4.0);
            if let Some(uv) = cam.project(&(truth * pw)) {
                world.push(pw);
                pixels.push(uv);
            }
        }
        (world, pixels, cam, truth)
    }

    fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
        let d = a.inverse() * b;
        (d.translation.vector.norm(), d.rotation.angle())
    }

    #[test]
    fn dlt_recovers_an_exact_pose() {
        let (w, p, cam, truth) = scene(30, 1);
        let est = pnp_dlt(&w, &p, &cam).unwrap();
        let (t, r) = pose_error(&est, &truth);
        assert!(t < 1e-6 && r < 1e-6, "{t} {r}");
    }

    #[test]
    fn ransac_and_motion_only_ba_handle_noise_and_outliers() {
        let (w, mut p, cam, truth) = scene(200, 2);
        let mut rng = SplitMix64::new(9);
        for (i, uv) in p.iter_mut().enumerate() {
            if i < 50 {
                *uv = [rng.uniform() * 640.0, rng.uniform() * 480.0];
            } else {
                uv[0] += rng.uniform() - 0.5;
                uv[1] += rng.uniform() - 0.5;
            }
        }
        let fit = pnp_ransac(&w, &p, &cam, &pnp_config(3.0, 500), &mut SplitMix64::new(4)).unwrap();
        let (t, r) = pose_error(&fit.cam_from_world, &truth);
        assert!(t < 0.01 && r < 0.002, "{t} m, {r} rad");
        assert!(fit.inliers.iter().skip(50).filter(|&&i| i).count() >= 145);
        assert!(fit.inliers.iter().take(50).filter(|&&i| i).count() <= 3);
        // From a perturbed start, BA alone converges to the same pose.
        let start = exp_se3(&Vector6::new(0.05, -0.03, 0.04, 0.02, -0.01, 0.03)) * truth;
        let refined = refine_pose(&w[50..], &p[50..], &cam, &start, 1.0);
        let (t2, r2) = pose_error(&refined.cam_from_world, &truth);
        assert!(t2 < 0.01 && r2 < 0.002, "{t2} {r2}");
    }

    #[test]
    fn degenerate_input_gives_no_pose_and_no_panic() {
        let (w, p, cam, _) = scene(10, 3);
        assert!(pnp_dlt(&w[..5], &p[..5], &cam).is_none());
        assert!(pnp_ransac(&w[..3], &p[..3], &cam, &pnp_config(2.0, 100), &mut SplitMix64::new(0)).is_none());
        let same = vec![Point3::new(1.0, 1.0, 3.0); 10];
        assert!(pnp_dlt(&same, &p, &cam).is_none());
        let fit = refine_pose(&[], &[], &cam, &Isometry3::identity(), 1.0);
        assert!(fit.inliers.is_empty());
    }
}
