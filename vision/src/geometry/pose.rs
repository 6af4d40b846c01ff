//! Camera pose from 3-D points and their images (PnP), as ORB-SLAM's tracking needs it:
//! a linear DLT for initial poses inside RANSAC, then motion-only bundle adjustment
//! (Levenberg-Marquardt on SE(3), Huber kernel, analytic Jacobians, inliers re-classified
//! over four rounds as ORB-SLAM's `PoseOptimization` does).

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, SMatrix, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};

use super::ransac::{SplitMix64, needed};

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x.
    pub cx: f64,
    /// Principal point y.
    pub cy: f64,
}

impl Camera {
    /// Pixel of a point in the camera frame (`None` behind the camera).
    pub fn project(&self, p: &Point3<f64>) -> Option<[f64; 2]> {
        (p.z > 1e-9).then(|| [self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy])
    }
    fn normalised(&self, uv: [f64; 2]) -> [f64; 2] {
        [(uv[0] - self.cx) / self.fx, (uv[1] - self.cy) / self.fy]
    }
}

/// Chi-square 95 % quantile for 2 degrees of freedom: ORB-SLAM's inlier test on squared
/// reprojection errors in units of the measurement's sigma.
pub const CHI2_2DOF_95: f64 = 5.991;

/// `cam_from_world` by the direct linear transform on `n >= 6` correspondences, the rotation
/// projected onto SO(3). `None` when degenerate (coplanar or collinear points can defeat it).
pub fn pnp_dlt(world: &[Point3<f64>], pixels: &[[f64; 2]], cam: &Camera) -> Option<Isometry3<f64>> {
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

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// SE(3) exponential of `xi = (rho, phi)` (translation first), as a pose increment.
fn exp_se3(xi: &Vector6<f64>) -> Isometry3<f64> {
    let rho = Vector3::new(xi[0], xi[1], xi[2]);
    let phi = Vector3::new(xi[3], xi[4], xi[5]);
    let theta = phi.norm();
    let rot = UnitQuaternion::from_scaled_axis(phi);
    let v = if theta < 1e-10 {
        Matrix3::identity() + 0.5 * skew(&phi)
    } else {
        let a = skew(&phi);
        Matrix3::identity()
            + (1.0 - theta.cos()) / (theta * theta) * a
            + (theta - theta.sin()) / (theta.powi(3)) * a * a
    };
    Isometry3::from_parts(Translation3::from(v * rho), rot)
}

/// Motion-only bundle adjustment result.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseFit {
    /// `cam_from_world`.
    pub pose: Isometry3<f64>,
    /// Per correspondence: reprojection error within the chi-square bound at the end.
    pub inliers: Vec<bool>,
    /// Reprojection error per correspondence, pixels.
    pub errors: Vec<f64>,
}

/// Refine `cam_from_world` by Levenberg-Marquardt on the reprojection error (pixels, sigma
/// `sigma`), Huber kernel at the chi-square bound; four rounds of 10 iterations, outliers of
/// each round left out of the next (ORB-SLAM's `PoseOptimization`).
pub fn refine_pose(
    world: &[Point3<f64>],
    pixels: &[[f64; 2]],
    cam: &Camera,
    initial: &Isometry3<f64>,
    sigma: f64,
) -> PoseFit {
    let mut pose = *initial;
    let n = world.len().min(pixels.len());
    let mut inlier = vec![true; n];
    let delta = CHI2_2DOF_95.sqrt() * sigma;
    let residual = |pose: &Isometry3<f64>, i: usize| -> Option<(Vector3<f64>, [f64; 2])> {
        let pc = pose * world[i];
        let uv = cam.project(&pc)?;
        Some((pc.coords, [uv[0] - pixels[i][0], uv[1] - pixels[i][1]]))
    };
    for _round in 0..4 {
        let mut lambda = 1e-3;
        for _ in 0..10 {
            let mut h = Matrix6::<f64>::zeros();
            let mut g = Vector6::<f64>::zeros();
            let mut cost = 0.0;
            for i in (0..n).filter(|&i| inlier[i]) {
                let Some((pc, r)) = residual(&pose, i) else { continue };
                let e = (r[0] * r[0] + r[1] * r[1]).sqrt();
                // Huber: weight 1 inside, delta / e outside.
                let w = if e <= delta { 1.0 } else { delta / e };
                cost += if e <= delta { e * e } else { 2.0 * delta * e - delta * delta };
                let (x, y, z) = (pc.x, pc.y, pc.z);
                let (iz, iz2) = (1.0 / z, 1.0 / (z * z));
                // d(uv)/d(xi) for a left perturbation: d(uv)/d(pc) * [I | -[pc]x].
                let j = SMatrix::<f64, 2, 6>::new(
                    cam.fx * iz,
                    0.0,
                    -cam.fx * x * iz2,
                    -cam.fx * x * y * iz2,
                    cam.fx * (1.0 + x * x * iz2),
                    -cam.fx * y * iz,
                    0.0,
                    cam.fy * iz,
                    -cam.fy * y * iz2,
                    -cam.fy * (1.0 + y * y * iz2),
                    cam.fy * x * y * iz2,
                    cam.fy * x * iz,
                );
                let rv = nalgebra::Vector2::new(r[0], r[1]);
                h += w * j.transpose() * j;
                g += w * j.transpose() * rv;
            }
            let mut damped = h;
            for k in 0..6 {
                damped[(k, k)] += lambda * h[(k, k)].max(1e-9);
            }
            let Some(step) = damped.cholesky().map(|c| c.solve(&(-g))) else { break };
            let candidate = exp_se3(&step) * pose;
            let new_cost: f64 = (0..n)
                .filter(|&i| inlier[i])
                .filter_map(|i| residual(&candidate, i))
                .map(|(_, r)| {
                    let e = (r[0] * r[0] + r[1] * r[1]).sqrt();
                    if e <= delta { e * e } else { 2.0 * delta * e - delta * delta }
                })
                .sum();
            if new_cost < cost {
                pose = candidate;
                lambda = (lambda * 0.3).max(1e-9);
                if step.norm() < 1e-12 {
                    break;
                }
            } else {
                lambda *= 10.0;
            }
        }
        // Re-classify every correspondence (ORB-SLAM lets outliers come back).
        for (i, flag) in inlier.iter_mut().enumerate() {
            *flag =
                residual(&pose, i).is_some_and(|(_, r)| (r[0] * r[0] + r[1] * r[1]) / (sigma * sigma) <= CHI2_2DOF_95);
        }
    }
    let errors = (0..n).map(|i| residual(&pose, i).map_or(f64::INFINITY, |(_, r)| r[0].hypot(r[1]))).collect();
    PoseFit { pose, inliers: inlier, errors }
}

