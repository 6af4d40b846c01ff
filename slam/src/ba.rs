//! Sparse bundle adjustment over key-frame poses and points: Levenberg-Marquardt on the
//! whitened reprojection (and RGB-D virtual-right) residuals with a Huber kernel, the points
//! eliminated by the Schur complement so each step solves one dense 6m x 6m system for the
//! m free poses (m is small in a local window) and back-substitutes 3x3 blocks for the
//! points. Poses use the same left SE(3) perturbation as motion-only BA.

use dynaflow_vision::camera::Pinhole;
use dynaflow_vision::geometry::{CHI2_2DOF_95, CHI2_3DOF_95, PoseObservation, compose, observation_jacobian};
use nalgebra::{DMatrix, DVector, Isometry3, Matrix3, Point3, SMatrix, Vector3, Vector6};

/// A pose taking part in the adjustment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaPose {
    /// `cam_from_world`.
    pub cam_from_world: Isometry3<f64>,
    /// Held constant (key frames outside the window that see window points, and the gauge).
    pub fixed: bool,
}

/// One observation of point `point` from pose `pose` (indices into the slices).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BaObservation {
    /// Index into the poses.
    pub pose: usize,
    /// Index into the points.
    pub point: usize,
    /// Pixel.
    pub uv: [f64; 2],
    /// Measured depth (adds the virtual right coordinate when `bf > 0`).
    pub depth: Option<f64>,
    /// Pixel sigma.
    pub sigma: f64,
}

/// What an adjustment did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct BaReport {
    /// Robust cost before.
    pub initial_cost: f64,
    /// Robust cost after.
    pub final_cost: f64,
    /// Iterations run (accepted or not).
    pub iterations: usize,
}

/// The chi-square bound of an observation (2 or 3 degrees of freedom).
pub fn chi2_bound(depth: Option<f64>, bf: f64) -> f64 {
    if depth.is_some() && bf > 0.0 { CHI2_3DOF_95 } else { CHI2_2DOF_95 }
}

/// Squared whitened error of an observation, `None` behind the camera.
pub fn chi2(cam: &Pinhole, bf: f64, pose: &Isometry3<f64>, point: &Point3<f64>, o: &BaObservation) -> Option<f64> {
    let po = PoseObservation { point: *point, uv: o.uv, sigma: o.sigma, depth: o.depth };
    let (r, _) = observation_jacobian(cam, bf, &(pose * point), &po)?;
    Some(r.norm_squared() / (o.sigma * o.sigma))
}

fn huber(e2: f64, bound: f64) -> (f64, f64) {
    let (e, delta) = (e2.sqrt(), bound.sqrt());
    if e <= delta { (e2, 1.0) } else { (2.0 * delta * e - delta * delta, delta / e) }
}

/// Adjust `poses` (the free ones) and `points` to minimise the robust cost of the observations
/// with `active[i]` true. Deterministic; never panics on degenerate input (a step that cannot be
/// solved raises the damping, and the adjustment stops after `iterations`).
pub fn bundle_adjust(
    cam: &Pinhole,
    bf: f64,
    poses: &mut [BaPose],
    points: &mut [Point3<f64>],
    obs: &[BaObservation],
    active: &[bool],
    iterations: usize,
) -> BaReport {
    let (np, nl) = (poses.len(), points.len());
    let used = |i: usize| active.get(i).copied().unwrap_or(true) && obs[i].pose < np && obs[i].point < nl;
    let cost_of = |poses: &[BaPose], points: &[Point3<f64>]| -> f64 {
        (0..obs.len())
            .filter(|&i| used(i))
            .filter_map(|i| {
                let o = &obs[i];
                chi2(cam, bf, &poses[o.pose].cam_from_world, &points[o.point], o)
                    .map(|c| huber(c, chi2_bound(o.depth, bf)).0)
            })
            .sum()
    };
    // Block index of each free pose.
    let mut block = vec![usize::MAX; poses.len()];
    let mut m = 0;
    for (b, p) in block.iter_mut().zip(poses.iter()) {
        if !p.fixed {
            *b = m;
            m += 1;
        }
    }
    // Observations per point.
    let mut by_point: Vec<Vec<usize>> = vec![Vec::new(); points.len()];
    for i in (0..obs.len()).filter(|&i| used(i)) {
        by_point[obs[i].point].push(i);
    }
    let mut cost = cost_of(poses, points);
    let mut report = BaReport { initial_cost: cost, final_cost: cost, iterations: 0 };
    let mut lambda = 1e-4;
    let n = 6 * m;
    for _ in 0..iterations {
        report.iterations += 1;
        let mut u = DMatrix::<f64>::zeros(n, n);
        let mut gc = DVector::<f64>::zeros(n);
        let mut v = vec![Matrix3::<f64>::zeros(); points.len()];
        let mut gl = vec![Vector3::<f64>::zeros(); points.len()];
        let mut w: Vec<SMatrix<f64, 6, 3>> = vec![SMatrix::zeros(); obs.len()];
        for i in (0..obs.len()).filter(|&i| used(i)) {
            let o = &obs[i];
            let pose = &poses[o.pose].cam_from_world;
            let po = PoseObservation { point: points[o.point], uv: o.uv, sigma: o.sigma, depth: o.depth };
            let Some((r, j)) = observation_jacobian(cam, bf, &(pose * points[o.point]), &po) else { continue };
            let info = 1.0 / (o.sigma * o.sigma);
            let (_, wt) = huber(r.norm_squared() * info, chi2_bound(o.depth, bf));
            let s = wt * info;
            let jl = j.fixed_columns::<3>(0) * pose.rotation.to_rotation_matrix().matrix();
            v[o.point] += s * jl.transpose() * jl;
            gl[o.point] += s * jl.transpose() * r;
            let b = block[o.pose];
            if b != usize::MAX {
                let jt = j.transpose();
                let h = s * jt * j;
                let g = s * jt * r;
                let mut ub = u.view_mut((6 * b, 6 * b), (6, 6));
                ub += h;
                let mut gb = gc.rows_mut(6 * b, 6);
                gb += g;
                w[i] = s * jt * jl;
            }
        }
        // Damped blocks.
        let mut ud = u.clone();
        for k in 0..n {
            ud[(k, k)] += lambda * u[(k, k)].max(1e-6);
        }
        let vinv: Vec<Option<Matrix3<f64>>> = v
            .iter()
            .map(|vl| {
                let mut d = *vl;
                for k in 0..3 {
                    d[(k, k)] += lambda * vl[(k, k)].max(1e-6);
                }
                d.try_inverse()
            })
            .collect();
        // Reduced camera system.
        let mut s = ud;
        let mut rhs = -gc.clone();
        for (l, list) in by_point.iter().enumerate() {
            let Some(vi) = vinv[l] else { continue };
            for &i in list {
                let bi = block[obs[i].pose];
                if bi == usize::MAX {
                    continue;
                }
                let wv = w[i] * vi;
                let mut rb = rhs.rows_mut(6 * bi, 6);
                rb += wv * gl[l];
                for &k in list {
                    let bk = block[obs[k].pose];
                    if bk == usize::MAX {
                        continue;
                    }
                    let mut sb = s.view_mut((6 * bi, 6 * bk), (6, 6));
                    sb -= wv * w[k].transpose();
                }
            }
        }
        let dx = if n == 0 { Some(DVector::zeros(0)) } else { s.cholesky().map(|c| c.solve(&rhs)) };
        let Some(dx) = dx else {
            lambda *= 10.0;
            continue;
        };
        // Candidate.
        let mut cand_poses = poses.to_vec();
        for (p, &b) in cand_poses.iter_mut().zip(&block) {
            if b != usize::MAX {
                let xi = Vector6::from_iterator(dx.rows(6 * b, 6).iter().copied());
                p.cam_from_world = compose(&xi, &p.cam_from_world);
            }
        }
        let mut cand_points = points.to_vec();
        for (l, list) in by_point.iter().enumerate() {
            let Some(vi) = vinv[l] else { continue };
            let mut r = -gl[l];
            for &i in list {
                let b = block[obs[i].pose];
                if b != usize::MAX {
                    r -= w[i].transpose() * dx.rows(6 * b, 6);
                }
            }
            let dl = vi * r;
            if dl.iter().all(|x| x.is_finite()) {
                cand_points[l] += dl;
            }
        }
        let new_cost = cost_of(&cand_poses, &cand_points);
        if new_cost < cost {
            let small = dx.norm() < 1e-10 && (cost - new_cost) < 1e-12 * cost.max(1.0);
            poses.copy_from_slice(&cand_poses);
            points.copy_from_slice(&cand_points);
            cost = new_cost;
            lambda = (lambda * 0.3).max(1e-9);
            if small {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    report.final_cost = cost;
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use dynaflow_vision::geometry::{SplitMix64, exp_se3};
    use nalgebra::{Translation3, UnitQuaternion};

    fn cam() -> Pinhole {
        Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5 }
    }

    /// Five poses along a line looking at a cloud; exact observations.
    fn problem(with_depth: bool) -> (Vec<BaPose>, Vec<Point3<f64>>, Vec<BaObservation>) {
        let mut rng = SplitMix64::new(5);
        let poses: Vec<BaPose> = (0..5)
            .map(|k| BaPose {
                cam_from_world: Isometry3::from_parts(
                    Translation3::new(-0.1 * f64::from(k), 0.02 * f64::from(k), 0.0),
                    UnitQuaternion::from_euler_angles(0.01 * f64::from(k), -0.02 * f64::from(k), 0.0),
                ),
                fixed: k == 0,
            })
            .collect();
        let points: Vec<Point3<f64>> = (0..150)
            .map(|_| Point3::new(rng.uniform() * 3.0 - 1.5, rng.uniform() * 2.0 - 1.0, 2.0 + rng.uniform() * 3.0))
            .collect();
        let mut obs = Vec::new();
        for (pi, p) in poses.iter().enumerate() {
            for (li, x) in points.iter().enumerate() {
                let pc = p.cam_from_world * x;
                if let Some(uv) = cam().project(&pc) {
                    obs.push(BaObservation { pose: pi, point: li, uv, depth: with_depth.then_some(pc.z), sigma: 1.0 });
                }
            }
        }
        (poses, points, obs)
    }

    #[test]
    fn recovers_perturbed_poses_and_points() {
        for with_depth in [false, true] {
            let (truth_poses, truth_points, obs) = problem(with_depth);
            let mut rng = SplitMix64::new(8);
            let mut poses = truth_poses.clone();
            for p in poses.iter_mut().skip(1) {
                let xi = Vector6::from_fn(|_, _| (rng.uniform() - 0.5) * 0.02);
                p.cam_from_world = compose(&xi, &p.cam_from_world);
            }
            let mut points: Vec<Point3<f64>> =
                truth_points.iter().map(|x| x + Vector3::from_fn(|_, _| (rng.uniform() - 0.5) * 0.05)).collect();
            // Two fixed poses fix the gauge and the scale for the pixel-only case.
            poses[1].fixed = !with_depth;
            poses[1].cam_from_world = truth_poses[1].cam_from_world;
            let report = bundle_adjust(&cam(), 40.0, &mut poses, &mut points, &obs, &vec![true; obs.len()], 30);
            assert!(report.final_cost < 1e-6 * report.initial_cost.max(1.0), "{report:?}");
            for (a, b) in poses.iter().zip(&truth_poses) {
                let d = a.cam_from_world.inverse() * b.cam_from_world;
                assert!(d.translation.vector.norm() < 1e-5 && d.rotation.angle() < 1e-6, "{with_depth}: {d:?}");
            }
            for (a, b) in points.iter().zip(&truth_points) {
                assert!((a - b).norm() < 1e-4);
            }
        }
    }

    #[test]
    fn huber_keeps_outliers_from_dragging_the_solution() {
        let (truth_poses, truth_points, mut obs) = problem(true);
        for o in obs.iter_mut().step_by(20) {
            o.uv[0] += 40.0;
        }
        let mut poses = truth_poses.clone();
        let mut points = truth_points.clone();
        poses[2].cam_from_world = exp_se3(&Vector6::new(0.01, 0.0, -0.01, 0.0, 0.005, 0.0)) * poses[2].cam_from_world;
        bundle_adjust(&cam(), 40.0, &mut poses, &mut points, &obs, &vec![true; obs.len()], 20);
        let d = poses[2].cam_from_world.inverse() * truth_poses[2].cam_from_world;
        assert!(d.translation.vector.norm() < 3e-3, "{d:?}");
    }

    #[test]
    fn empty_and_degenerate_problems_do_not_panic() {
        let r = bundle_adjust(&cam(), 40.0, &mut [], &mut [], &[], &[], 5);
        assert_eq!(r.final_cost, 0.0);
        let mut poses = [BaPose { cam_from_world: Isometry3::identity(), fixed: false }];
        let mut points = [Point3::new(0.0, 0.0, -1.0)];
        let obs = [BaObservation { pose: 0, point: 0, uv: [1.0, 1.0], depth: None, sigma: 1.0 }];
        bundle_adjust(&cam(), 40.0, &mut poses, &mut points, &obs, &[true], 5);
        assert!(poses[0].cam_from_world.translation.vector.iter().all(|v| v.is_finite()));
    }
}