/// PnP with RANSAC over 6-point DLT samples (reprojection threshold `threshold` pixels),
/// then motion-only BA on the best consensus. `None` with fewer than 6 correspondences or no
/// usable sample.
pub fn pnp_ransac(
    world: &[Point3<f64>],
    pixels: &[[f64; 2]],
    cam: &Camera,
    threshold: f64,
    max_iterations: usize,
    rng: &mut SplitMix64,
) -> Option<PoseFit> {
    let n = world.len();
    if n < 6 || pixels.len() != n {
        return None;
    }
    let count = |pose: &Isometry3<f64>| {
        (0..n)
            .filter(|&i| {
                cam.project(&(pose * world[i]))
                    .is_some_and(|uv| (uv[0] - pixels[i][0]).hypot(uv[1] - pixels[i][1]) <= threshold)
            })
            .count()
    };
    let mut best: Option<(Isometry3<f64>, usize)> = None;
    let mut limit = max_iterations.max(1);
    let mut it = 0;
    while it < limit {
        it += 1;
        let mut idx = [0usize; 6];
        for k in 0..6 {
            loop {
                let i = rng.below(n);
                if !idx[..k].contains(&i) {
                    idx[k] = i;
                    break;
                }
            }
        }
        let w: Vec<Point3<f64>> = idx.iter().map(|&i| world[i]).collect();
        let p: Vec<[f64; 2]> = idx.iter().map(|&i| pixels[i]).collect();
        let Some(pose) = pnp_dlt(&w, &p, cam) else { continue };
        let c = count(&pose);
        if best.as_ref().is_none_or(|b| c > b.1) {
            best = Some((pose, c));
            limit = limit.min(needed(c as f64 / n as f64, 6, 0.99, limit));
        }
    }
    let (pose, _) = best?;
    // Refine on the consensus (sigma: the threshold over the chi-square bound).
    Some(refine_pose(world, pixels, cam, &pose, threshold / CHI2_2DOF_95.sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points, their pixels, the camera and the true `cam_from_world`.
    type Scene = (Vec<Point3<f64>>, Vec<[f64; 2]>, Camera, Isometry3<f64>);

    fn scene(n: usize, seed: u64) -> Scene {
        let cam = Camera { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 };
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
        let fit = pnp_ransac(&w, &p, &cam, 3.0, 500, &mut SplitMix64::new(4)).unwrap();
        let (t, r) = pose_error(&fit.pose, &truth);
        assert!(t < 0.01 && r < 0.002, "{t} m, {r} rad");
        assert!(fit.inliers.iter().skip(50).filter(|&&i| i).count() >= 145);
        assert!(fit.inliers.iter().take(50).filter(|&&i| i).count() <= 3);
        // From a perturbed start, BA alone converges to the same pose.
        let start = exp_se3(&Vector6::new(0.05, -0.03, 0.04, 0.02, -0.01, 0.03)) * truth;
        let refined = refine_pose(&w[50..], &p[50..], &cam, &start, 1.0);
        let (t2, r2) = pose_error(&refined.pose, &truth);
        assert!(t2 < 0.01 && r2 < 0.002, "{t2} {r2}");
    }

    #[test]
    fn degenerate_input_gives_no_pose_and_no_panic() {
        let (w, p, cam, _) = scene(10, 3);
        assert!(pnp_dlt(&w[..5], &p[..5], &cam).is_none());
        assert!(pnp_ransac(&w[..5], &p[..5], &cam, 2.0, 100, &mut SplitMix64::new(0)).is_none());
        let same = vec![Point3::new(1.0, 1.0, 3.0); 10];
        assert!(pnp_dlt(&same, &p, &cam).is_none());
        let fit = refine_pose(&[], &[], &cam, &Isometry3::identity(), 1.0);
        assert!(fit.inliers.is_empty());
    }
}
